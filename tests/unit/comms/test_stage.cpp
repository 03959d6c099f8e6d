// The comms stage: a quadrotor's tiles reach a ground robot's localizer input, the ground robot's pose
// and claims reach the quadrotor, stats per peer, the journal across a restart, config errors, and the
// udp transport on loopback; an operator's command for one robot.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>

#include "airground/comms/link_hub.hpp"
#include "map_fixture.hpp"
#include "stage_rig.hpp"
#include "team_rig.hpp"

namespace ag::comms {
namespace {
using test::CommsRig;

std::vector<std::string> common(const std::string& key, int id) {
  return {"robot.id=" + std::to_string(id), "comms.key_file=" + key, "comms.epoch_from_clock=false", "comms.digest_period_s=0.2"};
}

struct Pair {
  test::TempDir dir;
  LinkHub hub{2, 0.1, 3};
  std::unique_ptr<CommsRig> uav, ugv;
  std::string key = test::write_key_file(dir.file("team.key"));
  Pair() {
    register_inproc_link("uav", &hub.endpoint(0));
    register_inproc_link("ugv1", &hub.endpoint(1));
  }
  ~Pair() {
    uav.reset();
    ugv.reset();
    register_inproc_link("uav", nullptr);
    register_inproc_link("ugv1", nullptr);
  }
  void make_uav() {
    auto s = common(key, 0);
    s.insert(s.end(), {"comms.transport=inproc", "comms.send_map_tiles=true", "comms.journal=" + dir.file("uav.agj")});
    auto r = CommsRig::make("uav", s);
    ASSERT_TRUE(r.ok()) << r.error().message;
    uav = std::move(r.value());
  }
  void make_ugv() {
    auto s = common(key, 1);
    s.insert(s.end(), {"comms.transport=inproc", "comms.send_pose=true", "comms.deliver_map_tiles=true",
                       "comms.journal=" + dir.file("ugv.agj"), "probe.read_tiles=true"});
    auto r = CommsRig::make("ugv1", s);
    ASSERT_TRUE(r.ok()) << r.error().message;
    ugv = std::move(r.value());
  }
};

TEST(CommsStage, TilesPosesAndClaimsFlowBetweenAQuadrotorAndAGroundRobot) {
  Pair p;
  p.make_uav();
  p.make_ugv();
  ASSERT_TRUE(p.uav && p.ugv);
  auto tile = std::make_unique<MapTileMsg>();
  for (int k = 0; k < 20; ++k) {
    test::make_tile(*tile, k % 5, k / 5, 160.0, 1);
    ASSERT_EQ(p.uav->tiles_w.push(*tile), 0U);
  }
  LocalizationMsg pose;
  pose.stamp = 5 * kNsPerS;
  pose.status = LocalizationStatus::kTracking;
  pose.pose = Pose2{12.5, -3.25, 0.75};
  pose.covariance[0] = 4.0;
  p.ugv->pose_w.publish(pose);
  GossipPublishMsg claim;
  claim.topic = make_topic(TopicKind::kClaims, 0);
  claim.size = 5;
  std::memcpy(claim.payload.data(), "goal7", 5);
  ASSERT_EQ(p.ugv->out_w.push(claim), 0U);

  std::vector<std::unique_ptr<MapTileMsg>> got;
  for (int k = 0; k < 200; ++k) {
    const TimeNs now = kNsPerS + k * 50 * kNsPerMs;
    p.uav->step(now);
    p.ugv->step(now);
    for (MapTileMsg* t = p.ugv->probe->tiles.front(); t != nullptr; t = p.ugv->probe->tiles.front()) {
      got.push_back(std::make_unique<MapTileMsg>(*t));
      p.ugv->probe->tiles.pop();
    }
  }
  ASSERT_EQ(got.size(), 20U) << "every tile reached the ground robot's map_tiles";
  for (const auto& t : got) {
    MapTileMsg want;
    test::make_tile(want, t->tx, t->ty, 160.0, 1);
    EXPECT_EQ(t->cls, want.cls);
    for (std::size_t i = 0; i < kTileCellCount; i += 97) EXPECT_NEAR(t->elevation[i], want.elevation[i], 0.0051);
  }
  const TeamPosesMsg& team = p.uav->stage->team();
  ASSERT_EQ(team.count, 1U);
  EXPECT_EQ(team.robots[0].robot, 1);
  EXPECT_DOUBLE_EQ(team.robots[0].pose.x, 12.5);
  EXPECT_DOUBLE_EQ(team.robots[0].pose.yaw, 0.75);
  EXPECT_FLOAT_EQ(team.robots[0].sigma_x_m, 2.0f);
  EXPECT_EQ(team.robots[0].stamp, 5 * kNsPerS);
  GossipRecordMsg* rec = p.uav->probe->records.front();
  ASSERT_NE(rec, nullptr) << "the claim reached the quadrotor's gossip_in";
  EXPECT_EQ(rec->key.origin, 1);
  EXPECT_EQ(rec->key.topic, make_topic(TopicKind::kClaims, 0));
  EXPECT_EQ(std::string(reinterpret_cast<const char*>(rec->payload.data()), rec->size), "goal7");

  const CommsStatsMsg& su = p.uav->probe->stats.read();
  const CommsStatsMsg& sg = p.ugv->probe->stats.read();
  EXPECT_EQ(su.tiles_out, 20U);
  EXPECT_EQ(sg.tiles_in, 20U);
  EXPECT_EQ(su.records, 22U);
  EXPECT_EQ(sg.records, 22U);
  ASSERT_EQ(su.peers, 1U);
  EXPECT_EQ(su.peer[0].robot, 1);
  EXPECT_EQ(su.peer[0].records_in, 2U) << "pose and claim from the ground robot";
  EXPECT_GE(su.peer[0].records_out, 20U);
  EXPECT_GT(su.peer[0].bytes_out, su.peer[0].bytes_in);
  EXPECT_EQ(sg.peer[0].records_in, 20U);
  EXPECT_EQ(sg.drops[static_cast<std::size_t>(DropReason::kForged)], 0U);
  EXPECT_GE(su.journal_appends, 22U);
}

TEST(CommsStage, ARestartedRobotGetsItsStoreBackFromTheJournalAndItsStagesSeeIt) {
  Pair p;
  p.make_uav();
  p.make_ugv();
  auto tile = std::make_unique<MapTileMsg>();
  for (int k = 0; k < 6; ++k) {
    test::make_tile(*tile, k, 0, 160.0, 1);
    ASSERT_EQ(p.uav->tiles_w.push(*tile), 0U);
  }
  for (int k = 0; k < 100; ++k) {
    p.uav->step(kNsPerS + k * 50 * kNsPerMs);
    p.ugv->step(kNsPerS + k * 50 * kNsPerMs);
  }
  ASSERT_EQ(p.ugv->stage->store().size(), 6U);
  p.ugv.reset();  // the ground robot restarts, alone (the quadrotor is gone)
  p.uav.reset();
  p.make_ugv();
  ASSERT_TRUE(p.ugv);
  EXPECT_EQ(p.ugv->stage->store().size(), 6U);
  EXPECT_EQ(p.ugv->stage->journal_report().records_loaded, 6U);
  int delivered = 0;
  for (int k = 0; k < 10; ++k) {
    p.ugv->step(20 * kNsPerS + k * 50 * kNsPerMs);
    for (MapTileMsg* t = p.ugv->probe->tiles.front(); t != nullptr; t = p.ugv->probe->tiles.front()) {
      ++delivered;
      p.ugv->probe->tiles.pop();
    }
  }
  EXPECT_EQ(delivered, 6) << "the localizer gets the restored map without any peer";
}

// The base station's arm / disarm for one robot: that robot's comms stage writes it to "radio_arm" once,
// as it arrives; another robot's command, a malformed one and the one its journal held at a restart
// never act.
TEST(CommsStage, AnOperatorCommandReachesItsRobotsRadioArmOnceAndNeverAfterARestart) {
  Pair p;
  p.make_uav();  // robot 0 plays the base station here
  p.make_ugv();
  TimeNs now = kNsPerS;
  auto run = [&](int steps) {
    for (int k = 0; k < steps; ++k, now += 50 * kNsPerMs) {
      p.uav->step(now);
      p.ugv->step(now);
    }
  };
  auto command = [&](RobotId robot, OperatorCommand c, std::uint32_t request, std::uint32_t size = kCommandPayloadBytes) {
    GossipPublishMsg g;
    g.stamp = now;
    g.topic = command_topic(robot);
    g.size = static_cast<std::uint32_t>(encode_command(c, request, std::span<std::uint8_t>(g.payload.data(), g.payload.size())));
    g.size = size;
    ASSERT_EQ(p.uav->out_w.push(g), 0U);
  };
  auto arms = [&]() {  // what reached "radio_arm" since the last look: -1 nothing, 0 disarm, 1 arm
    if (!p.ugv->probe->arm.fresh()) return -1;
    return p.ugv->probe->arm.read().arm ? 1 : 0;
  };
  auto stats = [&]() { return p.ugv->probe->stats.read(); };
  run(20);
  EXPECT_EQ(arms(), -1);
  command(1, OperatorCommand::kArm, 1);
  run(40);
  EXPECT_EQ(arms(), 1);
  EXPECT_EQ(stats().commands_in, 1U);
  run(40);
  EXPECT_EQ(arms(), -1) << "once";
  command(7, OperatorCommand::kArm, 2);  // another robot's
  run(40);
  EXPECT_EQ(arms(), -1);
  EXPECT_EQ(stats().commands_in, 1U);
  command(1, OperatorCommand::kArm, 3, 3);  // malformed
  run(40);
  EXPECT_EQ(arms(), -1);
  EXPECT_EQ(stats().commands_bad, 1U);
  command(1, OperatorCommand::kDisarm, 4);
  run(40);
  EXPECT_EQ(arms(), 0);
  EXPECT_EQ(stats().commands_in, 2U);
  // The ground robot restarts with the disarm in its journal: it does not act on it again.
  p.ugv.reset();
  p.make_ugv();
  ASSERT_TRUE(p.ugv);
  run(40);
  EXPECT_EQ(arms(), -1) << "a command the journal restored acted again";
  EXPECT_EQ(stats().commands_in, 0U);
  command(1, OperatorCommand::kArm, 5);  // a new one does
  run(40);
  EXPECT_EQ(arms(), 1);
  EXPECT_EQ(stats().commands_in, 1U);
}

TEST(CommsStage, ConfigErrorsNameTheKey) {
  test::TempDir dir;
  const std::string key = test::write_key_file(dir.file("team.key"));
  auto both = CommsRig::make("x", {"comms.send_map_tiles=true", "comms.deliver_map_tiles=true"});
  ASSERT_FALSE(both.ok());
  EXPECT_NE(both.error().message.find("deliver_map_tiles"), std::string::npos);
  auto nokey = CommsRig::make("x", {"comms.transport=udp", "comms.key_file=" + dir.file("missing.key")});
  ASSERT_FALSE(nokey.ok());
  EXPECT_NE(nokey.error().message.find("key_file"), std::string::npos);
  EXPECT_NE(nokey.error().message.find("missing.key"), std::string::npos);
  auto noreg = CommsRig::make("nobody", {"comms.transport=inproc", "comms.key_file=" + key});
  ASSERT_FALSE(noreg.ok());
  EXPECT_NE(noreg.error().message.find("nobody"), std::string::npos);
  auto badpeer = CommsRig::make("x", {"comms.transport=udp", "comms.key_file=" + key, "comms.peers=10.0.0.300"});
  ASSERT_FALSE(badpeer.ok());
  EXPECT_NE(badpeer.error().message.find("10.0.0.300"), std::string::npos);
  std::ofstream(dir.file("bad.key")) << "not a key";
  auto badkey = CommsRig::make("x", {"comms.transport=inproc", "comms.key_file=" + dir.file("bad.key")});
  ASSERT_FALSE(badkey.ok());
  EXPECT_NE(badkey.error().message.find("64 hex digits"), std::string::npos);
}

// Two stages on loopback UDP, each with the other as its unicast peer (no broadcast).
TEST(CommsStage, UdpTransportOnLoopback) {
  test::TempDir dir;
  const std::string key = test::write_key_file(dir.file("team.key"));
  const int pa = 47000 + static_cast<int>(::getpid() % 500) * 2, pb = pa + 1;
  auto a = CommsRig::make("a", {"robot.id=3", "comms.transport=udp", "comms.key_file=" + key, "comms.bind=127.0.0.1",
                                "comms.port=" + std::to_string(pa), "comms.broadcast=", "comms.peers=127.0.0.1:" + std::to_string(pb),
                                "comms.digest_period_s=0.1"});
  ASSERT_TRUE(a.ok()) << a.error().message;
  auto b = CommsRig::make("b", {"robot.id=4", "comms.transport=udp", "comms.key_file=" + key, "comms.bind=127.0.0.1",
                                "comms.port=" + std::to_string(pb), "comms.broadcast=", "comms.peers=127.0.0.1:" + std::to_string(pa),
                                "comms.digest_period_s=0.1"});
  ASSERT_TRUE(b.ok()) << b.error().message;
  GossipPublishMsg m;
  m.topic = make_topic(TopicKind::kFailures, 2);
  m.size = 3;
  ASSERT_EQ(a.value()->out_w.push(m), 0U);
  bool arrived = false;
  for (int k = 0; k < 400 && !arrived; ++k) {
    const TimeNs now = kNsPerS + k * 10 * kNsPerMs;
    a.value()->step(now);
    b.value()->step(now);
    arrived = b.value()->probe->records.front() != nullptr;
    usleep(2000);
  }
  EXPECT_TRUE(arrived) << "a's failure record reached b over UDP";
}

}  // namespace
}  // namespace ag::comms
