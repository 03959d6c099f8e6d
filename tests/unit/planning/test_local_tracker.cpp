// Local tracker: RANSAC ground on a tilted sensor among obstacles, the obstacle grid (free by ray
// casting, shadows unknown), the local goal stepping around an obstacle the aerial map missed, backing
// up then failing when blocked, the reflex stop.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "airground/messages/pose_math.hpp"
#include "airground/planning/local_tracker.hpp"
#include "synthetic_scan.hpp"

namespace ag::plan {
namespace {
using test::Box;
using test::scan;

const Pose3 kMount{0, 0, 0.6, 0, 0, 0};

TEST(LocalTracker, RansacFindsTheGroundOfATiltedSensorAmongObstacles) {
  const double roll = 0.05, pitch = -0.08;
  const auto pts = scan({{3, 5, -6, 6, 3.0}, {-4, -2, -1, 1, 1.0}}, 0.6, roll, pitch);
  LocalTracker t{LocalTrackerParams{}};
  ASSERT_TRUE(t.update(pts, kMount, Pose2{}, 0.0));
  const Eigen::Vector3d up = rotation_matrix(roll, pitch, 0).transpose() * Eigen::Vector3d::UnitZ();  // level up in the sensor frame
  const Plane& g = t.ground();
  const double cosang = g.a * up.x() + g.b * up.y() + g.c * up.z();
  EXPECT_LT(std::acos(std::min(1.0, cosang)), 1.0 * kPi / 180.0) << "normal off by more than 1 deg";
  EXPECT_NEAR(g.height(0, 0, 0), 0.6, 0.03) << "the sensor's height above the ground";
}

TEST(LocalTracker, ObstaclesBlockFreeSpaceAndCastShadows) {
  LocalTracker t{LocalTrackerParams{}};
  ASSERT_TRUE(t.update(scan({{4, 5, -0.5, 0.5, 1.0}}), kMount, Pose2{10, 20, 0}, 0.0));
  EXPECT_EQ(t.cell_at(14.1, 20.0), 2) << "the box";
  EXPECT_EQ(t.cell_at(12.0, 20.0), 1) << "free in front of it";
  EXPECT_EQ(t.cell_at(17.0, 20.0), 0) << "its shadow is unknown";
  EXPECT_EQ(t.cell_at(16.0, 23.0), 1) << "free beside";
  EXPECT_NEAR(t.clearance_at(12.0, 20.0), 2.0, 0.25);
}

// The tests' 32-beam sensor has its rings 1.45 deg apart, twice the Ouster's: ground returns lie close
// enough together for the no-ground check only within about 3 m.
LocalTrackerParams sparse_sensor() {
  LocalTrackerParams p;
  p.no_ground_range_m = 3.0;
  return p;
}

TEST(LocalTracker, TheLocalGoalStepsAroundAnObstacleTheAerialMapMissed) {
  LocalTracker t{sparse_sensor()};
  const Point2 path[] = {{0, 0}, {20, 0}};
  t.set_path(path);
  ASSERT_TRUE(t.update(scan({{4.5, 5.5, -0.6, 0.6, 1.0}}), kMount, Pose2{0, 0, 0}, 0.0));
  const LocalGoal g = t.local_goal(Pose2{0, 0, 0}, 0);
  ASSERT_TRUE(g.valid);
  EXPECT_EQ(t.state(), TrackState::kTracking);
  EXPECT_GE(g.clearance_m, LocalTrackerParams{}.min_clearance_m);
  EXPECT_GT(std::fabs(g.goal.y), 0.9) << "beside the box, with clearance";
  EXPECT_NEAR(g.goal.x, 5.0, 1.6);
  // Without the obstacle the goal stays on the path.
  ASSERT_TRUE(t.update(scan({}), kMount, Pose2{0, 0, 0}, 0.0));
  const LocalGoal h = t.local_goal(Pose2{0, 0, 0}, 0);
  ASSERT_TRUE(h.valid);
  EXPECT_LT(std::fabs(h.goal.y), 1.6);
}

TEST(LocalTracker, BlockedAheadBacksUpToTheLastWaypointThenFails) {
  LocalTracker t{LocalTrackerParams{}};
  const Point2 path[] = {{-2, 0}, {20, 0}};
  t.set_path(path);
  ASSERT_TRUE(t.update(scan({{1.2, 1.7, -12, 12, 1.5}}), kMount, Pose2{0, 0, 0}, 0.0));
  const LocalGoal g = t.local_goal(Pose2{0, 0, 0}, 0);
  EXPECT_EQ(t.state(), TrackState::kBackingUp);
  ASSERT_TRUE(g.valid);
  EXPECT_LT(g.goal.x, 0.0) << "behind the robot";
  // Now walled in behind as well.
  ASSERT_TRUE(t.update(scan({{1.2, 1.7, -12, 12, 1.5}, {-1.5, -1.2, -12, 12, 1.5}}), kMount, Pose2{0, 0, 0}, 0.0));
  const LocalGoal f = t.local_goal(Pose2{0, 0, 0}, kNsPerS);
  EXPECT_FALSE(f.valid);
  EXPECT_EQ(t.state(), TrackState::kFailed);
  EXPECT_EQ(t.failures(), 1U);
  EXPECT_STREQ(to_string(t.state()), "blocked: path cancelled");
}

TEST(LocalTracker, ReflexStopsForAReturnAboveTheThresholdAheadOnly) {
  LocalTracker t{LocalTrackerParams{}};
  ASSERT_TRUE(t.update(scan({{0.6, 0.9, -0.2, 0.2, 0.5}}), kMount, Pose2{}, 0.0));
  EXPECT_TRUE(t.reflex_stop()) << "a box 0.6 m ahead";
  ASSERT_TRUE(t.update(scan({{-0.9, -0.6, -0.2, 0.2, 0.5}}), kMount, Pose2{}, 0.0));
  EXPECT_FALSE(t.reflex_stop()) << "behind";
  ASSERT_TRUE(t.update(scan({{0.6, 0.9, -0.5, 0.5, 0.1}}), kMount, Pose2{}, 0.0));
  EXPECT_FALSE(t.reflex_stop()) << "a 10 cm curb";
  ASSERT_TRUE(t.update(scan({{1.1, 1.4, -0.2, 0.2, 0.5}}), kMount, Pose2{}, 0.0));
  EXPECT_FALSE(t.reflex_stop()) << "1.1 m ahead at rest";
  ASSERT_TRUE(t.update(scan({{1.1, 1.4, -0.2, 0.2, 0.5}}), kMount, Pose2{}, 1.2));
  EXPECT_TRUE(t.reflex_stop()) << "1.1 m ahead at 1.2 m/s";
}

// The free-space pass traces each end cell once per scan; the grid must be exactly the one of tracing a
// line to every ground return (the reference below, the tracker's rules written out plainly), also for
// returns beyond the grid (the far set), over updates at other poses (the per-scan marks are reset).
std::vector<std::uint8_t> reference_grid(const LocalTracker& t, const std::vector<ScanReturn>& pts, const Pose3& mount, const Pose2& robot) {
  const LocalTrackerParams p{};
  const int n = t.width();
  std::vector<std::uint8_t> g(static_cast<std::size_t>(n) * static_cast<std::size_t>(n), 0);
  const Eigen::Matrix3d rm = rotation_matrix(mount.roll, mount.pitch, mount.yaw);
  auto cell = [&](const ScanReturn& q, int& i, int& j) {
    const Eigen::Vector3d b = rm * Eigen::Vector3d(q.x, q.y, q.z) + Eigen::Vector3d(mount.x, mount.y, mount.z);
    const double mx = robot.x + std::cos(robot.yaw) * b.x() - std::sin(robot.yaw) * b.y();
    const double my = robot.y + std::sin(robot.yaw) * b.x() + std::cos(robot.yaw) * b.y();
    i = static_cast<int>(std::floor((mx - robot.x) / p.cell_m + 0.5 * n));
    j = static_cast<int>(std::floor((my - robot.y) / p.cell_m + 0.5 * n));
  };
  const int ri = static_cast<int>(std::floor(0.5 * n)), rj = ri;  // the robot is at the grid's centre
  for (const ScanReturn& q : pts) {
    if (!(q.range > 0.0F) || std::fabs(t.ground().height(q.x, q.y, q.z)) >= p.ground_band_m) continue;
    int ei = 0, ej = 0;
    cell(q, ei, ej);
    int x = ri, y = rj;
    const int dx = std::abs(ei - ri), dy = -std::abs(ej - rj), sx = ri < ei ? 1 : -1, sy = rj < ej ? 1 : -1;
    int err = dx + dy;
    for (int guard = 0; guard < 4 * n; ++guard) {
      if (x < 0 || y < 0 || x >= n || y >= n) break;
      g[static_cast<std::size_t>(y * n + x)] = 1;
      if (x == ei && y == ej) break;
      const int e2 = 2 * err;
      if (e2 >= dy) { err += dy; x += sx; }
      if (e2 <= dx) { err += dx; y += sy; }
    }
  }
  for (const ScanReturn& q : pts) {
    if (!(q.range > 0.0F)) continue;
    const double h = t.ground().height(q.x, q.y, q.z);
    if (h <= p.obstacle_min_m || h >= p.overhang_m) continue;
    int i = 0, j = 0;
    cell(q, i, j);
    if (i >= 0 && j >= 0 && i < n && j < n) g[static_cast<std::size_t>(j * n + i)] = 2;
  }
  return g;
}

// A pond beside the route (no return from it) and trees across it: the rays to the far shore cross the
// water, and the goal farthest from the trees would be on it; ground never hit near the robot is an obstacle.
TEST(LocalTracker, WaterThatGivesNoReturnIsNoPlaceForTheLocalGoal) {
  const std::vector<Box> trees = {{0.0, 12.0, -4.5, -1.1, 2.0}};  // 1.5 m of track between trees and water
  const std::vector<Box> pond = {{1.5, 12.0, 0.4, 8.0, 0.0}};
  const auto pts = scan(trees, 0.6, 0.0, 0.0, 1, 64, pond);  // 64 beams, 0.71 deg apart: the Ouster OS1-64's spacing
  const Point2 path[] = {{0, 0}, {20, 0}};
  for (const bool check : {true, false}) {
    LocalTrackerParams p;
    if (!check) p.no_ground_range_m = 0.0;
    LocalTracker t{p};
    t.set_path(path);
    ASSERT_TRUE(t.update(pts, kMount, Pose2{0, 0, 0}, 0.0));
    const LocalGoal g = t.local_goal(Pose2{0, 0, 0}, 0);
    ASSERT_TRUE(g.valid);
    if (check) {
      EXPECT_EQ(t.cell_at(4.0, 2.0), 2) << "water is an obstacle";
      EXPECT_EQ(t.cell_at(4.0, -0.3), 1) << "the track is free";
      EXPECT_EQ(t.cell_at(-3.0, 3.0), 1) << "dry ground beside the pond, behind the robot";
      EXPECT_LT(g.goal.y, 0.4 - p.min_clearance_m + 0.2) << "on the track, clear of the water's edge";
      EXPECT_GT(g.goal.y, -1.1 + p.min_clearance_m - 0.2) << "... and of the trees";
    } else {
      EXPECT_EQ(t.cell_at(4.0, 2.0), 1) << "without the check the rays to the far shore make the pond free";
      EXPECT_GT(g.goal.y, 0.4) << "and the goal farthest from the trees is on the water";
    }
  }
}

// One scan from the origin, the route east along the x axis: the tracker's local goal.
LocalGoal goal_along_x(LocalTracker& t, const std::vector<ScanReturn>& pts) {
  const Point2 path[] = {{0, 0}, {20, 0}};
  t.set_path(path);
  EXPECT_TRUE(t.update(pts, kMount, Pose2{0, 0, 0}, 0.0));
  return t.local_goal(Pose2{0, 0, 0}, 0);
}

// A pond too wide for any ray to reach its far shore (gen6's pond, session 41): no return and no ray
// over it, so its cells are unknown, not free, and the clearance field never saw them; the goal farthest
// from the trees sat on the water's edge and the robot's footprint went in. Ground unseen within the
// ring where the LiDAR sees all the ground is no ground.
TEST(LocalTracker, WaterBeyondTheLidarsReachIsNoPlaceForTheLocalGoalEither) {
  const std::vector<Box> trees = {{0.0, 12.0, -4.5, -1.1, 2.0}};
  const std::vector<Box> pond = {{1.5, 60.0, 0.4, 60.0, 0.0}};  // beyond the scan's 30 m every way over it
  const auto pts = scan(trees, 0.6, 0.0, 0.0, 1, 64, pond);
  for (const bool unseen : {true, false}) {
    LocalTrackerParams p;
    p.no_ground_unseen = unseen;
    LocalTracker t{p};
    const LocalGoal g = goal_along_x(t, pts);
    ASSERT_TRUE(g.valid);
    EXPECT_EQ(t.cell_at(-3.0, 3.0), 1) << "dry ground beside the pond, behind the robot";
    EXPECT_EQ(t.cell_at(4.0, -0.3), 1) << "the track is free";
    if (unseen) {
      EXPECT_EQ(t.cell_at(4.0, 2.0), 2) << "water within the ring is an obstacle";
      EXPECT_EQ(t.cell_at(8.0, 2.0), 0) << "beyond no_ground_range_m it stays unknown";
      EXPECT_LT(g.goal.y, 0.4 + p.no_ground_radius_m - p.min_clearance_m + 0.2) << "clear of the water's edge";
      EXPECT_GT(g.goal.y, -1.1 + p.min_clearance_m - 0.2) << "... and of the trees";
    } else {
      EXPECT_EQ(t.cell_at(4.0, 2.0), 0) << "without it the water is unknown";
      EXPECT_GT(g.goal.y, 0.3) << "and the goal farthest from the trees is at the water's edge";
    }
  }
}

// The track's ground returns reach to the water's edge, so cells up to no_ground_radius_m (0.5 m) into
// the water still have a return near them and stay free: the first obstacle cell lies up to 0.5 m past
// the edge. A no-ground cell's clearance counts from that much inside it; without it a cell 0.3 m from
// the water had 0.7 m of clearance and was a legal goal (gen6's robots touched the pond there).
TEST(LocalTracker, ClearanceFromWaterCountsFromWhereTheWaterMayBegin) {
  const std::vector<Box> pond = {{1.5, 60.0, 0.4, 60.0, 0.0}};
  const auto pts = scan({}, 0.6, 0.0, 0.0, 1, 64, pond);
  double gap[2] = {0, 0}, near[2] = {0, 0};  // [without, with]
  LocalTrackerParams p;
  for (const bool margin : {false, true}) {
    p.no_ground_edge_margin = margin;
    LocalTracker t{p};
    const LocalGoal g = goal_along_x(t, pts);
    ASSERT_TRUE(g.valid);
    gap[margin] = 0.4 - g.goal.y;  // from the goal to the water
    near[margin] = t.clearance_at(4.0, 0.1);
  }
  const double preferred = p.min_clearance_m + 0.9;  // the goal's "enough" clearance
  EXPECT_LT(near[1], near[0] - 0.4) << "the clearance 0.3 m from the water drops by the radius";
  EXPECT_LT(near[1], p.min_clearance_m) << "0.3 m from the water is no place for a goal";
  EXPECT_GE(gap[1], preferred - 0.1) << "the goal keeps its preferred clearance from the water itself";
  EXPECT_LT(gap[0], preferred - 0.1) << "without it the goal is nearer the water than it means to be";
}

// Beside the shore, the shore is inside the LiDAR's blind ring (its lowest beam meets the ground 1.45 m
// out here): what an earlier scan found without ground there is still an obstacle.
TEST(LocalTracker, AShoreSeenFromAfarIsStillAnObstacleBesideIt) {
  const std::vector<Box> pond_far = {{1.5, 12.0, 0.4, 8.0, 0.0}};    // from (0, 0)
  const std::vector<Box> pond_near = {{-1.5, 9.0, 0.9, 8.5, 0.0}};  // the same pond from (3, -0.5)
  for (const int memory : {100, 0}) {
    LocalTrackerParams p;
    p.no_ground_memory_updates = memory;
    LocalTracker t{p};
    ASSERT_TRUE(t.update(scan({}, 0.6, 0.0, 0.0, 1, 64, pond_far), kMount, Pose2{0, 0, 0}, 0.0));
    EXPECT_EQ(t.cell_at(3.5, 1.2), 2) << "seen from 3.5 m: no ground";
    ASSERT_TRUE(t.update(scan({}, 0.6, 0.0, 0.0, 1, 64, pond_near), kMount, Pose2{3, -0.5, 0}, 0.0));
    if (memory > 0) {
      EXPECT_EQ(t.cell_at(3.5, 1.2), 2) << "1.8 m from the robot, in its blind ring: remembered";
      EXPECT_NE(t.cell_at(3.0, -1.2), 2) << "dry ground in the blind ring is not";
    } else {
      EXPECT_NE(t.cell_at(3.5, 1.2), 2) << "without the memory the shore beside the robot is unknown to it";
    }
  }
}

TEST(LocalTracker, FreeSpaceTracedOncePerEndCellEqualsTracingEveryReturn) {
  LocalTrackerParams no_check;  // the reference grid is the rays alone
  no_check.no_ground_range_m = 0.0;
  LocalTracker t{no_check};
  const std::vector<std::vector<Box>> scenes = {{{4, 5, -0.5, 0.5, 1.0}}, {{-3, -2, 1, 6, 2.5}, {6, 7, -8, -4, 1.2}}, {}};
  const Pose2 poses[] = {{0, 0, 0}, {10.05, -3.3, 0.7}, {-7.2, 4.4, -2.1}};
  int checked = 0;
  for (int k = 0; k < 6; ++k) {
    // Sparse in azimuth (7 deg), so that a line left out leaves cells unknown.
    auto pts = scan(scenes[static_cast<std::size_t>(k % 3)], 0.6, 0.0, 0.0, 7);
    // Ground returns far outside the 20 m grid (as a 120 m Ouster gives), several in each far cell.
    for (int a = 0; a < 3 * 67; ++a) {
      const double az = (a / 3) * 2.0 * kPi / 67.0 + 0.01, r = 35.0 + 0.05 * (a % 3);
      pts.push_back(ScanReturn{static_cast<float>(r * std::cos(az)), static_cast<float>(r * std::sin(az)), -0.6F, static_cast<float>(r), 0, 0, 0});
    }
    const Pose2 robot = poses[static_cast<std::size_t>(k % 3)];
    ASSERT_TRUE(t.update(pts, kMount, robot, 0.0));
    const auto ref = reference_grid(t, pts, kMount, robot);
    int diff = 0, free_cells = 0;
    for (int j = 0; j < t.width(); ++j)
      for (int i = 0; i < t.width(); ++i) {
        diff += t.cell(i, j) != ref[static_cast<std::size_t>(j * t.width() + i)];
        free_cells += t.cell(i, j) == 1;
      }
    EXPECT_EQ(diff, 0) << "update " << k;
    EXPECT_GT(free_cells, t.width() * t.width() / 4) << "update " << k;
    ++checked;
  }
  EXPECT_EQ(checked, 6);
}

}  // namespace
}  // namespace ag::plan
