// LatestValue on one thread: initial value, newest-wins, fresh() and writing in place.
#include "airground/platform/latest_value.hpp"

#include <gtest/gtest.h>

#include <array>
#include <cstdint>

namespace ag {
namespace {

struct Pose {
  double x{0}, y{0};
  std::int64_t stamp{0};
};

TEST(LatestValue, DefaultConstructedReaderSeesAValueInitialisedT) {
  LatestValue<Pose> lv;
  const Pose& p = lv.read();
  EXPECT_EQ(p.x, 0.0);
  EXPECT_EQ(p.stamp, 0);
  EXPECT_FALSE(lv.fresh());
  EXPECT_EQ(lv.published(), 0u);
}

TEST(LatestValue, ReaderSeesTheInitialValueBeforeAnyWrite) {
  LatestValue<int> lv(17);
  EXPECT_FALSE(lv.fresh());
  EXPECT_EQ(lv.read(), 17);
  EXPECT_EQ(lv.read(), 17);
}

TEST(LatestValue, ReaderSeesTheNewestOfSeveralWrites) {
  LatestValue<int> lv(0);
  lv.write(1);
  lv.write(2);
  lv.write(3);
  EXPECT_TRUE(lv.fresh());
  EXPECT_EQ(lv.read(), 3);  // 1 and 2 were overwritten, never seen
  EXPECT_EQ(lv.published(), 3u);
}

TEST(LatestValue, FreshIsSetByPublishAndClearedByRead) {
  LatestValue<int> lv(0);
  EXPECT_FALSE(lv.fresh());
  lv.write(5);
  EXPECT_TRUE(lv.fresh());
  EXPECT_TRUE(lv.fresh());  // asking does not consume it
  EXPECT_EQ(lv.read(), 5);
  EXPECT_FALSE(lv.fresh());
  EXPECT_EQ(lv.read(), 5);  // a read without a new write repeats the last value
  lv.write(6);
  EXPECT_TRUE(lv.fresh());
  EXPECT_EQ(lv.read(), 6);
  EXPECT_FALSE(lv.fresh());
}

TEST(LatestValue, ReadAlternatingWithWriteSeesEveryValue) {
  LatestValue<int> lv(-1);
  for (int i = 0; i < 1000; ++i) {
    lv.write(i);
    ASSERT_EQ(lv.read(), i);
  }
}

TEST(LatestValue, WriteSlotAndPublishWriteInPlace) {
  struct Big {
    std::array<std::uint32_t, 512> cells{};
    std::uint32_t seq{0};
  };
  LatestValue<Big> lv;
  for (std::uint32_t seq = 1; seq <= 10; ++seq) {
    Big& slot = lv.write_slot();
    slot.seq = seq;
    slot.cells[seq] = seq * 10;
    lv.publish();
  }
  const Big& b = lv.read();
  EXPECT_EQ(b.seq, 10u);
  EXPECT_EQ(b.cells[10], 100u);
}

TEST(LatestValue, WriteSlotIsNeverTheSlotTheReaderHolds) {
  LatestValue<int> lv(0);
  for (int i = 1; i < 50; ++i) {
    lv.write(i);
    const int& held = lv.read();
    ASSERT_EQ(held, i);
    // Whatever the writer does next (one or many publications), the value the reader holds stays put.
    lv.write_slot() = -1;
    lv.publish();
    lv.write_slot() = -2;
    EXPECT_EQ(held, i);
    EXPECT_NE(&lv.write_slot(), &held);
    lv.publish();
    EXPECT_EQ(held, i);
    EXPECT_EQ(lv.read(), -2);
  }
}

}  // namespace
}  // namespace ag
