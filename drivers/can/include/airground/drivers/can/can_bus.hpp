// The CAN bus as the drivers see it: classic CAN frames, a non-blocking send and receive, counters.
// Backends: SocketCanBus (the robot), CandumpReplayBus (a recorded log), InProcessCanLink (the
// simulator), and RecordingCanBus (any of them, written to a candump log as it runs).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

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
  std::uint64_t rx_filtered{0};  // received but refused by the receive filters (software check)
  // Error frames by class (can_error.hpp): one error frame may count in several.
  std::uint64_t error_frames{0}, bus_off{0}, error_passive{0}, error_warning{0}, lost_arbitration{0};
  std::uint64_t protocol_errors{0}, ack_missing{0}, controller_overflow{0}, tx_timeout{0}, restarted{0};
};

// A receive filter with SocketCAN's semantics: a frame of the same format (standard/extended) passes
// when (frame.id & mask) == (id & mask). A bus with no filters passes every frame.
struct CanFilter {
  std::uint32_t id{0};
  std::uint32_t mask{0};
  bool extended{false};
};
inline constexpr std::size_t kMaxCanFilters = 16;
[[nodiscard]] inline bool matches(const CanFilter& flt, const CanFrame& f) noexcept {
  return f.extended == flt.extended && (f.id & flt.mask) == (flt.id & flt.mask);
}

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

  // Sets the receive filters (replacing any before); false when there are more than kMaxCanFilters.
  // Every backend applies them in receive(); SocketCAN also gives them to the kernel (CAN_RAW_FILTER).
  [[nodiscard]] virtual bool set_filters(std::span<const CanFilter> filters) noexcept {
    if (filters.size() > kMaxCanFilters) return false;
    for (std::size_t i = 0; i < filters.size(); ++i) filters_[i] = filters[i];
    n_filters_ = filters.size();
    return true;
  }
  [[nodiscard]] bool accepts(const CanFrame& f) const noexcept {
    if (n_filters_ == 0) return true;
    for (std::size_t i = 0; i < n_filters_; ++i)
      if (matches(filters_[i], f)) return true;
    return false;
  }
  [[nodiscard]] std::span<const CanFilter> filters() const noexcept { return {filters_.data(), n_filters_}; }

 private:
  std::array<CanFilter, kMaxCanFilters> filters_{};
  std::size_t n_filters_{0};
};

// A bus whose interface could not be opened: every send is refused (kDown, counted as dropped) and
// nothing is received. The driver above it faults "bus down" and keeps the wheels stopped.
class AbsentCanBus final : public CanBus {
 public:
  [[nodiscard]] CanResult send(const CanFrame&) noexcept override {
    ++c_.tx_dropped;
    return CanResult::kDown;
  }
  [[nodiscard]] CanResult receive(CanFrame&) noexcept override { return CanResult::kWouldBlock; }
  [[nodiscard]] const CanBusCounters& counters() const noexcept override { return c_; }

 private:
  CanBusCounters c_;
};

}  // namespace ag::can
