// WebStage::step() never allocates while tiles, records and poses flow (operator new counted on the
// stage's thread by tests/common/counting_new.hpp; the server thread may allocate, it is not counted).
#include <gtest/gtest.h>

#include "../../common/counting_new.hpp"
#include "base_rig.hpp"
#include "http_client.hpp"

namespace ag::base_station::test {
namespace {
using test_alloc::AllocationWindow;

TEST(NoAllocation, TheCounterSeesAllocations) {
  AllocationWindow w;
  std::vector<int> v(100);
  EXPECT_GE(w.allocations(), 1U);
}

TEST(NoAllocation, WebStageStepWithTilesRecordsPosesAndABrowserConnected) {
  TempDir dir;
  MissionPlayer pl;
  auto rig = BaseRig::make(dir);
  ASSERT_NE(rig, nullptr);
  WebStage* web = rig->web;
  std::vector<Stage*> others;
  for (auto& s : rig->role->stages())
    if (s.stage.get() != web) others.push_back(s.stage.get());
  Client ws(web->port());
  ws.send(ws_upgrade());
  TimeNs now = kNsPerS;
  pl.tile(0, 0, 1, now);
  std::uint64_t web_steps = 0;
  auto step_all = [&](bool window_on_web) {
    for (int r = 1; r <= 2; ++r) {
      const Pose2 p = MissionPlayer::robot_pose(r, static_cast<double>(now) * 1e-9);
      pl.pose(r, p.x, p.y, p.yaw, now);
    }
    pl.tick(now);
    rig->clock.set(now);
    for (Stage* s : others) s->step(now);
    if (window_on_web) {
      AllocationWindow w;
      web->step(now);
      EXPECT_EQ(w.allocations(), 0U) << "allocation in WebStage::step at t=" << now;
      ++web_steps;
    } else {
      web->step(now);
    }
    now += 50 * kNsPerMs;
  };
  for (int k = 0; k < 20; ++k) step_all(false);  // warm-up
  const std::uint64_t records0 = web->model().counters.records_in, tiles0 = web->model().counters.tiles_in;
  for (std::int32_t tx = 0; tx < 4; ++tx)
    for (std::int32_t ty = 0; ty < 3; ++ty) pl.tile(tx, ty, 2, now);
  pl.publish_mission_records(now);
  for (int k = 0; k < 40; ++k) step_all(true);
  EXPECT_EQ(web_steps, 40U);
  EXPECT_GE(web->model().counters.tiles_in, tiles0 + 12) << "tiles went through step() inside the windows";
  EXPECT_GE(web->model().counters.records_in, records0 + 5) << "records went through step()";
  EXPECT_GT(web->model().counters.poses_in, 20U);
  ASSERT_TRUE(ws.read_contains("\"type\":\"state\""));
}

}  // namespace
}  // namespace ag::base_station::test
