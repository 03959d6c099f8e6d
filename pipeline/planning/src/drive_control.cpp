// Path follower and differential-drive conversion.
#include "airground/planning/drive_control.hpp"

#include <algorithm>
#include <cmath>

namespace ag::plan {

DriveParams load_drive_params(const SectionView& s) { return load_params(s, kDriveFields); }

WheelSpeeds wheels_from_twist(double v, double w, double track, double max_wheel) noexcept {
  WheelSpeeds s{v - 0.5 * w * track, v + 0.5 * w * track};
  const double m = std::max(std::fabs(s.left_mps), std::fabs(s.right_mps));
  if (m > max_wheel && m > 0) {
    s.left_mps *= max_wheel / m;
    s.right_mps *= max_wheel / m;
  }
  return s;
}

void PathFollower::set_path(const Point2* pts, std::uint32_t n) noexcept {
  n_ = std::min<std::uint32_t>(n, static_cast<std::uint32_t>(kMaxPathPoints));
  for (std::uint32_t i = 0; i < n_; ++i) pts_[i] = pts[i];
  seg_ = 0;
  relocate_ = true;
  state_ = n_ >= 2 ? FollowState::kFollowing : FollowState::kIdle;
}

void PathFollower::clear() noexcept {
  n_ = 0;
  seg_ = 0;
  state_ = FollowState::kIdle;
}

TwistCommand PathFollower::limit(double v, double w, double dt) noexcept {
  v = std::clamp(v, -p_.max_speed_mps, p_.max_speed_mps);
  w = std::clamp(w, -p_.max_turn_rate_radps, p_.max_turn_rate_radps);
  const double dv = v - out_.v_mps;
  const bool slowing = std::fabs(v) < std::fabs(out_.v_mps) || v * out_.v_mps < 0;
  const double a = (slowing ? p_.max_decel_mps2 : p_.max_accel_mps2) * dt;
  out_.v_mps += std::clamp(dv, -a, a);
  const double aw = p_.max_turn_accel_radps2 * dt;
  out_.w_radps += std::clamp(w - out_.w_radps, -aw, aw);
  return out_;
}

TwistCommand PathFollower::stop(double dt) noexcept { return limit(0.0, 0.0, dt); }

namespace {
// target in the robot's frame (x ahead, y left).
Point2 in_robot_frame(const Pose2& pose, const Point2& target) noexcept {
  const double dx = target.x - pose.x, dy = target.y - pose.y;
  return Point2{std::cos(pose.yaw) * dx + std::sin(pose.yaw) * dy, -std::sin(pose.yaw) * dx + std::cos(pose.yaw) * dy};
}
}  // namespace

TwistCommand PathFollower::turn_toward(const Pose2& pose, const Point2& target, double dt, double min_heading_rad) noexcept {
  const Point2 l = in_robot_frame(pose, target);
  const double err = std::atan2(l.y, l.x);
  if (!std::isfinite(err) || std::fabs(err) <= min_heading_rad) return halt();
  out_.v_mps = 0.0;  // never forward, not even while ramping down
  if (state_ == FollowState::kFollowing) state_ = FollowState::kTurning;
  return limit(0.0, std::copysign(p_.max_turn_rate_radps, err) * std::min(1.0, std::fabs(err)), dt);
}

TwistCommand PathFollower::step(const Pose2& pose, double dt, double speed_cap, const Point2* steer_to) noexcept {
  if (state_ == FollowState::kIdle || state_ == FollowState::kArrived || n_ < 2) return stop(dt);
  // Advance the segment to the one nearest the robot (never backwards).
  auto project = [&](std::uint32_t s, double& t) {
    const Point2 a = pts_[s], b = pts_[s + 1];
    const double dx = b.x - a.x, dy = b.y - a.y, l2 = dx * dx + dy * dy;
    t = l2 > 0 ? std::clamp(((pose.x - a.x) * dx + (pose.y - a.y) * dy) / l2, 0.0, 1.0) : 1.0;
    return std::hypot(a.x + t * dx - pose.x, a.y + t * dy - pose.y);
  };
  double t = 0;
  double best = project(seg_, t);
  // After a new path, the nearest segment of the whole path (the robot may be anywhere along it); then
  // a few ahead only, so a path that passes by itself is not cut short.
  const std::uint32_t window = relocate_ ? n_ : 8;
  relocate_ = false;
  for (std::uint32_t s = seg_ + 1; s + 1 < n_ && s < seg_ + window; ++s) {
    double ts = 0;
    const double d = project(s, ts);
    if (d < best) {
      best = d;
      seg_ = s;
      t = ts;
    }
  }
  (void)project(seg_, t);
  // Remaining length and the look-ahead point.
  const Point2 a = pts_[seg_], b = pts_[seg_ + 1];
  const Point2 foot{a.x + t * (b.x - a.x), a.y + t * (b.y - a.y)};
  remaining_ = std::hypot(b.x - foot.x, b.y - foot.y);
  for (std::uint32_t s = seg_ + 1; s + 1 < n_; ++s) remaining_ += std::hypot(pts_[s + 1].x - pts_[s].x, pts_[s + 1].y - pts_[s].y);
  const Point2 goal = pts_[n_ - 1];
  const double to_goal = std::hypot(goal.x - pose.x, goal.y - pose.y);
  if (to_goal <= p_.goal_tolerance_m && seg_ + 2 >= n_) {
    state_ = FollowState::kArrived;
    return stop(dt);
  }
  const double look = std::max(p_.lookahead_min_m, std::fabs(out_.v_mps) * p_.lookahead_time_s);
  Point2 target = goal;
  double acc = std::hypot(b.x - foot.x, b.y - foot.y);
  if (acc >= look) {
    const double f = look / std::max(acc, 1e-9);
    target = Point2{foot.x + f * (b.x - foot.x), foot.y + f * (b.y - foot.y)};
  } else {
    for (std::uint32_t s = seg_ + 1; s + 1 < n_; ++s) {
      const double l = std::hypot(pts_[s + 1].x - pts_[s].x, pts_[s + 1].y - pts_[s].y);
      if (acc + l >= look) {
        const double f = (look - acc) / std::max(l, 1e-9);
        target = Point2{pts_[s].x + f * (pts_[s + 1].x - pts_[s].x), pts_[s].y + f * (pts_[s + 1].y - pts_[s].y)};
        break;
      }
      acc += l;
    }
  }
  if (steer_to != nullptr) target = *steer_to;
  const Point2 l = in_robot_frame(pose, target);
  const double lx = l.x, ly = l.y;
  const double heading_err = std::atan2(ly, lx);
  if (std::fabs(heading_err) > p_.turn_in_place_rad || (state_ == FollowState::kTurning && std::fabs(heading_err) > 0.3)) {
    state_ = FollowState::kTurning;
    return limit(0.0, std::copysign(p_.max_turn_rate_radps, heading_err) * std::min(1.0, std::fabs(heading_err)), dt);
  }
  state_ = FollowState::kFollowing;
  const double l2 = lx * lx + ly * ly;
  const double curvature = l2 > 1e-9 ? 2.0 * ly / l2 : 0.0;
  // Speed: the top speed, what the curvature allows within the turn rate, and what stops at the goal.
  double v = std::min(p_.max_speed_mps, std::max(0.0, speed_cap));
  if (std::fabs(curvature) > 1e-9) v = std::min(v, p_.max_turn_rate_radps / std::fabs(curvature));
  v = std::min(v, std::sqrt(2.0 * p_.max_decel_mps2 * std::max(0.0, remaining_ - 0.5 * p_.goal_tolerance_m)) + 0.05);
  return limit(v, v * curvature, dt);
}

}  // namespace ag::plan
