// The mission stages' step() never allocates once initialised (operator new counted by
// tests/common/counting_new.hpp): tiles in, extraction, batches out; records in, choosing, claiming,
// visiting, failing, returning, records and goals out.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "stage_rig.hpp"

#include "../../common/counting_new.hpp"

namespace ag::mission {
namespace {
using test::GridWorld;
using test_alloc::AllocationWindow;

TEST(NoAllocation, TheCounterSeesAllocations) {
  AllocationWindow w;
  std::vector<int> v(100);
  EXPECT_GE(w.allocations(), 1U);
}

TEST(NoAllocation, RegionsStageStepWithTilesExtractionAndPublishing) {
  GridWorld w(4, 4, ClassId::kRoad);
  w.rect(0, 60, 60, 80, ClassId::kBuilding);
  for (int k = 0; k < 50; ++k) w.car(4.0 + (k % 7) * 18.0, 4.0 + (k / 7) * 16.0);
  test::RegionsRig rig(w, 0.5);
  std::vector<std::vector<std::uint8_t>> tiles;  // three rounds of 16 tiles, made before the window
  for (int round = 0; round < 3; ++round) {
    for (int ty = 0; ty < 4; ++ty)
      for (int tx = 0; tx < 4; ++tx) tiles.push_back(w.tile(tx, ty));
    w.rect(0, 0, 20.0 + 18.0 * round, 20, ClassId::kRoad);  // cars leave: a new version each round
  }
  std::uint64_t published = 0;
  {
    AllocationWindow window;
    for (int round = 0; round < 3; ++round) {
      for (int ty = 0; ty < 4; ++ty)
        for (int tx = 0; tx < 4; ++tx)
          rig.push(tiles[static_cast<std::size_t>(round * 16 + ty * 4 + tx)], tx, ty, static_cast<std::uint64_t>(round + 1));
      rig.clock.set(rig.clock.now() + from_seconds(1.0));
      rig.stage->step(rig.clock.now());
      for (auto* m = rig.gossip_r.front(); m != nullptr; m = rig.gossip_r.front()) {
        ++published;
        rig.gossip_r.pop();
      }
    }
    EXPECT_EQ(window.allocations(), 0U) << "allocations in RegionsStage::step";
  }
  EXPECT_EQ(rig.stage->counters().extractions, 3U);
  EXPECT_GE(published, 4U);
}

TEST(NoAllocation, MissionStageStepThroughChoosingVisitingFailingAndReturning) {
  test::MissionRig rig(2, 1, {"mission.max_no_route=2", "mission.idle_return_s=2"});
  RegionBatch b;
  b.batches = 1;
  b.regions_version = 1;
  b.count = 3;
  b.regions[0] = RegionRecord{1, 10, 0, 10, 0, 36, true};
  b.regions[1] = RegionRecord{2, 20, 0, 20, 0, 36, true};
  b.regions[2] = RegionRecord{3, 30, 0, 30, 0, 36, true};
  std::array<std::uint8_t, 1024> buf{};
  const std::size_t nb = encode(b, buf);
  ClaimRecord c{ClaimState::kGoing, 3, 3, 30, 0, 0.4f};
  std::array<std::uint8_t, 64> cb{};
  const std::size_t nc = encode(c, cb);
  comms::TeamPosesMsg team;
  team.count = 1;
  team.robots[0].robot = 7;
  std::uint64_t out = 0;
  {
    AllocationWindow window;
    rig.record(0, regions_topic(0), std::span<const std::uint8_t>(buf.data(), nb));
    rig.record(7, kClaimTopic, std::span<const std::uint8_t>(cb.data(), nc));
    for (int i = 0; i < 60; ++i) {
      team.robots[0].stamp = rig.clock.now();
      rig.team_w.publish(team);
      const double x = i < 5 ? 0.0 : (i < 10 ? 10.0 : 0.0);
      rig.pose(x, 0, 0.5);
      if (i >= 10 && i < 14) {  // region 2: no route twice -> failure
        rig.path->goal_id = rig.goal_r.read().id;
        rig.path->seq = static_cast<std::uint32_t>(i);
        rig.path->status = RouteStatus::kNoRoute;
        rig.path_w.publish(*rig.path);
      }
      rig.step();
      for (auto* m = rig.gossip_r.front(); m != nullptr; m = rig.gossip_r.front()) {
        ++out;
        rig.gossip_r.pop();
      }
    }
    EXPECT_EQ(window.allocations(), 0U) << "allocations in MissionStage::step";
  }
  const MissionStatusMsg& s = rig.status_r.read();
  EXPECT_EQ(s.visited_own, 1U);
  EXPECT_EQ(s.failed_own, 1U);
  EXPECT_TRUE(s.state == ClaimState::kReturning || s.state == ClaimState::kDone);
  EXPECT_GE(out, 3U);
}

TEST(NoAllocation, TargetsStageStepAndTheMissionStageForwardingObjects) {
  test::MissionRig rig(2, 1);
  auto scan = std::make_unique<LidarScanMsg>();
  scan->labels = LabelSource::kGroundTruth;
  std::uint32_t n = 0;
  for (double v = -2.25; v <= 2.25; v += 0.05)
    for (double z = -0.6; z <= 0.6; z += 0.2) {
      ScanReturn& r = scan->points[n++];
      r.x = 9.0f;
      r.y = static_cast<float>(v);
      r.z = static_cast<float>(z);
      r.range = std::sqrt(r.x * r.x + r.y * r.y + r.z * r.z);
      r.cls = 5;
    }
  scan->count = n;
  std::uint64_t out = 0;
  {
    AllocationWindow window;
    for (int k = 0; k < 8; ++k) {
      rig.pose(100, 50 + 0.1 * k, 0.3);
      scan->stamp = rig.clock.now();
      (void)rig.lidar_w.push(*scan);
      rig.targets->step(rig.clock.now());
      rig.step(3.0);
      for (auto* m = rig.gossip_r.front(); m != nullptr; m = rig.gossip_r.front()) {
        if (is_object_topic(m->topic)) ++out;
        rig.gossip_r.pop();
      }
    }
    EXPECT_EQ(window.allocations(), 0U) << "allocations in TargetsStage::step / MissionStage::step";
  }
  EXPECT_GE(out, 2U);
}

}  // namespace
}  // namespace ag::mission
