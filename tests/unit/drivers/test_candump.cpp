// candump logs: lines in the can-utils format both ways, bad lines named and counted, recording and
// replay through the CanBus interface; the SocketCAN backend's error when no CAN interface exists.
#include <gtest/gtest.h>

#include <cstdio>

#include "airground/drivers/can/candump_log.hpp"
#include "airground/drivers/can/inprocess_bus.hpp"
#include "airground/drivers/can/socketcan_bus.hpp"

namespace ag::can {
namespace {

TEST(Candump, ParsesTheCanUtilsFormat) {
  auto r = parse_candump_line("(1436509052.249713) can0 1F334455#1122334455667788");
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r.value().iface, "can0");
  EXPECT_TRUE(r.value().frame.extended);
  EXPECT_EQ(r.value().frame.id, 0x1F334455U);
  EXPECT_EQ(r.value().frame.dlc, 8);
  EXPECT_EQ(r.value().frame.data[7], 0x88);
  EXPECT_EQ(r.value().frame.stamp, 1436509052LL * kNsPerS + 249713LL * kNsPerUs);
  auto s = parse_candump_line("(0.000001) vcan1 02D#0D.00.00.80");
  ASSERT_TRUE(s.ok()) << s.error().message;
  EXPECT_FALSE(s.value().frame.extended);
  EXPECT_EQ(s.value().frame.id, 0x2DU);
  EXPECT_EQ(s.value().frame.dlc, 4);
  auto rtr = parse_candump_line("(5.000000) can0 029#R8");
  ASSERT_TRUE(rtr.ok());
  EXPECT_TRUE(rtr.value().frame.rtr);
  EXPECT_EQ(rtr.value().frame.dlc, 8);
  auto empty = parse_candump_line("(5.000000) can0 123#");
  ASSERT_TRUE(empty.ok());
  EXPECT_EQ(empty.value().frame.dlc, 0);
}

TEST(Candump, FormatRoundTrips) {
  CanFrame f;
  f.id = 0x02D;
  f.dlc = 8;
  for (std::uint8_t i = 0; i < 8; ++i) f.data[i] = static_cast<std::uint8_t>(0xA0 + i);
  f.stamp = 1764633600LL * kNsPerS + 123456LL * kNsPerUs;
  EXPECT_EQ(format_candump_line(f, "can0"), "(1764633600.123456) can0 02D#A0A1A2A3A4A5A6A7");
  auto back = parse_candump_line(format_candump_line(f, "can0"));
  ASSERT_TRUE(back.ok());
  EXPECT_EQ(back.value().frame.data, f.data);
  EXPECT_EQ(back.value().frame.stamp, f.stamp);
  f.extended = true;
  f.id = 0x1ABCDEF;
  EXPECT_EQ(format_candump_line(f, "can1").substr(20), "can1 01ABCDEF#A0A1A2A3A4A5A6A7");
  f.rtr = true;
  f.dlc = 0;
  EXPECT_EQ(parse_candump_line(format_candump_line(f, "can1")).value().frame.rtr, true);
}

TEST(Candump, BadLinesAreNamedCountedAndSkipped) {
  for (const char* bad : {"1436509052.249713 can0 123#00", "(1436509052.2497) can0 123#00", "(1.000000) can0 1234#00",
                          "(1.000000) can0 123#0", "(1.000000) can0 123#001122334455667788", "(1.000000) can0 123##100",
                          "(1.000000) can0 FFF#00", "(1.000000) can0 12G#00", "(1.000000) can0", "(x.000000) can0 123#00"}) {
    auto r = parse_candump_line(bad);
    EXPECT_FALSE(r.ok()) << bad;
    if (!r.ok()) {
      EXPECT_FALSE(r.error().message.empty());
    }
  }
  const CandumpLog log = parse_candump_text("(1.000000) can0 123#00\nnot a frame\n\n# comment\n(2.000000) can0 124#01\n(3.0", "run.log");
  EXPECT_EQ(log.records.size(), 2U);
  EXPECT_EQ(log.bad_lines, 2U);
  EXPECT_EQ(log.first_error.rfind("run.log:2: ", 0), 0U) << log.first_error;
  auto missing = read_candump_file("/nonexistent/x.log");
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().message.find("/nonexistent/x.log"), std::string::npos);
}

TEST(Candump, RecordingAndReplayThroughTheBusInterface) {
  SimClock clock(100 * kNsPerS);
  InProcessCanLink link(clock);
  const std::string path = ::testing::TempDir() + "/rec.log";
  {
    auto w = CandumpWriter::create(path);
    ASSERT_TRUE(w.ok());
    RecordingCanBus rec(link.robot(), *w.value(), clock);
    CanFrame f;
    f.id = 0x20D;
    f.dlc = 2;
    f.data[0] = 1;
    ASSERT_EQ(rec.send(f), CanResult::kOk);
    clock.set(clock.now() + 5 * kNsPerMs);
    f.id = 0x009;
    f.data[0] = 2;
    ASSERT_EQ(link.device().send(f), CanResult::kOk);
    CanFrame got;
    ASSERT_EQ(rec.receive(got), CanResult::kOk);
    EXPECT_EQ(got.data[0], 2);
    EXPECT_EQ(rec.receive(got), CanResult::kWouldBlock);
    EXPECT_EQ(w.value()->lines(), 2U);
  }
  auto log = read_candump_file(path);
  ASSERT_TRUE(log.ok());
  ASSERT_EQ(log.value().records.size(), 2U);
  EXPECT_EQ(log.value().records[1].frame.stamp - log.value().records[0].frame.stamp, 5 * kNsPerMs);
  SimClock rc(0);
  CandumpReplayBus replay(log.value().records, rc, 1 * kNsPerS);
  CanFrame out;
  EXPECT_EQ(replay.receive(out), CanResult::kWouldBlock) << "not yet at the first frame";
  rc.set(1 * kNsPerS + 4 * kNsPerMs);
  ASSERT_EQ(replay.receive(out), CanResult::kOk);
  EXPECT_EQ(out.id, 0x20DU);
  EXPECT_EQ(out.stamp, 1 * kNsPerS);
  EXPECT_EQ(replay.receive(out), CanResult::kWouldBlock);
  rc.set(2 * kNsPerS);
  ASSERT_EQ(replay.receive(out), CanResult::kOk);
  EXPECT_EQ(out.id, 0x009U);
  EXPECT_TRUE(replay.finished());
}

// Mutated lines (bytes flipped, cut, duplicated): never a crash, and every line accepted formats back to
// a line that parses to the same frame.
TEST(Candump, MutatedLinesNeverCrashAndAcceptedOnesRoundTrip) {
  const std::string seeds[] = {"(1436509052.249713) can0 1F334455#1122334455667788", "(0.000001) vcan1 02D#0D.00.00.80",
                               "(5.000000) can0 029#R8", "(1764633600.010000) can0 009#0000000000000000"};
  std::uint64_t x = 0x243F6A8885A308D3ULL;
  auto next = [&]() {
    x ^= x << 13;
    x ^= x >> 7;
    x ^= x << 17;
    return x;
  };
  const char alphabet[] = "0123456789ABCDEFabcdefR#.() \tZ-";
  std::size_t accepted = 0;
  for (int k = 0; k < 20000; ++k) {
    std::string l = seeds[next() % 4];
    const int edits = 1 + static_cast<int>(next() % 3);
    for (int e = 0; e < edits && !l.empty(); ++e) {
      const std::size_t at = next() % l.size();
      switch (next() % 3) {
        case 0: l[at] = alphabet[next() % (sizeof alphabet - 1)]; break;
        case 1: l.erase(at, 1 + next() % 3); break;
        default: l.insert(at, 1, alphabet[next() % (sizeof alphabet - 1)]); break;
      }
    }
    auto r = parse_candump_line(l);
    if (!r.ok()) continue;
    ++accepted;
    ASSERT_TRUE(valid(r.value().frame)) << l;
    auto back = parse_candump_line(format_candump_line(r.value().frame, r.value().iface));
    ASSERT_TRUE(back.ok()) << l;
    EXPECT_EQ(back.value().frame.id, r.value().frame.id) << l;
    EXPECT_EQ(back.value().frame.dlc, r.value().frame.dlc) << l;
    EXPECT_EQ(back.value().frame.stamp, r.value().frame.stamp) << l;
    if (!r.value().frame.rtr) {
      EXPECT_EQ(back.value().frame.data, r.value().frame.data) << l;
    }
  }
  EXPECT_GT(accepted, 100U) << "some mutations stay valid";
}

TEST(InProcessBus, FullQueueAndCutCableAreCounted) {
  SimClock clock(0);
  InProcessCanLink link(clock);
  CanFrame f;
  f.id = 1;
  for (std::size_t i = 0; i < InProcessCanLink::kCapacity; ++i) ASSERT_EQ(link.robot().send(f), CanResult::kOk);
  EXPECT_EQ(link.robot().send(f), CanResult::kWouldBlock);
  EXPECT_EQ(link.robot().counters().tx_dropped, 1U);
  f.id = 0x800;
  EXPECT_EQ(link.robot().send(f), CanResult::kInvalid) << "11-bit id out of range";
  link.device().set_down(true);
  f.id = 1;
  EXPECT_EQ(link.robot().send(f), CanResult::kDown);
}

TEST(SocketCan, OpeningAMissingInterfaceNamesIt) {
  auto r = SocketCanBus::open("agnocan0");
  ASSERT_FALSE(r.ok()) << "no such interface on this machine";
  EXPECT_NE(r.error().message.find("agnocan0"), std::string::npos) << r.error().message;
  EXPECT_FALSE(SocketCanBus::open("").ok());
}

}  // namespace
}  // namespace ag::can
