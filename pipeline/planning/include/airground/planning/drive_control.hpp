// Drive control: a path follower (pure pursuit with a speed-dependent look-ahead, turning on the spot
// when the path is behind, slowing down to stop at the goal) producing linear and angular velocity
// under acceleration limits, and the differential-drive conversion to left/right wheel speeds.
#pragma once

#include <array>
#include <cstdint>

#include "airground/messages/geometry.hpp"
#include "airground/planning/roadmap.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/param_binding.hpp"

namespace ag::plan {

struct DriveParams {
  double max_speed_mps{1.2};
  double max_accel_mps2{0.8};       // [m/s^2] speeding up
  double max_decel_mps2{1.5};       // [m/s^2] slowing down
  double max_turn_rate_radps{1.2};
  double max_turn_accel_radps2{3.0};
  double lookahead_min_m{1.0};
  double lookahead_time_s{1.2};     // look-ahead = max(min, speed x this)
  double turn_in_place_rad{1.0};    // heading error beyond which the robot turns on the spot
  double goal_tolerance_m{0.25};
  double track_m{0.55};             // [m] wheel separation (the base's)
  double max_wheel_speed_mps{1.6};  // both wheels scaled down together beyond this (curvature kept)
};

inline constexpr ParamField<DriveParams> kDriveFields[] = {
    field::real("max_speed_mps", &DriveParams::max_speed_mps, 0.05, 5.0, "m/s", "top speed along the path"),
    field::real("max_accel_mps2", &DriveParams::max_accel_mps2, 0.05, 5.0, "m/s^2", "linear acceleration limit"),
    field::real("max_decel_mps2", &DriveParams::max_decel_mps2, 0.05, 10.0, "m/s^2", "linear deceleration limit (also for stopping at the goal)"),
    field::real("max_turn_rate_radps", &DriveParams::max_turn_rate_radps, 0.05, 6.0, "rad/s", "angular velocity limit"),
    field::real("max_turn_accel_radps2", &DriveParams::max_turn_accel_radps2, 0.1, 30.0, "rad/s^2", "angular acceleration limit"),
    field::real("lookahead_min_m", &DriveParams::lookahead_min_m, 0.1, 10.0, "m", "shortest pure-pursuit look-ahead"),
    field::real("lookahead_time_s", &DriveParams::lookahead_time_s, 0.0, 10.0, "s", "look-ahead grows with speed x this"),
    field::real("turn_in_place_rad", &DriveParams::turn_in_place_rad, 0.1, 3.2, "rad", "heading error beyond which the robot turns on the spot"),
    field::real("goal_tolerance_m", &DriveParams::goal_tolerance_m, 0.05, 5.0, "m", "the goal is reached within this (nav2's xy_goal_tolerance default)"),
    field::real("track_m", &DriveParams::track_m, 0.05, 5.0, "m", "wheel separation of the base"),
    field::real("max_wheel_speed_mps", &DriveParams::max_wheel_speed_mps, 0.1, 10.0, "m/s", "wheel speed limit (both wheels scaled together)"),
};
DriveParams load_drive_params(const SectionView& s);

struct WheelSpeeds {
  double left_mps{0}, right_mps{0};
};
// v, w -> wheel speeds; both scaled by the same factor when one would exceed max_wheel (keeps the curvature).
[[nodiscard]] WheelSpeeds wheels_from_twist(double v_mps, double w_radps, double track_m, double max_wheel_mps) noexcept;

enum class FollowState : std::uint8_t { kIdle = 0, kFollowing = 1, kTurning = 2, kArrived = 3 };

struct TwistCommand {
  double v_mps{0}, w_radps{0};
};

class PathFollower {
 public:
  explicit PathFollower(const DriveParams& p) noexcept : p_(p) {}
  // A new path (copied, at most kMaxPathPoints); the follower starts at its first segment.
  void set_path(const Point2* pts, std::uint32_t n) noexcept;
  void clear() noexcept;
  // One control step of dt seconds from pose: the limited twist to command. speed_cap lowers the top
  // speed for this step; steer_to (the local tracker's goal, map frame) replaces the route's look-ahead
  // point as the point to steer at, while progress, slowing down and arrival still follow the route.
  TwistCommand step(const Pose2& pose, double dt, double speed_cap = 1e9, const Point2* steer_to = nullptr) noexcept;
  // Slows to a stop within the deceleration limits (e-stop handling is the base's: this is a soft stop).
  TwistCommand stop(double dt) noexcept;
  // Zero at once (the reflex stop): no ramp.
  TwistCommand halt() noexcept {
    out_ = TwistCommand{};
    return out_;
  }
  // Under the reflex stop: no forward motion, but a turn on the spot toward target (map frame) when it is
  // more than min_heading_rad off the nose; else halt(). A robot that stopped facing a car turns away
  // from it instead of standing there for ever.
  TwistCommand turn_toward(const Pose2& pose, const Point2& target, double dt, double min_heading_rad = 0.1) noexcept;
  [[nodiscard]] FollowState state() const noexcept { return state_; }
  [[nodiscard]] double remaining_m() const noexcept { return remaining_; }
  [[nodiscard]] const TwistCommand& last() const noexcept { return out_; }
  [[nodiscard]] const DriveParams& params() const noexcept { return p_; }

 private:
  TwistCommand limit(double v, double w, double dt) noexcept;
  DriveParams p_;
  std::array<Point2, kMaxPathPoints> pts_{};
  std::uint32_t n_{0}, seg_{0};
  bool relocate_{false};
  FollowState state_{FollowState::kIdle};
  TwistCommand out_{};
  double remaining_{0};
};

}  // namespace ag::plan
