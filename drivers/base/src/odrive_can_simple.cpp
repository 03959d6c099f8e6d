// ODrive CAN Simple encoders and decoders.
#include "airground/drivers/base/odrive_can_simple.hpp"

#include <cstring>

namespace ag::odrive {

namespace {
void put_u32(can::CanFrame& f, int at, std::uint32_t v) noexcept {
  for (int i = 0; i < 4; ++i) f.data[static_cast<std::size_t>(at + i)] = static_cast<std::uint8_t>(v >> (8 * i));
}
void put_f32(can::CanFrame& f, int at, float v) noexcept {
  std::uint32_t b = 0;
  std::memcpy(&b, &v, sizeof b);
  put_u32(f, at, b);
}
std::uint32_t get_u32(const can::CanFrame& f, int at) noexcept {
  std::uint32_t v = 0;
  for (int i = 0; i < 4; ++i) v |= static_cast<std::uint32_t>(f.data[static_cast<std::size_t>(at + i)]) << (8 * i);
  return v;
}
float get_f32(const can::CanFrame& f, int at) noexcept {
  const std::uint32_t b = get_u32(f, at);
  float v = 0;
  std::memcpy(&v, &b, sizeof v);
  return v;
}
can::CanFrame frame(std::uint8_t node, Cmd c) noexcept {
  can::CanFrame f;
  f.id = arbitration_id(node, c);
  f.dlc = 8;
  return f;
}
bool is(const can::CanFrame& f, Cmd c) noexcept { return !f.extended && !f.rtr && f.dlc == 8 && cmd_of(f.id) == static_cast<std::uint8_t>(c); }
}  // namespace

can::CanFrame encode_set_input_vel(std::uint8_t node, float vel, float torque_ff) noexcept {
  can::CanFrame f = frame(node, Cmd::kSetInputVel);
  put_f32(f, 0, vel);
  put_f32(f, 4, torque_ff);
  return f;
}
can::CanFrame encode_set_axis_state(std::uint8_t node, AxisState s) noexcept {
  can::CanFrame f = frame(node, Cmd::kSetAxisState);
  put_u32(f, 0, static_cast<std::uint32_t>(s));
  return f;
}
can::CanFrame encode_set_controller_mode(std::uint8_t node, std::uint32_t control_mode, std::uint32_t input_mode) noexcept {
  can::CanFrame f = frame(node, Cmd::kSetControllerMode);
  put_u32(f, 0, control_mode);
  put_u32(f, 4, input_mode);
  return f;
}
can::CanFrame encode_heartbeat(std::uint8_t node, const Heartbeat& h) noexcept {
  can::CanFrame f = frame(node, Cmd::kHeartbeat);
  put_u32(f, 0, h.axis_error);
  put_u32(f, 4, h.axis_state);
  return f;
}
can::CanFrame encode_encoder_estimates(std::uint8_t node, const EncoderEstimates& e) noexcept {
  can::CanFrame f = frame(node, Cmd::kGetEncoderEstimates);
  put_f32(f, 0, e.pos_turns);
  put_f32(f, 4, e.vel_turns_s);
  return f;
}

bool decode_heartbeat(const can::CanFrame& f, Heartbeat& out) noexcept {
  if (!is(f, Cmd::kHeartbeat)) return false;
  out.axis_error = get_u32(f, 0);
  out.axis_state = get_u32(f, 4);
  return true;
}
bool decode_encoder_estimates(const can::CanFrame& f, EncoderEstimates& out) noexcept {
  if (!is(f, Cmd::kGetEncoderEstimates)) return false;
  out.pos_turns = get_f32(f, 0);
  out.vel_turns_s = get_f32(f, 4);
  return true;
}
bool decode_set_input_vel(const can::CanFrame& f, float& vel, float& torque_ff) noexcept {
  if (!is(f, Cmd::kSetInputVel)) return false;
  vel = get_f32(f, 0);
  torque_ff = get_f32(f, 4);
  return true;
}
bool decode_set_axis_state(const can::CanFrame& f, std::uint32_t& state) noexcept {
  if (!is(f, Cmd::kSetAxisState)) return false;
  state = get_u32(f, 0);
  return true;
}

}  // namespace ag::odrive
