// The ground robot's differential-drive base: two ODrive controllers on one CAN bus (CAN Simple), one
// per side. It arms them (velocity control, closed loop), sends each wheel's velocity every step, stops
// the wheels when no fresh command came within command_timeout_s (the watchdog), stops and reports
// when a controller reports an axis error, leaves closed-loop control or falls silent (no heartbeat
// within heartbeat_timeout_s), and integrates wheel odometry from the encoder estimates.
//
// Life cycle: kDisarmed -arm()-> kArming -both axes closed loop-> kRunning; any fault -> kFault (zero
// velocity every step) until arm() again. Never allocates after construction; never blocks.
#pragma once

#include <array>
#include <cstdint>

#include "airground/messages/messages.hpp"
#include "airground/drivers/base/odrive_can_simple.hpp"
#include "airground/drivers/can/can_bus.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/param_binding.hpp"

namespace ag::base {

struct BaseParams {
  std::uint8_t left_node{0}, right_node{1};
  double wheel_radius_m{0.165};
  double track_m{0.55};            // [m] distance between the wheel contact lines
  double gear_ratio{1.0};          // motor turns per wheel turn
  int left_sign{-1}, right_sign{1};  // motor direction that drives the wheel forward (mirrored motors)
  double command_timeout_s{0.2};   // [s] watchdog
  double heartbeat_timeout_s{0.35};  // [s] a controller silent this long is a fault (ODrive heartbeat: 100 ms)
  double arm_timeout_s{2.0};       // [s] closed loop must be reported within this after arm()
  double max_wheel_speed_mps{2.0}; // [m/s] commands are clamped here
};

// [rad/s] wheel `axis` (0 left, 1 right) turns forward at, from its motor's velocity [turns/s].
[[nodiscard]] inline double wheel_rad_s(const BaseParams& p, int axis, double motor_turns_s) noexcept {
  return (axis == 0 ? p.left_sign : p.right_sign) * motor_turns_s * 2.0 * kPi / p.gear_ratio;
}

inline constexpr ParamField<BaseParams> kBaseFields[] = {
    field::integer("left_node_id", &BaseParams::left_node, 0, 0x3F, "", "CAN Simple node id of the left wheel's controller"),
    field::integer("right_node_id", &BaseParams::right_node, 0, 0x3F, "", "CAN Simple node id of the right wheel's controller"),
    field::real("wheel_radius_m", &BaseParams::wheel_radius_m, 0.01, 2.0, "m", "wheel radius"),
    field::real("track_m", &BaseParams::track_m, 0.05, 5.0, "m", "distance between the left and right wheel contact lines"),
    field::real("gear_ratio", &BaseParams::gear_ratio, 0.01, 1000.0, "", "motor turns per wheel turn"),
    field::integer("left_sign", &BaseParams::left_sign, -1, 1, "", "motor direction (+1/-1) that drives the left wheel forward"),
    field::integer("right_sign", &BaseParams::right_sign, -1, 1, "", "motor direction (+1/-1) that drives the right wheel forward"),
    field::real("command_timeout_s", &BaseParams::command_timeout_s, 0.02, 5.0, "s", "watchdog: zero velocity when no fresh command came within this"),
    field::real("heartbeat_timeout_s", &BaseParams::heartbeat_timeout_s, 0.05, 10.0, "s", "a controller without a heartbeat this long stops the robot"),
    field::real("arm_timeout_s", &BaseParams::arm_timeout_s, 0.1, 30.0, "s", "both axes must report closed-loop control within this after arming"),
    field::real("max_wheel_speed_mps", &BaseParams::max_wheel_speed_mps, 0.1, 10.0, "m/s", "wheel speed commands are clamped here"),
};
// The rows above, the signs made +1/-1 (a 0 drives forward, as +1).
BaseParams load_base_params(const SectionView& s);

enum class BaseState : std::uint8_t { kDisarmed = 0, kArming = 1, kRunning = 2, kFault = 3 };
enum class BaseFault : std::uint8_t {
  kNone = 0,
  kAxisError = 1,          // a heartbeat carried a non-zero Axis_Error
  kControllerSilent = 2,   // no heartbeat within heartbeat_timeout_s
  kLeftClosedLoop = 3,     // an axis reported a state other than closed loop while running
  kArmTimeout = 4,         // closed loop not reached within arm_timeout_s
  kBusDown = 5,            // the bus refused to send
};
const char* to_string(BaseState s) noexcept;
const char* to_string(BaseFault f) noexcept;

struct BaseCounters {
  std::uint64_t commands{0};
  std::uint64_t watchdog_trips{0};     // fresh -> stale transitions
  std::uint64_t heartbeats{0}, encoder_frames{0};
  std::uint64_t rx_foreign{0};         // frames of other nodes or commands we do not read
  std::uint64_t rx_malformed{0};       // our node and command but wrong dlc / RTR / extended
  std::uint64_t non_finite_estimates{0};
  std::uint64_t tx_failed{0};
  std::uint64_t faults{0};
  std::uint64_t odometry_samples{0};
  std::uint64_t odometry_dropped{0};   // the sample ring was full
};

struct BaseStatus {
  BaseState state{BaseState::kDisarmed};
  BaseFault fault{BaseFault::kNone};
  std::uint8_t fault_node{0};
  std::uint32_t fault_axis_error{0};
  TimeNs fault_time{0};
};

class DiffDriveBase {
 public:
  DiffDriveBase(const BaseParams& p, can::CanBus& bus) noexcept;

  void arm(TimeNs now) noexcept;
  void disarm(TimeNs now) noexcept;
  // A fresh wheel speed command [m/s, forward positive]; non-finite values count as a stop.
  void command(double left_mps, double right_mps, TimeNs now) noexcept;
  // Reads every received frame, checks the controllers, sends both wheels' velocities.
  void step(TimeNs now) noexcept;
  // While inhibited (e-stop), every step sends zero velocity whatever the command.
  void set_inhibit(bool inhibit) noexcept { inhibit_ = inhibit; }
  [[nodiscard]] bool inhibited() const noexcept { return inhibit_; }
  // Folds encoder estimates into the odometry without commanding anything (replay of a recorded run).
  void receive_only(TimeNs now) noexcept { drain(now); }

  // The oldest odometry sample not taken yet.
  bool take_odometry(WheelOdometryMsg& out) noexcept;
  [[nodiscard]] const WheelOdometryMsg& odometry() const noexcept { return odom_; }
  [[nodiscard]] const BaseStatus& status() const noexcept { return st_; }
  [[nodiscard]] const BaseCounters& counters() const noexcept { return c_; }
  // [turns/s] the motor velocity last sent to each axis (0 left, 1 right).
  [[nodiscard]] float sent_velocity(int axis) const noexcept { return sent_[static_cast<std::size_t>(axis)]; }
  [[nodiscard]] bool command_fresh(TimeNs now) const noexcept;
  [[nodiscard]] const BaseParams& params() const noexcept { return p_; }

 private:
  struct Axis {
    std::uint8_t node{0};
    int sign{1};
    TimeNs last_heartbeat{0};
    std::uint32_t state{0};
    bool seen_closed_loop{false};
    bool have_estimate{false}, fresh_estimate{false};
    double pos_turns{0}, vel_turns_s{0};
    double prev_pos_turns{0};
    TimeNs estimate_stamp{0};
  };
  void drain(TimeNs now) noexcept;
  void fault(BaseFault f, const Axis* a, std::uint32_t axis_error, TimeNs now) noexcept;
  void integrate() noexcept;
  void send_velocity(TimeNs now, double left_mps, double right_mps) noexcept;
  void send(const can::CanFrame& f, TimeNs now) noexcept;

  BaseParams p_;
  can::CanBus& bus_;
  std::array<Axis, 2> ax_{};
  std::array<float, 2> sent_{};
  BaseStatus st_;
  BaseCounters c_;
  TimeNs arm_time_{0};
  TimeNs cmd_time_{-1};
  bool was_fresh_{false};
  bool inhibit_{false};
  double cmd_l_{0}, cmd_r_{0};
  bool odom_started_{false};
  WheelOdometryMsg odom_{};
  static constexpr std::size_t kRing = 64;
  std::array<WheelOdometryMsg, kRing> ring_{};
  std::size_t ring_head_{0}, ring_n_{0};
};

}  // namespace ag::base
