// The semantic localizer in one object: odometry gate, polar render, particle filter, fused pose.
#include "airground/localization/semantic_localizer.hpp"

namespace ag::loc {

LocalizerParams load_localizer_params(const SectionView& s, double map_resolution_m, int map_tile_cells) {
  LocalizerParams p;
  p.gate = load_odometry_gate_params(s);
  p.render = load_polar_render_params(s);
  p.filter = load_particle_filter_params(s);
  p.fused = load_fused_pose_params(s);
  p.label = load_geometric_label_params(s);
  p.fields = load_distance_field_params(s, map_resolution_m, map_tile_cells);
  return p;
}

SemanticLocalizer::SemanticLocalizer(const LocalizerParams& params, const LocalizationChannels& channels, std::uint64_t seed)
    : p_(params), gate_(params.gate), render_(params.render, channels), filter_(params.filter, params.render, seed),
      fused_(params.fused) {}

void SemanticLocalizer::initialise_gaussian(const Pose2& guess, double sigma_xy_m, double sigma_yaw_rad, TimeNs stamp) noexcept {
  filter_.initialise_gaussian(guess, sigma_xy_m, sigma_yaw_rad);
  fused_.reset(guess, sigma_xy_m, sigma_yaw_rad, gate_.gated_pose(), gate_.distance_m(), stamp);
}

void SemanticLocalizer::initialise_disc(const Pose2& guess, double radius_m, double yaw_halfwidth_rad, TimeNs stamp) noexcept {
  filter_.initialise_disc(guess, radius_m, yaw_halfwidth_rad);
  fused_.reset(guess, radius_m / 2.0, yaw_halfwidth_rad / 1.7320508075688772, gate_.gated_pose(), gate_.distance_m(), stamp);
}

void SemanticLocalizer::on_odometry(const Pose2& odom, TimeNs stamp) noexcept {
  const Pose2 d = gate_.feed(odom, stamp);
  if (d.x != 0.0 || d.y != 0.0 || d.yaw != 0.0) filter_.add_motion(d);
  fused_.on_odometry(gate_.gated_pose(), gate_.distance_m(), stamp);
  last_stamp_ = stamp;
}

void SemanticLocalizer::fill(LocalizationMsg& m) const noexcept {
  const FusedPoseSample s = fused_.sample();
  m.stamp = s.stamp;
  m.status = s.status;
  m.pose = s.pose;
  m.covariance = s.covariance;
  m.spread_m = s.spread_m;
  m.particles = filter_.estimate().particles;
  m.updates = static_cast<std::uint32_t>(filter_.estimate().updates);
}

UpdateReport SemanticLocalizer::on_scan(std::span<const ScanPoint> labelled, const ClassDistanceFields& fields, TimeNs stamp) noexcept {
  const bool moved = filter_.wants_update();
  if (!moved && !standing_update_due(fields)) return {};
  render_.render(labelled, filter_.range_bin_m());
  const UpdateReport rep = moved ? filter_.update(render_, fields) : filter_.update_standing(render_, fields);
  if (rep.updated) {
    last_update_stamp_ = last_stamp_;
    fused_.on_estimate(filter_.estimate(), gate_.gated_pose(), gate_.distance_m(), stamp);
  }
  return rep;
}

}  // namespace ag::loc
