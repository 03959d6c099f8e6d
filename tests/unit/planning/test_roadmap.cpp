// Roadmap: fields against brute force, coverage and edges, paths against the 8-connected grid
// reference, incremental tile updates, bad input.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>

#include "planning_world.hpp"

namespace ag::plan {
namespace {
using test::load_roadmap;
using test::reference_of;

constexpr std::uint8_t kRoad = raw(ClassId::kRoad), kBuilding = raw(ClassId::kBuilding), kUnknown = raw(ClassId::kUnknown);

// A one-tile map: all road, with what the test paints on it.
std::vector<std::uint8_t> road_tile() { return std::vector<std::uint8_t>(64 * 64, kRoad); }

TEST(RoadmapFields, UnknownHolesCloseButSeenObstaclesStay) {
  std::vector<std::uint8_t> t = road_tile();
  t[30 * 64 + 20] = kUnknown;   // a one-cell dropout of the aerial map
  t[30 * 64 + 40] = kBuilding;  // a one-cell obstacle that was seen
  for (std::size_t c = 0; c < 64 * 3; ++c) t[5 * 64 + c] = kUnknown;  // a band three cells wide is not a hole
  RoadmapParams p;
  Roadmap rm(p, ClassTable::builtin(), TileExtent{0, 0, 1, 1});
  ASSERT_TRUE(rm.set_tile(0, 0, 1, t));
  rm.rebuild();
  EXPECT_TRUE(rm.traversable_cell(20, 30));
  EXPECT_FALSE(rm.traversable_cell(40, 30));
  EXPECT_FALSE(rm.traversable_cell(10, 5));
  p.hole_fill_radius_cells = 0;
  Roadmap off(p, ClassTable::builtin(), TileExtent{0, 0, 1, 1});
  ASSERT_TRUE(off.set_tile(0, 0, 1, t));
  off.rebuild();
  EXPECT_FALSE(off.traversable_cell(20, 30)) << "hole filling off";
}

TEST(RoadmapFields, ClearanceAndFreeCellsMatchBruteForceOnASyntheticWorld) {
  const auto w = loc::test::make_world(3, 3, 11);
  RoadmapParams p;
  p.hole_fill_radius_cells = 0;  // the brute force knows no hole filling
  auto rm = load_roadmap(w, p);
  const GridReference ref = reference_of(w, p);
  int mismatched_free = 0, checked = 0;
  double worst = 0;
  for (int r = 0; r < w.height; r += 3)
    for (int c = 0; c < w.width; c += 3) {
      ++checked;
      if (rm->free_cell(c, r) != ref.keeps_clearance(c, r)) ++mismatched_free;
      if (!ref.traversable(c, r)) {
        EXPECT_FALSE(rm->traversable_cell(c, r));
        continue;
      }
      worst = std::max(worst, std::fabs(rm->clearance_cell_m(c, r) - ref.clearance_m(c, r, p.clearance_cap_m)));
    }
  EXPECT_EQ(mismatched_free, 0) << "of " << checked;
  EXPECT_LT(worst, 1e-3) << "clearance [m] vs brute force";
}

// The mission area is a geofence: an all-road tile fenced to [4, 28] m blocks the cells centred outside,
// routes keep min_clearance_m inside the fence, and a goal beyond it is refused rather than driven to.
TEST(RoadmapFields, TheGeofenceBlocksCellsOutsideTheMissionArea) {
  RoadmapParams p;
  p.fence = {4.0, 4.0, 28.0, 28.0};
  Roadmap rm(p, ClassTable::builtin(), TileExtent{0, 0, 1, 1});
  ASSERT_TRUE(rm.set_tile(0, 0, 1, road_tile()));
  rm.rebuild();
  EXPECT_FALSE(rm.traversable_cell(7, 30)) << "centre x 3.75 m: outside";
  EXPECT_TRUE(rm.traversable_cell(8, 30)) << "centre x 4.25 m: inside";
  EXPECT_TRUE(rm.traversable_cell(55, 30)) << "centre x 27.75 m: inside";
  EXPECT_FALSE(rm.traversable_cell(56, 30)) << "centre x 28.25 m: outside";
  EXPECT_FALSE(rm.traversable_cell(30, 7));
  EXPECT_FALSE(rm.traversable_cell(30, 56));
  EXPECT_FALSE(rm.free_cell(8, 30)) << "inside the fence but within min_clearance_m of it";
  auto path = std::make_unique<PlannedPath>();
  rm.plan({6, 6}, {6, 26}, *path);  // along the west fence
  ASSERT_EQ(path->status, PlanStatus::kOk);
  for (std::uint32_t i = 1; i + 1 < path->count; ++i) {  // the snapped ends aside
    EXPECT_GE(path->points[i].x, 4.0 + p.min_clearance_m - 0.25) << "point " << i;
    EXPECT_GE(path->points[i].y, 4.0 + p.min_clearance_m - 0.25) << "point " << i;
    EXPECT_LE(path->points[i].y, 28.0 - p.min_clearance_m + 0.25) << "point " << i;
  }
  EXPECT_GE(path->min_clearance_m, p.min_clearance_m - 1e-6);
  rm.plan({16, 16}, {1.5, 16}, *path);  // 2.5 m outside: beyond the snap radius of any free cell
  EXPECT_EQ(path->status, PlanStatus::kGoalBlocked);
  Roadmap open(RoadmapParams{}, ClassTable::builtin(), TileExtent{0, 0, 1, 1});
  ASSERT_TRUE(open.set_tile(0, 0, 1, road_tile()));
  open.rebuild();
  EXPECT_TRUE(open.traversable_cell(7, 30)) << "no fence by default";
}

TEST(RoadmapGraph, EveryFreeCellIsSeenAndEveryEdgeIsAFreeLine) {
  const auto w = loc::test::make_world(4, 4, 5);
  auto rm = load_roadmap(w);
  ASSERT_GT(rm->stats().nodes, 20U);
  int free_cells = 0, uncovered = 0;
  double best_clear = 0;
  for (int r = 0; r < w.height; ++r)
    for (int c = 0; c < w.width; ++c) {
      if (!rm->free_cell(c, r)) {
        EXPECT_EQ(rm->coverage(c, r), 0) << "a cell that is not free is never visible";
        continue;
      }
      ++free_cells;
      best_clear = std::max(best_clear, rm->clearance_cell_m(c, r));
      if (rm->coverage(c, r) == 0) ++uncovered;
    }
  EXPECT_EQ(uncovered, 0) << "of " << free_cells << " free cells";
  const auto nodes = rm->nodes();
  // The first node sits at the largest clearance of the map.
  EXPECT_NEAR(static_cast<double>(nodes[0].clearance_m), best_clear, 1e-4);
  std::uint32_t edges = 0;
  const double res = rm->resolution_m();
  for (std::uint32_t n = 0; n < nodes.size(); ++n) {
    if (!nodes[n].alive) continue;
    EXPECT_TRUE(rm->free_cell(nodes[n].cx, nodes[n].cy));
    for (std::uint16_t e = 0; e < nodes[n].n_edges; ++e) {
      const auto& ed = nodes[n].edges[e];
      const auto& o = nodes[ed.to];
      ASSERT_TRUE(o.alive);
      ++edges;
      const Point2 a{(nodes[n].cx + 0.5) * res, (nodes[n].cy + 0.5) * res}, b{(o.cx + 0.5) * res, (o.cy + 0.5) * res};
      double mc = 0;
      EXPECT_TRUE(rm->line_free(a, b, &mc));
      EXPECT_GE(mc, RoadmapParams{}.min_clearance_m - 1e-6);
      EXPECT_NEAR(static_cast<double>(ed.cost), rm->edge_cost(std::hypot(a.x - b.x, a.y - b.y), mc, 0.0), 1e-3 * static_cast<double>(ed.cost));
    }
  }
  EXPECT_EQ(edges, 2 * rm->stats().edges);
  EXPECT_GT(rm->stats().bridges, 0U) << "corners need bridging nodes";
}

TEST(RoadmapGraph, TheClearancePenaltyFallsWithClearance) {
  Roadmap rm(RoadmapParams{}, ClassTable::builtin(), TileExtent{0, 0, 1, 1});
  EXPECT_GT(rm.edge_cost(10, 0.6, 0), rm.edge_cost(10, 1.0, 0));
  EXPECT_GT(rm.edge_cost(10, 1.0, 0), rm.edge_cost(10, 5.0, 0));
  EXPECT_GT(rm.edge_cost(10, 5.0, 0), 10.0 * RoadmapParams{}.lambda) << "lambda * length plus a positive penalty";
  EXPECT_GT(rm.edge_cost(10, 5.0, 1.0), rm.edge_cost(10, 5.0, 0.0)) << "costly terrain costs more";
}

struct PathStats {
  double ratio_sum{0}, ratio_max{0};
  int planned{0};
};

PathStats plan_pairs(const Roadmap& rm_const, const loc::test::SyntheticWorld& w, int pairs, std::uint64_t seed) {
  auto& rm = const_cast<Roadmap&>(rm_const);
  const GridReference ref = reference_of(w);
  const auto pp = test::reachable_pairs(w, ref, pairs, seed);
  EXPECT_EQ(static_cast<int>(pp.size()), pairs);
  PathStats s;
  auto path = std::make_unique<PlannedPath>();
  for (const auto& [a, b] : pp) {
    rm.plan(a, b, *path);
    EXPECT_EQ(path->status, PlanStatus::kOk) << a.x << "," << a.y << " -> " << b.x << "," << b.y;
    if (path->status != PlanStatus::kOk) continue;
    ++s.planned;
    const PathCheck pc = ref.check(std::span<const Point2>(path->points.data(), path->count));
    EXPECT_TRUE(pc.traversable) << "through a non-traversable cell";
    EXPECT_TRUE(pc.clearance) << "closer than the minimum clearance (" << pc.bad_samples << " samples)";
    EXPECT_GE(pc.min_clearance_m, RoadmapParams{}.min_clearance_m - 1e-6);
    EXPECT_NEAR(pc.length_m, path->length_m, 1e-6);
    EXPECT_NEAR(path->points[0].x, a.x, 1e-9);
    EXPECT_NEAR(path->points[path->count - 1].y, b.y, 1e-9);
    const double grid = ref.shortest_m(a, b);
    EXPECT_GT(grid, 0);
    const double ratio = path->length_m / grid;
    if (std::getenv("AG_PLAN_VERBOSE") != nullptr) std::printf("ratio %.3f len %.1f grid %.1f pts %u clear %.2f\n", ratio, path->length_m, grid, path->count, path->min_clearance_m);
    s.ratio_sum += ratio;
    s.ratio_max = std::max(s.ratio_max, ratio);
  }
  return s;
}

TEST(RoadmapQuery, PathsKeepClearanceAndAreNearlyAsShortAsTheGridOptimum) {
  for (std::uint64_t seed : {3ULL, 8ULL}) {
    const auto w = loc::test::make_world(5, 5, seed);
    auto rm = load_roadmap(w);
    const PathStats s = plan_pairs(*rm, w, 20, seed + 100);
    ASSERT_EQ(s.planned, 20);
    EXPECT_LE(s.ratio_sum / s.planned, 1.05) << "world " << seed;
    EXPECT_LE(s.ratio_max, 1.15) << "world " << seed;
  }
}

TEST(RoadmapQuery, SeparatedPartsHaveNoRouteAndBadEndsAreNamed) {
  // Two road areas split by a building wall.
  std::vector<std::uint8_t> t = road_tile();
  for (int r = 0; r < 64; ++r)
    for (int c = 30; c < 34; ++c) t[static_cast<std::size_t>(r * 64 + c)] = kBuilding;
  Roadmap rm(RoadmapParams{}, ClassTable::builtin(), TileExtent{0, 0, 1, 1});
  ASSERT_TRUE(rm.set_tile(0, 0, 1, t));
  rm.rebuild();
  auto path = std::make_unique<PlannedPath>();
  rm.plan({5, 16}, {27, 16}, *path);
  EXPECT_EQ(path->status, PlanStatus::kNoRoute);
  rm.plan({-5, 16}, {27, 16}, *path);
  EXPECT_EQ(path->status, PlanStatus::kStartOutside);
  rm.plan({5, 16}, {27, 40}, *path);
  EXPECT_EQ(path->status, PlanStatus::kGoalOutside);
  rm.plan({16, 16}, {5, 16}, *path, 0.5);  // the middle of the wall, beyond the snap radius
  EXPECT_EQ(path->status, PlanStatus::kStartBlocked);
  rm.plan({15.2, 16}, {5, 20}, *path, 2.0);  // at the wall: snapped to the nearest free cell
  EXPECT_EQ(path->status, PlanStatus::kOk);
  EXPECT_STREQ(to_string(PlanStatus::kStartBlocked), "no free cell near the start");
}

// A start out on the grass beyond the snap radius (where the stall marks' widening took the robot) joins
// the road straight across the grass; never through a wall, and not with start_escape_m 0.
TEST(RoadmapQuery, AStartOnTheGrassBeyondTheSnapRadiusJoinsTheRoadAcrossItButNeverThroughAWall) {
  std::vector<std::uint8_t> t = road_tile();
  for (int r = 0; r < 44; ++r)  // grass south of y 22 m
    for (int c = 0; c < 64; ++c) t[static_cast<std::size_t>(r * 64 + c)] = raw(ClassId::kGrass);
  for (int r = 40; r < 42; ++r)  // a wall along the road's edge, x 0 - 20 m, y 20 - 21 m
    for (int c = 0; c < 40; ++c) t[static_cast<std::size_t>(r * 64 + c)] = kBuilding;
  auto path = std::make_unique<PlannedPath>();
  for (const double escape_m : {RoadmapParams{}.start_escape_m, 0.0}) {
    RoadmapParams p;
    p.start_escape_m = escape_m;
    Roadmap rm(p, ClassTable::builtin(), TileExtent{0, 0, 1, 1});
    ASSERT_TRUE(rm.set_tile(0, 0, 1, t));
    rm.rebuild();
    rm.plan({30, 19.5}, {5, 28}, *path, 2.0);  // 3 m out on the open grass
    if (escape_m > 0.0) {
      ASSERT_EQ(path->status, PlanStatus::kOk);
      EXPECT_TRUE(path->start_escaped);
      EXPECT_NEAR(path->points[0].x, 30.0, 1e-9);
      EXPECT_NEAR(path->points[0].y, 19.5, 1e-9);
      EXPECT_NEAR(path->points[1].x, 30.0, 0.5) << "straight to the nearest free cell";
      EXPECT_NEAR(path->points[1].y, 22.75, 0.3);
    } else {
      EXPECT_EQ(path->status, PlanStatus::kStartBlocked);
    }
    rm.plan({10, 19}, {5, 28}, *path, 2.0);  // behind the wall: the road within 6 m lies across it
    EXPECT_EQ(path->status, PlanStatus::kStartBlocked) << "escape " << escape_m;
    EXPECT_FALSE(path->start_escaped);
    rm.plan({30, 22.0}, {5, 28}, *path, 2.0);  // within the snap radius: snapped, as before
    ASSERT_EQ(path->status, PlanStatus::kOk);
    EXPECT_FALSE(path->start_escaped);
  }
}

TEST(RoadmapTiles, BadTilesAreRefused) {
  Roadmap rm(RoadmapParams{}, ClassTable::builtin(), TileExtent{2, 3, 2, 2});
  const std::vector<std::uint8_t> t = road_tile();
  EXPECT_FALSE(rm.set_tile(0, 0, 1, t)) << "outside the extent";
  EXPECT_FALSE(rm.set_tile(4, 3, 1, t)) << "outside the extent";
  EXPECT_FALSE(rm.set_tile(2, 3, 1, std::span<const std::uint8_t>(t.data(), 100))) << "wrong size";
  EXPECT_TRUE(rm.set_tile(3, 4, 1, t));
  EXPECT_FALSE(rm.set_tile(3, 4, 1, t)) << "same version";
  EXPECT_EQ(rm.tile_version(3, 4), 1U);
  EXPECT_EQ(rm.pending_tiles(), 1U);
  EXPECT_NEAR(rm.origin_x(), 2 * 32.0, 1e-12);
  EXPECT_NEAR(rm.origin_y(), 3 * 32.0, 1e-12);
}

TEST(RoadmapTiles, AChangedTileUpdatesOnlyItsRegionWithoutAFullRebuild) {
  auto w = loc::test::make_world(8, 8, 21);
  auto rm = load_roadmap(w);
  const RoadmapStats before = rm->stats();
  ASSERT_EQ(before.full_builds, 1U);
  // Snapshot of the nodes.
  struct Snap {
    std::int32_t cx, cy;
    std::vector<std::uint32_t> nbrs;
  };
  std::map<std::uint32_t, Snap> snap;
  const auto nodes0 = rm->nodes();
  for (std::uint32_t n = 0; n < nodes0.size(); ++n) {
    if (!nodes0[n].alive) continue;
    Snap s{nodes0[n].cx, nodes0[n].cy, {}};
    for (std::uint16_t e = 0; e < nodes0[n].n_edges; ++e) s.nbrs.push_back(nodes0[n].edges[e].to);
    std::sort(s.nbrs.begin(), s.nbrs.end());
    snap[n] = s;
  }
  // A route along the first east-west road, then a building dropped across that road in tile (tx, ty).
  const double ry = w.road_y[0];
  const int ty = static_cast<int>(ry / 32.0), tx = 3;
  const Point2 a{tx * 32.0 - 40.0, ry}, b{tx * 32.0 + 72.0, ry};
  auto path = std::make_unique<PlannedPath>();
  rm->plan(a, b, *path);
  ASSERT_EQ(path->status, PlanStatus::kOk);
  const double before_len = path->length_m;
  w.fill_rect(tx * 32.0 + 10, ry - 8, tx * 32.0 + 14, ry + 8, ClassId::kBuilding, 5.0F);
  ASSERT_TRUE(rm->set_tile(tx, ty, 2, w.tile(tx, ty)));
  EXPECT_EQ(rm->update(1), 1U);
  const RoadmapStats after = rm->stats();
  EXPECT_EQ(after.full_builds, 1U) << "no full rebuild";
  EXPECT_EQ(after.tile_updates, 1U);
  const std::uint64_t vis_full = before.visibility_computations, vis_tile = after.visibility_computations - before.visibility_computations;
  EXPECT_GT(vis_tile, 0U);
  EXPECT_LT(vis_tile * 4, vis_full) << "the update recomputed visibility of " << vis_tile << " nodes, the build " << vis_full;
  // Nodes far from the tile are untouched: same slot, same cell, same neighbours.
  const auto nodes1 = rm->nodes();
  int far_nodes = 0;
  const int margin = 2 * 1 + 20 + 1 + 20;  // close, clearance cap, visibility radius [cells]
  for (const auto& [n, s] : snap) {
    const bool far = s.cx < tx * 64 - margin - 2 * 20 - 2 || s.cx >= (tx + 1) * 64 + margin + 2 * 20 + 2 ||
                     s.cy < ty * 64 - margin - 2 * 20 - 2 || s.cy >= (ty + 1) * 64 + margin + 2 * 20 + 2;
    if (!far) continue;
    ++far_nodes;
    ASSERT_TRUE(nodes1[n].alive);
    EXPECT_EQ(nodes1[n].cx, s.cx);
    EXPECT_EQ(nodes1[n].cy, s.cy);
    std::vector<std::uint32_t> nb;
    for (std::uint16_t e = 0; e < nodes1[n].n_edges; ++e) nb.push_back(nodes1[n].edges[e].to);
    std::sort(nb.begin(), nb.end());
    EXPECT_EQ(nb, s.nbrs);
  }
  EXPECT_GT(far_nodes, 100);
  // Still a valid roadmap: every free cell seen, no edge through the new building.
  for (int r = 0; r < w.height; ++r)
    for (int c = 0; c < w.width; ++c)
      if (rm->free_cell(c, r)) {
        ASSERT_GT(rm->coverage(c, r), 0) << c << "," << r;
      }
  EXPECT_FALSE(rm->traversable_cell(static_cast<int>((tx * 32.0 + 12) / 0.5), static_cast<int>(ry / 0.5)));
  rm->plan(a, b, *path);
  ASSERT_EQ(path->status, PlanStatus::kOk);
  const GridReference ref = reference_of(w);
  const PathCheck pc = ref.check(std::span<const Point2>(path->points.data(), path->count));
  EXPECT_TRUE(pc.traversable);
  EXPECT_TRUE(pc.clearance);
  EXPECT_GT(path->length_m, before_len + 10.0) << "the road is closed: a detour";
  // The same query on a roadmap built from scratch on the changed map is about as long.
  auto fresh = load_roadmap(w);
  auto p2 = std::make_unique<PlannedPath>();
  fresh->plan(a, b, *p2);
  ASSERT_EQ(p2->status, PlanStatus::kOk);
  EXPECT_NEAR(path->length_m, p2->length_m, 0.05 * p2->length_m);
}

}  // namespace
}  // namespace ag::plan
