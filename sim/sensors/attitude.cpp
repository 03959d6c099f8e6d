// Simulated autopilot attitude: Gauss-Markov bias plus white noise per axis, rates from the truth.
#include "airground/sim/attitude.hpp"

#include <algorithm>
#include <cmath>

#include "airground/platform/param_binding.hpp"
#include "airground/sim/model_params.hpp"

namespace ag::sim {

namespace {
constexpr ParamField<AttitudeConfig> kAttitudeFields[] = {
    field::real("rate_hz", &AttitudeConfig::rate_hz, 1.0, 400.0, "Hz", "ATTITUDE rate"),
    field::real("roll_pitch_bias_sigma_rad", &AttitudeConfig::roll_pitch_bias_sigma_rad, 0.0, 0.5, "rad", "stationary std of the roll and pitch bias"),
    field::real("roll_pitch_bias_tau_s", &AttitudeConfig::roll_pitch_bias_tau_s, 0.1, 1e6, "s", "correlation time of the roll and pitch bias"),
    field::real("yaw_bias_sigma_rad", &AttitudeConfig::yaw_bias_sigma_rad, 0.0, 1.0, "rad", "stationary std of the yaw bias"),
    field::real("yaw_bias_tau_s", &AttitudeConfig::yaw_bias_tau_s, 0.1, 1e6, "s", "correlation time of the yaw bias"),
    field::real("roll_pitch_noise_rad", &AttitudeConfig::roll_pitch_noise_rad, 0.0, 0.5, "rad", "white noise on roll and pitch per sample"),
    field::real("yaw_noise_rad", &AttitudeConfig::yaw_noise_rad, 0.0, 0.5, "rad", "white noise on yaw per sample"),
    field::real("rate_noise_rad_s", &AttitudeConfig::rate_noise_rad_s, 0.0, 1.0, "rad/s", "white noise on each body rate"),
};
constexpr auto kAttitudeParams = param_specs(kAttitudeFields);
constexpr ParamSection kAttitudeSchema[] = {{"attitude", kAttitudeParams, "simulated autopilot attitude (PX4 EKF2 over MAVLink)"}};

Result<AttitudeConfig> attitude_from(const Result<Config>& c) {
  if (!c) return c.error();
  const SectionView v(c.value(), "attitude");
  return load_params(v, kAttitudeFields);
}
}  // namespace

std::span<const ParamSection> attitude_config_schema() noexcept { return kAttitudeSchema; }
Result<AttitudeConfig> load_attitude_config(const YAML::Node& node, std::string_view origin) {
  return attitude_from(load_model_params(kAttitudeSchema, node, origin));
}
Result<AttitudeConfig> load_attitude_config(std::string_view yaml, std::string_view origin) {
  return attitude_from(load_model_params(kAttitudeSchema, yaml, origin));
}

AttitudeSimulator::AttitudeSimulator(const AttitudeConfig& cfg, std::uint64_t seed)
    : cfg_(cfg), rng_(derive_seed(seed, 0)), period_(period_from_hz(cfg.rate_hz > 0 ? cfg.rate_hz : 50.0)) {
  // The bias starts from its stationary distribution: the first sample is as wrong as any other.
  bias_[0] = rng_.gaussian(0.0, cfg_.roll_pitch_bias_sigma_rad);
  bias_[1] = rng_.gaussian(0.0, cfg_.roll_pitch_bias_sigma_rad);
  bias_[2] = rng_.gaussian(0.0, cfg_.yaw_bias_sigma_rad);
}

bool AttitudeSimulator::sample(TimeNs t, const Pose3& truth, AttitudeSample& out) noexcept {
  if (!started_) {
    started_ = true;
    next_ = t;
  }
  if (t < next_) return false;
  next_ += period_ * ((t - next_) / period_ + 1);
  out = AttitudeSample{};
  out.stamp = t;
  const double dt = to_seconds(t - last_t_);
  if (have_last_ && dt > 0) {
    const double taus[3] = {cfg_.roll_pitch_bias_tau_s, cfg_.roll_pitch_bias_tau_s, cfg_.yaw_bias_tau_s};
    const double sigmas[3] = {cfg_.roll_pitch_bias_sigma_rad, cfg_.roll_pitch_bias_sigma_rad, cfg_.yaw_bias_sigma_rad};
    for (int k = 0; k < 3; ++k) {
      const double a = std::exp(-dt / taus[k]);
      bias_[k] = a * bias_[k] + std::sqrt(std::max(0.0, 1.0 - a * a)) * rng_.gaussian(0.0, sigmas[k]);
    }
    // ZYX Euler rates to body rates (FLU): p = dphi - sin(theta) dpsi, q = cos(phi) dtheta + sin(phi) cos(theta) dpsi,
    // r = -sin(phi) dtheta + cos(phi) cos(theta) dpsi.
    const double dphi = wrap_angle(truth.roll - last_.roll) / dt, dth = wrap_angle(truth.pitch - last_.pitch) / dt,
                 dpsi = wrap_angle(truth.yaw - last_.yaw) / dt;
    const double sp = std::sin(truth.roll), cp = std::cos(truth.roll), st = std::sin(truth.pitch), ct = std::cos(truth.pitch);
    out.roll_rate = dphi - st * dpsi;
    out.pitch_rate = cp * dth + sp * ct * dpsi;
    out.yaw_rate = -sp * dth + cp * ct * dpsi;
  }
  // Noise draws in a fixed order per sample, so a run is repeatable for a given seed.
  out.roll = truth.roll + bias_[0] + rng_.gaussian(0.0, cfg_.roll_pitch_noise_rad);
  out.pitch = truth.pitch + bias_[1] + rng_.gaussian(0.0, cfg_.roll_pitch_noise_rad);
  out.yaw = wrap_angle(truth.yaw + bias_[2] + rng_.gaussian(0.0, cfg_.yaw_noise_rad));
  out.roll_rate += rng_.gaussian(0.0, cfg_.rate_noise_rad_s);
  out.pitch_rate += rng_.gaussian(0.0, cfg_.rate_noise_rad_s);
  out.yaw_rate += rng_.gaussian(0.0, cfg_.rate_noise_rad_s);
  last_ = truth;
  last_t_ = t;
  have_last_ = true;
  return true;
}

}  // namespace ag::sim
