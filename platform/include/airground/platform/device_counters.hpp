// What a device stage says it received (frames, fixes, images or samples; complete or not; decode
// errors by kind; bytes), kept beside the scheduler's counters of that stage and shown by the status
// stage. One writer (the stage's thread), any reader: relaxed atomics, fixed size, never allocates.
#pragma once

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <initializer_list>

#include "airground/platform/time.hpp"

namespace ag {

struct DeviceCounters {
  static constexpr std::size_t kErrorKinds = 4;
  using Name = std::array<char, 20>;

  // At init: what a unit is called ("frames", "fixes") and the decode-error kinds, in index order.
  void describe(const char* unit_name, std::initializer_list<const char*> error_kinds) noexcept {
    std::snprintf(unit.data(), unit.size(), "%s", unit_name);
    std::size_t i = 0;
    for (const char* k : error_kinds)
      if (i < kErrorKinds) std::snprintf(error_name[i++].data(), Name{}.size(), "%s", k);
    active.store(true, std::memory_order_relaxed);
  }
  void unit_received(bool is_complete, TimeNs now) noexcept {
    bump(is_complete ? complete : incomplete);
    last_unit_ns.store(now, std::memory_order_relaxed);
  }
  void error(std::size_t kind, std::uint64_t n = 1) noexcept {
    if (kind < kErrorKinds) bump(errors[kind], n);
  }
  // A kind counted elsewhere (a parser's own counter): its running total.
  void error_total(std::size_t kind, std::uint64_t total) noexcept {
    if (kind < kErrorKinds) errors[kind].store(total, std::memory_order_relaxed);
  }
  void received_bytes(std::uint64_t n) noexcept { bump(bytes, n); }
  [[nodiscard]] std::uint64_t units() const noexcept {
    return complete.load(std::memory_order_relaxed) + incomplete.load(std::memory_order_relaxed);
  }
  [[nodiscard]] std::uint64_t error_total() const noexcept {
    std::uint64_t t = 0;
    for (const auto& e : errors) t += e.load(std::memory_order_relaxed);
    return t;
  }

  std::atomic<bool> active{false};  // a device stage described itself
  Name unit{};
  std::array<Name, kErrorKinds> error_name{};
  std::atomic<std::uint64_t> complete{0}, incomplete{0}, bytes{0};
  std::array<std::atomic<std::uint64_t>, kErrorKinds> errors{};
  std::atomic<TimeNs> last_unit_ns{0};  // [ns] when the last unit was received, 0 = never

 private:
  static void bump(std::atomic<std::uint64_t>& c, std::uint64_t n = 1) noexcept {
    c.store(c.load(std::memory_order_relaxed) + n, std::memory_order_relaxed);
  }
};

// "Nothing for a few seconds while it should": tells a device stage when to log its one warning.
// Armed from the first check (or the last unit); fires once per silence, re-arms when units come again.
class DeviceSilence {
 public:
  explicit DeviceSilence(TimeNs after_ns = 3 * kNsPerS) noexcept : after_(after_ns) {}
  // True once when `now` is `after` past the last unit (or the first call) with no unit since.
  [[nodiscard]] bool check(const DeviceCounters& c, TimeNs now) noexcept {
    const std::uint64_t u = c.units();
    if (!armed_ || u != units_) {
      armed_ = true;
      warned_ = false;
      units_ = u;
      since_ = now;
      return false;
    }
    if (warned_ || now - since_ < after_) return false;
    warned_ = true;
    return true;
  }
  [[nodiscard]] TimeNs silent_for(TimeNs now) const noexcept { return now - since_; }

 private:
  TimeNs after_;
  TimeNs since_{0};
  std::uint64_t units_{0};
  bool armed_{false}, warned_{false};
};

}  // namespace ag
