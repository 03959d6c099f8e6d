// Regions of interest on synthetic class grids: merging by the merge distance, noise, goals, stable ids.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "airground/mission/regions.hpp"
#include "grid_world.hpp"

namespace ag::mission {
namespace {
using test::GridWorld;

RegionParams params() {
  RegionParams p;
  p.merge_distance_m = 12.0;
  return p;
}

TEST(Regions, TwoCarGroupsEightMetresApartMergeThirtyDoNot) {
  GridWorld w(4, 4, ClassId::kRoad);
  // near pair: gap 8 m along x
  w.car(20, 20);
  w.car(20 + 4.5 + 8.0, 20);
  // far pair: gap 30 m along y from a car at (20, 60) to one at (20, 92)
  w.car(20, 60);
  w.car(20, 60 + 2.0 + 30.0);
  RegionExtractor ex(params(), ClassTable::builtin(), w.extent());
  w.load(ex, 1);
  ASSERT_EQ(ex.extract(), 3U);
  const auto regs = ex.regions();
  int merged = 0, single = 0;
  for (const Region& r : regs) {
    if (r.cells == 2 * 36) {
      ++merged;
      EXPECT_NEAR(r.cx, 20 + (4.5 + 8 + 4.5) / 2, 0.3);
      EXPECT_NEAR(r.cy, 21.0, 0.3);
    } else {
      EXPECT_EQ(r.cells, 36U);
      ++single;
    }
  }
  EXPECT_EQ(merged, 1);
  EXPECT_EQ(single, 2);
}

TEST(Regions, MergeDistanceIsTheBoundary) {
  for (const double gap : {11.0, 13.5}) {
    GridWorld w(4, 2, ClassId::kRoad);
    w.car(20, 20);
    w.car(20 + 4.5 + gap, 20);
    RegionExtractor ex(params(), ClassTable::builtin(), w.extent());
    w.load(ex, 1);
    EXPECT_EQ(ex.extract(), gap < 12.0 ? 1U : 2U) << "gap " << gap;
  }
}

TEST(Regions, NoiseCellsAndSliversAreDropped) {
  GridWorld w(2, 2, ClassId::kRoad);
  w.rect(10, 10, 10.5, 10.5, ClassId::kVehicle);   // one cell
  w.rect(30, 30, 31.0, 31.0, ClassId::kVehicle);   // 2x2 cells: survives a 3x3 opening? no
  w.rect(40, 5, 40.5, 25, ClassId::kVehicle);      // a 1-cell line, 20 m long
  RegionExtractor ex(params(), ClassTable::builtin(), w.extent());
  w.load(ex, 1);
  EXPECT_EQ(ex.extract(), 0U);
  // the same map with a real car: exactly that one
  w.car(50, 50);
  w.load(ex, 2);
  ASSERT_EQ(ex.extract(), 1U);
  EXPECT_EQ(ex.regions()[0].cells, 36U);
  // a blob that survives the opening but is below min_region_cells
  RegionParams p = params();
  p.min_region_cells = 40;
  RegionExtractor ex2(p, ClassTable::builtin(), w.extent());
  w.load(ex2, 1);
  EXPECT_EQ(ex2.extract(), 0U);
  EXPECT_EQ(ex2.stats().groups_dropped_small, 1U);
}

TEST(Regions, GoalIsOnTheReachableRoadWithTheLargestClearanceNotInACourtyard) {
  // Buildings everywhere; an 8 m road along y in [20, 28); a car parked on the road's north edge; a
  // closed courtyard (16 m x 16 m of road enclosed by building, more clearance than the road) 3 m north of it.
  GridWorld w(4, 2, ClassId::kBuilding);
  w.rect(0, 20, 128, 28, ClassId::kRoad);
  w.car(60, 26);
  w.rect(56, 31, 72, 47, ClassId::kRoad);
  RegionParams p = params();
  p.goal_clearance_cap_m = 10.0;  // so the courtyard's 7.75 m would beat the road's 3.75 m if it counted
  RegionExtractor ex(p, ClassTable::builtin(), w.extent());
  w.load(ex, 1);
  ASSERT_EQ(ex.extract(), 1U);
  const Region& r = ex.regions()[0];
  ASSERT_TRUE(r.goal_valid);
  EXPECT_GE(r.goal_y, 20.0);
  EXPECT_LT(r.goal_y, 28.0) << "the goal is on the road, not in the courtyard (y " << r.goal_y << ")";
  EXPECT_TRUE(ex.reachable_at(r.goal_x, r.goal_y));
  EXPECT_FALSE(ex.reachable_at(64, 39)) << "the courtyard is an enclosed pocket";
  // the best the road offers: its centre line, 3.75 m from the buildings, away from the car
  EXPECT_NEAR(r.goal_clearance_m, 3.75, 0.01);
  EXPECT_NEAR(r.goal_y, 24.0, 0.3);
  EXPECT_NEAR(r.goal_clearance_m, ex.clearance_at(r.goal_x, r.goal_y), 1e-9);
  EXPECT_LT(std::hypot(r.goal_x - r.cx, r.goal_y - r.cy), 15.0 + 3.0);
  // a region with only buildings around: no goal
  GridWorld b(2, 2, ClassId::kBuilding);
  b.car(30, 30);
  b.rect(0, 0, 64, 4, ClassId::kRoad);  // far away road
  RegionExtractor ex2(params(), ClassTable::builtin(), b.extent());
  b.load(ex2, 1);
  ASSERT_EQ(ex2.extract(), 1U);
  EXPECT_FALSE(ex2.regions()[0].goal_valid);
  EXPECT_EQ(ex2.stats().goals_missing, 1U);
}

TEST(Regions, IdsAreStableWhenTheMapGrows) {
  GridWorld w(4, 2, ClassId::kUnknown);
  w.rect(0, 0, 128, 64, ClassId::kRoad);
  w.car(10, 10);
  w.car(40, 40);
  w.car(90, 20);  // in tile x = 2: not loaded at first
  RegionExtractor ex(params(), ClassTable::builtin(), w.extent());
  w.load(ex, 1, /*max_tx=*/2);
  ASSERT_EQ(ex.extract(), 2U);
  const std::uint32_t v1 = ex.version();
  std::uint32_t id_a = 0, id_b = 0;
  for (const Region& r : ex.regions()) (r.cx < 20 ? id_a : id_b) = r.id;
  ASSERT_NE(id_a, id_b);
  // nothing changed: same ids, same version
  ex.extract();
  EXPECT_EQ(ex.version(), v1);
  // the map grows east and car A gets a neighbour 3 m away (same region, more cells)
  w.car(10, 15);
  w.load(ex, 2);
  ASSERT_EQ(ex.extract(), 3U);
  EXPECT_GT(ex.version(), v1);
  bool saw_a = false, saw_b = false, saw_new = false;
  for (const Region& r : ex.regions()) {
    if (r.cx < 20) {
      EXPECT_EQ(r.id, id_a);
      EXPECT_EQ(r.cells, 72U);
      saw_a = true;
    } else if (r.cx < 60) {
      EXPECT_EQ(r.id, id_b);
      saw_b = true;
    } else {
      EXPECT_NE(r.id, id_a);
      EXPECT_NE(r.id, id_b);
      saw_new = true;
    }
  }
  EXPECT_TRUE(saw_a && saw_b && saw_new);
  // car B moves away (gone): its id is not reused by the others
  w.rect(40, 40, 44.5, 42, ClassId::kRoad);
  w.load(ex, 3);
  ASSERT_EQ(ex.extract(), 2U);
  for (const Region& r : ex.regions()) EXPECT_NE(r.id, id_b);
}

TEST(Regions, WorkingOnTheMappedTilesOnlyGivesTheSameRegionsAsTheWholeArea) {
  // data in tiles (1..2, 1..2) of a 4 x 4 area, unknown elsewhere; cars near the data's edge
  GridWorld w(4, 4, ClassId::kUnknown);
  w.rect(32, 32, 96, 96, ClassId::kRoad);
  w.rect(40, 70, 60, 95, ClassId::kBuilding);
  w.car(33, 40);
  w.car(90, 33);
  w.car(70, 80);
  RegionExtractor part(params(), ClassTable::builtin(), w.extent());
  for (int ty = 1; ty <= 2; ++ty)
    for (int tx = 1; tx <= 2; ++tx) part.set_tile(tx, ty, 1, w.tile(tx, ty));
  RegionExtractor whole(params(), ClassTable::builtin(), w.extent());
  std::copy(w.cls.begin(), w.cls.end(), whole.classes().begin());
  whole.mark_changed();
  ASSERT_EQ(part.extract(), 3U);
  ASSERT_EQ(whole.extract(), 3U);
  for (std::size_t i = 0; i < 3; ++i) {
    const Region& a = part.regions()[i];
    const Region& b = whole.regions()[i];
    EXPECT_EQ(a.cells, b.cells);
    EXPECT_DOUBLE_EQ(a.cx, b.cx);
    EXPECT_DOUBLE_EQ(a.cy, b.cy);
    EXPECT_EQ(a.goal_valid, b.goal_valid);
    EXPECT_DOUBLE_EQ(a.goal_x, b.goal_x);
    EXPECT_DOUBLE_EQ(a.goal_y, b.goal_y);
    EXPECT_DOUBLE_EQ(a.goal_clearance_m, b.goal_clearance_m);
  }
}

TEST(Regions, TilesOutsideOrStaleAreRejected) {
  GridWorld w(2, 2, ClassId::kRoad);
  RegionExtractor ex(params(), ClassTable::builtin(), w.extent());
  const auto t = w.tile(0, 0);
  EXPECT_TRUE(ex.set_tile(0, 0, 2, t));
  EXPECT_FALSE(ex.set_tile(0, 0, 2, t)) << "same version";
  EXPECT_FALSE(ex.set_tile(5, 0, 1, t)) << "outside";
  EXPECT_FALSE(ex.set_tile(0, 0, 3, std::span<const std::uint8_t>(t.data(), 10))) << "wrong size";
  EXPECT_EQ(ex.stats().tiles_rejected, 3U);
}

}  // namespace
}  // namespace ag::mission
