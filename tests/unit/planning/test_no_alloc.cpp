// The planner's real-time calls (set_tile, update, rebuild, plan, stall marks) never allocate once the roadmap is
// constructed (operator new counted by tests/common/counting_new.hpp).
#include <gtest/gtest.h>

#include "airground/planning/local_tracker.hpp"
#include "stage_rig.hpp"

#include "../../common/counting_new.hpp"

namespace ag::plan {
namespace {
using test_alloc::AllocationWindow;

TEST(PlanningNoAllocation, TheCounterSeesAllocations) {
  AllocationWindow w;
  std::vector<int> v(100);
  EXPECT_GE(w.allocations(), 1U);
}

TEST(PlanningNoAllocation, TilesUpdatesRebuildAndQueries) {
  auto w = loc::test::make_world(5, 5, 4);
  auto rm = test::load_roadmap(w);
  const GridReference ref = test::reference_of(w);
  const auto pairs = test::reachable_pairs(w, ref, 10, 3);
  auto path = std::make_unique<PlannedPath>();
  auto changed = w.tile(2, 2);
  for (std::size_t i = 0; i < 600; ++i) changed[i] = raw(ClassId::kBuilding);
  const auto orig = w.tile(2, 2);
  int ok = 0;
  {
    AllocationWindow window;
    for (const auto& [a, b] : pairs) {
      rm->plan(a, b, *path);
      ok += path->status == PlanStatus::kOk ? 1 : 0;
    }
    EXPECT_TRUE(rm->set_tile(2, 2, 2, changed));
    EXPECT_EQ(rm->update(1), 1U);
    EXPECT_TRUE(rm->set_tile(2, 2, 3, orig));
    EXPECT_EQ(rm->update(), 1U);
    rm->rebuild();
    for (const auto& [a, b] : pairs) rm->plan(a, b, *path);
    EXPECT_EQ(window.allocations(), 0U) << "allocations in the planner's real-time calls";
  }
  EXPECT_EQ(ok, 10);
  EXPECT_EQ(rm->stats().tile_updates, 2U);
}

TEST(PlanningNoAllocation, TheLocalTrackerUpdatesAndPicksGoals) {
  // A ring of ground returns and a box ahead, made before the window.
  std::vector<ScanReturn> pts;
  for (int b = 0; b < 16; ++b)
    for (int a = 0; a < 360; ++a) {
      const double el = (-22.5 + 1.2 * b) * kPi / 180.0, az = a * kPi / 180.0, t = 0.6 / std::sin(-el);
      ScanReturn s;
      s.x = static_cast<float>(t * std::cos(el) * std::cos(az));
      s.y = static_cast<float>(t * std::cos(el) * std::sin(az));
      s.z = -0.6F;
      s.range = static_cast<float>(t);
      if (a < 5 && t > 3.0) s.z = 0.0F;  // returns 0.6 m above the ground straight ahead
      pts.push_back(s);
    }
  LocalTracker t{LocalTrackerParams{}};
  const Point2 path[] = {{0, 0}, {20, 0}};
  int valid = 0;
  {
    test_alloc::AllocationWindow window;
    for (int k = 0; k < 20; ++k) {
      t.set_path(path);
      EXPECT_TRUE(t.update(pts, Pose3{0, 0, 0.6, 0, 0, 0}, Pose2{0.1 * k, 0, 0}, 1.0));
      valid += t.local_goal(Pose2{0.1 * k, 0, 0}, k * kNsPerS / 10).valid ? 1 : 0;
    }
    EXPECT_EQ(window.allocations(), 0U) << "allocations in LocalTracker";
  }
  EXPECT_GT(valid, 10);
}

TEST(PlanningNoAllocation, ThePlannerAndDriveStagesStep) {
  auto w = loc::test::make_world(4, 4, 6);
  test::Rig rig(w);
  const GridReference ref = test::reference_of(w);
  const auto pairs = test::reachable_pairs(w, ref, 1, 5, 50.0);
  ASSERT_EQ(pairs.size(), 1U);
  rig.pose = Pose2{pairs[0].first.x, pairs[0].first.y, 0.0};
  std::vector<std::vector<std::uint8_t>> tiles;
  for (int ty = 0; ty < w.tiles_y(); ++ty)
    for (int tx = 0; tx < w.tiles_x(); ++tx) tiles.push_back(w.tile(tx, ty));
  auto changed = tiles[5];
  for (std::size_t i = 0; i < 300; ++i) changed[i] = raw(ClassId::kBuilding);
  {
    test_alloc::AllocationWindow window;
    for (int ty = 0; ty < w.tiles_y(); ++ty)
      for (int tx = 0; tx < w.tiles_x(); ++tx) rig.push_tile(tx, ty, 1, tiles[static_cast<std::size_t>(ty * w.tiles_x() + tx)]);
    do rig.step_planner();
    while (rig.planner->roadmap().pending_tiles() > 0);
    rig.goal(pairs[0].second.x, pairs[0].second.y, 1);
    for (int k = 0; k < 400; ++k) {
      if (k == 100) rig.push_tile(1, 1, 2, changed);
      rig.tick(k);
    }
    // held in place on its route (wheels blocked): the planner marks the ground ahead and re-plans
    const Pose2 held = rig.pose;
    for (int k = 400; k < 800; ++k) {
      rig.tick(k);
      rig.pose = held;
    }
    EXPECT_EQ(window.allocations(), 0U) << "allocations in PlannerStage::step() / DriveStage::step()";
  }
  EXPECT_GE(rig.planner->counters().stalls, 1U) << "20 s held on the route: at least one stall mark";
  EXPECT_GT(rig.planner->counters().plans, 2U);
  EXPECT_EQ(rig.planner->published().status, RouteStatus::kOk);
  EXPECT_GT(rig.planner->roadmap().stats().tile_updates, 16U);
}

}  // namespace
}  // namespace ag::plan
