// Where the robot could not go: blocked discs in the roadmap (they survive a new version of their tile
// and lift cleanly), the stall detector (standing on a route marks the ground ahead; driving, standing at
// the goal or not following marks nothing; marks expire; a full table lifts its oldest), and the
// planner stage re-routing through the other gap of a wall after the robot stood in the first.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "airground/planning/stall_marks.hpp"
#include "stage_rig.hpp"

namespace ag::plan {
namespace {

constexpr std::uint8_t kRoad = raw(ClassId::kRoad), kBuilding = raw(ClassId::kBuilding);
constexpr double kRes = 0.5;

// Two road tiles (64 m x 32 m) cut by a building wall at x = 32 m with two 3 m gaps: A at y 4-7 m (on the
// straight line of the test's route) and B at y 25-28 m (the long way round).
std::vector<std::uint8_t> wall_tile(int tx, bool gap_b = true) {
  std::vector<std::uint8_t> t(64 * 64, kRoad);
  if (tx != 1) return t;
  for (int r = 0; r < 64; ++r) {
    const bool gap = (r >= 8 && r < 14) || (gap_b && r >= 50 && r < 56);
    if (!gap)
      for (int c = 0; c < 2; ++c) t[static_cast<std::size_t>(r * 64 + c)] = kBuilding;
  }
  return t;
}

// Where a route crosses x = at_x (the wall: 32 m), or NaN.
double crossing_y(std::span<const Point2> pts, double at_x = 32.0) {
  for (std::size_t i = 1; i < pts.size(); ++i)
    if ((pts[i - 1].x - at_x) * (pts[i].x - at_x) <= 0 && pts[i].x != pts[i - 1].x)
      return pts[i - 1].y + (pts[i].y - pts[i - 1].y) * (at_x - pts[i - 1].x) / (pts[i].x - pts[i - 1].x);
  return std::nan("");
}

std::unique_ptr<Roadmap> wall_map() {
  auto rm = std::make_unique<Roadmap>(RoadmapParams{}, ClassTable::builtin(), TileExtent{0, 0, 2, 1});
  for (int tx = 0; tx < 2; ++tx) EXPECT_TRUE(rm->set_tile(tx, 0, 1, wall_tile(tx)));
  rm->rebuild();
  return rm;
}

double route_crossing(Roadmap& rm) {
  auto path = std::make_unique<PlannedPath>();
  rm.plan(Point2{20.0, 5.5}, Point2{44.0, 5.5}, *path);
  if (path->status != PlanStatus::kOk) return std::nan("");
  return crossing_y(std::span<const Point2>(path->points.data(), path->count));
}

TEST(RoadmapBlocks, ABlockedDiscClosesAGapUntilLiftedAndOutlivesANewTile) {
  auto rm = wall_map();
  const double open = route_crossing(*rm);
  ASSERT_GT(open, 4.0);
  ASSERT_LT(open, 7.0) << "the short way is through gap A";

  const std::size_t cells = rm->block_disc(Point2{32.0, 5.5}, 0.6);
  EXPECT_NEAR(static_cast<double>(cells), M_PI * 0.36 / (kRes * kRes), 3.0) << "cells whose centre is within the radius";
  EXPECT_TRUE(rm->blocked_cell(64, 11));
  EXPECT_FALSE(rm->blocked_cell(64, 14)) << "1.0 m from the centre";
  EXPECT_GT(rm->pending_tiles(), 0U) << "the roadmap around the disc is stale until update()";
  rm->update();
  const double blocked = route_crossing(*rm);
  EXPECT_GT(blocked, 25.0) << "around through gap B";
  EXPECT_LT(blocked, 28.0);

  ASSERT_TRUE(rm->set_tile(1, 0, 2, wall_tile(1))) << "a new version of the tile from the quadrotor";
  rm->update();
  EXPECT_TRUE(rm->blocked_cell(64, 11)) << "the robot's own finding is not overwritten by the aerial map";
  EXPECT_GT(route_crossing(*rm), 25.0);

  rm->block_disc(Point2{32.0, 5.5}, 0.6);  // blocks nest
  rm->unblock_disc(Point2{32.0, 5.5}, 0.6);
  rm->update();
  EXPECT_GT(route_crossing(*rm), 25.0) << "still blocked by the first disc";
  rm->unblock_disc(Point2{32.0, 5.5}, 0.6);
  rm->update();
  EXPECT_FALSE(rm->blocked_cell(64, 11));
  EXPECT_NEAR(route_crossing(*rm), open, 1e-9) << "lifted: the same route as before";
}

TEST(StallMarks, StandingOnTheRouteMarksTheGroundAheadAndNothingElseDoes) {
  auto rm = wall_map();
  StallParams p;
  p.stall_s = 10.0;
  p.keep_s = 100.0;
  StallMarks s(p);
  const Point2 goal{44.0, 5.5};
  auto at = [](double t) { return static_cast<TimeNs>(t * 1e9); };
  // driving at 1 m/s for 30 s: no mark
  for (int k = 0; k <= 300; ++k) EXPECT_FALSE(s.observe(Pose2{1.0 + 0.1 * k, 5.5, 0.0}, goal, true, at(0.1 * k), *rm));
  // then standing (from 30.1 s, 0.5 m on): for 9.9 s none; at 10 s one, 1 m ahead (east) of the robot
  const Pose2 stand{31.5, 5.5, 0.0};
  for (int k = 0; k < 100; ++k) EXPECT_FALSE(s.observe(stand, goal, true, at(30.1 + 0.1 * k), *rm)) << k;
  EXPECT_TRUE(s.observe(Pose2{31.6, 5.6, 0.0}, goal, true, at(40.1), *rm)) << "jitter within move_m is standing";
  ASSERT_EQ(s.count(), 1U);
  EXPECT_NEAR(s.mark(0).centre.x, 32.6, 1e-9);
  EXPECT_NEAR(s.mark(0).centre.y, 5.6, 1e-9);
  EXPECT_TRUE(rm->blocked_cell(64, 10));
  // standing on: the next mark only after another stall_s
  EXPECT_FALSE(s.observe(stand, goal, true, at(45.0), *rm));
  EXPECT_TRUE(s.observe(stand, goal, true, at(50.1), *rm));
  EXPECT_EQ(s.count(), 2U);
  EXPECT_EQ(s.stalls(), 2U);

  // standing still but not following a route (no goal, not tracking) or at the goal: no mark
  StallMarks q(p);
  for (int k = 0; k <= 300; ++k) EXPECT_FALSE(q.observe(stand, goal, false, at(0.1 * k), *rm));
  for (int k = 0; k <= 300; ++k) EXPECT_FALSE(q.observe(Pose2{42.0, 5.5, 0.0}, goal, true, at(100.0 + 0.1 * k), *rm)) << "2 m from the goal";
  EXPECT_EQ(q.count(), 0U);

  // marks lift after keep_s, oldest first
  EXPECT_FALSE(s.expire(at(140.0), *rm));
  EXPECT_TRUE(s.expire(at(140.1), *rm));
  EXPECT_EQ(s.count(), 1U);
  EXPECT_TRUE(s.expire(at(150.1), *rm));
  EXPECT_EQ(s.count(), 0U);
  EXPECT_FALSE(rm->blocked_cell(64, 10));
  EXPECT_FALSE(rm->blocked_cell(64, 11));
}

TEST(StallMarks, AFullTableLiftsItsOldestMark) {
  auto rm = wall_map();
  StallParams p;
  p.stall_s = 1.0;
  StallMarks s(p);
  TimeNs t = 0;
  for (std::size_t i = 0; i <= StallMarks::kMaxMarks; ++i) {
    const Pose2 stand{2.0 + 1.5 * static_cast<double>(i), 20.0, M_PI / 2};  // a new spot each time, facing north
    for (int k = 0; k <= 11; ++k, t += 100'000'000) s.observe(stand, Point2{60.0, 5.0}, true, t, *rm);
  }
  EXPECT_EQ(s.stalls(), StallMarks::kMaxMarks + 1);
  EXPECT_EQ(s.count(), StallMarks::kMaxMarks);
  EXPECT_FALSE(rm->blocked_cell(4, 42)) << "the first mark (2, 21) was lifted";
  EXPECT_TRUE(rm->blocked_cell(7, 42)) << "the second (3.5, 21) is still there";
}

TEST(StallMarks, PointAlongARouteFromTheRobot) {
  const std::vector<Point2> route{{0, 0}, {10, 0}, {10, 10}};
  const auto at = [&](Point2 from, double d) { return point_along(route, from, d); };
  EXPECT_NEAR(at({3, 1}, 1.0).x, 4.0, 1e-12) << "from the nearest point (3, 0), 1 m on";
  EXPECT_NEAR(at({3, 1}, 1.0).y, 0.0, 1e-12);
  EXPECT_NEAR(at({9.5, -1}, 1.0).x, 10.0, 1e-12) << "round the corner";
  EXPECT_NEAR(at({9.5, -1}, 1.0).y, 0.5, 1e-12);
  EXPECT_NEAR(at({11, 9}, 5.0).y, 10.0, 1e-12) << "past the end: its last point";
  EXPECT_NEAR(point_along(std::span<const Point2>(route.data(), 1), Point2{3, 1}, 1.0).x, 3.0, 1e-12) << "no polyline: the robot itself";
}

// The mark goes where the route goes, not where the robot faces: wedged against the pond's shore, a robot
// on gen6 faced south-west while its route went north-west over the water the map calls road; marks
// along its heading left that way open, 32 times on one spot (session 40).
TEST(StallMarks, TheMarkGoesAlongTheRouteNotTheHeading) {
  auto rm = wall_map();
  StallParams p;
  p.stall_s = 1.0;
  StallMarks s(p);
  const std::vector<Point2> route{{20.0, 5.5}, {44.0, 5.5}};
  const Pose2 facing_north{25.0, 5.5, M_PI / 2};
  for (int k = 0; k <= 11 && s.count() == 0; ++k) s.observe(facing_north, Point2{44.0, 5.5}, true, k * 100'000'000LL, *rm, route);
  ASSERT_EQ(s.count(), 1U);
  EXPECT_NEAR(s.mark(0).centre.x, 26.0, 1e-9) << "1 m east along the route";
  EXPECT_NEAR(s.mark(0).centre.y, 5.5, 1e-9);
  StallMarks q(p);
  for (int k = 0; k <= 11 && q.count() == 0; ++k) q.observe(facing_north, Point2{44.0, 5.5}, true, k * 100'000'000LL, *rm);
  ASSERT_EQ(q.count(), 1U);
  EXPECT_NEAR(q.mark(0).centre.y, 6.5, 1e-9) << "no route: 1 m along the heading";
}

// Standing again on a marked spot: the way round the first mark did not get the robot moving, so each
// new mark there is larger (radius_m more per mark already on the spot, up to max_radius_m); a mark on
// another spot starts small again, and every mark lifts with its own radius.
TEST(StallMarks, StandingAgainOnAMarkedSpotGrowsTheNextMark) {
  auto rm = wall_map();
  StallParams p;
  p.stall_s = 1.0;
  p.keep_s = 1000.0;
  StallMarks s(p);
  TimeNs t = 0;
  auto stand = [&](const Pose2& at) {
    const std::size_t before = s.count();
    for (int k = 0; k <= 11 && s.count() == before; ++k, t += 100'000'000) s.observe(at, Point2{60.0, 5.0}, true, t, *rm);
    EXPECT_EQ(s.count(), before + 1);
    return s.mark(s.count() - 1).radius_m;
  };
  // The marks at (11, 20); the centres of cells (22, 41), (22, 42), (22, 43) lie 0.79, 1.27 and 1.77 m from it.
  const Pose2 spot{10.0, 20.0, 0.0};
  EXPECT_DOUBLE_EQ(stand(spot), 0.6);
  EXPECT_FALSE(rm->blocked_cell(22, 41)) << "outside the first mark";
  EXPECT_DOUBLE_EQ(stand(spot), 1.2);
  EXPECT_TRUE(rm->blocked_cell(22, 41)) << "inside the second";
  EXPECT_FALSE(rm->blocked_cell(22, 42));
  EXPECT_DOUBLE_EQ(stand(spot), 1.8);
  EXPECT_TRUE(rm->blocked_cell(22, 43)) << "inside the third";
  EXPECT_DOUBLE_EQ(stand(spot), 1.8) << "capped at max_radius_m";
  EXPECT_DOUBLE_EQ(stand(Pose2{30.0, 20.0, 0.0}), 0.6) << "another spot starts small";
  ASSERT_TRUE(s.lift_all(*rm));
  for (std::int32_t c = 16; c < 30; ++c)
    for (std::int32_t r = 34; r < 47; ++r) EXPECT_FALSE(rm->blocked_cell(c, r)) << c << ", " << r << ": each mark lifted with its own radius";
}

// A 3 m road between buildings (north) and a 3 m strip of grass (south, then buildings): gen6's pond
// track, where the map's "road" was water and its "grass" the track.
std::unique_ptr<Roadmap> track_map() {
  constexpr std::uint8_t kGrass = raw(ClassId::kGrass);
  std::vector<std::uint8_t> t(64 * 64, kBuilding);
  for (int r = 10; r < 16; ++r)
    for (int c = 0; c < 64; ++c) t[static_cast<std::size_t>(r * 64 + c)] = kGrass;
  for (int r = 16; r < 22; ++r)
    for (int c = 0; c < 64; ++c) t[static_cast<std::size_t>(r * 64 + c)] = kRoad;
  auto rm = std::make_unique<Roadmap>(RoadmapParams{}, ClassTable::builtin(), TileExtent{0, 0, 1, 1});
  EXPECT_TRUE(rm->set_tile(0, 0, 1, t));
  rm->rebuild();
  return rm;
}

// Three ways round a mark on a one-lane road with grass beside it: everywhere over grass from the first
// mark on (stall_traversable: costly), over grass only near the mark (the default, stall_widen_radius_m),
// or not at all (both off: the mark closes the track).
TEST(StallMarks, NearAMarkTheRobotAlsoPlansOverGrassAndOnlyThere) {
  enum class Mode { kEverywhere, kNearTheMark, kNever };
  for (const Mode mode : {Mode::kEverywhere, Mode::kNearTheMark, Mode::kNever}) {
    SCOPED_TRACE(static_cast<int>(mode));
    auto rm = track_map();
    auto path = std::make_unique<PlannedPath>();
    rm->plan(Point2{3.0, 9.5}, Point2{29.0, 9.5}, *path);
    ASSERT_EQ(path->status, PlanStatus::kOk) << "along the road";
    StallParams p;
    p.traversable = mode == Mode::kEverywhere ? Traversability::kCostly : Traversability::kRough;
    if (mode != Mode::kNearTheMark) p.widen_radius_m = 0.0;
    ASSERT_GT(StallParams{}.widen_radius_m, 0.0) << "near the mark is the default";
    StallMarks s(p);
    const Pose2 stand{15.0, 9.5, 0.0};
    for (int k = 0; k <= 100; ++k) s.observe(stand, Point2{29.0, 9.5}, true, static_cast<TimeNs>(k) * 100'000'000, *rm);
    ASSERT_EQ(s.count(), 1U);
    rm->update();
    rm->plan(Point2{3.0, 9.5}, Point2{29.0, 9.5}, *path);
    const auto grass_at = [&](double x) { return rm->traversable_cell(static_cast<std::int32_t>(x / kRes), 12); };  // y 6.25 m: grass
    if (mode == Mode::kNever) {
      EXPECT_FALSE(s.widened());
      EXPECT_NE(path->status, PlanStatus::kOk) << "road only: the mark closes the track";
      EXPECT_FALSE(grass_at(16.0));
      continue;
    }
    EXPECT_EQ(s.widened(), mode == Mode::kEverywhere);
    ASSERT_EQ(path->status, PlanStatus::kOk) << "round the mark over the grass";
    EXPECT_LT(crossing_y(std::span<const Point2>(path->points.data(), path->count), 16.0), 8.5)
        << "passes south of the mark (8.9-10.1 m), keeping its clearance over the grass";
    EXPECT_TRUE(grass_at(16.0)) << "beside the mark";
    EXPECT_EQ(grass_at(26.0), mode == Mode::kEverywhere) << "10 m from the mark: grass only when widened everywhere";
    if (mode == Mode::kNearTheMark) {
      ASSERT_TRUE(s.lift_all(*rm));
      rm->update();
      EXPECT_FALSE(grass_at(16.0)) << "lifting the mark narrows the roadmap again";
      rm->plan(Point2{3.0, 9.5}, Point2{29.0, 9.5}, *path);
      ASSERT_EQ(path->status, PlanStatus::kOk);
      EXPECT_GT(crossing_y(std::span<const Point2>(path->points.data(), path->count), 16.0), 8.5) << "back on the road";
    }
  }
}

// The stage: a robot standing in gap A on its tracking pose for stall_s gets a route through gap B.
TEST(StallMarks, ThePlannerStageRoutesAroundWhereTheRobotStood) {
  const auto w = loc::test::make_world(2, 1, 3);
  test::Rig rig(w);
  for (int tx = 0; tx < 2; ++tx) rig.push_tile(tx, 0, 1, wall_tile(tx));
  do rig.step_planner();
  while (rig.planner->roadmap().pending_tiles() > 0);
  rig.pose = Pose2{20.0, 5.5, 0.0};
  rig.goal(44.0, 5.5, 1);
  rig.step_planner();
  auto crossing = [&] {
    const PlannedPathMsg& m = rig.planner->published();
    std::vector<Point2> pts;
    for (std::uint32_t i = 0; i < m.count; ++i) pts.push_back(Point2{m.points[i].x, m.points[i].y});
    return crossing_y(pts);
  };
  ASSERT_EQ(rig.planner->published().status, RouteStatus::kOk);
  ASSERT_LT(crossing(), 7.0);
  // the robot reached the gap and stands there (in the field: the aerial map was wrong about it)
  rig.pose = Pose2{31.0, 5.5, 0.0};
  for (int k = 0; k < 110; ++k) {  // 11 s at 10 Hz
    rig.clock.set(rig.clock.now() + 100 * kNsPerMs);
    rig.step_planner();
  }
  EXPECT_EQ(rig.planner->counters().stalls, 1U);
  ASSERT_EQ(rig.planner->published().status, RouteStatus::kOk);
  EXPECT_GT(crossing(), 25.0) << "re-planned through gap B";
  // the same standing robot, lost: no more marks
  rig.status = LocalizationStatus::kLost;
  for (int k = 0; k < 200; ++k) {
    rig.clock.set(rig.clock.now() + 100 * kNsPerMs);
    rig.step_planner();
  }
  EXPECT_EQ(rig.planner->counters().stalls, 1U);
}


// With gap A the only way, the mark where the robot stood closes it: the stage lifts its marks and plans
// again at once, so the route is never "no route" because of the robot's own marks.
TEST(StallMarks, AMarkNeverClosesTheLastWay) {
  const auto w = loc::test::make_world(2, 1, 3);
  test::Rig rig(w);
  for (int tx = 0; tx < 2; ++tx) rig.push_tile(tx, 0, 1, wall_tile(tx, false));
  do rig.step_planner();
  while (rig.planner->roadmap().pending_tiles() > 0);
  rig.pose = Pose2{31.0, 5.5, 0.0};
  rig.goal(44.0, 5.5, 1);
  std::uint64_t failed = 0;
  for (int k = 0; k < 150; ++k) {  // 15 s standing in the gap
    rig.clock.set(rig.clock.now() + 100 * kNsPerMs);
    rig.step_planner();
    failed += rig.planner->published().status != RouteStatus::kOk ? 1U : 0U;
  }
  EXPECT_EQ(rig.planner->counters().stalls, 1U);
  EXPECT_EQ(rig.planner->stall_marks().count(), 0U) << "lifted";
  EXPECT_GE(rig.planner->stall_marks().lifted_for_route(), 1U);
  EXPECT_EQ(failed, 0U) << "no route was ever published";
  EXPECT_FALSE(rig.planner->roadmap().blocked_cell(64, 11));
}

}  // namespace
}  // namespace ag::plan
