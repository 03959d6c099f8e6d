// Simulated differential-drive ground robot (Clearpath Jackal class): wheel commands in, exact arcs, collisions.
#pragma once

#include <cstdint>
#include <span>
#include <string_view>

#include "airground/messages/geometry.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/result.hpp"
#include "airground/sim/world.hpp"

namespace YAML {
class Node;
}

namespace ag::sim {

struct DiffDriveConfig {
  double track_width_m{0.37};             // [m] distance between the left and right wheels
  double wheel_radius_m{0.098};           // [m]
  double max_wheel_speed_rad_s{2.0 / 0.098};  // [rad/s] 2.0 m/s at the rim
  double max_linear_accel_mps2{2.0};      // [m/s^2]
  double max_angular_accel_radps2{8.0};   // [rad/s^2]
  double footprint_radius_m{0.3};         // [m] collision disc (Jackal: 0.508 x 0.430 m)
  double max_step_height_m{0.25};         // [m] a higher rise of the surface under the footprint blocks (curbs of 0.15 m pass)
  double command_timeout_s{0.5};          // [s] without a new command the wheels are commanded to 0; 0 = never
  bool block_building{true};              // classes whose cells the footprint may not enter
  bool block_tree{true};
  bool block_vehicle{true};
  bool block_water{true};
};

std::span<const ParamSection> diff_drive_config_schema() noexcept;  // one section, "diff_drive"
// The model with a robot's own wheels (its base configuration's radius and track), at the same rim speed.
[[nodiscard]] DiffDriveConfig with_wheels(DiffDriveConfig c, double wheel_radius_m, double track_width_m) noexcept;
Result<DiffDriveConfig> load_diff_drive_config(const YAML::Node& node, std::string_view origin);
Result<DiffDriveConfig> load_diff_drive_config(std::string_view yaml, std::string_view origin);

class DiffDriveRobot {
 public:
  explicit DiffDriveRobot(const DiffDriveConfig& cfg, const Pose2& start = {});

  // Wheel angular velocity commands [rad/s] (positive = forward); clamped to the wheel speed limit.
  void command_wheels(double left_rad_s, double right_rad_s) noexcept;
  // Convenience for tests and scripted drivers: body speed [m/s] and yaw rate [rad/s] as wheel commands.
  void command_twist(double v_mps, double omega_rad_s) noexcept;

  // Advances dt seconds: accelerates toward the command within the limits, then moves along the exact
  // arc of the new speeds. If the footprint would enter a new cell that blocks (a blocking class, outside
  // the world, or a surface more than max_step_height_m above the cell under the centre), the robot stays
  // at its pre-step pose with zero speed and the step returns true (a collision). Cells it already
  // covers never block, so it can always back away; going down a drop is not checked.
  bool step(double dt, const World& world);

  void reset(const Pose2& pose) noexcept;

  [[nodiscard]] const Pose2& pose() const noexcept { return pose_; }
  // The body pose in 3D: z on the surface under the centre, roll and pitch from the surface at the
  // footprint's edge (bilinear between cell centres; as of the last step).
  [[nodiscard]] Pose3 pose3() const noexcept { return Pose3{pose_.x, pose_.y, z_, roll_, pitch_, pose_.yaw}; }
  [[nodiscard]] double linear_speed() const noexcept { return v_; }   // [m/s]
  [[nodiscard]] double yaw_rate() const noexcept { return omega_; }   // [rad/s]
  // The wheel speeds the robot actually turned with in the last step [rad/s] (0 after a collision):
  // what the encoders saw, the input of the odometry model.
  [[nodiscard]] double wheel_left_rad_s() const noexcept { return wheel_left_; }
  [[nodiscard]] double wheel_right_rad_s() const noexcept { return wheel_right_; }
  // Collision events (colliding steps less than 1 s apart count once) and colliding steps.
  [[nodiscard]] std::uint64_t collisions() const noexcept { return collisions_; }
  [[nodiscard]] std::uint64_t collision_steps() const noexcept { return collision_steps_; }
  [[nodiscard]] bool in_collision() const noexcept { return in_collision_; }
  [[nodiscard]] double distance_travelled() const noexcept { return distance_; }  // [m]
  [[nodiscard]] const DiffDriveConfig& config() const noexcept { return cfg_; }

  // True if the footprint at (x, y) is free, given the surface height the robot stands on.
  [[nodiscard]] bool footprint_free(const World& world, double x, double y, double ground_z) const noexcept;

 private:
  [[nodiscard]] bool blocks(ClassId c) const noexcept;
  // True if the footprint at (x, y) covers an obstacle cell, ignoring the cells the footprint at
  // `from` already covers (none if null).
  [[nodiscard]] bool enters_obstacle(const World& world, double x, double y, double ground_z,
                                     const Pose2* from) const noexcept;
  void update_attitude(const World& world) noexcept;

  DiffDriveConfig cfg_;
  Pose2 pose_;
  double z_{0}, roll_{0}, pitch_{0};
  double ground_z_{0};  // surface of the cell under the centre: the reference for climbable steps
  bool have_z_{false};
  double cmd_left_{0}, cmd_right_{0};
  double since_command_{0};
  double v_{0}, omega_{0};
  double wheel_left_{0}, wheel_right_{0};
  std::uint64_t collisions_{0}, collision_steps_{0};
  bool in_collision_{false};
  double sim_time_{0}, last_collision_time_{0};  // [s] summed step lengths
  double distance_{0};
};

}  // namespace ag::sim
