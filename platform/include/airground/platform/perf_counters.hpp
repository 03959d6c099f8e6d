// Per-stage scheduler counters: execution-time and lateness histograms, overruns and slips.
#pragma once

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>
#include <memory>

#include "airground/platform/device_counters.hpp"
#include "airground/platform/time.hpp"

namespace ag {

// Log-linear histogram of durations in ns (32 sub-buckets per octave, ~3% resolution, up to ~18 min).
// One writer (the executor thread that runs the stage); readers on any thread see a consistent-enough
// view through relaxed atomics. Fixed size: recording never allocates.
class DurationHistogram {
 public:
  static constexpr int kSubBits = 5;
  static constexpr std::uint64_t kSub = 1u << kSubBits;
  static constexpr std::size_t kBuckets = 37 * kSub;  // up to 2^41 ns

  void record(TimeNs d) noexcept;
  void reset() noexcept;
  [[nodiscard]] std::uint64_t count() const noexcept { return count_.load(std::memory_order_relaxed); }
  [[nodiscard]] TimeNs min() const noexcept;
  [[nodiscard]] TimeNs max() const noexcept { return max_.load(std::memory_order_relaxed); }
  // Value at quantile q in [0,1]: the upper edge of the bucket holding that rank, clamped to max().
  [[nodiscard]] TimeNs quantile(double q) const noexcept;

  static std::size_t bucket_of(std::uint64_t v) noexcept;
  static std::uint64_t bucket_upper(std::size_t idx) noexcept;  // exclusive upper edge

 private:
  std::array<std::atomic<std::uint32_t>, kBuckets> bins_{};
  std::atomic<std::uint64_t> count_{0};
  std::atomic<TimeNs> min_{std::numeric_limits<TimeNs>::max()};
  std::atomic<TimeNs> max_{0};
};

struct StagePerf {
  std::string name;          // "<instance>/<stage>" in lockstep teams, "<stage>" on a robot
  TimeNs budget_ns{0};
  TimeNs period_ns{0};
  DurationHistogram exec;      // step() execution time
  DurationHistogram lateness;  // release-to-start delay (wake-up lateness)
  std::atomic<std::uint64_t> runs{0};
  std::atomic<std::uint64_t> overruns{0};  // step() took longer than its budget
  std::atomic<std::uint64_t> slips{0};     // whole releases skipped because the stage started a period late
  std::atomic<TimeNs> exec_total{0};       // sum of every step()'s execution time (one writer, like the rest)
  DeviceCounters device;                   // what a device stage received (inactive for the others)

  void count(std::atomic<std::uint64_t>& c, std::uint64_t n = 1) noexcept {
    c.store(c.load(std::memory_order_relaxed) + n, std::memory_order_relaxed);
  }
};

struct StagePerfSnapshot {
  std::uint64_t runs, overruns, slips;
  TimeNs exec_min, exec_p50, exec_p99, exec_max;
  TimeNs late_p50, late_p99, late_max;
  TimeNs budget_ns, period_ns;
};
[[nodiscard]] StagePerfSnapshot snapshot(const StagePerf& p) noexcept;

// Owns every stage's counters; filled at start-up, read by the status stage and the reports.
class PerfRegistry {
 public:
  StagePerf& add(std::string name, TimeNs budget_ns, TimeNs period_ns);
  [[nodiscard]] std::size_t size() const noexcept { return perf_.size(); }
  [[nodiscard]] const StagePerf& at(std::size_t i) const noexcept { return *perf_[i]; }
  [[nodiscard]] StagePerf& at(std::size_t i) noexcept { return *perf_[i]; }
  [[nodiscard]] const StagePerf* find(std::string_view name) const noexcept;

 private:
  std::vector<std::unique_ptr<StagePerf>> perf_;
};

}  // namespace ag
