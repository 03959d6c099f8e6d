// The planner's real-time calls (set_tile, update, rebuild, plan) never allocate once the roadmap is
// constructed (operator new counted by tests/common/counting_new.hpp).
#include <gtest/gtest.h>

#include "planning_world.hpp"

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

}  // namespace
}  // namespace ag::plan
