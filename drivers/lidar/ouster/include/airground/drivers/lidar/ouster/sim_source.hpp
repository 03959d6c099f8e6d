// The simulator's Ouster (the lidar stage's `source: sim`): a simulated sensor hands its UDP payloads to
// the robot's lidar stage in-process, and answers get_metadata with its SensorInfo, as a real sensor
// answers over HTTP. The sensor side is the simulator's world stage, the source side the robot's lidar
// stage; the lockstep executor never runs the two at once (like InProcessCanLink).
//
// Invariants: the ring's storage (capacity x max_packet bytes) is allocated once, at construction;
// send() and next() never allocate and never block; a packet that finds the ring full is dropped and
// counted, as a socket buffer drops it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "airground/drivers/lidar/ouster/metadata.hpp"
#include "airground/drivers/lidar/ouster/packet_source.hpp"

namespace ag::ouster {

class SimPacketLink {
 public:
  // Room for `capacity` packets of up to `max_packet` bytes.
  SimPacketLink(SensorInfo info, std::size_t capacity, std::size_t max_packet);
  SimPacketLink(const SimPacketLink&) = delete;
  SimPacketLink& operator=(const SimPacketLink&) = delete;

  // What the simulated sensor answers get_metadata with.
  [[nodiscard]] const SensorInfo& info() const noexcept { return info_; }
  // The sensor sends one lidar packet at `stamp`; false (and counted) when the ring is full or it is too long.
  bool send(std::span<const std::uint8_t> bytes, TimeNs stamp) noexcept;
  // The stage's side: a PacketSource reading this link (it must not outlive the link).
  [[nodiscard]] std::unique_ptr<PacketSource> open_source();
  [[nodiscard]] std::uint64_t sent() const noexcept { return sent_; }
  [[nodiscard]] std::uint64_t dropped() const noexcept { return dropped_; }
  [[nodiscard]] std::size_t queued() const noexcept { return size_; }

 private:
  friend class SimPacketSource;
  PacketKind pop(std::span<std::uint8_t> buf, std::size_t& size, TimeNs& stamp, SourceCounters& c) noexcept;
  SensorInfo info_;
  std::size_t capacity_, max_packet_;
  std::vector<std::uint8_t> storage_;  // capacity_ slots of max_packet_ bytes
  std::vector<std::size_t> length_;
  std::vector<TimeNs> stamp_;
  std::size_t head_{0}, size_{0};
  std::uint64_t sent_{0}, dropped_{0};
};

// Links the simulator provides for its robots' lidar stages, by robot name (the stage's instance); false
// when the name already has one (two teams in one process).
[[nodiscard]] bool register_sim_lidar(std::string_view robot, SimPacketLink* link);
void unregister_sim_lidar(std::string_view robot);
[[nodiscard]] SimPacketLink* find_sim_lidar(std::string_view robot);

}  // namespace ag::ouster
