// Histogram bucketing and snapshots of the scheduler counters.
#include "airground/platform/perf_counters.hpp"

#include <algorithm>
#include <bit>
#include <cmath>

namespace ag {

std::size_t DurationHistogram::bucket_of(std::uint64_t v) noexcept {
  if (v < kSub) return static_cast<std::size_t>(v);
  const int msb = 63 - std::countl_zero(v);
  const int shift = msb - kSubBits;
  const std::size_t idx = static_cast<std::size_t>(shift) * kSub + static_cast<std::size_t>(v >> shift);
  return std::min(idx, kBuckets - 1);
}

std::uint64_t DurationHistogram::bucket_upper(std::size_t idx) noexcept {
  if (idx < 2 * kSub) return idx + 1;
  const std::size_t shift = idx / kSub - 1;
  const std::uint64_t mantissa = idx - shift * kSub;
  return (mantissa + 1) << shift;
}

void DurationHistogram::record(TimeNs d) noexcept {
  if (d < 0) d = 0;
  auto& b = bins_[bucket_of(static_cast<std::uint64_t>(d))];
  b.store(b.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
  count_.store(count_.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
  if (d < min_.load(std::memory_order_relaxed)) min_.store(d, std::memory_order_relaxed);
  if (d > max_.load(std::memory_order_relaxed)) max_.store(d, std::memory_order_relaxed);
}

void DurationHistogram::reset() noexcept {
  for (auto& b : bins_) b.store(0, std::memory_order_relaxed);
  count_.store(0, std::memory_order_relaxed);
  min_.store(std::numeric_limits<TimeNs>::max(), std::memory_order_relaxed);
  max_.store(0, std::memory_order_relaxed);
}

TimeNs DurationHistogram::min() const noexcept {
  const TimeNs m = min_.load(std::memory_order_relaxed);
  return m == std::numeric_limits<TimeNs>::max() ? 0 : m;
}

TimeNs DurationHistogram::quantile(double q) const noexcept {
  const std::uint64_t n = count();
  if (n == 0) return 0;
  q = std::clamp(q, 0.0, 1.0);
  const auto rank = std::max<std::uint64_t>(1, static_cast<std::uint64_t>(std::ceil(q * static_cast<double>(n))));
  std::uint64_t seen = 0;
  for (std::size_t i = 0; i < kBuckets; ++i) {
    seen += bins_[i].load(std::memory_order_relaxed);
    if (seen >= rank) {
      const auto upper = static_cast<TimeNs>(bucket_upper(i));
      return std::clamp(upper, min(), max());
    }
  }
  return max();
}

StagePerfSnapshot snapshot(const StagePerf& p) noexcept {
  return StagePerfSnapshot{
      p.runs.load(std::memory_order_relaxed), p.overruns.load(std::memory_order_relaxed),
      p.slips.load(std::memory_order_relaxed), p.exec.min(), p.exec.quantile(0.5), p.exec.quantile(0.99),
      p.exec.max(), p.lateness.quantile(0.5), p.lateness.quantile(0.99), p.lateness.max(), p.budget_ns,
      p.period_ns};
}

StagePerf& PerfRegistry::add(std::string name, TimeNs budget_ns, TimeNs period_ns) {
  auto p = std::make_unique<StagePerf>();
  p->name = std::move(name);
  p->budget_ns = budget_ns;
  p->period_ns = period_ns;
  perf_.push_back(std::move(p));
  return *perf_.back();
}

const StagePerf* PerfRegistry::find(std::string_view name) const noexcept {
  for (const auto& p : perf_)
    if (p->name == name) return p.get();
  return nullptr;
}

}  // namespace ag
