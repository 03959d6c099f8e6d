// The simulated autopilot attitude: repeatable per seed, errors of the configured size (bias and white
// noise), body rates from the truth's motion, and its model file checked key by key.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "airground/sim/attitude.hpp"

namespace ag::sim {
namespace {

TEST(SimAttitude, SameSeedSameSamplesAndFiftyHertzGrid) {
  AttitudeSimulator a(AttitudeConfig{}, 7), b(AttitudeConfig{}, 7), c(AttitudeConfig{}, 8);
  int n = 0;
  for (TimeNs t = 0; t <= kNsPerS; t += 5 * kNsPerMs) {  // a 200 Hz caller
    const Pose3 truth{0, 0, 40, 0.01, -0.02, 1.0};
    AttitudeSample sa, sb, sc;
    const bool da = a.sample(t, truth, sa), db = b.sample(t, truth, sb);
    ASSERT_EQ(da, db);
    (void)c.sample(t, truth, sc);
    if (!da) continue;
    ++n;
    EXPECT_EQ(sa.roll, sb.roll);
    EXPECT_EQ(sa.yaw_rate, sb.yaw_rate);
    if (n == 1) {
      EXPECT_NE(sa.roll, sc.roll) << "another seed, other errors";
    }
  }
  EXPECT_EQ(n, 51);  // 0, 20, ..., 1000 ms
}

TEST(SimAttitude, ErrorsHaveTheConfiguredSize) {
  AttitudeConfig cfg;
  cfg.roll_pitch_bias_tau_s = 1.0;  // short, so one run sees many independent biases
  cfg.yaw_bias_tau_s = 1.0;
  double s_roll = 0, s_yaw = 0, s_rate = 0;
  int n = 0;
  AttitudeSimulator sim(cfg, 42);
  for (TimeNs t = 0; t < 2000 * kNsPerS; t += 20 * kNsPerMs) {
    AttitudeSample s;
    const Pose3 truth{0, 0, 40, 0, 0, 0.5};
    if (!sim.sample(t, truth, s)) continue;
    s_roll += s.roll * s.roll;
    s_yaw += (s.yaw - 0.5) * (s.yaw - 0.5);
    s_rate += s.pitch_rate * s.pitch_rate;
    ++n;
  }
  EXPECT_NEAR(std::sqrt(s_roll / n), std::hypot(cfg.roll_pitch_bias_sigma_rad, cfg.roll_pitch_noise_rad), 0.1 * cfg.roll_pitch_bias_sigma_rad);
  EXPECT_NEAR(std::sqrt(s_yaw / n), std::hypot(cfg.yaw_bias_sigma_rad, cfg.yaw_noise_rad), 0.1 * cfg.yaw_bias_sigma_rad);
  EXPECT_NEAR(std::sqrt(s_rate / n), cfg.rate_noise_rad_s, 0.05 * cfg.rate_noise_rad_s);
}

TEST(SimAttitude, BodyRatesFollowTheTruthAndModelFileIsChecked) {
  AttitudeConfig cfg;
  cfg.roll_pitch_bias_sigma_rad = cfg.yaw_bias_sigma_rad = 0;
  cfg.roll_pitch_noise_rad = cfg.yaw_noise_rad = cfg.rate_noise_rad_s = 0;
  AttitudeSimulator sim(cfg, 1);
  AttitudeSample s;
  // Turning left at 0.3 rad/s, level: yaw rate 0.3 about the body's up axis, nothing else.
  for (TimeNs t = 0; t <= 200 * kNsPerMs; t += 20 * kNsPerMs) ASSERT_TRUE(sim.sample(t, Pose3{0, 0, 0, 0, 0, 0.3 * to_seconds(t)}, s));
  EXPECT_NEAR(s.yaw_rate, 0.3, 1e-9);
  EXPECT_NEAR(s.pitch_rate, 0.0, 1e-9);
  EXPECT_NEAR(s.yaw, 0.06, 1e-12);
  auto ok = load_attitude_config(std::string_view("rate_hz: 25\nyaw_bias_sigma_rad: 0.05\n"), "attitude.yaml");
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  EXPECT_EQ(ok.value().rate_hz, 25.0);
  auto bad = load_attitude_config(std::string_view("yaw_bias_sigma: 0.05\n"), "attitude.yaml");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("yaw_bias_sigma"), std::string::npos) << bad.error().message;
  auto range = load_attitude_config(std::string_view("rate_hz: 0\n"), "attitude.yaml");
  ASSERT_FALSE(range.ok());
  EXPECT_NE(range.error().message.find("attitude.rate_hz"), std::string::npos) << range.error().message;
}

}  // namespace
}  // namespace ag::sim
