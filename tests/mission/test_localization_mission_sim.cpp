// Localization missions: one ground robot drives the default world's roads through its real role table
// (lockstep runner, simulated 64x1024 LiDAR and wheel odometry, the world's class map as aerial tiles)
// from an initial guess 16 m and 30 deg off, and its published pose is scored against the truth (issue
// 5). Shorter routes than the 2 km of tools/eval/localization-matrix.sh, whose figures are in
// docs/benchmarks.md; the bounds here are issue 5's goals.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>

#include "airground/sim/eval_localization.hpp"

namespace ag::sim {
namespace {

namespace fs = std::filesystem;

std::string out_dir(const std::string& name) {
  const char* b = std::getenv("AG_BINARY_DIR");
  return (fs::path(b != nullptr ? b : fs::temp_directory_path().string()) / "mission-localization" / name).string();
}

EvalLocalizationOptions base(const std::string& name, std::uint64_t seed) {
  EvalLocalizationOptions o;
  o.world = "default";
  o.seed = seed;
  o.out_dir = out_dir(name);
  o.init_error_m = 16;
  o.init_yaw_error_deg = 30;
  o.route_km = 0.4;
  o.quiet = true;
  return o;
}

void print(const char* what, const LocalizationMetrics& m) {
  std::printf("%s: converged %d after %.1f s (%.0f m); error mean %.2f m, p95 %.2f m, max %.2f m, yaw %.2f deg; odometry alone %.1f m; "
              "divergences %llu\n",
              what, m.converged ? 1 : 0, m.convergence_time_s, m.convergence_distance_m, m.loc_error_mean_m, m.loc_error_p95_m,
              m.loc_error_max_m, m.yaw_error_mean_deg, m.odom_only_error_mean_m, static_cast<unsigned long long>(m.divergences));
}

// The localizer on the world's true point classes: the ablation --oracle labels (a LiDAR gives none);
// the field-mode labeller is GeometricTwoClassLabelsConverge below.
TEST(LocalizationMission, GroundTruthLabelsConvergeWithin60sAndTrackWithinTheGoals) {
  EvalLocalizationOptions o = base("gt", 2);
  o.oracles = {"labels"};
  auto r = eval_localization(o);
  ASSERT_TRUE(r.ok()) << r.error().message;
  const LocalizationMetrics& m = r.value();
  print("gt labels", m);
  EXPECT_EQ(m.labels, "gt");
  EXPECT_TRUE(m.localization_published);
  ASSERT_TRUE(m.converged);
  EXPECT_LE(m.convergence_time_s, 60.0);
  EXPECT_LE(m.loc_error_mean_m, 1.5);
  EXPECT_LE(m.loc_error_p95_m, 3.0);
  EXPECT_LE(m.yaw_error_mean_deg, 2.0);
  EXPECT_EQ(m.divergences, 0u);
  EXPECT_GT(m.odom_only_error_mean_m, m.loc_error_mean_m) << "the map must do better than odometry alone";
  EXPECT_TRUE(fs::exists(fs::path(out_dir("gt")) / "trajectory.png"));
  EXPECT_TRUE(fs::exists(fs::path(out_dir("gt")) / "error.png"));
}

// The paper's failure: the odometry's yaw drifted while the robot stood, and the estimate diverged when
// it drove on. 5 minutes at 0.003 rad/s is 52 degrees of drift.
// Pinned to the labels ablation: this holds the odometry gate and recovery through a long stop. In field
// mode (geometric labels, seed 3) the same run measured converged no, 1 divergence, error mean 31.1 m,
// p95 217 m (issue 27, 2026-12-05): an open problem of the geometric labeller, not hidden here; field
// mode's convergence is held by GeometricTwoClassLabelsConverge.
TEST(LocalizationMission, StandingStillFiveMinutesWithYawDriftThenDrivingOnDoesNotDiverge) {
  EvalLocalizationOptions o = base("stand", 3);
  o.oracles = {"labels"};
  o.stand_still_s = 300;
  o.stand_still_at_s = 90;
  o.yaw_drift_at_rest = 0.003;
  o.yaw_drift_at_rest_set = true;
  auto r = eval_localization(o);
  ASSERT_TRUE(r.ok()) << r.error().message;
  const LocalizationMetrics& m = r.value();
  print("stand 300 s with yaw drift", m);
  ASSERT_TRUE(m.converged);
  EXPECT_LT(m.convergence_time_s, 90.0) << "converged before the stop, and stayed converged through it";
  EXPECT_EQ(m.divergences, 0u);
  EXPECT_LE(m.loc_error_mean_m, 1.5);
  EXPECT_LE(m.yaw_error_mean_deg, 2.0);
}

TEST(LocalizationMission, GeometricTwoClassLabelsConverge) {
  EvalLocalizationOptions o = base("geometric", 4);
  o.labels = "geometric";
  auto r = eval_localization(o);
  ASSERT_TRUE(r.ok()) << r.error().message;
  const LocalizationMetrics& m = r.value();
  print("geometric labels", m);
  EXPECT_EQ(m.labels, "geometric");
  ASSERT_TRUE(m.converged);
  EXPECT_LE(m.loc_error_mean_m, 3.0);
}

}  // namespace
}  // namespace ag::sim
