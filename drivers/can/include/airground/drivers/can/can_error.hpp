// CAN error frames (SocketCAN's CAN_ERR_FLAG frames, linux/can/error.h) decoded into what happened,
// the controller's error state they imply (active, warning, passive, bus-off), and the bus-off
// supervisor: a restart policy with exponential backoff that asks the backend to restart the controller.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

#include "airground/drivers/can/can_bus.hpp"
#include "airground/platform/time.hpp"

namespace ag::can {

enum class CanBusState : std::uint8_t { kErrorActive = 0, kErrorWarning = 1, kErrorPassive = 2, kBusOff = 3 };
const char* to_string(CanBusState s) noexcept;

// Error classes (the can_id bits of an error frame, as linux/can/error.h numbers them).
inline constexpr std::uint32_t kErrFlag = 0x20000000U;  // CAN_ERR_FLAG
inline constexpr std::uint32_t kErrTxTimeout = 0x001, kErrLostArb = 0x002, kErrCrtl = 0x004, kErrProt = 0x008, kErrTrx = 0x010,
                               kErrAck = 0x020, kErrBusOff = 0x040, kErrBusError = 0x080, kErrRestarted = 0x100, kErrCnt = 0x200;
// data[1] controller status bits.
inline constexpr std::uint8_t kCrtlRxOverflow = 0x01, kCrtlTxOverflow = 0x02, kCrtlRxWarning = 0x04, kCrtlTxWarning = 0x08,
                              kCrtlRxPassive = 0x10, kCrtlTxPassive = 0x20, kCrtlActive = 0x40;

struct CanErrorReport {
  std::uint32_t classes{0};
  bool tx_timeout{false}, lost_arbitration{false}, controller{false}, protocol{false}, transceiver{false};
  bool ack_missing{false}, bus_off{false}, bus_error{false}, restarted{false};
  bool error_warning{false}, error_passive{false}, back_to_active{false}, rx_overflow{false}, tx_overflow{false};
  std::uint8_t lost_arbitration_bit{0};   // data[0]
  std::uint8_t protocol_type{0}, protocol_location{0}, transceiver_status{0};
  bool has_counts{false};
  std::uint8_t tx_error_count{0}, rx_error_count{0};  // data[6], data[7]
};

// Decodes an error frame's identifier (with or without CAN_ERR_FLAG) and its 8 data bytes.
[[nodiscard]] CanErrorReport decode_error_frame(std::uint32_t can_id, const std::array<std::uint8_t, 8>& data) noexcept;
// A line for the log ("bus-off; controller tx-passive; tec 128 rec 0"); returns the length (truncated to cap-1).
std::size_t describe(const CanErrorReport& r, char* buf, std::size_t cap) noexcept;

// Follows the controller's state through its error frames and counts them.
class CanErrorTracker {
 public:
  void apply(const CanErrorReport& r, CanBusCounters& c) noexcept;
  [[nodiscard]] CanBusState state() const noexcept { return state_; }
  [[nodiscard]] const CanErrorReport& last() const noexcept { return last_; }
  void reset() noexcept { state_ = CanBusState::kErrorActive; }

 private:
  CanBusState state_{CanBusState::kErrorActive};
  CanErrorReport last_;
};

struct RestartPolicy {
  TimeNs initial_backoff{100 * kNsPerMs};  // first restart this long after bus-off
  TimeNs max_backoff{5 * kNsPerS};
  int factor{2};                           // backoff multiplies by this after each failed attempt
  int max_attempts{0};                     // per bus-off episode; 0 = keep trying
};

// Decides when to restart a controller that went bus-off. The caller feeds the state each cycle and
// calls the backend's restart when told to.
class BusOffSupervisor {
 public:
  enum class Action : std::uint8_t { kNone = 0, kRestart = 1, kGaveUp = 2 };
  explicit BusOffSupervisor(RestartPolicy p = {}) noexcept : p_(p) {}
  Action update(TimeNs now, CanBusState state) noexcept;
  [[nodiscard]] bool in_bus_off() const noexcept { return in_bus_off_; }
  [[nodiscard]] std::uint64_t episodes() const noexcept { return episodes_; }
  [[nodiscard]] std::uint64_t restarts() const noexcept { return restarts_; }
  [[nodiscard]] std::uint64_t recoveries() const noexcept { return recoveries_; }
  [[nodiscard]] TimeNs last_outage() const noexcept { return last_outage_; }  // [ns] bus-off to recovery
  [[nodiscard]] TimeNs next_attempt() const noexcept { return next_; }

 private:
  RestartPolicy p_;
  bool in_bus_off_{false}, gave_up_{false};
  int attempts_{0};
  TimeNs since_{0}, next_{0}, backoff_{0}, last_outage_{0};
  std::uint64_t episodes_{0}, restarts_{0}, recoveries_{0};
};

}  // namespace ag::can
