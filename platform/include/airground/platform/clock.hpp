// Clocks: stages and executors read time only through these, never from the system directly.
#pragma once

#include <atomic>

#include "airground/platform/time.hpp"

namespace ag {

class Clock {
 public:
  virtual ~Clock() = default;
  [[nodiscard]] virtual TimeNs now() const noexcept = 0;
};

// CLOCK_MONOTONIC: what the robots run on.
class MonotonicClock final : public Clock {
 public:
  [[nodiscard]] TimeNs now() const noexcept override;
  // Absolute-deadline sleep on CLOCK_MONOTONIC; returns early only on a signal.
  static void sleep_until(TimeNs deadline) noexcept;
};

// Simulated time, advanced only by the lockstep executor (or a test).
class SimClock final : public Clock {
 public:
  explicit SimClock(TimeNs start = 0) noexcept : now_(start) {}
  [[nodiscard]] TimeNs now() const noexcept override { return now_.load(std::memory_order_relaxed); }
  void set(TimeNs t) noexcept { now_.store(t, std::memory_order_relaxed); }

 private:
  std::atomic<TimeNs> now_;
};

// CPU time consumed by the calling thread: what budgets are measured in where machines are shared.
[[nodiscard]] TimeNs thread_cpu_now() noexcept;
[[nodiscard]] TimeNs monotonic_now() noexcept;

}  // namespace ag
