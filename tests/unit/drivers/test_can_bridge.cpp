// CAN receive filters in every backend, error frames decoded and the bus state they imply, the bus-off
// supervisor's backoff, and the cannelloni CAN-over-UDP bridge over real loopback sockets.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <cstring>
#include <vector>

#include "airground/drivers/can/can_error.hpp"
#include "airground/drivers/can/candump_log.hpp"
#include "airground/drivers/can/cannelloni.hpp"
#include "airground/drivers/can/inprocess_bus.hpp"
#include "airground/platform/clock.hpp"

namespace ag::can {
namespace {

CanFrame frame(std::uint32_t id, bool ext = false, std::uint8_t dlc = 2) {
  CanFrame f;
  f.id = id;
  f.extended = ext;
  f.dlc = dlc;
  for (std::uint8_t i = 0; i < dlc; ++i) f.data[i] = static_cast<std::uint8_t>(id + i);
  return f;
}

// ODrive CAN Simple: node 3's messages are ids 0x060..0x07F (node << 5 | cmd).
const CanFilter kNode3{0x060, 0x7E0, false};

TEST(CanFilters, InProcessLinkAppliesThem) {
  SimClock clock;
  InProcessCanLink link(clock);
  ASSERT_TRUE(link.robot().set_filters(std::span(&kNode3, 1)));
  for (std::uint32_t id : {0x069u, 0x029u, 0x07Fu, 0x080u}) ASSERT_EQ(link.device().send(frame(id)), CanResult::kOk);
  ASSERT_EQ(link.device().send(frame(0x069, true)), CanResult::kOk);  // extended 0x69: another format
  std::vector<std::uint32_t> got;
  CanFrame f;
  while (link.robot().receive(f) == CanResult::kOk) got.push_back(f.id);
  EXPECT_EQ(got, (std::vector<std::uint32_t>{0x069, 0x07F}));
  EXPECT_EQ(link.robot().counters().rx_filtered, 3u);
  std::vector<CanFilter> too_many(kMaxCanFilters + 1);
  EXPECT_FALSE(link.robot().set_filters(too_many));
  ASSERT_TRUE(link.robot().set_filters({}));
  ASSERT_EQ(link.device().send(frame(0x080)), CanResult::kOk);
  EXPECT_EQ(link.robot().receive(f), CanResult::kOk);
}

TEST(CanFilters, ReplayAndRecordingBusesApplyThem) {
  SimClock clock;
  std::vector<CandumpRecord> recs;
  for (std::uint32_t id : {0x061u, 0x123u, 0x062u}) {
    CandumpRecord r;
    r.frame = frame(id);
    r.frame.stamp = 1000;
    r.iface = "can0";
    recs.push_back(r);
  }
  CandumpReplayBus replay(recs, clock, 0);
  const CanFilter two[] = {kNode3, CanFilter{0x1F334455, 0x1FFFFFFF, true}};
  ASSERT_TRUE(replay.set_filters(two));
  clock.set(kNsPerS);
  CanFrame f;
  ASSERT_EQ(replay.receive(f), CanResult::kOk);
  EXPECT_EQ(f.id, 0x061u);
  ASSERT_EQ(replay.receive(f), CanResult::kOk);
  EXPECT_EQ(f.id, 0x062u);
  EXPECT_EQ(replay.receive(f), CanResult::kWouldBlock);
  EXPECT_EQ(replay.counters().rx_filtered, 1u);
}

TEST(CanErrors, DecodesTheKernelsErrorFrames) {
  // Controller problem: TX error-passive, counters tec 136 rec 3 (as the kernel's can_change_state sends).
  std::array<std::uint8_t, 8> d{};
  d[1] = kCrtlTxPassive;
  d[6] = 136;
  d[7] = 3;
  const CanErrorReport passive = decode_error_frame(kErrFlag | kErrCrtl | kErrCnt, d);
  EXPECT_TRUE(passive.controller);
  EXPECT_TRUE(passive.error_passive);
  EXPECT_FALSE(passive.bus_off);
  EXPECT_EQ(passive.tx_error_count, 136);
  char text[128];
  describe(passive, text, sizeof text);
  EXPECT_STREQ(text, "error-passive; tec 136 rec 3");
  const CanErrorReport arb = decode_error_frame(kErrFlag | kErrLostArb, {{7, 0, 0, 0, 0, 0, 0, 0}});
  EXPECT_TRUE(arb.lost_arbitration);
  EXPECT_EQ(arb.lost_arbitration_bit, 7);
  const CanErrorReport off = decode_error_frame(kErrFlag | kErrBusOff, {});
  EXPECT_TRUE(off.bus_off);
  describe(off, text, 8);  // truncates, stays terminated
  EXPECT_EQ(std::strlen(text), 7u);

  CanErrorTracker t;
  CanBusCounters c;
  std::array<std::uint8_t, 8> w{};
  w[1] = kCrtlRxWarning;
  t.apply(decode_error_frame(kErrFlag | kErrCrtl, w), c);
  EXPECT_EQ(t.state(), CanBusState::kErrorWarning);
  t.apply(passive, c);
  EXPECT_EQ(t.state(), CanBusState::kErrorPassive);
  t.apply(decode_error_frame(kErrFlag | kErrCrtl, w), c);  // a warning does not undo passive
  EXPECT_EQ(t.state(), CanBusState::kErrorPassive);
  t.apply(arb, c);
  t.apply(off, c);
  EXPECT_EQ(t.state(), CanBusState::kBusOff);
  t.apply(decode_error_frame(kErrFlag | kErrRestarted, {}), c);
  EXPECT_EQ(t.state(), CanBusState::kErrorActive);
  EXPECT_EQ(c.error_frames, 6u);
  EXPECT_EQ(c.bus_off, 1u);
  EXPECT_EQ(c.error_passive, 1u);
  EXPECT_EQ(c.error_warning, 2u);
  EXPECT_EQ(c.lost_arbitration, 1u);
  EXPECT_EQ(c.restarted, 1u);
}

TEST(BusOffSupervisor, RestartsWithExponentialBackoffAndCountsRecovery) {
  BusOffSupervisor s(RestartPolicy{100 * kNsPerMs, 1 * kNsPerS, 2, 0});
  std::vector<TimeNs> restarts;
  for (TimeNs t = 0; t <= 2 * kNsPerS; t += 10 * kNsPerMs) {
    const CanBusState st = t >= 50 * kNsPerMs && t < 1600 * kNsPerMs ? CanBusState::kBusOff : CanBusState::kErrorActive;
    if (s.update(t, st) == BusOffSupervisor::Action::kRestart) restarts.push_back(t);
  }
  // Bus-off at 50 ms: restarts at 150, 150+200, 350+400, 750+800 (then capped at 1 s).
  EXPECT_EQ(restarts, (std::vector<TimeNs>{150 * kNsPerMs, 350 * kNsPerMs, 750 * kNsPerMs, 1550 * kNsPerMs}));
  EXPECT_EQ(s.episodes(), 1u);
  EXPECT_EQ(s.recoveries(), 1u);
  EXPECT_EQ(s.last_outage(), 1550 * kNsPerMs);
  EXPECT_FALSE(s.in_bus_off());

  BusOffSupervisor g(RestartPolicy{10 * kNsPerMs, 10 * kNsPerMs, 2, 2});
  int restart_count = 0, gave_up = 0;
  for (TimeNs t = 0; t < kNsPerS; t += kNsPerMs) {
    const auto a = g.update(t, CanBusState::kBusOff);
    restart_count += a == BusOffSupervisor::Action::kRestart;
    gave_up += a == BusOffSupervisor::Action::kGaveUp;
  }
  EXPECT_EQ(restart_count, 2);
  EXPECT_EQ(gave_up, 1);
}

TEST(Cannelloni, WireFormatIsByteExact) {
  CanFrame a = frame(0x123, false, 3);
  a.data = {0xDE, 0xAD, 0xBE};
  CanFrame b = frame(0x1ABCDEF0, true, 0);
  CanFrame r = frame(0x7FF, false, 4);
  r.rtr = true;
  const CanFrame frames[] = {a, b, r};
  std::uint8_t buf[64];
  const std::size_t n = cannelloni::encode(0x2A, frames, buf);
  const std::uint8_t want[] = {2, 0, 0x2A, 0, 3,                                 // version, DATA, seq, count (BE)
                               0x00, 0x00, 0x01, 0x23, 3, 0xDE, 0xAD, 0xBE,      // can_id BE, len, data
                               0x9A, 0xBC, 0xDE, 0xF0, 0,                        // EFF flag | id
                               0x40, 0x00, 0x07, 0xFF, 4};                       // RTR flag: len, no data
  ASSERT_EQ(n, sizeof want);
  EXPECT_EQ(0, std::memcmp(buf, want, n));
  std::array<cannelloni::WireFrame, 8> out{};
  cannelloni::Decoded d;
  ASSERT_EQ(cannelloni::decode(std::span(buf, n), out, d), cannelloni::DecodeStatus::kOk);
  EXPECT_EQ(d.seq, 0x2A);
  ASSERT_EQ(d.frames, 3u);
  EXPECT_EQ(out[0].frame.id, 0x123u);
  EXPECT_EQ(out[0].frame.data[2], 0xBE);
  EXPECT_TRUE(out[1].frame.extended);
  EXPECT_EQ(out[1].frame.id, 0x1ABCDEF0u);
  EXPECT_TRUE(out[2].frame.rtr);
  EXPECT_EQ(out[2].frame.dlc, 4);
  // Malformed datagrams.
  EXPECT_EQ(cannelloni::decode(std::span(buf, 4), out, d), cannelloni::DecodeStatus::kShort);
  EXPECT_EQ(cannelloni::decode(std::span(buf, n - 1), out, d), cannelloni::DecodeStatus::kTruncated);
  EXPECT_EQ(d.frames, 2u);  // the frames before the cut
  std::uint8_t v1[sizeof want];
  std::memcpy(v1, want, sizeof want);
  v1[0] = 1;
  EXPECT_EQ(cannelloni::decode(v1, out, d), cannelloni::DecodeStatus::kBadVersion);
  v1[0] = 2;
  v1[9] = 9;  // classic len 9
  EXPECT_EQ(cannelloni::decode(v1, out, d), cannelloni::DecodeStatus::kBadLength);
  std::uint8_t fd[] = {2, 0, 0, 0, 1, 0, 0, 1, 0x23, 0x82, 0x01, 0xAA, 0xBB};  // CAN FD frame, 2 bytes
  EXPECT_EQ(cannelloni::decode(fd, out, d), cannelloni::DecodeStatus::kOk);
  EXPECT_TRUE(out[0].fd);
}

struct BridgePair {
  std::unique_ptr<CannelloniBus> robot, sim;
  BridgePair() {
    CannelloniConfig a;
    a.bind_address = "127.0.0.1";
    a.local_port = 0;
    a.learn_remote = true;
    auto r = CannelloniBus::open(a);
    EXPECT_TRUE(r.ok());
    robot = std::move(r.value());
    CannelloniConfig b;
    b.bind_address = "127.0.0.1";
    b.local_port = 0;
    b.remote_port = robot->local_port();
    auto s = CannelloniBus::open(b);
    EXPECT_TRUE(s.ok());
    sim = std::move(s.value());
  }
};

CanResult receive_within(CanBus& bus, CanFrame& f, int ms = 200) {
  for (int i = 0; i < ms; ++i) {
    const CanResult r = bus.receive(f);
    if (r != CanResult::kWouldBlock) return r;
    ::usleep(1000);
  }
  return CanResult::kWouldBlock;
}

TEST(Cannelloni, LoopbackBridgeCarriesFramesBothWays) {
  BridgePair p;
  CanFrame f;
  EXPECT_EQ(p.robot->receive(f), CanResult::kWouldBlock);
  const CanFrame batch[] = {frame(0x069), frame(0x1F334455, true, 8), frame(0x029, false, 0)};
  ASSERT_EQ(p.sim->send_batch(batch), CanResult::kOk);
  for (const CanFrame& want : batch) {
    ASSERT_EQ(receive_within(*p.robot, f), CanResult::kOk);
    EXPECT_EQ(f.id, want.id);
    EXPECT_EQ(f.extended, want.extended);
    EXPECT_EQ(f.dlc, want.dlc);
    EXPECT_EQ(f.data, want.data);
    EXPECT_GT(f.stamp, 0);
  }
  // The robot answers the simulator's (learned) port.
  ASSERT_EQ(p.robot->send(frame(0x06D, false, 8)), CanResult::kOk);
  ASSERT_EQ(receive_within(*p.sim, f), CanResult::kOk);
  EXPECT_EQ(f.id, 0x06Du);
  EXPECT_EQ(p.robot->bridge_counters().datagrams_rx, 1u);
  EXPECT_EQ(p.robot->bridge_counters().sequence_gaps, 0u);
  EXPECT_EQ(p.robot->send(frame(0x800)), CanResult::kInvalid);
}

TEST(Cannelloni, FiltersGapsGarbageAndBusOffOverTheBridge) {
  BridgePair p;
  ASSERT_TRUE(p.robot->set_filters(std::span(&kNode3, 1)));
  ASSERT_EQ(p.sim->send(frame(0x061)), CanResult::kOk);
  ASSERT_EQ(p.sim->send(frame(0x123)), CanResult::kOk);  // filtered
  // Datagrams 2..6 lost on the way: the next one carries sequence number 7.
  const int raw = ::socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons(p.robot->local_port());
  to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  const CanFrame late[] = {frame(0x062)};
  std::uint8_t dg[32];
  const std::size_t dn = cannelloni::encode(7, late, dg);
  ASSERT_GT(::sendto(raw, dg, dn, 0, reinterpret_cast<sockaddr*>(&to), sizeof to), 0);
  // A garbage datagram.
  const char junk[] = "hello";
  ASSERT_GT(::sendto(raw, junk, sizeof junk, 0, reinterpret_cast<sockaddr*>(&to), sizeof to), 0);
  ::close(raw);
  std::vector<std::uint32_t> got;
  CanFrame f;
  while (receive_within(*p.robot, f, 30) == CanResult::kOk) got.push_back(f.id);
  EXPECT_EQ(got, (std::vector<std::uint32_t>{0x061, 0x062}));
  EXPECT_EQ(p.robot->counters().rx_filtered, 1u);
  EXPECT_EQ(p.robot->bridge_counters().decode_errors, 1u);
  EXPECT_EQ(p.robot->bridge_counters().sequence_gaps, 1u);
  // Bus-off reported by the remote side as an error frame, then traffic again.
  const CanFrame err[] = {frame(kErrBusOff, true, 8)};
  const std::uint32_t raw_id[] = {cannelloni::kErrFlag | cannelloni::kEffFlag | kErrBusOff};
  ASSERT_EQ(p.sim->send_batch(err, raw_id), CanResult::kOk);
  EXPECT_EQ(receive_within(*p.robot, f, 30), CanResult::kWouldBlock);
  EXPECT_EQ(p.robot->state(), CanBusState::kBusOff);
  EXPECT_EQ(p.robot->counters().bus_off, 1u);
  BusOffSupervisor sup;
  EXPECT_EQ(sup.update(0, p.robot->state()), BusOffSupervisor::Action::kNone);
  EXPECT_EQ(sup.update(100 * kNsPerMs, p.robot->state()), BusOffSupervisor::Action::kRestart);
  ASSERT_EQ(p.sim->send(frame(0x069)), CanResult::kOk);
  ASSERT_EQ(receive_within(*p.robot, f), CanResult::kOk);
  EXPECT_EQ(p.robot->state(), CanBusState::kErrorActive);
  EXPECT_EQ(sup.update(150 * kNsPerMs, p.robot->state()), BusOffSupervisor::Action::kNone);
  EXPECT_EQ(sup.recoveries(), 1u);
}

}  // namespace
}  // namespace ag::can
