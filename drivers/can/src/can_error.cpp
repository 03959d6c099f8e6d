// CAN error frames, controller state and the bus-off supervisor.
#include "airground/drivers/can/can_error.hpp"

#include <algorithm>
#include <cstdio>
#include <cstring>

namespace ag::can {

const char* to_string(CanBusState s) noexcept {
  switch (s) {
    case CanBusState::kErrorActive: return "error-active";
    case CanBusState::kErrorWarning: return "error-warning";
    case CanBusState::kErrorPassive: return "error-passive";
    case CanBusState::kBusOff: return "bus-off";
  }
  return "?";
}

CanErrorReport decode_error_frame(std::uint32_t can_id, const std::array<std::uint8_t, 8>& d) noexcept {
  CanErrorReport r;
  r.classes = can_id & 0x1FFFFFFFU;
  r.tx_timeout = (r.classes & kErrTxTimeout) != 0;
  r.lost_arbitration = (r.classes & kErrLostArb) != 0;
  r.controller = (r.classes & kErrCrtl) != 0;
  r.protocol = (r.classes & kErrProt) != 0;
  r.transceiver = (r.classes & kErrTrx) != 0;
  r.ack_missing = (r.classes & kErrAck) != 0;
  r.bus_off = (r.classes & kErrBusOff) != 0;
  r.bus_error = (r.classes & kErrBusError) != 0;
  r.restarted = (r.classes & kErrRestarted) != 0;
  if (r.lost_arbitration) r.lost_arbitration_bit = d[0];
  if (r.controller) {
    const std::uint8_t s = d[1];
    r.rx_overflow = (s & kCrtlRxOverflow) != 0;
    r.tx_overflow = (s & kCrtlTxOverflow) != 0;
    r.error_warning = (s & (kCrtlRxWarning | kCrtlTxWarning)) != 0;
    r.error_passive = (s & (kCrtlRxPassive | kCrtlTxPassive)) != 0;
    r.back_to_active = (s & kCrtlActive) != 0;
  }
  if (r.protocol) {
    r.protocol_type = d[2];
    r.protocol_location = d[3];
  }
  if (r.transceiver) r.transceiver_status = d[4];
  // Kernels >= 5.19 flag the counters with CAN_ERR_CNT; older ones fill them for controller errors.
  if ((r.classes & kErrCnt) != 0 || r.controller) {
    r.has_counts = true;
    r.tx_error_count = d[6];
    r.rx_error_count = d[7];
  }
  return r;
}

std::size_t describe(const CanErrorReport& r, char* buf, std::size_t cap) noexcept {
  if (cap == 0) return 0;
  std::size_t n = 0;
  auto add = [&](const char* s) {
    if (n + 1 >= cap) return;
    if (n > 0 && n + 2 < cap) {
      buf[n++] = ';';
      buf[n++] = ' ';
    }
    const std::size_t l = std::min(std::strlen(s), cap - 1 - n);
    std::memcpy(buf + n, s, l);
    n += l;
  };
  if (r.bus_off) add("bus-off");
  if (r.restarted) add("restarted");
  if (r.error_passive) add("error-passive");
  if (r.error_warning) add("error-warning");
  if (r.back_to_active) add("back to error-active");
  if (r.rx_overflow) add("rx overflow");
  if (r.tx_overflow) add("tx overflow");
  if (r.lost_arbitration) add("lost arbitration");
  if (r.protocol) add("protocol violation");
  if (r.ack_missing) add("no ack");
  if (r.tx_timeout) add("tx timeout");
  if (r.transceiver) add("transceiver");
  if (r.bus_error) add("bus error");
  if (r.has_counts && n + 1 < cap) {
    char c[32];
    std::snprintf(c, sizeof c, "tec %u rec %u", static_cast<unsigned>(r.tx_error_count), static_cast<unsigned>(r.rx_error_count));
    add(c);
  }
  if (n == 0) add("error frame (no class)");
  buf[n] = '\0';
  return n;
}

void CanErrorTracker::apply(const CanErrorReport& r, CanBusCounters& c) noexcept {
  last_ = r;
  ++c.error_frames;
  if (r.bus_off) ++c.bus_off;
  if (r.error_passive) ++c.error_passive;
  if (r.error_warning) ++c.error_warning;
  if (r.lost_arbitration) ++c.lost_arbitration;
  if (r.protocol) ++c.protocol_errors;
  if (r.ack_missing) ++c.ack_missing;
  if (r.rx_overflow || r.tx_overflow) ++c.controller_overflow;
  if (r.tx_timeout) ++c.tx_timeout;
  if (r.restarted) ++c.restarted;

  if (r.bus_off) {
    state_ = CanBusState::kBusOff;
  } else if (r.restarted || r.back_to_active) {
    state_ = CanBusState::kErrorActive;
  } else if (state_ != CanBusState::kBusOff) {
    if (r.error_passive) state_ = CanBusState::kErrorPassive;
    else if (r.error_warning && state_ != CanBusState::kErrorPassive) state_ = CanBusState::kErrorWarning;
    else if (r.has_counts) {  // ISO 11898-1: 128 passive, 96 warning (SocketCAN's default warning level)
      const unsigned m = std::max(r.tx_error_count, r.rx_error_count);
      state_ = m >= 128 ? CanBusState::kErrorPassive : m >= 96 ? CanBusState::kErrorWarning : state_;
    }
  }
}

BusOffSupervisor::Action BusOffSupervisor::update(TimeNs now, CanBusState state) noexcept {
  if (state != CanBusState::kBusOff) {
    if (in_bus_off_) {
      in_bus_off_ = false;
      ++recoveries_;
      last_outage_ = now - since_;
    }
    return Action::kNone;
  }
  if (!in_bus_off_) {
    in_bus_off_ = true;
    gave_up_ = false;
    ++episodes_;
    attempts_ = 0;
    since_ = now;
    backoff_ = p_.initial_backoff;
    next_ = now + backoff_;
  }
  if (gave_up_ || now < next_) return Action::kNone;
  if (p_.max_attempts > 0 && attempts_ >= p_.max_attempts) {
    gave_up_ = true;
    return Action::kGaveUp;
  }
  ++attempts_;
  ++restarts_;
  backoff_ = std::min(backoff_ * std::max(p_.factor, 1), p_.max_backoff);
  next_ = now + backoff_;
  return Action::kRestart;
}

}  // namespace ag::can
