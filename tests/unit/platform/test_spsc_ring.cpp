// SpscRing on one thread: capacity, FIFO order across wrap-arounds, in-place use and element lifetimes.
#include "airground/platform/spsc_ring.hpp"

#include <gtest/gtest.h>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <type_traits>
#include <utility>

namespace ag {
namespace {

// Counts constructions and destructions so every element the ring made is shown to be destroyed.
struct Counted {
  static inline int constructed = 0;
  static inline int destroyed = 0;
  static void reset() { constructed = destroyed = 0; }

  explicit Counted(int v) noexcept : value(v) { ++constructed; }
  Counted(const Counted& o) noexcept : value(o.value) { ++constructed; }
  Counted(Counted&& o) noexcept : value(o.value) { ++constructed; }
  Counted& operator=(const Counted&) = delete;
  ~Counted() { ++destroyed; }
  int value;
};

// Built in place from several arguments; neither copyable nor movable, so only try_emplace can make it.
struct Pinned {
  Pinned(int a, std::string b) noexcept : x(a), s(std::move(b)) {}
  Pinned(const Pinned&) = delete;
  Pinned& operator=(const Pinned&) = delete;
  int x;
  std::string s;
};

// The consumer's contract: pop() only after front() returned an element.
template <typename Ring>
void pop_one(Ring& r) {
  ASSERT_NE(r.front(), nullptr);
  r.pop();
}

TEST(SpscRing, CapacityIsTheTemplateArgument) {
  static_assert(SpscRing<int, 8>::capacity() == 8);
  static_assert(SpscRing<int, 1024>::capacity() == 1024);
  SpscRing<int, 16> r;
  EXPECT_EQ(r.capacity(), 16u);
}

TEST(SpscRing, NewRingIsEmpty) {
  SpscRing<int, 4> r;
  EXPECT_TRUE(r.empty());
  EXPECT_EQ(r.size(), 0u);
  EXPECT_EQ(r.front(), nullptr);
}

TEST(SpscRing, EverySlotIsUsableAndTheNextPushIsRefused) {
  SpscRing<int, 8> r;
  for (int i = 0; i < 8; ++i) {
    const bool pushed = r.try_push(i);
    ASSERT_TRUE(pushed) << "slot " << i;
    EXPECT_EQ(r.size(), static_cast<std::size_t>(i + 1));
  }
  const bool overflow = r.try_push(99);
  EXPECT_FALSE(overflow);
  EXPECT_EQ(r.size(), 8u);
  // The refused push left the ring untouched: the contents are still 0..7.
  for (int i = 0; i < 8; ++i) {
    const int* f = r.front();
    ASSERT_NE(f, nullptr);
    EXPECT_EQ(*f, i);
    r.pop();
  }
  EXPECT_TRUE(r.empty());
}

TEST(SpscRing, CapacityNeedNotBeAPowerOfTwo) {
  SpscRing<int, 5> r;
  for (int round = 0; round < 50; ++round) {  // across wrap-arounds of the underlying slot array
    for (int i = 0; i < 5; ++i) ASSERT_TRUE(r.try_push(round * 5 + i));
    EXPECT_FALSE(r.try_push(-1));
    EXPECT_EQ(r.size(), 5u);
    for (int i = 0; i < 5; ++i) {
      const int* f = r.front();
      ASSERT_NE(f, nullptr);
      ASSERT_EQ(*f, round * 5 + i);
      r.pop();
    }
  }
  SpscRing<int, 1> one;
  ASSERT_TRUE(one.try_push(1));
  EXPECT_FALSE(one.try_push(2));
  pop_one(one);
  EXPECT_TRUE(one.try_push(3));
}

TEST(SpscRing, PopFreesASlotForTheNextPush) {
  SpscRing<int, 4> r;
  for (int i = 0; i < 4; ++i) ASSERT_TRUE(r.try_push(i));
  ASSERT_FALSE(r.try_push(4));
  ASSERT_NE(r.front(), nullptr);
  r.pop();
  EXPECT_TRUE(r.try_push(4));
  EXPECT_FALSE(r.try_push(5));
}

TEST(SpscRing, KeepsFifoOrderAcrossManyWrapArounds) {
  SpscRing<std::uint64_t, 8> r;
  std::uint64_t next_in = 0;
  std::uint64_t next_out = 0;
  // Varying fill levels so the read and write positions meet the wrap point at every offset.
  for (int round = 0; round < 10'000; ++round) {
    const int burst = 1 + round % 8;
    for (int i = 0; i < burst; ++i) {
      if (!r.try_push(next_in)) break;
      ++next_in;
    }
    const int drain = 1 + (round * 7) % 8;
    for (int i = 0; i < drain; ++i) {
      std::uint64_t* f = r.front();
      if (f == nullptr) break;
      ASSERT_EQ(*f, next_out);
      ++next_out;
      r.pop();
    }
    ASSERT_EQ(r.size(), next_in - next_out);
  }
  while (std::uint64_t* f = r.front()) {
    ASSERT_EQ(*f, next_out++);
    r.pop();
  }
  EXPECT_EQ(next_out, next_in);
  EXPECT_GT(next_in, 8u * 1000u);  // wrapped many times
}

TEST(SpscRing, SizeFullAndEmptyTrackPushesAndPops) {
  SpscRing<int, 4> r;
  EXPECT_TRUE(r.empty());
  ASSERT_TRUE(r.try_push(1));
  EXPECT_FALSE(r.empty());
  EXPECT_EQ(r.size(), 1u);
  ASSERT_TRUE(r.try_push(2));
  ASSERT_TRUE(r.try_push(3));
  ASSERT_TRUE(r.try_push(4));
  EXPECT_EQ(r.size(), r.capacity());
  pop_one(r);
  EXPECT_EQ(r.size(), 3u);
  pop_one(r);
  pop_one(r);
  pop_one(r);
  EXPECT_TRUE(r.empty());
  EXPECT_EQ(r.front(), nullptr);
}

TEST(SpscRing, FrontGivesTheOldestElementInPlaceUntilPop) {
  struct Frame {
    std::uint32_t seq;
    std::uint8_t pixels[256];
  };
  SpscRing<Frame, 4> r;
  ASSERT_TRUE(r.try_emplace(Frame{7, {}}));
  ASSERT_TRUE(r.try_emplace(Frame{8, {}}));
  Frame* f = r.front();
  ASSERT_NE(f, nullptr);
  EXPECT_EQ(f->seq, 7u);
  // Repeated front() without pop() is the same element at the same address, and may be modified.
  f->pixels[10] = 42;
  Frame* again = r.front();
  ASSERT_EQ(again, f);
  EXPECT_EQ(again->pixels[10], 42);
  r.pop();
  Frame* next = r.front();
  ASSERT_NE(next, nullptr);
  EXPECT_EQ(next->seq, 8u);
}

TEST(SpscRing, EveryConstructedElementIsDestroyedAfterPops) {
  Counted::reset();
  {
    SpscRing<Counted, 8> r;
    for (int round = 0; round < 100; ++round) {
      for (int i = 0; i < 5; ++i) ASSERT_TRUE(r.try_emplace(round * 10 + i));
      for (int i = 0; i < 5; ++i) {
        const Counted* f = r.front();
        ASSERT_NE(f, nullptr);
        ASSERT_EQ(f->value, round * 10 + i);
        r.pop();
      }
    }
    EXPECT_EQ(Counted::constructed, 500);
    EXPECT_EQ(Counted::destroyed, 500);
  }
  EXPECT_EQ(Counted::constructed, Counted::destroyed);
}

TEST(SpscRing, DestroyingANonEmptyRingDestroysWhatIsLeft) {
  Counted::reset();
  {
    SpscRing<Counted, 8> r;
    for (int i = 0; i < 6; ++i) ASSERT_TRUE(r.try_emplace(i));
    pop_one(r);
    EXPECT_EQ(Counted::destroyed, 1);
  }
  EXPECT_EQ(Counted::constructed, 6);
  EXPECT_EQ(Counted::destroyed, 6);
}

TEST(SpscRing, RefusedPushConstructsNothing) {
  Counted::reset();
  {
    SpscRing<Counted, 2> r;
    ASSERT_TRUE(r.try_emplace(1));
    ASSERT_TRUE(r.try_emplace(2));
    EXPECT_FALSE(r.try_emplace(3));
    EXPECT_EQ(Counted::constructed, 2);
  }
  EXPECT_EQ(Counted::destroyed, 2);
}

TEST(SpscRing, CopyPushCopiesAndMovePushMoves) {
  Counted::reset();
  {
    SpscRing<Counted, 4> r;
    const Counted a(1);
    ASSERT_TRUE(r.try_push(a));
    ASSERT_TRUE(r.try_push(Counted(2)));
    const Counted* f = r.front();
    ASSERT_NE(f, nullptr);
    EXPECT_EQ(f->value, 1);
    r.pop();
    f = r.front();
    ASSERT_NE(f, nullptr);
    EXPECT_EQ(f->value, 2);
  }
  EXPECT_EQ(Counted::constructed, Counted::destroyed);
}

TEST(SpscRing, MoveOnlyTypesWork) {
  static_assert(!std::is_copy_constructible_v<std::unique_ptr<int>>);
  SpscRing<std::unique_ptr<int>, 4> r;
  for (int round = 0; round < 10; ++round) {
    for (int i = 0; i < 4; ++i) ASSERT_TRUE(r.try_push(std::make_unique<int>(round * 4 + i)));
    auto extra = std::make_unique<int>(-1);
    EXPECT_FALSE(r.try_push(std::move(extra)));
    for (int i = 0; i < 4; ++i) {
      std::unique_ptr<int>* f = r.front();
      ASSERT_NE(f, nullptr);
      ASSERT_NE(*f, nullptr);
      const std::unique_ptr<int> taken = std::move(*f);  // the consumer may take ownership before pop()
      r.pop();
      EXPECT_EQ(*taken, round * 4 + i);
    }
  }
  // Left non-empty on purpose: the destructor must release these (LeakSanitizer checks it).
  ASSERT_TRUE(r.try_push(std::make_unique<int>(1)));
  ASSERT_TRUE(r.try_push(std::make_unique<int>(2)));
}

TEST(SpscRing, TryEmplaceConstructsInPlaceFromArguments) {
  SpscRing<Pinned, 4> r;
  ASSERT_TRUE(r.try_emplace(3, "three"));
  ASSERT_TRUE(r.try_emplace(4, std::string(40, 'x')));  // heap-sized string, released by pop()/destructor
  const Pinned* first = r.front();
  ASSERT_NE(first, nullptr);
  EXPECT_EQ(first->x, 3);
  EXPECT_EQ(first->s, "three");
  r.pop();
  const Pinned* second = r.front();
  ASSERT_NE(second, nullptr);
  EXPECT_EQ(second->x, 4);
  EXPECT_EQ(second->s.size(), 40u);
}

TEST(SpscRing, OverAlignedElementsAreAligned) {
  struct alignas(64) Wide {
    std::uint64_t v;
  };
  SpscRing<Wide, 8> r;
  for (std::uint64_t i = 0; i < 8; ++i) ASSERT_TRUE(r.try_push(Wide{i}));
  for (std::uint64_t i = 0; i < 8; ++i) {
    Wide* f = r.front();
    ASSERT_NE(f, nullptr);
    EXPECT_EQ(reinterpret_cast<std::uintptr_t>(f) % 64, 0u);
    EXPECT_EQ(f->v, i);
    r.pop();
  }
}

TEST(SpscRing, PushResultsMustBeChecked) {
  // try_push/try_emplace are [[nodiscard]]: ignoring them would not compile with -Werror. What can be
  // checked here is that the result is a bool the caller has to look at.
  SpscRing<int, 2> r;
  static_assert(std::is_same_v<decltype(r.try_push(1)), bool>);
  static_assert(std::is_same_v<decltype(r.try_emplace(1)), bool>);
  static_assert(noexcept(r.try_push(1)));
  static_assert(noexcept(r.front()));
  static_assert(noexcept(r.pop()));
  EXPECT_TRUE(r.try_push(1));
}

}  // namespace
}  // namespace ag
