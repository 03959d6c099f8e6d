// The regions stage (tiles in, region batches on gossip_out and the regions channel) and the mission
// stage (gossip records, poses and routes in; goal, records and status out) on real channels.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "stage_rig.hpp"

namespace ag::mission {
namespace {
using test::GridWorld;
using test::MissionRig;
using test::RegionsRig;

std::vector<RegionBatch> drain(RingReader<comms::GossipPublishMsg, comms::kGossipRing>& r) {
  std::vector<RegionBatch> out;
  for (comms::GossipPublishMsg* m = r.front(); m != nullptr; m = r.front()) {
    EXPECT_EQ(comms::topic_kind(m->topic), comms::TopicKind::kRegions);
    RegionBatch b;
    EXPECT_EQ(decode(std::span<const std::uint8_t>(m->payload.data(), m->size), b), DecodeError::kOk);
    EXPECT_EQ(comms::topic_index(m->topic), out.size());
    out.push_back(b);
    r.pop();
  }
  return out;
}

TEST(RegionsStage, PublishesVersionedBatchesWhenTilesChangeAtMostEveryPeriod) {
  GridWorld w(6, 4, ClassId::kRoad);
  for (int k = 0; k < 45; ++k) w.car(4.0 + (k % 9) * 18.0, 4.0 + (k / 9) * 16.0);  // 45 cars 13.5 / 14 m apart: each its own region
  RegionsRig rig(w, 1.0);
  for (int ty = 0; ty < 4; ++ty)
    for (int tx = 0; tx < 6; ++tx) rig.push(w, tx, ty, 1);
  rig.clock.set(from_seconds(0.1));
  rig.stage->step(rig.clock.now());
  const auto b1 = drain(rig.gossip_r);
  ASSERT_EQ(b1.size(), 2U) << "45 regions travel in two batches of at most 40";
  EXPECT_EQ(b1[0].count, 40);
  EXPECT_EQ(b1[1].count, 5);
  EXPECT_EQ(b1[0].batches, 2);
  EXPECT_EQ(b1[0].regions_version, b1[1].regions_version);
  const RegionsMsg& m = rig.regions_r.read();
  EXPECT_EQ(m.count, 45U);
  EXPECT_EQ(m.version, b1[0].regions_version);
  for (std::uint32_t i = 0; i < m.count; ++i) EXPECT_TRUE(m.regions[i].goal_valid);
  // a tile changes (cars removed from tile 0,0) -- within the period: not yet; after it: a new version
  w.rect(0, 0, 32, 32, ClassId::kRoad);
  rig.push(w, 0, 0, 2);
  rig.clock.set(from_seconds(0.6));
  rig.stage->step(rig.clock.now());
  EXPECT_TRUE(drain(rig.gossip_r).empty()) << "re-extraction waits for period_s";
  rig.clock.set(from_seconds(1.2));
  rig.stage->step(rig.clock.now());
  const auto b2 = drain(rig.gossip_r);
  ASSERT_FALSE(b2.empty());
  EXPECT_GT(b2[0].regions_version, b1[0].regions_version);
  std::size_t n = 0;
  for (const auto& b : b2) n += b.count;
  EXPECT_LT(n, 45U);
  EXPECT_EQ(rig.regions_r.read().count, n);
  EXPECT_EQ(rig.stage->counters().extractions, 2U);
  // nothing changed since: nothing extracted, nothing published
  rig.clock.set(from_seconds(5.0));
  rig.stage->step(rig.clock.now());
  EXPECT_TRUE(drain(rig.gossip_r).empty());
  EXPECT_EQ(rig.stage->counters().extractions, 2U);
}

TEST(RegionsStage, TilesOutsideTheAreaAreCounted) {
  GridWorld w(2, 2, ClassId::kRoad);
  RegionsRig rig(w);
  rig.push(w, 7, 7, 1);
  rig.stage->step(0);
  EXPECT_EQ(rig.stage->counters().tiles_rejected, 1U);
}

TEST(MissionStage, ClaimsTheNearestRegionSendsTheGoalAndReportsAVisit) {
  MissionRig rig(2, 1);
  RegionBatch b;
  b.batches = 1;
  b.regions_version = 1;
  b.count = 2;
  b.regions[0] = RegionRecord{10, 50, 0, 50, 0, 36, true};
  b.regions[1] = RegionRecord{11, 20, 0, 20, 1, 36, true};
  std::array<std::uint8_t, 1024> buf{};
  rig.record(0, regions_topic(0), std::span<const std::uint8_t>(buf.data(), encode(b, buf)));
  rig.pose(0, 0, 0.5);
  rig.step();
  const GoalMsg& g = rig.goal_r.read();
  EXPECT_FALSE(g.cancel);
  EXPECT_DOUBLE_EQ(g.goal.x, 20.0);
  EXPECT_DOUBLE_EQ(g.goal.y, 1.0);
  bool claim = false;
  for (comms::GossipPublishMsg* m = rig.gossip_r.front(); m != nullptr; m = rig.gossip_r.front()) {
    if (m->topic == kClaimTopic) {
      ClaimRecord c;
      ASSERT_EQ(decode(std::span<const std::uint8_t>(m->payload.data(), m->size), c), DecodeError::kOk);
      EXPECT_EQ(c.region_id, 11U);
      EXPECT_EQ(c.state, ClaimState::kGoing);
      EXPECT_EQ(c.priority, 1);
      claim = true;
    }
    rig.gossip_r.pop();
  }
  EXPECT_TRUE(claim);
  EXPECT_EQ(rig.status_r.read().region_id, 11U);
  // arrive
  rig.pose(19, 1, 0.5);
  rig.step();
  bool visited = false;
  for (comms::GossipPublishMsg* m = rig.gossip_r.front(); m != nullptr; m = rig.gossip_r.front()) {
    if (m->topic == kVisitedTopic) {
      VisitedRecord v;
      ASSERT_EQ(decode(std::span<const std::uint8_t>(m->payload.data(), m->size), v), DecodeError::kOk);
      ASSERT_EQ(v.count, 1);
      EXPECT_EQ(v.entries[0].region_id, 11U);
      visited = true;
    }
    rig.gossip_r.pop();
  }
  EXPECT_TRUE(visited);
  EXPECT_DOUBLE_EQ(rig.goal_r.read().goal.x, 50.0) << "on to the next";
  EXPECT_EQ(rig.status_r.read().visited_own, 1U);
}

TEST(MissionStage, RouteFailuresFromThePlannerBecomeAFailureRecord) {
  MissionRig rig(1, 1, {"mission.max_no_route=2"});
  RegionBatch b;
  b.batches = 1;
  b.regions_version = 1;
  b.count = 1;
  b.regions[0] = RegionRecord{4, 30, 0, 30, 0, 36, true};
  std::array<std::uint8_t, 1024> buf{};
  rig.record(0, regions_topic(0), std::span<const std::uint8_t>(buf.data(), encode(b, buf)));
  rig.pose(0, 0, 0.5);
  rig.step();
  const std::uint32_t gid = rig.goal_r.read().id;
  for (std::uint32_t s = 1; s <= 2; ++s) {
    rig.path->goal_id = gid;
    rig.path->seq = s;
    rig.path->status = RouteStatus::kNoRoute;
    rig.path_w.publish(*rig.path);
    rig.step();
  }
  bool failure = false;
  for (comms::GossipPublishMsg* m = rig.gossip_r.front(); m != nullptr; m = rig.gossip_r.front()) {
    if (comms::topic_kind(m->topic) == comms::TopicKind::kFailures) {
      FailureRecord f;
      ASSERT_EQ(decode(std::span<const std::uint8_t>(m->payload.data(), m->size), f), DecodeError::kOk);
      EXPECT_EQ(f.region_id, 4U);
      EXPECT_EQ(f.reason, FailureReason::kNoRoute);
      EXPECT_EQ(m->topic, failure_topic(4));
      failure = true;
    }
    rig.gossip_r.pop();
  }
  EXPECT_TRUE(failure);
  EXPECT_TRUE(rig.goal_r.read().cancel);
  EXPECT_EQ(rig.status_r.read().failed_own, 1U);
}

TEST(MissionStage, ATeamPoseKeepsAClaimAliveAndMalformedRecordsAreCounted) {
  MissionRig rig(2, 2, {"mission.claim_timeout_s=5"});
  RegionBatch b;
  b.batches = 1;
  b.regions_version = 1;
  b.count = 1;
  b.regions[0] = RegionRecord{4, 10, 0, 10, 0, 36, true};
  std::array<std::uint8_t, 1024> buf{};
  rig.record(0, regions_topic(0), std::span<const std::uint8_t>(buf.data(), encode(b, buf)));
  ClaimRecord c{ClaimState::kGoing, 1, 4, 10, 0, 0.5f};
  rig.record(1, kClaimTopic, std::span<const std::uint8_t>(buf.data(), encode(c, buf)));
  const std::uint8_t junk[3] = {1, 0, 0};
  rig.record(1, kVisitedTopic, junk);
  comms::TeamPosesMsg team;
  team.count = 1;
  team.robots[0].robot = 1;
  for (int i = 0; i < 40; ++i) {  // 8 s: robot 1 keeps sending poses
    team.robots[0].stamp = rig.clock.now();
    rig.team_w.publish(team);
    rig.pose(0, 0, 0.5);
    rig.step();
    ASSERT_EQ(rig.status_r.read().region_id, kNoRegion) << "robot 1 is alive and claims it";
  }
  EXPECT_EQ(rig.stage->counters().records_bad, 1U);
  for (int i = 0; i < 30; ++i) {  // robot 1 goes silent
    rig.pose(0, 0, 0.5);
    rig.step();
  }
  EXPECT_EQ(rig.status_r.read().region_id, 4U);
  EXPECT_EQ(rig.status_r.read().takeovers, 1U);
}

TEST(MissionStage, WaypointsParameter) {
  ManagerParams p;
  ASSERT_TRUE(parse_waypoints("1,2; 3.5 , -4;;", p).ok());
  ASSERT_EQ(p.waypoint_count, 2U);
  EXPECT_DOUBLE_EQ(p.waypoint_x[1], 3.5);
  EXPECT_DOUBLE_EQ(p.waypoint_y[1], -4);
  ASSERT_TRUE(parse_waypoints("", p).ok());
  EXPECT_EQ(p.waypoint_count, 0U);
  const auto bad = parse_waypoints("1,2;3;4,5", p);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("mission.waypoints item 2 '3'"), std::string::npos) << bad.error().message;
  EXPECT_FALSE(parse_waypoints("1,2,3", p).ok());
  EXPECT_FALSE(parse_waypoints("a,b", p).ok());
  // through the config: the stage goes to the first waypoint
  MissionRig rig(1, 1, {"mission.waypoints=7,8;9,10"});
  rig.pose(0, 0, 0.5);
  rig.step();
  EXPECT_DOUBLE_EQ(rig.goal_r.read().goal.x, 7.0);
  EXPECT_DOUBLE_EQ(rig.goal_r.read().goal.y, 8.0);
}

TEST(TargetsStage, ACarInTheScansBecomesAnObjectRecordOnGossip) {
  MissionRig rig(2, 1);
  auto scan = std::make_unique<LidarScanMsg>();
  scan->labels = LabelSource::kGroundTruth;
  scan->sensor_in_body = Pose3{0, 0, 0.8, 0, 0, 0};
  // a car's long side facing the robot, centre line 10 m east of it: returns on the near side only
  std::uint32_t n = 0;
  for (double v = -2.25; v <= 2.25; v += 0.05)
    for (double z = 0.2; z <= 1.4; z += 0.2) {
      ScanReturn& r = scan->points[n++];
      r.x = 9.0f;  // near face at x = 9, the car spans 9..11
      r.y = static_cast<float>(v);
      r.z = static_cast<float>(z - 0.8);
      r.range = std::sqrt(r.x * r.x + r.y * r.y + r.z * r.z);
      r.cls = 5;
    }
  scan->count = n;
  for (int k = 0; k < 5; ++k) {
    rig.pose(100, 50, 0.3);  // robot at (100, 50) facing east
    scan->stamp = rig.clock.now();
    EXPECT_EQ(rig.lidar_w.push(*scan), 0U);
    rig.targets->step(rig.clock.now());
    rig.step();
  }
  EXPECT_EQ(rig.targets->counters().detections, 5U);
  ASSERT_EQ(rig.targets->tracker().objects().size(), 1U);
  bool object = false;
  for (comms::GossipPublishMsg* m = rig.gossip_r.front(); m != nullptr; m = rig.gossip_r.front()) {
    if (is_object_topic(m->topic)) {
      ObjectRecord o;
      ASSERT_EQ(decode(std::span<const std::uint8_t>(m->payload.data(), m->size), o), DecodeError::kOk);
      EXPECT_NEAR(o.x, 109.0, 0.3) << "the visible face";
      EXPECT_NEAR(o.y, 50.0, 0.3);
      EXPECT_GE(o.detections, 3);
      EXPECT_GT(o.cxx, 0.0f);
      object = true;
    }
    rig.gossip_r.pop();
  }
  EXPECT_TRUE(object) << "confirmed after min_detections, forwarded by the mission stage";
  // an uncertain pose: scans are not used
  rig.pose(100, 50, 3.0);
  EXPECT_EQ(rig.lidar_w.push(*scan), 0U);
  rig.targets->step(rig.clock.now());
  EXPECT_EQ(rig.targets->counters().scans_skipped_pose, 1U);
}

}  // namespace
}  // namespace ag::mission
