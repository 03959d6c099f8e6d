// LatestValue across two threads: every value read is whole (never torn) and never older than the last.
#include <gtest/gtest.h>

#include <array>
#include <atomic>
#include <cstdint>
#include <string>
#include <thread>

#include "airground/platform/latest_value.hpp"
#include "stress_env.hpp"

namespace ag {
namespace {

struct Sample {
  std::uint64_t seq{0};
  std::uint64_t triple{0};  // seq * 3
  std::uint64_t inverse{~std::uint64_t{0}};  // ~seq
  [[nodiscard]] bool whole() const noexcept { return triple == seq * 3 && inverse == ~seq; }
};

// Several cache lines, so a slot handed over before it is fully written would show.
struct WideSample {
  std::uint64_t seq{0};
  std::array<std::uint64_t, 31> words{};  // words[k] = mix(seq + k)
};

TEST(LatestValueStress, ReaderNeverSeesATornValueOrGoesBackwards) {
  const std::uint64_t n = test::stress_items(10'000'000) / 2;
  LatestValue<Sample> lv;
  std::thread writer([&] {
    for (std::uint64_t seq = 1; seq <= n; ++seq) {
      if (seq % 2 == 0) {
        lv.write(Sample{seq, seq * 3, ~seq});
      } else {  // the in-place path
        Sample& s = lv.write_slot();
        s.seq = seq;
        s.triple = seq * 3;
        s.inverse = ~seq;
        lv.publish();
      }
    }
  });
  std::uint64_t last = 0;
  std::uint64_t reads = 0;
  std::uint64_t distinct = 0;
  std::uint64_t torn = 0;
  std::uint64_t backwards = 0;
  test::Backoff b;
  while (last < n) {
    const Sample& s = lv.read();
    ++reads;
    if (!s.whole()) {
      ++torn;
      break;
    }
    if (s.seq < last) {
      ++backwards;
      break;
    }
    if (s.seq != last) {
      ++distinct;
      b.reset();
    } else {
      b.pause();
    }
    last = s.seq;
  }
  writer.join();
  EXPECT_EQ(torn, 0u);
  EXPECT_EQ(backwards, 0u);
  EXPECT_EQ(last, n);  // the final value always arrives
  EXPECT_GE(distinct, 1u);
  EXPECT_EQ(lv.published(), n);
  RecordProperty("reads", std::to_string(reads));
  RecordProperty("distinct_values_seen", std::to_string(distinct));
}

TEST(LatestValueStress, WideValuesAreAlwaysWholeAndFreshAgreesWithRead) {
  const std::uint64_t n = test::stress_items(10'000'000) / 20;
  LatestValue<WideSample> lv;
  std::thread writer([&] {
    for (std::uint64_t seq = 1; seq <= n; ++seq) {
      WideSample& w = lv.write_slot();
      w.seq = seq;
      for (std::size_t k = 0; k < w.words.size(); ++k) w.words[k] = test::mix(seq + k);
      lv.publish();
    }
  });
  std::uint64_t last = 0;
  std::uint64_t bad = 0;
  test::Backoff b;
  while (last < n && bad == 0) {
    const bool was_fresh = lv.fresh();
    const WideSample& w = lv.read();
    bool whole = true;
    for (std::size_t k = 0; k < w.words.size(); ++k) whole = whole && w.words[k] == test::mix(w.seq + k);
    if (w.seq == 0) whole = true;  // the initial value before the first publication
    if (!whole || w.seq < last) bad = w.seq == 0 ? 1 : w.seq;
    // fresh() seen true means a newer value was waiting, so the read must have moved forward.
    if (was_fresh && w.seq == last) bad = last == 0 ? 1 : last;
    if (w.seq == last) b.pause();
    last = w.seq;
  }
  writer.join();
  EXPECT_EQ(bad, 0u) << "value " << bad << " was torn, stale or went backwards";
  EXPECT_EQ(last, n);
}

}  // namespace
}  // namespace ag
