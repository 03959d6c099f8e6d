// Simulated ODrive controllers on the device side of a CAN bus (the simulator's base and the tests):
// each axis obeys Set_Axis_State and Set_Input_Vel (velocity ramps at accel_turns_s2), integrates its
// position, and sends Heartbeat and Get_Encoder_Estimates cyclically, like a controller configured
// with heartbeat_msg_rate_ms and encoder_msg_rate_ms. Faults can be injected: an axis error (the axis
// drops to idle, as the real one does) or a silent controller.
#pragma once

#include <array>
#include <cstdint>

#include "airground/drivers/base/odrive_can_simple.hpp"
#include "airground/drivers/can/can_bus.hpp"

namespace ag::base {

struct OdriveSimParams {
  double accel_turns_s2{60.0};       // [turns/s^2] velocity ramp
  double heartbeat_period_s{0.1};
  double encoder_period_s{0.01};
};

class OdriveSimulator {
 public:
  OdriveSimulator(can::CanBus& device_side, std::array<std::uint8_t, 2> nodes, const OdriveSimParams& p = {}) noexcept;
  void step(TimeNs now) noexcept;
  void inject_error(int axis, std::uint32_t axis_error) noexcept;
  void set_silent(int axis, bool silent) noexcept { silent_[static_cast<std::size_t>(axis)] = silent; }
  // A wheel on the shaft (the simulator's vehicle): from now on the encoder reports this position and
  // velocity [turns, turns/s] (what the wheel did: slip, a blocked wheel), not the controller's own ramp.
  void set_shaft(int axis, double pos_turns, double vel_turns_s) noexcept {
    const auto i = static_cast<std::size_t>(axis);
    shaft_[i] = true;
    shaft_pos_[i] = pos_turns;
    shaft_vel_[i] = vel_turns_s;
  }
  [[nodiscard]] double pos_turns(int axis) const noexcept { return pos_[static_cast<std::size_t>(axis)]; }
  [[nodiscard]] double vel_turns_s(int axis) const noexcept { return vel_[static_cast<std::size_t>(axis)]; }
  [[nodiscard]] double input_vel(int axis) const noexcept { return input_[static_cast<std::size_t>(axis)]; }
  [[nodiscard]] std::uint32_t axis_state(int axis) const noexcept { return state_[static_cast<std::size_t>(axis)]; }
  [[nodiscard]] std::uint64_t commands_received() const noexcept { return commands_; }

 private:
  can::CanBus& bus_;
  std::array<std::uint8_t, 2> nodes_;
  OdriveSimParams p_;
  std::array<double, 2> pos_{}, vel_{}, input_{};
  std::array<std::uint32_t, 2> state_{1, 1}, error_{0, 0};
  std::array<bool, 2> silent_{false, false};
  std::array<bool, 2> shaft_{false, false};
  std::array<double, 2> shaft_pos_{}, shaft_vel_{};
  TimeNs last_{-1}, next_hb_{0}, next_enc_{0};
  std::uint64_t commands_{0};
};

}  // namespace ag::base
