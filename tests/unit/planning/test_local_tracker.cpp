// Local tracker: RANSAC ground on a tilted sensor among obstacles, the obstacle grid (free by ray
// casting, shadows unknown), the local goal stepping around an obstacle the aerial map missed, backing
// up then failing when blocked, the reflex stop.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "airground/core/pose_math.hpp"
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

TEST(LocalTracker, TheLocalGoalStepsAroundAnObstacleTheAerialMapMissed) {
  LocalTracker t{LocalTrackerParams{}};
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

}  // namespace
}  // namespace ag::plan
