// Drive control: wheel speeds from a twist, acceleration limits, following a planned path to its goal
// with a unicycle model, turning on the spot, stopping at the goal.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "airground/planning/drive_control.hpp"

namespace ag::plan {
namespace {

TEST(DriveControl, WheelSpeedsFromTwistKeepTheCurvature) {
  const WheelSpeeds s = wheels_from_twist(1.0, 0.5, 0.6, 5.0);
  EXPECT_NEAR(s.left_mps, 0.85, 1e-12);
  EXPECT_NEAR(s.right_mps, 1.15, 1e-12);
  const WheelSpeeds c = wheels_from_twist(2.0, 2.0, 0.6, 1.0);  // 1.4 / 2.6 scaled to max 1.0
  EXPECT_NEAR(c.right_mps, 1.0, 1e-12);
  EXPECT_NEAR(c.left_mps / c.right_mps, 1.4 / 2.6, 1e-12);
  const WheelSpeeds spin = wheels_from_twist(0.0, 1.0, 0.5, 5.0);
  EXPECT_NEAR(spin.left_mps, -spin.right_mps, 1e-12);
}

struct Unicycle {
  Pose2 p;
  void move(const TwistCommand& c, double dt) {
    p.x += c.v_mps * dt * std::cos(p.yaw + 0.5 * c.w_radps * dt);
    p.y += c.v_mps * dt * std::sin(p.yaw + 0.5 * c.w_radps * dt);
    p.yaw = wrap_angle(p.yaw + c.w_radps * dt);
  }
};

TEST(DriveControl, FollowsAnLShapedPathWithinTheLimitsAndStopsAtTheGoal) {
  DriveParams dp;
  PathFollower f(dp);
  const Point2 path[] = {{0, 0}, {20, 0}, {20, 15}};
  f.set_path(path, 3);
  Unicycle u;
  const double dt = 0.05;
  double max_dev = 0, prev_v = 0, prev_w = 0;
  int steps = 0;
  for (; steps < 2000 && f.state() != FollowState::kArrived; ++steps) {
    const TwistCommand c = f.step(u.p, dt);
    EXPECT_LE(c.v_mps - prev_v, dp.max_accel_mps2 * dt + 1e-9);
    EXPECT_GE(c.v_mps - prev_v, -dp.max_decel_mps2 * dt - 1e-9);
    EXPECT_LE(std::fabs(c.w_radps - prev_w), dp.max_turn_accel_radps2 * dt + 1e-9);
    EXPECT_LE(c.v_mps, dp.max_speed_mps + 1e-9);
    EXPECT_LE(std::fabs(c.w_radps), dp.max_turn_rate_radps + 1e-9);
    prev_v = c.v_mps;
    prev_w = c.w_radps;
    u.move(c, dt);
    const double d1 = std::hypot(u.p.x - std::clamp(u.p.x, 0.0, 20.0), u.p.y);
    const double d2 = std::hypot(u.p.x - 20.0, u.p.y - std::clamp(u.p.y, 0.0, 15.0));
    max_dev = std::max(max_dev, std::min(d1, d2));
  }
  ASSERT_EQ(f.state(), FollowState::kArrived);
  EXPECT_LT(std::hypot(u.p.x - 20, u.p.y - 15), dp.goal_tolerance_m + 0.05);
  EXPECT_LT(max_dev, 1.0) << "stays near the path";
  EXPECT_LT(steps * dt, 45.0) << "35 m at up to 1.2 m/s";
  for (int i = 0; i < 40; ++i) u.move(f.step(u.p, dt), dt);
  EXPECT_NEAR(f.last().v_mps, 0.0, 1e-9) << "stopped at the goal";
}

TEST(DriveControl, TurnsOnTheSpotWhenThePathIsBehind) {
  PathFollower f(DriveParams{});
  const Point2 path[] = {{0, 0}, {-10, 0}};
  f.set_path(path, 2);
  Unicycle u;  // facing east, the path goes west
  TwistCommand c{};
  for (int i = 0; i < 10; ++i) {
    c = f.step(u.p, 0.05);
    u.move(c, 0.05);
  }
  EXPECT_EQ(f.state(), FollowState::kTurning);
  EXPECT_NEAR(c.v_mps, 0.0, 1e-9);
  EXPECT_GT(std::fabs(c.w_radps), 0.1);
}

TEST(DriveControl, AnEmptyPathStops) {
  PathFollower f(DriveParams{});
  const Point2 one[] = {{1, 1}};
  f.set_path(one, 1);
  EXPECT_EQ(f.state(), FollowState::kIdle);
  const TwistCommand c = f.step(Pose2{}, 0.1);
  EXPECT_EQ(c.v_mps, 0.0);
}

}  // namespace
}  // namespace ag::plan
