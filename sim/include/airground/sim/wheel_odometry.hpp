// Simulated ground-robot odometry: wheel encoders with calibration error and slip, or truth plus noise.
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

enum class OdometryMode : std::uint8_t {
  kWheels,          // integrate the true wheel speeds with a mis-calibrated model and slip
  kTruthPlusNoise,  // the paper's simulation: the true increment plus Gaussian noise on each step
};

// Noise that grows with distance is given per square root of metres so that it does not depend on the
// step rate; the truth_plus_noise sigmas are per call of step(), as in the paper.
//
// Yaw drift at rest defaults to 0: the ground robots' odometry is wheel encoders over CAN, and encoders do
// not tick while the robot stands, so any drift at rest would be invented. The paper's failure (yaw drift
// while standing, from their LiDAR/IMU odometry) is reproduced by setting yaw_drift_at_rest_rad_per_s
// (~0.001 rad/s is a poorly calibrated MEMS gyro), which a localizer must then survive.
struct WheelOdometryConfig {
  OdometryMode mode{OdometryMode::kWheels};
  double wheel_radius_m{0.098};          // [m] nominal radius the odometry integrates with
  double track_width_m{0.37};            // [m] nominal track width the odometry integrates with
  double wheel_radius_error{0.0005};     // [-] std of each wheel's relative radius error, drawn once (a calibrated robot)
  double track_width_error{0.01};        // [-] std of the relative track-width error, drawn once
  double slip_sigma_per_sqrt_m{0.005};   // [m/sqrt(m)] white distance error of each wheel, per sqrt(m) rolled
  double yaw_drift_rad_per_s{0.0};       // [rad/s] constant yaw-rate bias while moving
  double yaw_drift_at_rest_rad_per_s{0.0};  // [rad/s] constant yaw-rate bias while standing still
  double sigma_xy_m{0.01};               // [m] truth_plus_noise: std on dx and dy per step while moving
  double sigma_yaw_rad{0.002};           // [rad] truth_plus_noise: std on dyaw per step while moving
};

std::span<const ParamSection> wheel_odometry_config_schema() noexcept;  // one section, "wheel_odometry"
// mode is "wheels" or "truth_plus_noise"; every key is checked.
Result<WheelOdometryConfig> load_wheel_odometry_config(const YAML::Node& node, std::string_view origin);
Result<WheelOdometryConfig> load_wheel_odometry_config(std::string_view yaml, std::string_view origin);

struct OdometrySample {
  TimeNs stamp{0};
  Pose2 pose;                 // integrated pose in the odometry frame (the robot's pose at the first step)
  double dx{0}, dy{0};        // [m] increment since the previous step, in the robot frame at that step
  double dyaw{0};             // [rad]
  double distance{0};         // [m] the wheels' mean distance over the step (signed): the arc dx, dy, dyaw lie on
  double wheel_left_rad_s{0}, wheel_right_rad_s{0};  // [rad/s] measured wheel speeds (what CAN reports)
  bool moving{false};         // the wheels turned (wheels mode) or the truth moved (truth_plus_noise)
};

class WheelOdometrySimulator {
 public:
  WheelOdometrySimulator(const WheelOdometryConfig& cfg, std::uint64_t seed);

  // Call at every step with the true planar pose and the true wheel speeds over the step that ends at t
  // (the wheels mode uses the speeds, truth_plus_noise the poses). The first call only initialises.
  OdometrySample step(TimeNs t, const Pose2& truth, double wheel_left_rad_s, double wheel_right_rad_s);

  [[nodiscard]] const Pose2& pose() const noexcept { return pose_; }
  [[nodiscard]] const WheelOdometryConfig& config() const noexcept { return cfg_; }
  // The calibration errors drawn for this robot: odometry radius / true radius - 1, and the same for width.
  [[nodiscard]] double left_radius_error() const noexcept { return err_left_; }
  [[nodiscard]] double right_radius_error() const noexcept { return err_right_; }
  [[nodiscard]] double track_width_error() const noexcept { return err_width_; }

 private:
  WheelOdometryConfig cfg_;
  Rng rng_;
  double err_left_{0}, err_right_{0}, err_width_{0};
  bool started_{false};
  TimeNs last_t_{0};
  Pose2 last_truth_{};
  Pose2 pose_{};
};

}  // namespace ag::sim
