// Survey quadrotor: line-following guidance with a braking profile, acceleration-limited velocity, lean.
#include "airground/sim/quadrotor.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

#include "airground/platform/param_binding.hpp"
#include "airground/sim/model_params.hpp"

namespace ag::sim {

namespace {

constexpr ParamField<QuadrotorConfig> kQuadFields[] = {
    field::real("cruise_speed_mps", &QuadrotorConfig::cruise_speed_mps, 0.1, 30.0, "m/s", "default speed toward a waypoint"),
    field::real("max_speed_mps", &QuadrotorConfig::max_speed_mps, 0.1, 30.0, "m/s", "limit of any waypoint speed"),
    field::real("max_accel_mps2", &QuadrotorConfig::max_accel_mps2, 0.1, 20.0, "m/s^2", "limit on the change of velocity"),
    field::real("max_vertical_speed_mps", &QuadrotorConfig::max_vertical_speed_mps, 0.1, 20.0, "m/s", "climb and descent limit"),
    field::real("max_yaw_rate_rad_s", &QuadrotorConfig::max_yaw_rate_rad_s, 0.01, 10.0, "rad/s", "yaw rate limit"),
    field::real("waypoint_tolerance_m", &QuadrotorConfig::waypoint_tolerance_m, 0.01, 100.0, "m", "a waypoint is reached within this distance"),
    field::choice<&QuadrotorConfig::yaw_mode>("yaw_mode", "motion|fixed", {YawMode::kMotion, YawMode::kFixed}, "nose along the motion, or a fixed yaw"),
    field::real("fixed_yaw_rad", &QuadrotorConfig::fixed_yaw_rad, -kPi, kPi, "rad", "yaw in fixed mode"),
    field::boolean("tilt_from_acceleration", &QuadrotorConfig::tilt_from_acceleration, "roll and pitch follow the horizontal acceleration"),
};
constexpr auto kQuadParams = param_specs(kQuadFields);
constexpr ParamSection kQuadSchema[] = {{"quadrotor", kQuadParams, "survey quadrotor"}};

Result<QuadrotorConfig> quad_from(const Result<Config>& c, std::string_view origin) {
  if (!c) return c.error();
  const SectionView v(c.value(), "quadrotor");
  const QuadrotorConfig q = load_params(v, kQuadFields);
  if (q.cruise_speed_mps > q.max_speed_mps)
    return model_config_error(origin, "key 'quadrotor.cruise_speed_mps' must not exceed 'quadrotor.max_speed_mps'");
  return q;
}

constexpr double kGravity = 9.80665;  // [m/s^2]
constexpr double kBrakeShare = 0.8;    // share of the acceleration limit planned for braking (the rest steers)
constexpr double kMinYawSpeed = 0.5;   // [m/s] below this the heading of the motion is not followed
constexpr double kCrossTrackGain = 0.5; // [1/s] desired speed back toward the leg's line per metre off it

}  // namespace

std::span<const ParamSection> quadrotor_config_schema() noexcept { return kQuadSchema; }

Result<QuadrotorConfig> load_quadrotor_config(const YAML::Node& node, std::string_view origin) {
  return quad_from(load_model_params(kQuadSchema, node, origin), origin);
}
Result<QuadrotorConfig> load_quadrotor_config(std::string_view yaml, std::string_view origin) {
  return quad_from(load_model_params(kQuadSchema, yaml, origin), origin);
}

double estimate_route_time_s(const QuadrotorConfig& cfg, const Pose3& start, std::span<const Waypoint> route) noexcept {
  double t = 0, x = start.x, y = start.y, z = start.z;
  const double accel = cfg.max_accel_mps2, brake = kBrakeShare * cfg.max_accel_mps2;
  for (const Waypoint& wp : route) {
    const double h = std::hypot(wp.x - x, wp.y - y), v = std::abs(wp.z - z), len = std::hypot(h, v);
    double s = std::min(wp.speed_mps > 0 ? wp.speed_mps : cfg.cruise_speed_mps, cfg.max_speed_mps);
    if (len > 1e-9 && s * v / len > cfg.max_vertical_speed_mps) s = cfg.max_vertical_speed_mps * len / v;
    // Trapezoid from rest to rest (a triangle on short legs), the tolerance sphere cut off the end.
    const double d = std::max(0.0, len - cfg.waypoint_tolerance_m);
    const double ramp = s * s / (2 * accel) + s * s / (2 * brake);
    if (d >= ramp) {
      t += d / s + s / (2 * accel) + s / (2 * brake);
    } else {
      const double peak = std::sqrt(d / (1 / (2 * accel) + 1 / (2 * brake)));
      t += peak / accel + peak / brake;
    }
    x = wp.x, y = wp.y, z = wp.z;
  }
  return t;
}

Quadrotor::Quadrotor(const QuadrotorConfig& cfg, const Pose3& start) : cfg_(cfg), pose_(start) {}

void Quadrotor::set_waypoints(std::vector<Waypoint> route) {
  route_ = std::move(route);
  index_ = 0;
  leg_start_[0] = pose_.x;
  leg_start_[1] = pose_.y;
  leg_start_[2] = pose_.z;
}

double Quadrotor::speed() const noexcept { return std::sqrt(vel_[0] * vel_[0] + vel_[1] * vel_[1] + vel_[2] * vel_[2]); }

void Quadrotor::step(double dt) {
  if (!(dt > 0)) return;
  // Take the next waypoint once within tolerance; the next leg starts from the ideal point just reached.
  while (index_ < route_.size()) {
    const Waypoint& wp = route_[index_];
    if (std::hypot(wp.x - pose_.x, wp.y - pose_.y, wp.z - pose_.z) > cfg_.waypoint_tolerance_m) break;
    leg_start_[0] = wp.x;
    leg_start_[1] = wp.y;
    leg_start_[2] = wp.z;
    ++index_;
  }

  double want[3] = {0, 0, 0};  // desired velocity; hover after the last waypoint
  double axis[3] = {0, 0, 0};  // direction of the leg
  if (index_ < route_.size()) {
    const Waypoint& wp = route_[index_];
    const double s = std::min(wp.speed_mps > 0 ? wp.speed_mps : cfg_.cruise_speed_mps, cfg_.max_speed_mps);
    const double brake = kBrakeShare * cfg_.max_accel_mps2;
    const double b[3] = {wp.x, wp.y, wp.z}, p[3] = {pose_.x, pose_.y, pose_.z};
    double u[3], rel[3];
    double len = 0;
    for (int i = 0; i < 3; ++i) {
      u[i] = b[i] - leg_start_[i];
      rel[i] = p[i] - leg_start_[i];
      len += u[i] * u[i];
    }
    len = std::sqrt(len);
    if (len < 1e-6) {  // a leg of no length: fly straight at the point
      len = 0;
      for (int i = 0; i < 3; ++i) {
        u[i] = b[i] - p[i];
        rel[i] = 0;
        len += u[i] * u[i];
      }
      len = std::sqrt(len);
    }
    for (int i = 0; i < 3; ++i) axis[i] = u[i] /= len;
    // Follow the line of the leg (as autopilots do between mission items): along it with a braking profile
    // that stops on the waypoint, across it back toward the line.
    const double along = rel[0] * u[0] + rel[1] * u[1] + rel[2] * u[2];
    const double remaining = len - along;
    const double s_along = std::copysign(std::min(s, std::sqrt(2.0 * brake * std::abs(remaining))), remaining);
    double wn = 0;
    for (int i = 0; i < 3; ++i) {
      const double cross = rel[i] - along * u[i];
      want[i] = u[i] * s_along - kCrossTrackGain * cross;
      wn += want[i] * want[i];
    }
    wn = std::sqrt(wn);
    if (wn > s) {
      for (double& w : want) w *= s / wn;
    }
    if (std::abs(want[2]) > cfg_.max_vertical_speed_mps) {
      const double k = cfg_.max_vertical_speed_mps / std::abs(want[2]);
      for (double& w : want) w *= k;
    }
  }
  // The acceleration budget goes first across the leg (back onto the line), what is left along it.
  double dv[3] = {want[0] - vel_[0], want[1] - vel_[1], want[2] - vel_[2]};
  const double dv_max = cfg_.max_accel_mps2 * dt;
  const double dv_along = dv[0] * axis[0] + dv[1] * axis[1] + dv[2] * axis[2];
  double cross[3], cn = 0;
  for (int i = 0; i < 3; ++i) {
    cross[i] = dv[i] - dv_along * axis[i];
    cn += cross[i] * cross[i];
  }
  cn = std::sqrt(cn);
  double along = 0;
  if (cn > dv_max) {
    for (double& x : cross) x *= dv_max / cn;
  } else {
    const double room = std::sqrt(dv_max * dv_max - cn * cn);
    along = std::clamp(dv_along, -room, room);
  }
  for (int i = 0; i < 3; ++i) dv[i] = cross[i] + along * axis[i];
  const double step_x = (vel_[0] + 0.5 * dv[0]) * dt, step_y = (vel_[1] + 0.5 * dv[1]) * dt,
               step_z = (vel_[2] + 0.5 * dv[2]) * dt;
  pose_.x += step_x;
  pose_.y += step_y;
  pose_.z += step_z;
  distance_ += std::sqrt(step_x * step_x + step_y * step_y + step_z * step_z);
  for (int i = 0; i < 3; ++i) vel_[i] += dv[i];

  double yaw_goal = pose_.yaw;
  if (cfg_.yaw_mode == YawMode::kFixed) {
    yaw_goal = cfg_.fixed_yaw_rad;
  } else if (std::hypot(vel_[0], vel_[1]) > kMinYawSpeed) {
    yaw_goal = std::atan2(vel_[1], vel_[0]);
  }
  const double max_turn = cfg_.max_yaw_rate_rad_s * dt;
  pose_.yaw = wrap_angle(pose_.yaw + std::clamp(wrap_angle(yaw_goal - pose_.yaw), -max_turn, max_turn));

  if (cfg_.tilt_from_acceleration) {
    // The thrust leans into the horizontal acceleration: forward -> nose down (+pitch), left -> -roll.
    const double ax = dv[0] / dt, ay = dv[1] / dt, c = std::cos(pose_.yaw), s = std::sin(pose_.yaw);
    pose_.pitch = std::atan((c * ax + s * ay) / kGravity);
    pose_.roll = -std::atan((-s * ax + c * ay) / kGravity);
  } else {
    pose_.roll = pose_.pitch = 0.0;
  }
}

}  // namespace ag::sim
