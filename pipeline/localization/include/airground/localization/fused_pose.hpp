// What the localizer publishes: a smooth pose in the map frame at the control rate, from the odometry
// between filter updates, eased onto each new filter estimate; and the odometry gate that keeps a robot
// standing still from turning (the paper's failure: the odometry's yaw drifted while the robot stood, the
// estimate followed it and diverged when the robot drove on).
#pragma once

#include <array>
#include <cstdint>

#include "airground/messages/geometry.hpp"
#include "airground/messages/messages.hpp"
#include "airground/localization/particle_filter.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/param_binding.hpp"
#include "airground/platform/time.hpp"

namespace ag::loc {

// Planar pose composition: a (+) b, and the b that takes a to c: a (+) b = c.
[[nodiscard]] Pose2 compose(const Pose2& a, const Pose2& b) noexcept;
[[nodiscard]] Pose2 between(const Pose2& a, const Pose2& c) noexcept;

struct OdometryGateParams {
  double standstill_speed_mps{0.05};     // [m/s] slower than this ...
  double standstill_yaw_rate_rad_s{0.03};// [rad/s] ... and turning slower than this is standing still
  double max_gap_s{1.0};                 // [s] a longer gap between samples is not judged (taken as motion)
};

inline constexpr ParamField<OdometryGateParams> kOdometryGateFields[] = {
    field::real("gate_standstill_speed_mps", &OdometryGateParams::standstill_speed_mps, 0.0, 1.0, "m/s", "slower than this ..."),
    field::real("gate_standstill_yaw_rate_rad_s", &OdometryGateParams::standstill_yaw_rate_rad_s, 0.0, 1.0, "rad/s", "... and turning slower: standing still, the increment is dropped"),
    field::real("gate_max_gap_s", &OdometryGateParams::max_gap_s, 0.01, 60.0, "s", "longer gaps between odometry samples are taken as motion"),
};
inline constexpr auto kOdometryGateParamSpecs = param_specs(kOdometryGateFields);
OdometryGateParams load_odometry_gate_params(const SectionView& s);

// Turns the odometry's cumulative pose into increments, dropping those of a robot standing still (slow
// yaw drift of a gyro at rest must not turn the particles). Keeps its own cumulative "gated" pose.
class OdometryGate {
 public:
  explicit OdometryGate(const OdometryGateParams& params = {}) : p_(params) {}
  // Returns the increment to apply (body frame at the previous sample; zero when dropped).
  Pose2 feed(const Pose2& odom, TimeNs stamp) noexcept;
  [[nodiscard]] const Pose2& gated_pose() const noexcept { return gated_; }  // odometry without dropped increments
  [[nodiscard]] bool standing() const noexcept { return standing_; }
  [[nodiscard]] double dropped_yaw_rad() const noexcept { return dropped_yaw_; }  // total |dyaw| dropped
  [[nodiscard]] double distance_m() const noexcept { return distance_; }  // path length of the gated odometry

 private:
  OdometryGateParams p_;
  bool has_last_{false};
  Pose2 last_{};
  TimeNs last_stamp_{0};
  Pose2 gated_{};
  bool standing_{true};
  double dropped_yaw_{0};
  double distance_{0};
};

// Status of the published pose: ag::LocalizationStatus of the "localization" channel (messages.hpp);
// FusedPose reports kInitialising (not converged: the initial guess moved by odometry, not for control),
// kTracking (converged, in the map frame) and kLost (diverged: the last good pose moved by odometry while
// the filter recovers). kNoMap is the stage's to report.

struct FusedPoseParams {
  double correction_time_s{0.3};       // [s] time constant of easing onto a new estimate (1 s gave a yaw error of 0.96 deg, 0.3 s 0.76 deg)
  double jump_threshold_m{4.0};        // [m] larger corrections are applied at once
  double jump_threshold_rad{0.35};     // [rad]
  double odom_sigma_per_m{0.03};       // [m/m] position uncertainty added per metre since the estimate
  double odom_sigma_yaw_per_m{0.003};  // [rad/m]
};

inline constexpr ParamField<FusedPoseParams> kFusedPoseFields[] = {
    field::real("fused_correction_time_s", &FusedPoseParams::correction_time_s, 0.0, 60.0, "s", "time constant of easing onto a new estimate (wheel-odometry yaw jitters: 0.3 s measured best)"),
    field::real("fused_jump_threshold_m", &FusedPoseParams::jump_threshold_m, 0.0, 100.0, "m", "larger corrections are applied at once"),
    field::real("fused_jump_threshold_rad", &FusedPoseParams::jump_threshold_rad, 0.0, 3.2, "rad", "larger yaw corrections are applied at once"),
    field::real("fused_odom_sigma_per_m", &FusedPoseParams::odom_sigma_per_m, 0.0, 1.0, "m/m", "position uncertainty per metre since the estimate"),
    field::real("fused_odom_sigma_yaw_per_m", &FusedPoseParams::odom_sigma_yaw_per_m, 0.0, 0.1, "rad/m", "yaw uncertainty per metre since the estimate"),
};
inline constexpr auto kFusedPoseParamSpecs = param_specs(kFusedPoseFields);
FusedPoseParams load_fused_pose_params(const SectionView& s);

struct FusedPoseSample {
  TimeNs stamp{0};
  Pose2 pose;                          // [m, rad] map frame
  std::array<double, 9> covariance{};  // row-major 3x3 over (x, y, yaw)
  LocalizationStatus status{LocalizationStatus::kInitialising};
  double spread_m{0};                  // [m] the filter's spread at its last estimate
};

// pose(t) = E (+) (O_E^-1 (+) O(t)) + offset x exp(-(t - t_E) / correction_time), where E is the last
// filter estimate, O_E the gated odometry when it was made, O(t) the gated odometry now, and the offset
// what the pose had to move at that estimate (zero for jumps).
class FusedPose {
 public:
  explicit FusedPose(const FusedPoseParams& params = {}) : p_(params) {}
  // Starts from an initial guess (status initialising, 1-sigma uncertainty) at the gated odometry `odom`.
  void reset(const Pose2& guess, double sigma_xy_m, double sigma_yaw_rad, const Pose2& odom, double gated_distance_m,
             TimeNs stamp) noexcept;
  void on_odometry(const Pose2& gated_odom, double gated_distance_m, TimeNs stamp) noexcept;
  // A filter estimate made with the gated odometry at `odom`.
  void on_estimate(const FilterEstimate& e, const Pose2& odom, double gated_distance_m, TimeNs stamp) noexcept;
  [[nodiscard]] FusedPoseSample sample() const noexcept { return sample_at(odom_stamp_); }
  [[nodiscard]] FusedPoseSample sample_at(TimeNs stamp) const noexcept;

 private:
  FusedPoseParams p_;
  Pose2 anchor_{};        // map pose at anchor_odom_
  Pose2 anchor_odom_{};
  double anchor_dist_{0};
  TimeNs anchor_stamp_{0};
  std::array<double, 3> offset_{};  // map-frame (dx, dy, dyaw) easing out
  std::array<double, 9> cov_{};
  double spread_{0};
  LocalizationStatus status_{LocalizationStatus::kInitialising};
  Pose2 odom_{};
  double dist_{0};
  TimeNs odom_stamp_{0};
};

}  // namespace ag::loc
