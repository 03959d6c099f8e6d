// The fused pose and the odometry gate: pose algebra, standing still, easing onto a new estimate,
// jumps, covariance growth and status.
#include <gtest/gtest.h>

#include <cmath>

#include "airground/localization/fused_pose.hpp"

namespace ag::loc {
namespace {

TEST(PoseAlgebra, ComposeAndBetweenAreInverse) {
  const Pose2 a{3.0, -2.0, 0.7}, b{1.5, 0.5, -0.3};
  const Pose2 c = compose(a, b);
  EXPECT_NEAR(c.x, 3.0 + 1.5 * std::cos(0.7) - 0.5 * std::sin(0.7), 1e-12);
  EXPECT_NEAR(c.y, -2.0 + 1.5 * std::sin(0.7) + 0.5 * std::cos(0.7), 1e-12);
  EXPECT_NEAR(c.yaw, 0.4, 1e-12);
  const Pose2 d = between(a, c);
  EXPECT_NEAR(d.x, b.x, 1e-12);
  EXPECT_NEAR(d.y, b.y, 1e-12);
  EXPECT_NEAR(d.yaw, b.yaw, 1e-12);
}

TEST(OdometryGate, DropsTheDriftOfARobotStandingStill) {
  OdometryGate gate;
  Pose2 odom{};
  EXPECT_EQ(gate.feed(odom, 0).x, 0.0);
  // 100 s at rest at 100 Hz with a gyro drifting 0.002 rad/s
  for (int k = 1; k <= 10000; ++k) {
    odom.yaw += 0.002 * 0.01;
    const Pose2 d = gate.feed(odom, from_seconds(k * 0.01));
    EXPECT_EQ(d.yaw, 0.0);
    EXPECT_TRUE(gate.standing());
  }
  EXPECT_NEAR(gate.dropped_yaw_rad(), 0.2, 1e-6);
  EXPECT_EQ(gate.gated_pose().yaw, 0.0);
  // driving at 1 m/s passes through
  for (int k = 1; k <= 100; ++k) {
    odom = compose(odom, Pose2{0.01, 0.0, 0.0});
    const Pose2 d = gate.feed(odom, from_seconds(100.0 + k * 0.01));
    EXPECT_NEAR(d.x, 0.01, 1e-9);
    EXPECT_FALSE(gate.standing());
  }
  EXPECT_NEAR(gate.distance_m(), 1.0, 1e-6);
  EXPECT_NEAR(gate.gated_pose().x, 1.0, 1e-6);  // in the gated frame: no drift in its heading
  EXPECT_NEAR(gate.gated_pose().y, 0.0, 1e-6);
  // turning in place at 0.5 rad/s passes through
  double turned = 0.0;
  for (int k = 1; k <= 100; ++k) {
    odom.yaw += 0.005;
    turned += gate.feed(odom, from_seconds(101.0 + k * 0.01)).yaw;
  }
  EXPECT_NEAR(turned, 0.5, 1e-9);
  // a gap in the samples is not judged: the increment is motion
  odom = compose(odom, Pose2{0.01, 0.0, 0.0});
  EXPECT_NEAR(gate.feed(odom, from_seconds(110.0)).x, 0.01, 1e-9);
}

FilterEstimate estimate(const Pose2& p, FilterStatus s, double sigma = 0.3) {
  FilterEstimate e;
  e.pose = p;
  e.status = s;
  e.covariance = {sigma * sigma, 0, 0, 0, sigma * sigma, 0, 0, 0, 0.01 * 0.01};
  e.spread_m = sigma;
  return e;
}

TEST(FusedPose, OdometryBetweenEstimatesAndStatus) {
  FusedPose f;
  f.reset(Pose2{10.0, 20.0, 0.5}, 8.0, 0.5, Pose2{}, 0.0, 0);
  EXPECT_EQ(f.sample().status, LocalizationStatus::kInitialising);
  EXPECT_NEAR(f.sample().covariance[0], 64.0, 1e-9);
  f.on_odometry(Pose2{2.0, 0.0, 0.0}, 2.0, from_seconds(1.0));
  EXPECT_NEAR(f.sample().pose.x, 10.0 + 2.0 * std::cos(0.5), 1e-9);
  EXPECT_NEAR(f.sample().pose.y, 20.0 + 2.0 * std::sin(0.5), 1e-9);
  // converged: tracking, from the estimate on
  f.on_estimate(estimate(Pose2{50.0, 60.0, 1.0}, FilterStatus::kTracking), Pose2{2.0, 0.0, 0.0}, 2.0, from_seconds(1.0));
  EXPECT_EQ(f.sample().status, LocalizationStatus::kTracking);
  EXPECT_NEAR(f.sample().pose.x, 50.0, 1e-9) << "the first tracking estimate is taken at once";
  f.on_odometry(Pose2{2.0, 1.0, 0.1}, 3.0, from_seconds(2.0));
  const FusedPoseSample s = f.sample();
  EXPECT_NEAR(s.pose.x, 50.0 - std::sin(1.0), 1e-9);
  EXPECT_NEAR(s.pose.y, 60.0 + std::cos(1.0), 1e-9);
  EXPECT_NEAR(s.pose.yaw, 1.1, 1e-9);
  // covariance grows with the distance since the estimate
  EXPECT_NEAR(s.covariance[0], 0.09 + std::pow(0.03 * 1.0, 2), 1e-12);
  // lost: dead-reckoning from the last good anchor goes on
  f.on_estimate(estimate(Pose2{0.0, 0.0, 0.0}, FilterStatus::kLost, 6.0), Pose2{2.0, 1.0, 0.1}, 3.0, from_seconds(2.0));
  EXPECT_EQ(f.sample().status, LocalizationStatus::kLost);
  EXPECT_NEAR(f.sample().pose.x, 50.0 - std::sin(1.0), 1e-9);
}

TEST(FusedPose, EasesOntoACorrectionAndJumpsOverLargeOnes) {
  FusedPoseParams p;
  p.correction_time_s = 1.0;  // the bounds below are for a 1 s time constant
  FusedPose f(p);
  f.reset(Pose2{}, 1.0, 0.1, Pose2{}, 0.0, 0);
  f.on_estimate(estimate(Pose2{0.0, 0.0, 0.0}, FilterStatus::kTracking), Pose2{}, 0.0, 0);
  // drive 10 s at 1 m/s; at t = 1 s the filter says the robot is 1 m further left
  double last_y = 0.0, max_step = 0.0;
  for (int k = 1; k <= 100; ++k) {
    const double t = k * 0.1;
    const Pose2 odom{t, 0.0, 0.0};
    f.on_odometry(odom, t, from_seconds(t));
    if (k == 10) f.on_estimate(estimate(Pose2{1.0, 1.0, 0.0}, FilterStatus::kTracking), odom, t, from_seconds(t));
    const FusedPoseSample s = f.sample();
    max_step = std::max(max_step, std::fabs(s.pose.y - last_y));
    last_y = s.pose.y;
    EXPECT_NEAR(s.pose.x, t, 1e-9);
    if (k == 11) {
      EXPECT_GT(s.pose.y, 0.05);
      EXPECT_LT(s.pose.y, 0.2) << "eased, not jumped";
    }
  }
  EXPECT_LT(max_step, 0.12) << "no step larger than the easing allows";
  EXPECT_NEAR(last_y, 1.0, 0.01) << "and it got there";
  // a correction beyond the jump threshold is applied at once
  const Pose2 odom{10.0, 0.0, 0.0};
  f.on_estimate(estimate(Pose2{10.0, 1.0 + 2.0 * p.jump_threshold_m, 0.0}, FilterStatus::kTracking), odom, 10.0,
                from_seconds(10.0));
  EXPECT_NEAR(f.sample().pose.y, 1.0 + 2.0 * p.jump_threshold_m, 1e-9);
}

}  // namespace
}  // namespace ag::loc
