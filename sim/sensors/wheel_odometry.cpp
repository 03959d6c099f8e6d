// Simulated ground-robot odometry: per-robot calibration errors, distance-proportional slip, yaw drift.
#include "airground/sim/wheel_odometry.hpp"

#include <cmath>

#include "airground/platform/param_binding.hpp"
#include "airground/sim/model_params.hpp"

namespace ag::sim {

namespace {

constexpr ParamField<WheelOdometryConfig> kOdoFields[] = {
    field::choice<&WheelOdometryConfig::mode>("mode", "wheels|truth_plus_noise", {OdometryMode::kWheels, OdometryMode::kTruthPlusNoise},
                                               "wheel encoders, or the paper's truth plus noise"),
    field::real("wheel_radius_m", &WheelOdometryConfig::wheel_radius_m, 0.01, 2.0, "m", "nominal wheel radius used by the odometry"),
    field::real("track_width_m", &WheelOdometryConfig::track_width_m, 0.05, 5.0, "m", "nominal track width used by the odometry"),
    field::real("wheel_radius_error", &WheelOdometryConfig::wheel_radius_error, 0.0, 0.2, "", "std of each wheel's relative radius error (drawn once)"),
    field::real("track_width_error", &WheelOdometryConfig::track_width_error, 0.0, 0.5, "", "std of the relative track-width error (drawn once)"),
    field::real("slip_sigma_per_sqrt_m", &WheelOdometryConfig::slip_sigma_per_sqrt_m, 0.0, 1.0, "m/sqrt(m)", "white distance error per wheel"),
    field::real("yaw_drift_rad_per_s", &WheelOdometryConfig::yaw_drift_rad_per_s, -1.0, 1.0, "rad/s", "yaw-rate bias while moving"),
    field::real("yaw_drift_at_rest_rad_per_s", &WheelOdometryConfig::yaw_drift_at_rest_rad_per_s, -1.0, 1.0, "rad/s", "yaw-rate bias while standing still"),
    field::real("sigma_xy_m", &WheelOdometryConfig::sigma_xy_m, 0.0, 10.0, "m", "truth_plus_noise: std of dx, dy per step while moving"),
    field::real("sigma_yaw_rad", &WheelOdometryConfig::sigma_yaw_rad, 0.0, 1.0, "rad", "truth_plus_noise: std of dyaw per step while moving"),
};
constexpr auto kOdoParams = param_specs(kOdoFields);
constexpr ParamSection kOdoSchema[] = {{"wheel_odometry", kOdoParams, "simulated ground-robot odometry"}};

Result<WheelOdometryConfig> odo_from(const Result<Config>& c) {
  if (!c) return c.error();
  const SectionView v(c.value(), "wheel_odometry");
  return load_params(v, kOdoFields);
}

constexpr double kStill = 1e-9;  // [m], [rad]: below this a step is standing still

}  // namespace

std::span<const ParamSection> wheel_odometry_config_schema() noexcept { return kOdoSchema; }

Result<WheelOdometryConfig> load_wheel_odometry_config(const YAML::Node& node, std::string_view origin) {
  return odo_from(load_model_params(kOdoSchema, node, origin));
}
Result<WheelOdometryConfig> load_wheel_odometry_config(std::string_view yaml, std::string_view origin) {
  return odo_from(load_model_params(kOdoSchema, yaml, origin));
}

WheelOdometrySimulator::WheelOdometrySimulator(const WheelOdometryConfig& cfg, std::uint64_t seed)
    : cfg_(cfg), rng_(seed) {
  err_left_ = rng_.gaussian(0.0, cfg_.wheel_radius_error);
  err_right_ = rng_.gaussian(0.0, cfg_.wheel_radius_error);
  err_width_ = rng_.gaussian(0.0, cfg_.track_width_error);
}

OdometrySample WheelOdometrySimulator::step(TimeNs t, const Pose2& truth, double wheel_left_rad_s,
                                            double wheel_right_rad_s) {
  OdometrySample out;
  out.stamp = t;
  if (!started_) {
    started_ = true;
    last_t_ = t;
    last_truth_ = truth;
    out.pose = pose_;
    return out;
  }
  const double dt = to_seconds(t - last_t_);
  double dx = 0, dy = 0, dyaw = 0;
  const double r = cfg_.wheel_radius_m, w = cfg_.track_width_m;

  if (cfg_.mode == OdometryMode::kWheels) {
    const double rot_l = wheel_left_rad_s * dt, rot_r = wheel_right_rad_s * dt;  // [rad] encoder angle
    out.moving = std::abs(rot_l) * r > kStill || std::abs(rot_r) * r > kStill;
    // Distance each wheel is believed to have rolled: the wrong radius, plus slip that grows with sqrt(distance).
    double dl = rot_l * r * (1.0 + err_left_);
    double dr = rot_r * r * (1.0 + err_right_);
    if (out.moving) {
      dl += rng_.gaussian(0.0, cfg_.slip_sigma_per_sqrt_m * std::sqrt(std::abs(rot_l) * r));
      dr += rng_.gaussian(0.0, cfg_.slip_sigma_per_sqrt_m * std::sqrt(std::abs(rot_r) * r));
    }
    const double d = 0.5 * (dl + dr);
    out.distance = d;
    dyaw = (dr - dl) / (w * (1.0 + err_width_));
    dyaw += (out.moving ? cfg_.yaw_drift_rad_per_s : cfg_.yaw_drift_at_rest_rad_per_s) * dt;
    // Exact arc over the step.
    if (std::abs(dyaw) < 1e-12) {
      dx = d;
    } else {
      dx = d * std::sin(dyaw) / dyaw;
      dy = d * (1.0 - std::cos(dyaw)) / dyaw;
    }
    out.wheel_left_rad_s = dt > 0 ? dl / (r * dt) : 0.0;
    out.wheel_right_rad_s = dt > 0 ? dr / (r * dt) : 0.0;
  } else {
    const double gx = truth.x - last_truth_.x, gy = truth.y - last_truth_.y;
    const double c = std::cos(last_truth_.yaw), s = std::sin(last_truth_.yaw);
    dx = c * gx + s * gy;
    dy = -s * gx + c * gy;
    dyaw = wrap_angle(truth.yaw - last_truth_.yaw);
    out.moving = std::hypot(dx, dy) > kStill || std::abs(dyaw) > kStill;
    if (out.moving) {
      dx += rng_.gaussian(0.0, cfg_.sigma_xy_m);
      dy += rng_.gaussian(0.0, cfg_.sigma_xy_m);
      dyaw += rng_.gaussian(0.0, cfg_.sigma_yaw_rad);
    }
    out.distance = std::copysign(std::hypot(dx, dy), dx);
    dyaw += (out.moving ? cfg_.yaw_drift_rad_per_s : cfg_.yaw_drift_at_rest_rad_per_s) * dt;
    if (dt > 0) {  // the wheel speeds that would produce this increment
      const double v = dx / dt, om = dyaw / dt;
      out.wheel_left_rad_s = (v - 0.5 * w * om) / r;
      out.wheel_right_rad_s = (v + 0.5 * w * om) / r;
    }
  }

  const double c = std::cos(pose_.yaw), s = std::sin(pose_.yaw);
  pose_.x += c * dx - s * dy;
  pose_.y += s * dx + c * dy;
  pose_.yaw = wrap_angle(pose_.yaw + dyaw);
  out.dx = dx;
  out.dy = dy;
  out.dyaw = dyaw;
  out.pose = pose_;
  last_t_ = t;
  last_truth_ = truth;
  return out;
}

}  // namespace ag::sim
