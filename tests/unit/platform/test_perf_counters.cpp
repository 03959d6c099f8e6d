// DurationHistogram and StagePerf: bucket edges, quantile accuracy, exact extremes, snapshots.
#include "airground/platform/perf_counters.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace ag {
namespace {

using H = DurationHistogram;

// Every value lands in a bucket whose upper edge is above it and whose lower edge (the previous
// bucket's upper edge) is at or below it.
void expect_bucket_holds(std::uint64_t v) {
  const std::size_t idx = H::bucket_of(v);
  ASSERT_LT(idx, H::kBuckets) << "v=" << v;
  ASSERT_GT(H::bucket_upper(idx), v) << "v=" << v << " idx=" << idx;
  if (idx > 0) {
    ASSERT_LE(H::bucket_upper(idx - 1), v) << "v=" << v << " idx=" << idx;
  }
}

TEST(DurationHistogram, EveryValueBelowOneHundredThousandLandsInTheRightBucket) {
  for (std::uint64_t v = 0; v < 100'000; ++v) expect_bucket_holds(v);
}

TEST(DurationHistogram, BucketEdgesHoldAcrossTheWholeRange) {
  std::mt19937_64 rng(12345);
  for (int k = 1; k < 41; ++k) {
    const std::uint64_t p = std::uint64_t{1} << k;
    for (std::uint64_t v : {p - 1, p, p + 1}) expect_bucket_holds(v);
    std::uniform_int_distribution<std::uint64_t> in_octave(p, 2 * p - 1);
    for (int i = 0; i < 2000; ++i) expect_bucket_holds(in_octave(rng));
  }
  expect_bucket_holds((std::uint64_t{1} << 41) - 1);
}

TEST(DurationHistogram, BucketEdgesRiseStrictlyAndAreAtMostThreePercentApart) {
  for (std::size_t i = 1; i < H::kBuckets; ++i) {
    const std::uint64_t lo = H::bucket_upper(i - 1);
    const std::uint64_t hi = H::bucket_upper(i);
    ASSERT_GT(hi, lo) << "idx=" << i;
    if (lo >= H::kSub) {
      ASSERT_LE(static_cast<double>(hi - lo) / static_cast<double>(lo), 1.0 / 32.0 + 1e-12) << "idx=" << i;
    }
  }
  EXPECT_EQ(H::bucket_upper(H::kBuckets - 1), std::uint64_t{1} << 41);
}

TEST(DurationHistogram, ValuesBeyondTheRangeGoToTheLastBucketWithoutOverflow) {
  EXPECT_EQ(H::bucket_of(std::uint64_t{1} << 41), H::kBuckets - 1);
  EXPECT_EQ(H::bucket_of(std::numeric_limits<std::uint64_t>::max()), H::kBuckets - 1);
  H h;
  h.record(std::numeric_limits<TimeNs>::max());
  EXPECT_EQ(h.count(), 1u);
  EXPECT_EQ(h.max(), std::numeric_limits<TimeNs>::max());
}

TEST(DurationHistogram, EmptyHistogramReportsZeros) {
  H h;
  EXPECT_EQ(h.count(), 0u);
  EXPECT_EQ(h.min(), 0);
  EXPECT_EQ(h.max(), 0);
  EXPECT_EQ(h.quantile(0.5), 0);
  EXPECT_EQ(h.quantile(0.99), 0);
}

TEST(DurationHistogram, MinAndMaxAreExact) {
  H h;
  for (TimeNs v : {TimeNs{987'654'321}, TimeNs{12'345}, TimeNs{5'000'000}, TimeNs{12'346}, TimeNs{987'654'320}})
    h.record(v);
  EXPECT_EQ(h.min(), 12'345);
  EXPECT_EQ(h.max(), 987'654'321);
  EXPECT_EQ(h.quantile(1.0), 987'654'321);  // the top quantile is clamped to the exact maximum
  EXPECT_GE(h.quantile(0.0), 12'345);
  EXPECT_EQ(h.count(), 5u);
}

TEST(DurationHistogram, NegativeDurationsCountAsZero) {
  H h;
  h.record(-5);
  EXPECT_EQ(h.count(), 1u);
  EXPECT_EQ(h.min(), 0);
  EXPECT_EQ(h.max(), 0);
}

TEST(DurationHistogram, SingleValueGivesThatValueAtEveryQuantile) {
  H h;
  for (int i = 0; i < 10; ++i) h.record(777'777);
  for (double q : {0.0, 0.01, 0.5, 0.99, 1.0}) EXPECT_EQ(h.quantile(q), 777'777) << "q=" << q;
}

TEST(DurationHistogram, ResetForgetsEverything) {
  H h;
  h.record(100);
  h.record(1'000'000);
  h.reset();
  EXPECT_EQ(h.count(), 0u);
  EXPECT_EQ(h.min(), 0);
  EXPECT_EQ(h.max(), 0);
  EXPECT_EQ(h.quantile(0.5), 0);
  h.record(42);
  EXPECT_EQ(h.min(), 42);
  EXPECT_EQ(h.max(), 42);
}

// The histogram's answer is the upper edge of the bucket holding the exact order statistic: never
// below it, and at most one bucket width (1/32) above.
void expect_quantiles_close(const H& h, std::vector<TimeNs> values) {
  std::sort(values.begin(), values.end());
  const auto n = static_cast<double>(values.size());
  for (double q : {0.01, 0.1, 0.25, 0.5, 0.75, 0.9, 0.99, 0.999}) {
    const auto rank = static_cast<std::size_t>(std::max(1.0, std::ceil(q * n)));
    const TimeNs exact = values[rank - 1];
    const TimeNs got = h.quantile(q);
    const double rel = static_cast<double>(got - exact) / static_cast<double>(exact);
    EXPECT_GE(rel, 0.0) << "q=" << q << " exact=" << exact << " got=" << got;
    EXPECT_LE(rel, 0.035) << "q=" << q << " exact=" << exact << " got=" << got;
  }
  EXPECT_EQ(h.min(), values.front());
  EXPECT_EQ(h.max(), values.back());
  EXPECT_EQ(h.count(), values.size());
}

TEST(DurationHistogram, QuantilesOfAUniformDistributionAreWithinThreeAndAHalfPercent) {
  H h;
  std::vector<TimeNs> values;
  for (TimeNs v = 1'000; v <= 2'000'000; v += 7) {
    h.record(v);
    values.push_back(v);
  }
  expect_quantiles_close(h, values);
}

TEST(DurationHistogram, QuantilesOfALogUniformDistributionAreWithinThreeAndAHalfPercent) {
  H h;
  std::vector<TimeNs> values;
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> exponent(std::log(1e3), std::log(1e9));  // 1 µs .. 1 s
  for (int i = 0; i < 200'000; ++i) {
    const auto v = static_cast<TimeNs>(std::exp(exponent(rng)));
    h.record(v);
    values.push_back(v);
  }
  expect_quantiles_close(h, values);
}

TEST(DurationHistogram, QuantilesOfATwoModeStepTimeDistributionFindTheTail) {
  // Typical step times: most near 200 µs, 2% near 5 ms (a slow path): p50 is in the bulk, p99 in the tail.
  H h;
  std::vector<TimeNs> values;
  std::mt19937_64 rng(99);
  std::normal_distribution<double> bulk(200'000.0, 10'000.0);
  std::normal_distribution<double> tail(5'000'000.0, 100'000.0);
  for (int i = 0; i < 100'000; ++i) {
    const auto v = static_cast<TimeNs>(i % 50 == 0 ? tail(rng) : bulk(rng));
    h.record(v);
    values.push_back(v);
  }
  expect_quantiles_close(h, values);
  EXPECT_LT(h.quantile(0.5), 300'000);
  EXPECT_GT(h.quantile(0.99), 4'000'000);
}

TEST(StagePerf, SnapshotCarriesCountersQuantilesAndBudget) {
  StagePerf p;
  p.budget_ns = 1'000'000;
  p.period_ns = 100'000'000;
  for (int i = 1; i <= 100; ++i) {
    p.exec.record(i * 10'000);
    p.lateness.record(i * 100);
    p.count(p.runs);
  }
  p.count(p.overruns, 3);
  p.count(p.slips);
  const StagePerfSnapshot s = snapshot(p);
  EXPECT_EQ(s.runs, 100u);
  EXPECT_EQ(s.overruns, 3u);
  EXPECT_EQ(s.slips, 1u);
  EXPECT_EQ(s.exec_min, 10'000);
  EXPECT_EQ(s.exec_max, 1'000'000);
  EXPECT_NEAR(static_cast<double>(s.exec_p50), 500'000.0, 500'000.0 * 0.035);
  EXPECT_NEAR(static_cast<double>(s.exec_p99), 990'000.0, 990'000.0 * 0.035);
  EXPECT_EQ(s.late_max, 10'000);
  EXPECT_EQ(s.budget_ns, 1'000'000);
  EXPECT_EQ(s.period_ns, 100'000'000);
}

TEST(PerfRegistry, FindsCountersByNameAndKeepsTheirAddressesStable) {
  PerfRegistry reg;
  StagePerf& first = reg.add("camera", 1'000, 100'000);
  for (int i = 0; i < 64; ++i) (void)reg.add("stage" + std::to_string(i), 10, 1'000);
  EXPECT_EQ(reg.size(), 65u);
  EXPECT_EQ(&reg.at(0), &first);  // executors hold this pointer for the life of the robot
  EXPECT_EQ(reg.find("camera"), &first);
  EXPECT_EQ(reg.find("stage63"), &reg.at(64));
  EXPECT_EQ(reg.find("nope"), nullptr);
  EXPECT_EQ(first.budget_ns, 1'000);
  EXPECT_EQ(first.period_ns, 100'000);
}

}  // namespace
}  // namespace ag
