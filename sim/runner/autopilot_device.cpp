// The simulated PX4's MAVLink.
#include "autopilot_device.hpp"

#include <array>

#include "airground/drivers/autopilot/mavlink/frames.hpp"
#include "airground/drivers/autopilot/mavlink/mavlink.hpp"

namespace ag::sim {

namespace {
constexpr std::uint8_t kSystem = 1, kComponent = 1;  // PX4's defaults (MAV_SYS_ID, MAV_COMP_ID_AUTOPILOT1)
}  // namespace

void SimPx4::send(std::span<const std::uint8_t> frame) noexcept {
  if (frame.empty()) return;
  (void)link_.to_robot.write(frame);  // an overrun is counted by the ring
  ++frames_;
}

void SimPx4::step(TimeNs now) noexcept {
  std::array<std::uint8_t, 256> buf{};
  for (std::size_t n; (n = link_.from_robot.read(buf)) > 0;) received_ += n;
  if (now < next_heartbeat_) return;
  next_heartbeat_ = now + kNsPerS;
  mavlink::Heartbeat hb;
  hb.type = 2;           // MAV_TYPE_QUADROTOR
  hb.autopilot = 12;     // MAV_AUTOPILOT_PX4
  hb.base_mode = 0x81;   // custom mode enabled, armed
  hb.system_status = 4;  // MAV_STATE_ACTIVE
  std::array<std::uint8_t, mavlink::kMaxFrame> frame{};
  send(std::span<const std::uint8_t>(frame.data(), mavlink::encode_message(mavlink::FrameHeader{2, 0, 0, seq_++, kSystem, kComponent, 0}, hb, frame)));
}

void SimPx4::send_attitude(const AttitudeSample& s) noexcept {
  const mavlink::EulerAttitude e =
      mavlink::flu_enu_to_frd_ned(mavlink::EulerAttitude{s.roll, s.pitch, s.yaw, s.roll_rate, s.pitch_rate, s.yaw_rate});
  mavlink::Attitude a;
  a.time_boot_ms = static_cast<std::uint32_t>(s.stamp / kNsPerMs);  // the simulation started with the autopilot
  a.roll = static_cast<float>(e.roll);
  a.pitch = static_cast<float>(e.pitch);
  a.yaw = static_cast<float>(e.yaw);
  a.rollspeed = static_cast<float>(e.roll_rate);
  a.pitchspeed = static_cast<float>(e.pitch_rate);
  a.yawspeed = static_cast<float>(e.yaw_rate);
  std::array<std::uint8_t, mavlink::kMaxFrame> frame{};
  send(std::span<const std::uint8_t>(frame.data(), mavlink::encode_message(mavlink::FrameHeader{2, 0, 0, seq_++, kSystem, kComponent, 0}, a, frame)));
}

}  // namespace ag::sim
