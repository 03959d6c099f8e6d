// SpscRing across two threads: millions of items through a small ring arrive complete and in order.
#include <gtest/gtest.h>

#include <array>
#include <atomic>
#include <cstdint>
#include <thread>

#include "airground/platform/spsc_ring.hpp"
#include "stress_env.hpp"

namespace ag {
namespace {

using test::Backoff;
using test::mix;

struct Item {
  std::uint64_t seq;
  std::uint64_t payload;  // mix(seq)
};

// A message several cache lines long, so a slot published before it is fully written would show.
struct Fat {
  std::uint64_t seq;
  std::array<std::uint64_t, 23> words;  // words[k] = mix(seq + k)
};

struct Tally {
  std::uint64_t count{0};
  std::uint64_t sum{0};
  std::uint64_t xr{0};
  void add(std::uint64_t v) noexcept {
    ++count;
    sum += v;
    xr ^= v;
  }
};

struct Outcome {
  Tally produced;
  Tally consumed;
  std::uint64_t first_bad_index{UINT64_MAX};
  std::uint64_t got_seq{0};
};

// The producer pushes 0..n-1 (spinning while full); the consumer checks strict order and the payload of
// every item in place, then pops. Either side gives up if the other reported a failure.
template <std::size_t Capacity>
Outcome run_items(std::uint64_t n) {
  SpscRing<Item, Capacity> ring;
  std::atomic<bool> failed{false};
  Outcome out;
  std::thread producer([&] {
    Backoff b;
    for (std::uint64_t i = 0; i < n; ++i) {
      const std::uint64_t v = mix(i);
      while (!ring.try_emplace(Item{i, v})) {
        if (failed.load(std::memory_order_relaxed)) return;
        b.pause();
      }
      b.reset();
      out.produced.add(v);
    }
  });
  Backoff b;
  for (std::uint64_t expect = 0; expect < n; ++expect) {
    Item* it = nullptr;
    while ((it = ring.front()) == nullptr) b.pause();
    b.reset();
    if (it->seq != expect || it->payload != mix(expect)) {
      out.first_bad_index = expect;
      out.got_seq = it->seq;
      failed.store(true, std::memory_order_relaxed);
      break;
    }
    out.consumed.add(it->payload);
    ring.pop();
  }
  producer.join();
  return out;
}

TEST(SpscRingStress, TwoThreadsPassEveryItemInOrderThroughASmallRing) {
  const std::uint64_t n = test::stress_items(10'000'000);
  const Outcome o = run_items<1024>(n);
  ASSERT_EQ(o.first_bad_index, UINT64_MAX) << "item " << o.first_bad_index << " arrived as seq " << o.got_seq;
  EXPECT_EQ(o.consumed.count, n);
  EXPECT_EQ(o.produced.count, n);
  EXPECT_EQ(o.consumed.sum, o.produced.sum);
  EXPECT_EQ(o.consumed.xr, o.produced.xr);
}

TEST(SpscRingStress, TinyRingSurvivesConstantFullAndEmptyTransitions) {
  // Every item is a hand-over between the threads here, slow when they share a core: fewer items.
  const std::uint64_t n = test::stress_items(10'000'000) / 100;
  const Outcome o = run_items<2>(n);
  ASSERT_EQ(o.first_bad_index, UINT64_MAX) << "item " << o.first_bad_index << " arrived as seq " << o.got_seq;
  EXPECT_EQ(o.consumed.count, n);
  EXPECT_EQ(o.consumed.sum, o.produced.sum);
  EXPECT_EQ(o.consumed.xr, o.produced.xr);
}

TEST(SpscRingStress, MultiCacheLineMessagesAreNeverSeenHalfWritten) {
  const std::uint64_t n = test::stress_items(10'000'000) / 10;
  SpscRing<Fat, 64> ring;
  std::atomic<bool> failed{false};
  std::thread producer([&] {
    Backoff b;
    for (std::uint64_t i = 0; i < n; ++i) {
      Fat f;
      f.seq = i;
      for (std::size_t k = 0; k < f.words.size(); ++k) f.words[k] = mix(i + k);
      while (!ring.try_push(f)) {
        if (failed.load(std::memory_order_relaxed)) return;
        b.pause();
      }
      b.reset();
    }
  });
  std::uint64_t bad = UINT64_MAX;
  Backoff b;
  for (std::uint64_t expect = 0; expect < n && bad == UINT64_MAX; ++expect) {
    Fat* f = nullptr;
    while ((f = ring.front()) == nullptr) b.pause();
    b.reset();
    bool whole = f->seq == expect;
    for (std::size_t k = 0; k < f->words.size(); ++k) whole = whole && f->words[k] == mix(expect + k);
    if (!whole) {
      bad = expect;
      failed.store(true, std::memory_order_relaxed);
    }
    ring.pop();
  }
  producer.join();
  EXPECT_EQ(bad, UINT64_MAX) << "message " << bad << " was torn or out of order";
}

}  // namespace
}  // namespace ag
