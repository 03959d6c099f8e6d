// The simulated PX4 on the quadrotor's TELEM2 (the autopilot stage's `source: sim`): HEARTBEAT once a
// second and each sample of the attitude model (attitude.yaml) as MAVLink 2 ATTITUDE in FRD / NED,
// system 1, component 1 (MAV_COMP_ID_AUTOPILOT1). What the stage sends it (SET_MESSAGE_INTERVAL) is
// read and counted; the model's rate already is what the stage asks for (50 Hz).
#pragma once

#include <cstdint>

#include "airground/drivers/autopilot/mavlink/link.hpp"
#include "airground/platform/time.hpp"
#include "airground/sim/attitude.hpp"

namespace ag::sim {

class SimPx4 {
 public:
  explicit SimPx4(mavlink::SimAutopilotLink& link) : link_(link) {}
  // A heartbeat when one is due, and whatever the robot sent drained (counted).
  void step(TimeNs now) noexcept;
  // One attitude sample (REP-103, as the model gives it) as ATTITUDE on the wire.
  void send_attitude(const AttitudeSample& s) noexcept;
  [[nodiscard]] std::uint64_t frames_sent() const noexcept { return frames_; }
  [[nodiscard]] std::uint64_t bytes_received() const noexcept { return received_; }

 private:
  void send(std::span<const std::uint8_t> frame) noexcept;
  mavlink::SimAutopilotLink& link_;
  std::uint8_t seq_{0};
  TimeNs next_heartbeat_{0};
  std::uint64_t frames_{0}, received_{0};
};

}  // namespace ag::sim
