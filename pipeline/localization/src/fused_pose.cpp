// The odometry gate and the fused pose the localizer publishes.
#include "airground/localization/fused_pose.hpp"

#include <cmath>

namespace ag::loc {

Pose2 compose(const Pose2& a, const Pose2& b) noexcept {
  const double c = std::cos(a.yaw), s = std::sin(a.yaw);
  return Pose2{a.x + c * b.x - s * b.y, a.y + s * b.x + c * b.y, wrap_angle(a.yaw + b.yaw)};
}

Pose2 between(const Pose2& a, const Pose2& c) noexcept {
  const double co = std::cos(a.yaw), si = std::sin(a.yaw);
  const double dx = c.x - a.x, dy = c.y - a.y;
  return Pose2{co * dx + si * dy, -si * dx + co * dy, wrap_angle(c.yaw - a.yaw)};
}

OdometryGateParams load_odometry_gate_params(const SectionView& s) {
  return load_params(s, kOdometryGateFields);
}

FusedPoseParams load_fused_pose_params(const SectionView& s) {
  return load_params(s, kFusedPoseFields);
}

Pose2 OdometryGate::feed(const Pose2& odom, TimeNs stamp) noexcept {
  if (!has_last_) {
    has_last_ = true;
    last_ = odom;
    last_stamp_ = stamp;
    return {};
  }
  const Pose2 d = between(last_, odom);
  const double dt = to_seconds(stamp - last_stamp_);
  last_ = odom;
  last_stamp_ = stamp;
  const double step = std::hypot(d.x, d.y);
  if (dt > 0.0 && dt <= p_.max_gap_s)
    standing_ = step / dt < p_.standstill_speed_mps && std::fabs(d.yaw) / dt < p_.standstill_yaw_rate_rad_s;
  else if (dt <= 0.0)
    standing_ = step < 1e-4 && std::fabs(d.yaw) < 1e-4;
  else
    standing_ = false;
  if (standing_) {
    dropped_yaw_ += std::fabs(d.yaw);
    return {};
  }
  gated_ = compose(gated_, d);
  distance_ += step;
  return d;
}

void FusedPose::reset(const Pose2& guess, double sigma_xy_m, double sigma_yaw_rad, const Pose2& odom,
                      double gated_distance_m, TimeNs stamp) noexcept {
  anchor_ = guess;
  anchor_odom_ = odom;
  anchor_dist_ = gated_distance_m;
  anchor_stamp_ = stamp;
  offset_ = {};
  cov_ = {sigma_xy_m * sigma_xy_m, 0, 0, 0, sigma_xy_m * sigma_xy_m, 0, 0, 0, sigma_yaw_rad * sigma_yaw_rad};
  spread_ = sigma_xy_m;
  status_ = LocalizationStatus::kInitialising;
  odom_ = odom;
  dist_ = gated_distance_m;
  odom_stamp_ = stamp;
}

void FusedPose::on_odometry(const Pose2& gated_odom, double gated_distance_m, TimeNs stamp) noexcept {
  odom_ = gated_odom;
  dist_ = gated_distance_m;
  odom_stamp_ = stamp;
}

void FusedPose::on_estimate(const FilterEstimate& e, const Pose2& odom, double gated_distance_m, TimeNs stamp) noexcept {
  on_odometry(odom, gated_distance_m, stamp);
  if (e.status == FilterStatus::kLost) {  // keep dead-reckoning from the last good anchor
    status_ = LocalizationStatus::kLost;
    return;
  }
  if (e.status != FilterStatus::kTracking) {  // not converged: the filter's mean, no easing
    anchor_ = e.pose;
    anchor_odom_ = odom;
    anchor_dist_ = gated_distance_m;
    anchor_stamp_ = stamp;
    offset_ = {};
    cov_ = e.covariance;
    spread_ = e.spread_m;
    status_ = LocalizationStatus::kInitialising;
    return;
  }
  const Pose2 now = sample_at(stamp).pose;
  std::array<double, 3> off{now.x - e.pose.x, now.y - e.pose.y, wrap_angle(now.yaw - e.pose.yaw)};
  if (status_ != LocalizationStatus::kTracking || std::hypot(off[0], off[1]) > p_.jump_threshold_m ||
      std::fabs(off[2]) > p_.jump_threshold_rad)
    off = {};
  anchor_ = e.pose;
  anchor_odom_ = odom;
  anchor_dist_ = gated_distance_m;
  anchor_stamp_ = stamp;
  offset_ = off;
  cov_ = e.covariance;
  spread_ = e.spread_m;
  status_ = LocalizationStatus::kTracking;
}

FusedPoseSample FusedPose::sample_at(TimeNs stamp) const noexcept {
  FusedPoseSample out;
  out.stamp = stamp;
  Pose2 p = compose(anchor_, between(anchor_odom_, odom_));
  const double age = to_seconds(stamp - anchor_stamp_);
  const double k = p_.correction_time_s > 0.0 ? std::exp(-std::max(0.0, age) / p_.correction_time_s) : 0.0;
  p.x += offset_[0] * k;
  p.y += offset_[1] * k;
  p.yaw = wrap_angle(p.yaw + offset_[2] * k);
  out.pose = p;
  out.covariance = cov_;
  const double d = std::max(0.0, dist_ - anchor_dist_);
  const double sxy = p_.odom_sigma_per_m * d, syaw = p_.odom_sigma_yaw_per_m * d;
  out.covariance[0] += sxy * sxy;
  out.covariance[4] += sxy * sxy;
  out.covariance[8] += syaw * syaw;
  out.status = status_;
  out.spread_m = spread_;
  return out;
}

}  // namespace ag::loc
