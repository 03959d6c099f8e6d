// ChannelRegistry: fan-out to every reader, one writer per channel, one type per name, sealed after init.
#include "airground/platform/channels.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <string>
#include <vector>

namespace ag {
namespace {

struct Odometry {
  std::int64_t sample_time_ns{0};
  double x{0}, y{0};
};

// A reader of a channel nobody writes (a misspelled name: "odometry" for "odom") would wait forever: the
// registry names it. A tap alone (a recorder) is not waiting, and a writer taken later (the simulator's
// devices) clears it.
TEST(Channels, AChannelReadButNeverWrittenIsNamed) {
  ChannelRegistry reg;
  auto w = reg.latest_writer<Odometry>("odom");
  auto r = reg.latest_reader<Odometry>("odometry");
  auto ring = reg.ring_reader<Odometry, 4>("scan");
  auto tap = reg.ring_tap<Odometry, 4>("tapped");
  auto fine = reg.latest_reader<Odometry>("odom");
  ASSERT_TRUE(w.ok() && r.ok() && ring.ok() && tap.ok() && fine.ok());
  reg.seal();
  EXPECT_EQ(reg.read_but_unwritten(), (std::vector<std::string>{"odometry", "scan"}));
  auto scan_w = reg.ring_writer<Odometry, 4>("scan");
  ASSERT_TRUE(scan_w.ok());
  EXPECT_EQ(reg.read_but_unwritten(), (std::vector<std::string>{"odometry"}));
  reg.allow_unwritten("odometry");  // an input the reader polls and some roles never write
  EXPECT_TRUE(reg.read_but_unwritten().empty());
}

TEST(Channels, LatestChannelFansOutToEveryReader) {
  ChannelRegistry reg;
  auto w = reg.latest_writer<Odometry>("odom");
  auto r1 = reg.latest_reader<Odometry>("odom");
  auto r2 = reg.latest_reader<Odometry>("odom");
  ASSERT_TRUE(w.ok() && r1.ok() && r2.ok());
  reg.seal();
  EXPECT_EQ(w.value().reader_count(), 2u);
  EXPECT_FALSE(r1.value().fresh());

  w.value().publish(Odometry{1, 2.0, 3.0});
  EXPECT_TRUE(r1.value().fresh());
  EXPECT_TRUE(r2.value().fresh());
  EXPECT_EQ(r1.value().read().sample_time_ns, 1);
  // Each reader has its own buffer: reading through one leaves the other's value fresh.
  EXPECT_FALSE(r1.value().fresh());
  EXPECT_TRUE(r2.value().fresh());

  w.value().publish(Odometry{2, 4.0, 6.0});
  w.value().publish(Odometry{3, 5.0, 7.0});
  EXPECT_EQ(r1.value().read().sample_time_ns, 3);
  EXPECT_EQ(r2.value().read().sample_time_ns, 3);
  EXPECT_DOUBLE_EQ(r2.value().read().y, 7.0);
}

TEST(Channels, RingChannelFansOutEveryMessageToEveryReader) {
  ChannelRegistry reg;
  auto w = reg.ring_writer<int, 8>("detections");
  auto r1 = reg.ring_reader<int, 8>("detections");
  auto r2 = reg.ring_reader<int, 8>("detections");
  ASSERT_TRUE(w.ok() && r1.ok() && r2.ok());
  reg.seal();
  for (int i = 0; i < 5; ++i) EXPECT_EQ(w.value().push(i), 0u);
  EXPECT_EQ(r1.value().size(), 5u);
  EXPECT_EQ(r2.value().size(), 5u);
  for (int i = 0; i < 5; ++i) {
    ASSERT_NE(r1.value().front(), nullptr);
    EXPECT_EQ(*r1.value().front(), i);
    r1.value().pop();
  }
  EXPECT_EQ(r1.value().front(), nullptr);
  EXPECT_EQ(r2.value().size(), 5u);  // draining one reader leaves the other's queue alone
  EXPECT_EQ(*r2.value().front(), 0);
}

TEST(Channels, AFullReaderRefusesOnlyItsOwnCopy) {
  ChannelRegistry reg;
  auto w = reg.ring_writer<int, 4>("q");
  auto slow = reg.ring_reader<int, 4>("q");
  auto fast = reg.ring_reader<int, 4>("q");
  ASSERT_TRUE(w.ok() && slow.ok() && fast.ok());
  for (int i = 0; i < 4; ++i) {
    EXPECT_EQ(w.value().push(i), 0u);
    ASSERT_NE(fast.value().front(), nullptr);  // pop() only after front() found an element
    fast.value().pop();
  }
  EXPECT_EQ(w.value().push(4), 1u);  // the slow reader is full
  EXPECT_EQ(fast.value().size(), 1u);
  EXPECT_EQ(*fast.value().front(), 4);
  EXPECT_EQ(slow.value().size(), 4u);
  EXPECT_EQ(*slow.value().front(), 0);
}

TEST(Channels, FreeSlotsIsTheFullestReadersRoom) {
  ChannelRegistry reg;
  auto w = reg.ring_writer<int, 4>("q");
  auto slow = reg.ring_reader<int, 4>("q");
  auto fast = reg.ring_reader<int, 4>("q");
  ASSERT_TRUE(w.ok() && slow.ok() && fast.ok());
  EXPECT_EQ(w.value().free_slots(), 4u);
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(w.value().push(i), 0u);
    ASSERT_NE(fast.value().front(), nullptr);
    fast.value().pop();
  }
  EXPECT_EQ(w.value().free_slots(), 1u) << "the slow reader holds 3 of 4";
  EXPECT_EQ(w.value().push(3), 0u);
  EXPECT_EQ(w.value().free_slots(), 0u);
  ASSERT_NE(slow.value().front(), nullptr);
  slow.value().pop();
  EXPECT_EQ(w.value().free_slots(), 1u);
}

// A recorder's tap: the producer's free_slots() ignores it, so a stalled tap loses messages (counted
// per reader) while the real reader keeps getting everything.
TEST(Channels, ATapNeverHoldsTheProducerBackAndCountsItsDrops) {
  ChannelRegistry reg;
  auto w = reg.ring_writer<int, 4>("q");
  auto reader = reg.ring_reader<int, 4>("q");
  auto tap = reg.ring_tap<int, 4>("q");
  ASSERT_TRUE(w.ok() && reader.ok() && tap.ok());
  for (int i = 0; i < 10; ++i) {
    EXPECT_EQ(w.value().free_slots(), 4u) << "the stalled tap must not count, message " << i;
    EXPECT_EQ(w.value().push(i), i < 4 ? 0u : 1u);
    ASSERT_NE(reader.value().front(), nullptr);
    EXPECT_EQ(*reader.value().front(), i);
    reader.value().pop();
  }
  EXPECT_EQ(reader.value().drops(), 0u);
  EXPECT_EQ(tap.value().drops(), 6u);
  EXPECT_EQ(tap.value().size(), 4u);
  EXPECT_EQ(*tap.value().front(), 0);
}

TEST(Channels, ReadersMaySubscribeBeforeTheWriterAdvertises) {
  ChannelRegistry reg;
  auto r = reg.latest_reader<int>("pose");
  auto rr = reg.ring_reader<int, 4>("events");
  auto w = reg.latest_writer<int>("pose");
  auto rw = reg.ring_writer<int, 4>("events");
  ASSERT_TRUE(r.ok() && rr.ok() && w.ok() && rw.ok());
  reg.seal();
  w.value().publish(9);
  EXPECT_EQ(r.value().read(), 9);
  EXPECT_EQ(rw.value().push(1), 0u);
  EXPECT_EQ(rr.value().size(), 1u);
  EXPECT_EQ(reg.size(), 2u);
}

TEST(Channels, WriterWithoutReadersPublishesIntoNothing) {
  ChannelRegistry reg;
  auto w = reg.latest_writer<int>("unused");
  auto rw = reg.ring_writer<int, 4>("unused_ring");
  ASSERT_TRUE(w.ok() && rw.ok());
  reg.seal();
  EXPECT_TRUE(w.value().connected());
  EXPECT_EQ(w.value().reader_count(), 0u);
  w.value().publish(1);
  EXPECT_EQ(rw.value().push(1), 0u);
}

TEST(Channels, DefaultHandlesAreNotConnected) {
  const LatestWriter<int> w;
  const LatestReader<int> r;
  EXPECT_FALSE(w.connected());
  EXPECT_FALSE(r.connected());
  EXPECT_EQ(w.reader_count(), 0u);
}

TEST(Channels, SecondWriterIsRejected) {
  ChannelRegistry reg;
  ASSERT_TRUE(reg.latest_writer<int>("pose").ok());
  auto second = reg.latest_writer<int>("pose");
  ASSERT_FALSE(second.ok());
  EXPECT_EQ(second.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(second.error().message.find("'pose'"), std::string::npos);
  EXPECT_NE(second.error().message.find("writer"), std::string::npos);

  ASSERT_TRUE((reg.ring_writer<int, 4>("events").ok()));
  auto second_ring = reg.ring_writer<int, 4>("events");
  ASSERT_FALSE(second_ring.ok());
  EXPECT_EQ(second_ring.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(second_ring.error().message.find("'events'"), std::string::npos);
}

TEST(Channels, TypeMismatchIsRejected) {
  ChannelRegistry reg;
  ASSERT_TRUE(reg.latest_writer<Odometry>("odom").ok());
  auto wrong_type = reg.latest_reader<int>("odom");
  ASSERT_FALSE(wrong_type.ok());
  EXPECT_EQ(wrong_type.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(wrong_type.error().message.find("'odom'"), std::string::npos);
  EXPECT_NE(wrong_type.error().message.find("type"), std::string::npos);

  // A latest channel is not a ring channel of the same message, and ring capacity is part of the type.
  EXPECT_FALSE((reg.ring_reader<Odometry, 4>("odom").ok()));
  ASSERT_TRUE((reg.ring_writer<int, 4>("events").ok()));
  EXPECT_FALSE((reg.ring_reader<int, 8>("events").ok()));
  EXPECT_FALSE((reg.latest_reader<int>("events").ok()));
  EXPECT_TRUE((reg.ring_reader<int, 4>("events").ok()));
  EXPECT_EQ(reg.size(), 2u);  // refused lookups add no channel
}

TEST(Channels, ReadersAfterSealAreRejected) {
  ChannelRegistry reg;
  ASSERT_TRUE(reg.latest_writer<int>("pose").ok());
  ASSERT_TRUE((reg.ring_writer<int, 4>("events").ok()));
  ASSERT_TRUE(reg.latest_reader<int>("pose").ok());
  reg.seal();
  auto late = reg.latest_reader<int>("pose");
  ASSERT_FALSE(late.ok());
  EXPECT_EQ(late.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(late.error().message.find("init()"), std::string::npos);
  auto late_ring = reg.ring_reader<int, 4>("events");
  ASSERT_FALSE(late_ring.ok());
  EXPECT_EQ(late_ring.error().code, ErrorCode::kInvalidArgument);
  // Also for a channel nobody has mentioned yet.
  EXPECT_FALSE(reg.latest_reader<int>("brand_new").ok());
}

}  // namespace
}  // namespace ag
