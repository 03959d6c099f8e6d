// Tests of the simulated ground-robot odometry: exact when perfect, error statistics, standing still, config.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <vector>

#include "airground/sim/wheel_odometry.hpp"

namespace ag::sim {
namespace {

constexpr double kR = 0.098, kW = 0.37;

WheelOdometryConfig perfect() {
  WheelOdometryConfig c;
  c.wheel_radius_error = c.track_width_error = c.slip_sigma_per_sqrt_m = 0.0;
  c.sigma_xy_m = c.sigma_yaw_rad = 0.0;
  return c;
}

double sd_of(const std::vector<double>& v) {
  double m = 0, s2 = 0;
  for (double x : v) m += x;
  m /= static_cast<double>(v.size());
  for (double x : v) s2 += (x - m) * (x - m);
  return std::sqrt(s2 / static_cast<double>(v.size() - 1));
}

TEST(WheelOdometry, PerfectWheelsIntegrateExactArcs) {
  WheelOdometrySimulator odo(perfect(), 1);
  // v = 1 m/s, omega = 0.5 rad/s: a circle of radius 2 m closes after 4*pi s.
  const double v = 1.0, om = 0.5;
  const double wl = (v - 0.5 * kW * om) / kR, wr = (v + 0.5 * kW * om) / kR;
  const TimeNs dt = 10 * kNsPerMs;
  const auto steps = static_cast<int>(std::llround(4 * kPi / 0.01));
  odo.step(0, Pose2{}, wl, wr);
  OdometrySample s;
  for (int i = 1; i <= steps; ++i) s = odo.step(i * dt, Pose2{}, wl, wr);
  const double t_end = steps * 0.01;  // not exactly 4*pi
  EXPECT_NEAR(s.pose.x, 2.0 * std::sin(om * t_end), 1e-9);
  EXPECT_NEAR(s.pose.y, 2.0 * (1 - std::cos(om * t_end)), 1e-9);
  EXPECT_NEAR(wrap_angle(s.pose.yaw - om * t_end), 0.0, 1e-9);
  EXPECT_NEAR(s.wheel_left_rad_s, wl, 1e-9);
  EXPECT_NEAR(s.dx, v * 0.01 * std::sin(om * 0.01) / (om * 0.01), 1e-12);
  EXPECT_TRUE(s.moving);
}

TEST(WheelOdometry, TurningInPlaceHasNoTranslation) {
  WheelOdometrySimulator odo(perfect(), 1);
  odo.step(0, Pose2{}, 0, 0);
  OdometrySample s;
  for (int i = 1; i <= 100; ++i) s = odo.step(i * 10 * kNsPerMs, Pose2{}, -5.0, 5.0);
  EXPECT_NEAR(s.pose.x, 0.0, 1e-12);
  EXPECT_NEAR(s.pose.y, 0.0, 1e-12);
  EXPECT_NEAR(s.pose.yaw, wrap_angle(2 * 5.0 * kR / kW * 1.0), 1e-9);
}

TEST(WheelOdometry, StandingStillGivesZeroIncrementsByDefault) {
  for (const OdometryMode mode : {OdometryMode::kWheels, OdometryMode::kTruthPlusNoise}) {
    WheelOdometryConfig c;  // defaults, with all their noise
    c.mode = mode;
    WheelOdometrySimulator odo(c, 3);
    const Pose2 still{5.0, -2.0, 1.0};
    for (int i = 0; i < 1000; ++i) {
      const OdometrySample s = odo.step(i * 10 * kNsPerMs, still, 0.0, 0.0);
      EXPECT_EQ(s.dx, 0.0);
      EXPECT_EQ(s.dy, 0.0);
      EXPECT_EQ(s.dyaw, 0.0);
      EXPECT_FALSE(s.moving);
    }
    EXPECT_EQ(odo.pose().x, 0.0);
    EXPECT_EQ(odo.pose().yaw, 0.0);
  }
}

TEST(WheelOdometry, YawDriftAtRestWhenConfigured) {
  for (const OdometryMode mode : {OdometryMode::kWheels, OdometryMode::kTruthPlusNoise}) {
    WheelOdometryConfig c;
    c.mode = mode;
    c.yaw_drift_at_rest_rad_per_s = 0.001;
    WheelOdometrySimulator odo(c, 3);
    for (int i = 0; i <= 6000; ++i) odo.step(i * 10 * kNsPerMs, Pose2{}, 0.0, 0.0);
    EXPECT_NEAR(odo.pose().yaw, 0.06, 1e-9);  // 60 s
    EXPECT_EQ(odo.pose().x, 0.0);
  }
}

TEST(WheelOdometry, CalibrationErrorsAreSystematic) {
  WheelOdometryConfig c = perfect();
  c.wheel_radius_error = 0.01;
  c.track_width_error = 0.05;
  for (std::uint64_t seed = 0; seed < 20; ++seed) {
    WheelOdometrySimulator odo(c, seed);
    const double w = 1.0 / kR;  // 1 m/s on both wheels
    double along = 0;
    odo.step(0, Pose2{}, w, w);
    for (int i = 1; i <= 1000; ++i) along += odo.step(i * 10 * kNsPerMs, Pose2{}, w, w).dx;
    const double el = odo.left_radius_error(), er = odo.right_radius_error();
    // 10 m at the believed radii: the mean stretches the distance, the difference turns the heading.
    EXPECT_NEAR(along, 10.0 * (1 + 0.5 * (el + er)), 1e-3);
    EXPECT_NEAR(odo.pose().yaw, 10.0 * (er - el) / (kW * (1 + odo.track_width_error())), 1e-9);
  }
}

TEST(WheelOdometry, StraightLineSlipMatchesItsStatistics) {
  WheelOdometryConfig c = perfect();
  c.slip_sigma_per_sqrt_m = 0.005;
  constexpr double kL = 20.0;  // [m] at 1 m/s, 100 Hz
  constexpr int kRuns = 400;
  std::vector<double> along, heading, lateral;
  for (int run = 0; run < kRuns; ++run) {
    WheelOdometrySimulator odo(c, static_cast<std::uint64_t>(1000 + run));
    const double w = 1.0 / kR;
    double path = 0;
    odo.step(0, Pose2{}, w, w);
    for (int i = 1; i <= 2000; ++i) path += odo.step(i * 10 * kNsPerMs, Pose2{}, w, w).dx;
    along.push_back(path - kL);
    heading.push_back(odo.pose().yaw);
    lateral.push_back(odo.pose().y);
  }
  const double s = c.slip_sigma_per_sqrt_m;
  // Two independent wheel random walks of variance s^2 per metre: their mean moves the path length,
  // their difference / W the heading, whose integral the lateral position.
  EXPECT_NEAR(sd_of(along), s * std::sqrt(kL / 2), 0.15 * s * std::sqrt(kL / 2));
  const double heading_sd = std::sqrt(2.0) * s * std::sqrt(kL) / kW;
  EXPECT_NEAR(sd_of(heading), heading_sd, 0.15 * heading_sd);
  const double lateral_sd = std::sqrt(2.0 / 3.0) * s * std::pow(kL, 1.5) / kW;
  EXPECT_NEAR(sd_of(lateral), lateral_sd, 0.15 * lateral_sd);
  // Bounded: no run strays beyond 5 sigma.
  for (double y : lateral) EXPECT_LT(std::abs(y), 5 * lateral_sd);
}

TEST(WheelOdometry, SlipDoesNotDependOnTheStepRate) {
  WheelOdometryConfig c = perfect();
  c.slip_sigma_per_sqrt_m = 0.01;
  std::vector<double> fine, coarse;
  for (int run = 0; run < 400; ++run) {
    for (const int hz : {200, 10}) {
      WheelOdometrySimulator odo(c, static_cast<std::uint64_t>(run));
      const double w = 1.0 / kR;
      double path = 0;
      odo.step(0, Pose2{}, w, w);
      for (int i = 1; i <= 10 * hz; ++i) path += odo.step(i * (kNsPerS / hz), Pose2{}, w, w).dx;
      (hz == 200 ? fine : coarse).push_back(path - 10.0);
    }
  }
  EXPECT_NEAR(sd_of(fine) / sd_of(coarse), 1.0, 0.15);
}

TEST(WheelOdometry, TruthPlusNoiseAddsGaussianNoisePerStep) {
  WheelOdometryConfig c;
  c.mode = OdometryMode::kTruthPlusNoise;
  c.sigma_xy_m = 0.02;
  c.sigma_yaw_rad = 0.003;
  WheelOdometrySimulator odo(c, 9);
  std::vector<double> ex, ey, eyaw;
  odo.step(0, Pose2{}, 0, 0);
  for (int i = 1; i <= 20000; ++i) {
    // Drive along a circle: truth increment in the robot frame is (sin(a)*R, (1-cos a)*R, a).
    const double a = 0.01 * i, r = 2.0;
    const Pose2 truth{r * std::sin(a), r * (1 - std::cos(a)), wrap_angle(a)};
    const OdometrySample s = odo.step(i * 100 * kNsPerMs, truth, 0, 0);
    ex.push_back(s.dx - r * std::sin(0.01));
    ey.push_back(s.dy - r * (1 - std::cos(0.01)));
    eyaw.push_back(s.dyaw - 0.01);
    EXPECT_TRUE(s.moving);
  }
  EXPECT_NEAR(sd_of(ex), 0.02, 0.001);
  EXPECT_NEAR(sd_of(ey), 0.02, 0.001);
  EXPECT_NEAR(sd_of(eyaw), 0.003, 0.00015);
  // Perfect truth_plus_noise reproduces the truth exactly.
  WheelOdometryConfig p = perfect();
  p.mode = OdometryMode::kTruthPlusNoise;
  WheelOdometrySimulator exact(p, 1);
  exact.step(0, Pose2{1, 1, 0.3}, 0, 0);
  const OdometrySample s = exact.step(kNsPerS, Pose2{1 + std::cos(0.3), 1 + std::sin(0.3), 0.5}, 0, 0);
  EXPECT_NEAR(s.dx, 1.0, 1e-12);
  EXPECT_NEAR(s.dy, 0.0, 1e-12);
  EXPECT_NEAR(s.dyaw, 0.2, 1e-12);
}

TEST(WheelOdometry, DeterministicBySeed) {
  auto run = [](std::uint64_t seed) {
    WheelOdometrySimulator odo(WheelOdometryConfig{}, seed);
    for (int i = 0; i <= 500; ++i) odo.step(i * 10 * kNsPerMs, Pose2{}, 10.0, 12.0);
    return odo.pose();
  };
  EXPECT_EQ(run(4).x, run(4).x);
  EXPECT_EQ(run(4).yaw, run(4).yaw);
  EXPECT_NE(run(4).x, run(5).x);
}

TEST(WheelOdometryConfigYaml, LoadsAndValidatesEveryKey) {
  auto ok = load_wheel_odometry_config("mode: truth_plus_noise\nsigma_xy_m: 0.05\nyaw_drift_at_rest_rad_per_s: 0.001\n",
                                       "odo.yaml");
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  EXPECT_EQ(ok->mode, OdometryMode::kTruthPlusNoise);
  EXPECT_DOUBLE_EQ(ok->sigma_xy_m, 0.05);
  EXPECT_DOUBLE_EQ(ok->yaw_drift_at_rest_rad_per_s, 0.001);

  auto mode = load_wheel_odometry_config("mode: lidar\n", "odo.yaml");
  ASSERT_FALSE(mode.ok());
  EXPECT_NE(mode.error().message.find("wheels|truth_plus_noise"), std::string::npos) << mode.error().message;
  auto unknown = load_wheel_odometry_config("slip: 0.1\n", "odo.yaml");
  ASSERT_FALSE(unknown.ok());
  EXPECT_NE(unknown.error().message.find("wheel_odometry.slip"), std::string::npos);
  auto range = load_wheel_odometry_config("track_width_m: -1\n", "odo.yaml");
  ASSERT_FALSE(range.ok());
  EXPECT_NE(range.error().message.find("[0.05, 5] m"), std::string::npos) << range.error().message;
}

}  // namespace
}  // namespace ag::sim
