// ODrive "CAN Simple" protocol, transcribed from the ODrive CAN protocol documentation and checked
// against the vendor's DBC (../shared/fixtures/can/odrive-cansimple.dbc) by tests/unit/drivers:
// 11-bit identifier = node_id << 5 | command id; 8 data bytes, little-endian; floats are IEEE-754
// binary32. Velocities and positions are in motor turns (per second).
#pragma once

#include <cstdint>

#include "airground/drivers/can/can_bus.hpp"

namespace ag::odrive {

enum class Cmd : std::uint8_t {
  kHeartbeat = 0x01,            // controller -> host, cyclic: Axis_Error u32 @0, Axis_State u32 @32
  kSetAxisState = 0x07,         // host -> controller: Axis_Requested_State u32 @0
  kGetEncoderEstimates = 0x09,  // controller -> host, cyclic or on RTR: Pos_Estimate f32 @0 [turns], Vel_Estimate f32 @32 [turns/s]
  kSetControllerMode = 0x0B,    // host -> controller: Control_Mode u32 @0, Input_Mode u32 @32
  kSetInputVel = 0x0D,          // host -> controller: Input_Vel f32 @0 [turns/s], Input_Torque_FF f32 @32 [Nm]
};

enum class AxisState : std::uint32_t { kUndefined = 0, kIdle = 1, kClosedLoopControl = 8 };
inline constexpr std::uint32_t kControlModeVelocity = 2;
inline constexpr std::uint32_t kInputModePassthrough = 1;
inline constexpr std::uint8_t kMaxNodeId = 0x3F;

[[nodiscard]] constexpr std::uint32_t arbitration_id(std::uint8_t node, Cmd c) noexcept {
  return (static_cast<std::uint32_t>(node) << 5) | static_cast<std::uint32_t>(c);
}
[[nodiscard]] constexpr std::uint8_t node_of(std::uint32_t id) noexcept { return static_cast<std::uint8_t>(id >> 5); }
[[nodiscard]] constexpr std::uint8_t cmd_of(std::uint32_t id) noexcept { return static_cast<std::uint8_t>(id & 0x1F); }

struct Heartbeat {
  std::uint32_t axis_error{0};
  std::uint32_t axis_state{0};
};
struct EncoderEstimates {
  float pos_turns{0};
  float vel_turns_s{0};
};

[[nodiscard]] can::CanFrame encode_set_input_vel(std::uint8_t node, float vel_turns_s, float torque_ff_nm = 0.0F) noexcept;
[[nodiscard]] can::CanFrame encode_set_axis_state(std::uint8_t node, AxisState s) noexcept;
[[nodiscard]] can::CanFrame encode_set_controller_mode(std::uint8_t node, std::uint32_t control_mode, std::uint32_t input_mode) noexcept;
[[nodiscard]] can::CanFrame encode_heartbeat(std::uint8_t node, const Heartbeat& h) noexcept;  // what a controller sends
[[nodiscard]] can::CanFrame encode_encoder_estimates(std::uint8_t node, const EncoderEstimates& e) noexcept;

// Decoders check the identifier's command, the standard format, no RTR and dlc 8.
[[nodiscard]] bool decode_heartbeat(const can::CanFrame& f, Heartbeat& out) noexcept;
[[nodiscard]] bool decode_encoder_estimates(const can::CanFrame& f, EncoderEstimates& out) noexcept;
[[nodiscard]] bool decode_set_input_vel(const can::CanFrame& f, float& vel_turns_s, float& torque_ff_nm) noexcept;
[[nodiscard]] bool decode_set_axis_state(const can::CanFrame& f, std::uint32_t& state) noexcept;

}  // namespace ag::odrive
