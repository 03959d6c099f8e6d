// Simulated survey quadrotor: follows 3D waypoints with speed, acceleration and yaw-rate limits.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>
#include <vector>

#include "airground/messages/geometry.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/result.hpp"

namespace YAML {
class Node;
}

namespace ag::sim {

// A point to fly to in the map frame; z is height above the datum [m].
struct Waypoint {
  double x{0}, y{0}, z{0};  // [m]
  double speed_mps{0};      // [m/s] cruise speed toward this waypoint, 0 = the configured cruise speed
};

enum class YawMode : std::uint8_t {
  kMotion,  // nose along the horizontal velocity (held while hovering)
  kFixed,   // constant yaw (fixed_yaw_rad)
};

struct QuadrotorConfig {
  double cruise_speed_mps{5.0};       // [m/s] default speed toward a waypoint (and the limit of any speed)
  double max_speed_mps{15.0};         // [m/s] no waypoint speed may exceed this
  double max_accel_mps2{2.0};         // [m/s^2] limit on the change of the velocity vector
  double max_vertical_speed_mps{3.0}; // [m/s]
  double max_yaw_rate_rad_s{1.0};     // [rad/s]
  double waypoint_tolerance_m{1.0};   // [m] a waypoint is reached within this 3D distance
  YawMode yaw_mode{YawMode::kMotion};
  double fixed_yaw_rad{0.0};          // [rad] yaw for kFixed
  bool tilt_from_acceleration{true};  // roll and pitch follow the horizontal acceleration (a multirotor leans)
};

std::span<const ParamSection> quadrotor_config_schema() noexcept;  // one section, "quadrotor"
// yaw_mode is "motion" or "fixed"; every key is checked, and cruise_speed_mps <= max_speed_mps.
Result<QuadrotorConfig> load_quadrotor_config(const YAML::Node& node, std::string_view origin);
Result<QuadrotorConfig> load_quadrotor_config(std::string_view yaml, std::string_view origin);

// How long flying route from start takes [s]: per leg, its length at the leg's speed (limited by the
// vertical speed on climbs) plus the time lost accelerating from and braking to a stop (stop-and-turn
// corners, as Quadrotor::step flies them). Within a few percent of the simulated flight; the ground robots
// are told it so they wait for the survey's regions (mission.survey_end_s).
[[nodiscard]] double estimate_route_time_s(const QuadrotorConfig& cfg, const Pose3& start, std::span<const Waypoint> route) noexcept;

class Quadrotor {
 public:
  explicit Quadrotor(const QuadrotorConfig& cfg, const Pose3& start = {});

  // Replaces the route; the first waypoint becomes the target.
  void set_waypoints(std::vector<Waypoint> route);
  // Advances dt seconds. It follows the straight line from the last waypoint to the current one at the
  // waypoint's speed, braking so that it would stop on it (corners are flown stop-and-turn, as survey
  // cameras want), and takes the next one within waypoint_tolerance_m. After the last one it hovers.
  void step(double dt);

  [[nodiscard]] const Pose3& pose() const noexcept { return pose_; }
  [[nodiscard]] double vx() const noexcept { return vel_[0]; }  // [m/s] map frame
  [[nodiscard]] double vy() const noexcept { return vel_[1]; }
  [[nodiscard]] double vz() const noexcept { return vel_[2]; }
  [[nodiscard]] double speed() const noexcept;              // [m/s] norm of the velocity
  [[nodiscard]] std::size_t current_waypoint() const noexcept { return index_; }
  [[nodiscard]] std::size_t waypoints_reached() const noexcept { return index_; }
  [[nodiscard]] bool finished() const noexcept { return index_ >= route_.size(); }
  [[nodiscard]] double distance_flown() const noexcept { return distance_; }  // [m]
  [[nodiscard]] const QuadrotorConfig& config() const noexcept { return cfg_; }

 private:
  QuadrotorConfig cfg_;
  Pose3 pose_;
  double vel_[3]{0, 0, 0};
  std::vector<Waypoint> route_;
  std::size_t index_{0};
  double leg_start_[3]{0, 0, 0};  // where the current leg's line begins (the last waypoint reached)
  double distance_{0};
};

}  // namespace ag::sim
