// The CAN bus as the drivers see it: classic CAN frames, a non-blocking send and receive, counters.
// Backends: SocketCanBus (the robot), CandumpReplayBus (a recorded log), InProcessCanLink (the
// simulator), and RecordingCanBus (any of them, written to a candump log as it runs).
#pragma once

#include <array>
#include <cstdint>

#include "airground/platform/time.hpp"

namespace ag::can {

inline constexpr std::uint32_t kStandardIdMask = 0x7FF;
inline constexpr std::uint32_t kExtendedIdMask = 0x1FFFFFFF;

struct CanFrame {
  std::uint32_t id{0};        // 11-bit standard or 29-bit extended identifier
  bool extended{false};
  bool rtr{false};            // remote transmission request (no data)
  std::uint8_t dlc{0};        // 0..8
  std::array<std::uint8_t, 8> data{};
  TimeNs stamp{0};            // [ns] when received (or sent), on the bus's clock
};

enum class CanResult : std::uint8_t {
  kOk = 0,
  kWouldBlock = 1,  // nothing to read, or the transmit queue is full (counted)
  kDown = 2,        // the interface is down or was never opened
  kInvalid = 3,     // a frame with dlc > 8 or an id beyond its format
};
const char* to_string(CanResult r) noexcept;

struct CanBusCounters {
  std::uint64_t tx{0}, rx{0};
  std::uint64_t tx_dropped{0};   // queue full or interface down
  std::uint64_t rx_errors{0};    // error frames, truncated reads, malformed records
};

[[nodiscard]] inline bool valid(const CanFrame& f) noexcept {
  return f.dlc <= 8 && (f.extended ? f.id <= kExtendedIdMask : f.id <= kStandardIdMask);
}

class CanBus {
 public:
  CanBus() = default;
  CanBus(const CanBus&) = delete;
  CanBus& operator=(const CanBus&) = delete;
  virtual ~CanBus() = default;
  // Queues one frame; never blocks.
  [[nodiscard]] virtual CanResult send(const CanFrame& f) noexcept = 0;
  // The next received frame (stamped), kWouldBlock when there is none; never blocks.
  [[nodiscard]] virtual CanResult receive(CanFrame& out) noexcept = 0;
  [[nodiscard]] virtual const CanBusCounters& counters() const noexcept = 0;
};

}  // namespace ag::can
