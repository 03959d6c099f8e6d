// Simulated autopilot attitude (PX4 EKF2 output as ATTITUDE over MAVLink): the quadrotor's true
// attitude in REP-103 plus, per axis, a slowly varying bias (first-order Gauss-Markov) and white noise,
// on a fixed grid at rate_hz; body rates from the truth's change between samples, plus white noise.
#pragma once

#include <cstdint>
#include <span>
#include <string_view>

#include "airground/messages/geometry.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/result.hpp"
#include "airground/platform/time.hpp"
#include "airground/platform/rng.hpp"

namespace YAML {
class Node;
}

namespace ag::sim {

// Defaults and their sources: docs/simulator.md, "Autopilot attitude".
struct AttitudeConfig {
  double rate_hz{50.0};                       // [Hz] ATTITUDE rate (what the autopilot stage asks for)
  double roll_pitch_bias_sigma_rad{0.0035};   // [rad] stationary std of the roll and pitch bias (0.2 deg)
  double roll_pitch_bias_tau_s{60.0};         // [s] its correlation time
  double yaw_bias_sigma_rad{0.026};           // [rad] stationary std of the yaw bias (1.5 deg)
  double yaw_bias_tau_s{300.0};               // [s]
  double roll_pitch_noise_rad{0.00003};       // [rad] white noise per sample
  double yaw_noise_rad{0.00003};              // [rad]
  double rate_noise_rad_s{0.005};             // [rad/s] white noise on each body rate
};

std::span<const ParamSection> attitude_config_schema() noexcept;
Result<AttitudeConfig> load_attitude_config(const YAML::Node& node, std::string_view origin);
Result<AttitudeConfig> load_attitude_config(std::string_view yaml, std::string_view origin);

struct AttitudeSample {
  TimeNs stamp{0};                                   // [ns] time of the true attitude
  double roll{0}, pitch{0}, yaw{0};                  // [rad] body FLU in ENU, with the errors
  double roll_rate{0}, pitch_rate{0}, yaw_rate{0};   // [rad/s] about the body FLU axes
};

class AttitudeSimulator {
 public:
  AttitudeSimulator() : AttitudeSimulator(AttitudeConfig{}, 0) {}
  AttitudeSimulator(const AttitudeConfig& cfg, std::uint64_t seed);
  // Call every simulation step with the true pose; true when a sample is due (the first call, then every
  // 1/rate_hz on a fixed grid).
  bool sample(TimeNs t, const Pose3& truth, AttitudeSample& out) noexcept;
  [[nodiscard]] const AttitudeConfig& config() const noexcept { return cfg_; }
  [[nodiscard]] double bias(int axis) const noexcept { return bias_[axis]; }

 private:
  AttitudeConfig cfg_;
  Rng rng_;
  TimeNs period_{0}, next_{0}, last_t_{0};
  bool started_{false}, have_last_{false};
  Pose3 last_{};
  double bias_[3]{0, 0, 0};
};

}  // namespace ag::sim
