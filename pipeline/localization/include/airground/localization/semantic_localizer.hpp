// The ground robot's semantic localizer in one object, for the stage wrapper: gated odometry in, labelled
// scans in (rendered at the filter's range-bin size and matched against the aerial distance fields), a
// smooth fused pose out. The scan labeller and the distance fields are owned by the caller (the labeller
// is chosen by configuration; the fields follow the aerial map's tiles).
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <iterator>
#include <span>

#include "airground/localization/class_distance_fields.hpp"
#include "airground/localization/fused_pose.hpp"
#include "airground/localization/particle_filter.hpp"
#include "airground/localization/polar_render.hpp"
#include "airground/localization/scan_labeller.hpp"
#include "airground/platform/time.hpp"
#include "airground/platform/param_binding.hpp"

namespace ag::loc {

struct LocalizerParams {
  OdometryGateParams gate;
  PolarRenderParams render;
  ParticleFilterParams filter;
  FusedPoseParams fused;
  GeometricLabelParams label;     // used by the caller's GeometricLabeller
  DistanceFieldParams fields;     // used by the caller's ClassDistanceFields (resolution and tiles from the map)
};

// Every parameter of the localizer, with unique keys, for one stage section of a role's YAML.
inline constexpr auto kLocalizerParamSpecs =
    param_specs(kOdometryGateFields, kPolarRenderParamSpecs, kParticleFilterFields, kFusedPoseFields,
                kGeometricLabelFields, kDistanceFieldFields);
// Reads them from one section (resolution and tile size of the fields come from the aerial map).
LocalizerParams load_localizer_params(const SectionView& s, double map_resolution_m = 0.5, int map_tile_cells = 64);

class SemanticLocalizer {
 public:
  SemanticLocalizer(const LocalizerParams& params, const LocalizationChannels& channels, std::uint64_t seed);

  // Initial guess in the map frame at the current odometry (status initialising).
  void initialise_gaussian(const Pose2& guess, double sigma_xy_m, double sigma_yaw_rad, TimeNs stamp) noexcept;
  void initialise_disc(const Pose2& guess, double radius_m, double yaw_halfwidth_rad, TimeNs stamp) noexcept;

  // The odometry's cumulative pose (any fixed odometry frame) at `stamp`; call it with the odometry at a
  // scan's time before on_scan().
  void on_odometry(const Pose2& odom, TimeNs stamp) noexcept;
  // The robot moved enough since the last update for a scan to be worth labelling and matching, or it is
  // lost (or still converging after converging_standing_after_m of driving, or tracking at a pose that
  // `fields` now say it cannot hold: ParticleFilter::pose_blocked) and lost_standing_update_s passed since
  // the last update (at the last odometry stamp).
  [[nodiscard]] bool wants_scan(const ClassDistanceFields& fields) const noexcept {
    return filter_.wants_update() || standing_update_due(fields);
  }
  // A labelled scan (sensor frame). Renders it and updates the filter when wants_scan(); never allocates.
  UpdateReport on_scan(std::span<const ScanPoint> labelled, const ClassDistanceFields& fields, TimeNs stamp) noexcept;

  // The planner found no free cell near the tracked pose (or, false, it found one): see
  // ParticleFilter::set_start_blocked; a standing robot is matched again while it holds.
  void set_start_blocked(bool blocked) noexcept { filter_.set_start_blocked(blocked); }

  // The smooth pose at the last odometry stamp, or extrapolated in time at `stamp` (same odometry).
  [[nodiscard]] FusedPoseSample pose() const noexcept { return fused_.sample(); }
  [[nodiscard]] FusedPoseSample pose_at(TimeNs stamp) const noexcept { return fused_.sample_at(stamp); }
  // The "localization" channel's message for the last odometry stamp (stamp, status, pose, covariance,
  // spread, particles, updates; `published` is the caller's).
  void fill(LocalizationMsg& m) const noexcept;

  [[nodiscard]] const ParticleFilter& filter() const noexcept { return filter_; }
  [[nodiscard]] const ScanRenderPolar& render() const noexcept { return render_; }
  [[nodiscard]] const OdometryGate& gate() const noexcept { return gate_; }
  [[nodiscard]] const LocalizerParams& params() const noexcept { return p_; }
  // Memory of the filter, the render and the rest (the caller's distance fields and labeller not included).
  [[nodiscard]] std::size_t memory_bytes() const noexcept {
    return sizeof(*this) + filter_.memory_bytes() - sizeof(filter_) + render_.memory_bytes() - sizeof(render_);
  }

 private:
  LocalizerParams p_;
  OdometryGate gate_;
  ScanRenderPolar render_;
  ParticleFilter filter_;
  FusedPose fused_;
  TimeNs last_stamp_{0};
  TimeNs last_update_stamp_{0};

  [[nodiscard]] bool standing_update_due(const ClassDistanceFields& fields) const noexcept {
    if (p_.filter.lost_standing_update_s <= 0.0 || last_stamp_ - last_update_stamp_ < from_seconds(p_.filter.lost_standing_update_s))
      return false;
    switch (filter_.status()) {
      case FilterStatus::kLost: return true;
      case FilterStatus::kInitialising: return filter_.driven_m() >= p_.filter.converging_standing_after_m;
      case FilterStatus::kTracking: return filter_.start_blocked() || filter_.pose_blocked(fields);  // the planner's word, or the map filled in under it
      case FilterStatus::kUninitialised: return false;
    }
    return false;
  }
};

}  // namespace ag::loc
