// Simulated ODrive controllers.
#include "airground/drivers/base/odrive_sim.hpp"

#include <algorithm>
#include <cmath>

namespace ag::base {

OdriveSimulator::OdriveSimulator(can::CanBus& bus, std::array<std::uint8_t, 2> nodes, const OdriveSimParams& p) noexcept
    : bus_(bus), nodes_(nodes), p_(p) {}

void OdriveSimulator::inject_error(int axis, std::uint32_t axis_error) noexcept {
  const auto i = static_cast<std::size_t>(axis);
  error_[i] = axis_error;
  state_[i] = static_cast<std::uint32_t>(odrive::AxisState::kIdle);
  input_[i] = 0;
}

void OdriveSimulator::step(TimeNs now) noexcept {
  can::CanFrame f;
  while (bus_.receive(f) == can::CanResult::kOk) {
    for (std::size_t i = 0; i < 2; ++i) {
      if (f.extended || odrive::node_of(f.id) != nodes_[i]) continue;
      float v = 0, tff = 0;
      std::uint32_t s = 0;
      if (odrive::decode_set_input_vel(f, v, tff)) {
        ++commands_;
        if (state_[i] == static_cast<std::uint32_t>(odrive::AxisState::kClosedLoopControl) && std::isfinite(v)) input_[i] = static_cast<double>(v);
      } else if (odrive::decode_set_axis_state(f, s)) {
        if (error_[i] == 0) state_[i] = s;  // an axis in error refuses to arm until cleared
        if (s != static_cast<std::uint32_t>(odrive::AxisState::kClosedLoopControl)) input_[i] = 0;
      }
    }
  }
  if (last_ < 0) {
    last_ = now;
    next_hb_ = now;
    next_enc_ = now;
  }
  const double dt = to_seconds(now - last_);
  last_ = now;
  for (std::size_t i = 0; i < 2; ++i) {
    const double target = state_[i] == static_cast<std::uint32_t>(odrive::AxisState::kClosedLoopControl) ? input_[i] : 0.0;
    const double dv = std::clamp(target - vel_[i], -p_.accel_turns_s2 * dt, p_.accel_turns_s2 * dt);
    const double v0 = vel_[i];
    vel_[i] += dv;
    pos_[i] += 0.5 * (v0 + vel_[i]) * dt;
  }
  if (now >= next_enc_) {
    next_enc_ += from_seconds(p_.encoder_period_s);
    if (next_enc_ <= now) next_enc_ = now + from_seconds(p_.encoder_period_s);
    for (std::size_t i = 0; i < 2; ++i)
      if (!silent_[i]) {
        const double pos = shaft_[i] ? shaft_pos_[i] : pos_[i], vel = shaft_[i] ? shaft_vel_[i] : vel_[i];
        (void)bus_.send(odrive::encode_encoder_estimates(nodes_[i], {static_cast<float>(pos), static_cast<float>(vel)}));
      }
  }
  if (now >= next_hb_) {
    next_hb_ += from_seconds(p_.heartbeat_period_s);
    if (next_hb_ <= now) next_hb_ = now + from_seconds(p_.heartbeat_period_s);
    for (std::size_t i = 0; i < 2; ++i)
      if (!silent_[i]) (void)bus_.send(odrive::encode_heartbeat(nodes_[i], {error_[i], state_[i]}));
  }
}

}  // namespace ag::base
