// The localizer's parameter table: unique keys, and its defaults are the structs' defaults.
#include <gtest/gtest.h>

#include <set>
#include <string>

#include "airground/localization/semantic_localizer.hpp"

namespace ag::loc {
namespace {

TEST(LocalizerParams, KeysAreUnique) {
  std::set<std::string> keys;
  for (const ParamSpec& s : kLocalizerParamSpecs) EXPECT_TRUE(keys.insert(std::string(s.key)).second) << s.key;
  EXPECT_EQ(keys.size(), kLocalizerParamSpecs.size());
}

TEST(LocalizerParams, TableDefaultsAreTheStructDefaults) {
  const ParamSection section{"localizer", kLocalizerParamSpecs, "semantic localizer"};
  const Config cfg = Config::defaults(std::span<const ParamSection>(&section, 1));
  const LocalizerParams got = load_localizer_params(SectionView(cfg, "localizer"), 0.5, 64);
  const LocalizerParams want;
  // gate
  EXPECT_EQ(got.gate.standstill_speed_mps, want.gate.standstill_speed_mps);
  EXPECT_EQ(got.gate.standstill_yaw_rate_rad_s, want.gate.standstill_yaw_rate_rad_s);
  EXPECT_EQ(got.gate.max_gap_s, want.gate.max_gap_s);
  // render
  EXPECT_EQ(got.render.angle_bins, want.render.angle_bins);
  EXPECT_EQ(got.render.range_bins, want.render.range_bins);
  EXPECT_EQ(got.render.min_range_m, want.render.min_range_m);
  EXPECT_EQ(got.render.max_height_m, want.render.max_height_m);
  EXPECT_EQ(got.render.max_count_per_bin, want.render.max_count_per_bin);
  EXPECT_EQ(got.render.sensor_in_body.x, want.render.sensor_in_body.x);
  EXPECT_EQ(got.render.sensor_in_body.y, want.render.sensor_in_body.y);
  EXPECT_EQ(got.render.sensor_in_body.yaw, want.render.sensor_in_body.yaw);
  // filter
  const ParticleFilterParams& a = got.filter;
  const ParticleFilterParams& b = want.filter;
  EXPECT_EQ(a.min_particles, b.min_particles);
  EXPECT_EQ(a.max_particles, b.max_particles);
  EXPECT_EQ(a.kld_epsilon, b.kld_epsilon);
  EXPECT_EQ(a.kld_z, b.kld_z);
  EXPECT_EQ(a.kld_bin_xy_m, b.kld_bin_xy_m);
  EXPECT_EQ(a.kld_bin_yaw_rad, b.kld_bin_yaw_rad);
  EXPECT_EQ(a.motion_sigma_xy_per_m, b.motion_sigma_xy_per_m);
  EXPECT_EQ(a.motion_sigma_yaw_per_m, b.motion_sigma_yaw_per_m);
  EXPECT_EQ(a.motion_sigma_yaw_per_rad, b.motion_sigma_yaw_per_rad);
  EXPECT_EQ(a.motion_sigma_xy_min_m, b.motion_sigma_xy_min_m);
  EXPECT_EQ(a.update_min_distance_m, b.update_min_distance_m);
  EXPECT_EQ(a.update_min_turn_rad, b.update_min_turn_rad);
  EXPECT_EQ(a.yaw_window_bins, b.yaw_window_bins);
  EXPECT_EQ(a.yaw_window_bins_tracking, b.yaw_window_bins_tracking);
  EXPECT_EQ(a.gamma_m, b.gamma_m);
  EXPECT_EQ(a.weight_exponent, b.weight_exponent);
  EXPECT_EQ(a.uniform_mix, b.uniform_mix);
  EXPECT_EQ(a.resample_ess_ratio, b.resample_ess_ratio);
  EXPECT_EQ(a.unknown_mode, b.unknown_mode);
  EXPECT_EQ(a.unknown_cost_m, b.unknown_cost_m);
  EXPECT_EQ(a.min_known_fraction, b.min_known_fraction);
  EXPECT_EQ(a.range_bin_min_m, b.range_bin_min_m);
  EXPECT_EQ(a.range_bin_max_m, b.range_bin_max_m);
  EXPECT_EQ(a.range_bin_per_spread, b.range_bin_per_spread);
  EXPECT_EQ(a.converged_spread_m, b.converged_spread_m);
  EXPECT_EQ(a.converged_updates, b.converged_updates);
  EXPECT_EQ(a.lost_spread_m, b.lost_spread_m);
  EXPECT_EQ(a.lost_cost_ratio, b.lost_cost_ratio);
  EXPECT_EQ(a.lost_cost_min_m, b.lost_cost_min_m);
  EXPECT_EQ(a.lost_updates, b.lost_updates);
  EXPECT_EQ(a.recovery_retry_updates, b.recovery_retry_updates);
  EXPECT_EQ(a.recovery_sigma_xy_m, b.recovery_sigma_xy_m);
  EXPECT_EQ(a.recovery_sigma_yaw_rad, b.recovery_sigma_yaw_rad);
  EXPECT_EQ(a.recovery_growth, b.recovery_growth);
  EXPECT_EQ(a.recovery_sigma_xy_max_m, b.recovery_sigma_xy_max_m);
  EXPECT_EQ(a.lost_drift_per_m, b.lost_drift_per_m);
  // fused pose
  EXPECT_EQ(got.fused.correction_time_s, want.fused.correction_time_s);
  EXPECT_EQ(got.fused.jump_threshold_m, want.fused.jump_threshold_m);
  EXPECT_EQ(got.fused.jump_threshold_rad, want.fused.jump_threshold_rad);
  EXPECT_EQ(got.fused.odom_sigma_per_m, want.fused.odom_sigma_per_m);
  EXPECT_EQ(got.fused.odom_sigma_yaw_per_m, want.fused.odom_sigma_yaw_per_m);
  // labelling and fields
  EXPECT_EQ(got.label.sensor_height_m, want.label.sensor_height_m);
  EXPECT_EQ(got.label.max_ground_slope_deg, want.label.max_ground_slope_deg);
  EXPECT_EQ(got.label.obstacle_height_m, want.label.obstacle_height_m);
  EXPECT_EQ(got.label.min_step_m, want.label.min_step_m);
  EXPECT_EQ(got.label.max_roughness_m, want.label.max_roughness_m);
  EXPECT_EQ(got.label.max_range_m, want.label.max_range_m);
  EXPECT_EQ(got.fields.truncation_m, want.fields.truncation_m);
  EXPECT_EQ(got.fields.unknown_is_source, want.fields.unknown_is_source);
  EXPECT_EQ(got.fields.resolution_m, want.fields.resolution_m);
  EXPECT_EQ(got.fields.tile_cells, want.fields.tile_cells);
}

TEST(LocalizerParams, FixedUnknownCostIsSelectable) {
  const ParamSection section{"localizer", kLocalizerParamSpecs, "semantic localizer"};
  Config cfg = Config::defaults(std::span<const ParamSection>(&section, 1));
  ASSERT_TRUE(cfg.set("localizer.pf_unknown_mode=fixed").ok());
  EXPECT_EQ(load_localizer_params(SectionView(cfg, "localizer")).filter.unknown_mode, UnknownCost::kFixed);
  EXPECT_FALSE(cfg.set("localizer.pf_unknown_mode=guess").ok());
}

}  // namespace
}  // namespace ag::loc
