// The autopilot stage in a one-stage role: the ArduPilot .tlog replayed (unpaced and paced), the PX4
// capture over real UDP with the SET_MESSAGE_INTERVAL request answered, reordering / duplicates /
// reboots of time_boot_ms, latency, configuration errors; step() does not allocate.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <iterator>
#include <memory>

#include "airground/drivers/autopilot/mavlink/frames.hpp"
#include "airground/drivers/autopilot/mavlink/link.hpp"
#include "airground/drivers/autopilot/mavlink/stage.hpp"
#include "airground/platform/role_instance.hpp"

#if AG_COUNT_ALLOC
#include "../../../common/counting_new.hpp"
#endif

namespace ag::mavlink {
namespace {

inline constexpr StageSpec kStages[] = {
    {"autopilot", &AutopilotStage::make, 50.0, 2'000, 35, -1, AutopilotStage::kParams, "the stage under test"},
};
inline constexpr RoleDescription kRole{"uav", "autopilot stage rig", kStages, {}};
const std::string kDir = std::string(AG_TEST_DATA_DIR) + "/mavlink/";
const std::string kTlog = kDir + "ardupilot-sitl-quadplane-40s.tlog";
constexpr double kPi = 3.14159265358979323846;
using Bytes = std::vector<std::uint8_t>;

struct Rig {
  std::unique_ptr<RoleInstance> role;
  AutopilotStage* stage{nullptr};
};

Rig make_rig(SimClock& clock, std::vector<std::string> sets) {
  static const std::vector<ParamSection> schema = role_schema(kRole);
  Config cfg = Config::defaults(schema);
  for (const std::string& s : sets) EXPECT_TRUE(cfg.set(s).ok()) << s;
  auto r = RoleInstance::create(kRole, cfg, clock, "uav");
  EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().message);
  Rig rig;
  if (!r.ok()) return rig;
  rig.role = std::move(r).value();
  rig.stage = dynamic_cast<AutopilotStage*>(rig.role->stages().front().stage.get());
  return rig;
}

Bytes load(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return Bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

// The ATTITUDE messages of the tlog and their recorded times, read with the driver's own pieces.
struct Recorded {
  TimeNs t;
  Attitude a;
};
std::vector<Recorded> tlog_attitudes() {
  auto r = TlogReplay::open(kTlog);
  std::vector<Recorded> out;
  FrameParser p;
  std::array<std::uint8_t, 512> buf{};
  Frame f;
  for (TimeNs rec = 0;;) {
    const long n = r.value()->read(buf, rec);
    if (n < 0) break;
    (void)p.feed(std::span(buf.data(), static_cast<std::size_t>(n)));
    p.end_of_packet();
    while (p.next(f))
      if (f.header.msgid == kIdAttitude) {
        Attitude a;
        EXPECT_TRUE(decode(f.payload, a));
        out.push_back({rec, a});
      }
  }
  return out;
}

TEST(AutopilotStage, TlogReplayPublishesEveryAttitudeInRep103) {
  SimClock clock(0);
  Rig rig = make_rig(clock, {"autopilot.source=replay", "autopilot.replay=" + kTlog, "autopilot.replay_pace=false",
                             "autopilot.max_bytes_per_step=65536", "autopilot.latency_s=0.01"});
  ASSERT_NE(rig.stage, nullptr);
  const std::vector<Recorded> truth = tlog_attitudes();
  ASSERT_EQ(truth.size(), 213u);
  TimeNs last_stamp = 0;
  std::size_t seen = 0;
  for (int i = 1; i <= 100 && !(rig.stage->link()->at_end() && seen == rig.stage->counters().published); ++i) {
    clock.set(i * 20 * kNsPerMs);
    rig.stage->step(clock.now());
    if (rig.stage->counters().published > seen) {
      seen = rig.stage->counters().published;
      EXPECT_GT(rig.stage->last_attitude().stamp, last_stamp);
      last_stamp = rig.stage->last_attitude().stamp;
    }
  }
  const AutopilotCounters& c = rig.stage->counters();
  EXPECT_EQ(c.attitude, 213u);
  EXPECT_EQ(c.published + c.duplicates + c.reordered, 213u);
  EXPECT_EQ(c.resets, 0u);
  EXPECT_EQ(c.heartbeats, 37u);
  EXPECT_EQ(c.autopilot, kAutopilotArdupilot);
  EXPECT_EQ(c.device_errors, 0u);
  EXPECT_EQ(rig.stage->parser_counters().errors(), 0u);
  // The last one, converted by hand from its ATTITUDE: roll kept, pitch negated, yaw = pi/2 - yaw_ned.
  const Attitude& a = truth.back().a;
  const AttitudeMsg& m = rig.stage->last_attitude();
  EXPECT_NEAR(m.roll, a.roll, 1e-7);
  EXPECT_NEAR(m.pitch, -a.pitch, 1e-7);
  EXPECT_NEAR(m.yaw, std::remainder(kPi / 2 - static_cast<double>(a.yaw), 2 * kPi), 1e-6);
  EXPECT_NEAR(m.yaw_rate, -a.yawspeed, 1e-7);
  // Stamped on this clock: the recording's times moved so that its first record is the first step's time.
  EXPECT_EQ(m.stamp, truth.back().t + (20 * kNsPerMs - TimeNs{1533737161905000} * 1000) - 10 * kNsPerMs);
}

TEST(AutopilotStage, PacedReplayFollowsTheRecordedTimes) {
  SimClock clock(0);
  Rig rig = make_rig(clock, {"autopilot.source=replay", "autopilot.replay=" + kTlog});
  ASSERT_NE(rig.stage, nullptr);
  const std::vector<Recorded> truth = tlog_attitudes();
  const TimeNs t0 = TimeNs{1533737161905000} * 1000;  // the first record
  const TimeNs start = 5 * kNsPerS;
  for (TimeNs t = start; t <= start + 10 * kNsPerS; t += 20 * kNsPerMs) {
    clock.set(t);
    rig.stage->step(t);
  }
  std::size_t due = 0;
  for (const Recorded& r : truth) due += r.t - t0 <= 10 * kNsPerS;
  EXPECT_EQ(rig.stage->counters().attitude, due);
  EXPECT_LT(due, truth.size());
  EXPECT_GT(due, 20u);
}

TEST(AutopilotStage, Px4OverUdpAsksForFiftyHertzAndCountsTheAck) {
  SimClock clock(0);
  Rig rig = make_rig(clock, {"autopilot.source=udp", "autopilot.udp_bind=127.0.0.1", "autopilot.udp_port=0", "autopilot.latency_s=0.004"});
  ASSERT_NE(rig.stage, nullptr);
  auto* udp = dynamic_cast<UdpLink*>(rig.stage->link());
  ASSERT_NE(udp, nullptr);
  const int tx = ::socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons(static_cast<std::uint16_t>(udp->port()));
  to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  // The PX4 capture's frames, a few per datagram as PX4 packs them.
  const Bytes d = load(kDir + "px4-v2-3412-packets.bin");
  FrameParser p;
  Frame f;
  std::vector<Bytes> frames;
  for (std::span<const std::uint8_t> in = std::span(d).first(14000); !in.empty();) {
    in = in.subspan(p.feed(in));
    while (p.next(f)) {
      const std::uint8_t* s = f.payload.data() - kHeaderV2;
      frames.emplace_back(s, s + f.wire_bytes);
    }
  }
  std::size_t sent_att = 0, sent_hb = 0;
  for (std::size_t i = 0; i < frames.size(); i += 3) {
    Bytes dg;
    for (std::size_t k = i; k < std::min(frames.size(), i + 3); ++k) {
      dg.insert(dg.end(), frames[k].begin(), frames[k].end());
      const std::uint32_t id = frames[k][7] | frames[k][8] << 8 | frames[k][9] << 16;
      sent_att += id == kIdAttitude;
      sent_hb += id == kIdHeartbeat;
    }
    ASSERT_GT(::sendto(tx, dg.data(), dg.size(), 0, reinterpret_cast<sockaddr*>(&to), sizeof to), 0);
  }
  ASSERT_GT(sent_hb, 0u) << "the first 14000 bytes hold a heartbeat (at byte 11691)";
  ::usleep(20000);
  clock.set(kNsPerS);
  rig.stage->step(clock.now());
  const AutopilotCounters& c = rig.stage->counters();
  EXPECT_EQ(c.attitude, sent_att);
  EXPECT_EQ(c.published, sent_att);
  EXPECT_EQ(c.autopilot, kAutopilotPx4);
  EXPECT_EQ(rig.stage->parser_counters().errors(), 0u);
  // All arrived in one step: the newest is stamped at arrival - latency, the earlier ones by their
  // time_boot_ms intervals (20 ms apart at 50 Hz).
  EXPECT_EQ(rig.stage->last_attitude().stamp, kNsPerS - 4 * kNsPerMs);
  // It asked for ATTITUDE every 20000 us (COMMAND_LONG, MAV_CMD_SET_MESSAGE_INTERVAL) to the sender.
  EXPECT_EQ(c.rate_requests, 1u);
  std::array<std::uint8_t, 512> back{};
  const ssize_t n = ::recv(tx, back.data(), back.size(), MSG_DONTWAIT);
  ASSERT_GT(n, 0);
  FrameParser q;
  (void)q.feed(std::span(back.data(), static_cast<std::size_t>(n)));
  ASSERT_TRUE(q.next(f));
  EXPECT_EQ(f.header.msgid, kIdCommandLong);
  EXPECT_EQ(f.header.compid, kCompOnboardComputer);
  CommandLong cmd;
  ASSERT_TRUE(decode(f.payload, cmd));
  EXPECT_EQ(cmd.command, kCmdSetMessageInterval);
  EXPECT_EQ(cmd.param[0], 30.0f);
  EXPECT_EQ(cmd.param[1], 20000.0f);
  EXPECT_EQ(cmd.target_system, 1);
  EXPECT_EQ(cmd.target_component, 1);
  // The autopilot's COMMAND_ACK (accepted) is counted; a message from another system is filtered out.
  std::array<std::uint8_t, kMaxFrame> buf{};
  FrameHeader h;
  h.sysid = 1;
  h.compid = 1;
  CommandAck ack;
  ack.command = kCmdSetMessageInterval;
  ack.result = kResultAccepted;
  std::size_t len = encode_message(h, ack, buf);
  ASSERT_GT(::sendto(tx, buf.data(), len, 0, reinterpret_cast<sockaddr*>(&to), sizeof to), 0);
  h.sysid = 2;
  len = encode_message(h, Attitude{}, buf);
  ASSERT_GT(::sendto(tx, buf.data(), len, 0, reinterpret_cast<sockaddr*>(&to), sizeof to), 0);
  ::usleep(20000);
  rig.stage->step(kNsPerS + 20 * kNsPerMs);
  EXPECT_EQ(c.rate_accepted, 1u);
  EXPECT_EQ(c.other_sources, 1u);
  ::close(tx);
}

TEST(AutopilotStage, ReorderedDuplicateAndRebootedTimesAndNoAllocation) {
  // A tlog of ATTITUDE at boot times 5000, 5020, 5010 (late), 5020 (again), 100 (rebooted), 120.
  Bytes log;
  std::array<std::uint8_t, kMaxFrame> buf{};
  FrameHeader h;
  h.sysid = 1;
  h.compid = 1;
  std::uint64_t us = 1'700'000'000'000'000;
  for (std::uint32_t boot : {5000u, 5020u, 5010u, 5020u, 100u, 120u}) {
    Attitude a;
    a.time_boot_ms = boot;
    a.yaw = 0.25f;
    const std::size_t n = encode_message(h, a, buf);
    append_tlog_record(log, us, std::span(buf.data(), n));
    us += 20'000;
  }
  const std::string path = std::string(::testing::TempDir()) + "ag_autopilot_reorder.tlog";
  {
    std::ofstream o(path, std::ios::binary);
    o.write(reinterpret_cast<const char*>(log.data()), static_cast<std::streamsize>(log.size()));
  }
  SimClock clock(0);
  Rig rig = make_rig(clock, {"autopilot.source=replay", "autopilot.replay=" + path, "autopilot.latency_s=0.002"});
  ASSERT_NE(rig.stage, nullptr);
  for (TimeNs t = kNsPerS; t <= kNsPerS + 200 * kNsPerMs; t += 20 * kNsPerMs) {
    clock.set(t);
#if AG_COUNT_ALLOC
    test_alloc::AllocationWindow w;
#endif
    rig.stage->step(t);
#if AG_COUNT_ALLOC
    EXPECT_EQ(w.allocations(), 0u) << "step() allocated";
#endif
  }
  const AutopilotCounters& c = rig.stage->counters();
  EXPECT_EQ(c.attitude, 6u);
  EXPECT_EQ(c.reordered, 1u);
  EXPECT_EQ(c.duplicates, 1u);
  EXPECT_EQ(c.resets, 1u);
  EXPECT_EQ(c.published, 4u);
  EXPECT_NEAR(rig.stage->last_attitude().yaw, kPi / 2 - 0.25, 1e-7);
  // Paced from the first step: the sixth record (100 ms after the first) arrives at 1.1 s.
  EXPECT_EQ(rig.stage->last_attitude().stamp, kNsPerS + 100 * kNsPerMs - 2 * kNsPerMs);
}

TEST(AutopilotStage, ConfigurationErrorsNameTheKeyAndAbsentDevicesDoNotStopTheRobot) {
  static const std::vector<ParamSection> schema = role_schema(kRole);
  Config cfg = Config::defaults(schema);
  const Status bad = cfg.set("autopilot.source=usb");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("autopilot.source"), std::string::npos) << bad.error().message;
  const Status baud = cfg.set("autopilot.baud=9600");
  ASSERT_FALSE(baud.ok());
  EXPECT_NE(baud.error().message.find("autopilot.baud"), std::string::npos) << baud.error().message;
  ASSERT_TRUE(cfg.set("autopilot.source=replay").ok());
  SimClock clock(0);
  auto r = RoleInstance::create(kRole, cfg, clock, "uav");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("autopilot.replay"), std::string::npos) << r.error().message;
  // An absent serial device: logged and counted; the stage runs and publishes nothing.
  Rig rig = make_rig(clock, {"autopilot.source=serial", "autopilot.device=/dev/nonexistent-autopilot"});
  ASSERT_NE(rig.stage, nullptr);
  EXPECT_FALSE(rig.stage->active());
  EXPECT_EQ(rig.stage->counters().device_errors, 1u);
  rig.stage->step(kNsPerS);
  EXPECT_EQ(rig.stage->counters().published, 0u);
  Rig none = make_rig(clock, {"autopilot.source=none"});
  ASSERT_NE(none.stage, nullptr);
  EXPECT_FALSE(none.stage->active());
  EXPECT_EQ(none.stage->counters().device_errors, 0u);
}

}  // namespace
}  // namespace ag::mavlink

namespace ag::mavlink {
namespace {

// The simulator's backend (source: sim): a simulated PX4's HEARTBEAT and ATTITUDE frames through the
// in-process TELEM2 link come out in REP-103, the stage's SET_MESSAGE_INTERVAL goes back over it, and a
// robot the simulator gave no autopilot is a configuration error naming it.
TEST(AutopilotStage, TheSimulatorsAutopilotTalksMavlinkBothWays) {
  SimClock clock(0);
  {
    static const std::vector<ParamSection> schema = role_schema(kRole);
    Config cfg = Config::defaults(schema);
    ASSERT_TRUE(cfg.set("autopilot.source=sim").ok());
    auto r = RoleInstance::create(kRole, cfg, clock, "uav");
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("autopilot.source is sim but the simulator gave robot 'uav' no autopilot"), std::string::npos)
        << r.error().message;
  }
  SimAutopilotLink link;
  ASSERT_TRUE(register_sim_autopilot("uav", &link));
  Rig rig = make_rig(clock, {"autopilot.source=sim"});
  unregister_sim_autopilot("uav");
  ASSERT_NE(rig.stage, nullptr);
  std::array<std::uint8_t, kMaxFrame> frame{};
  Heartbeat hb;
  hb.type = 2;
  hb.autopilot = 12;  // PX4
  (void)link.to_robot.write(std::span(frame.data(), encode_message(FrameHeader{2, 0, 0, 0, 1, 1, 0}, hb, frame)));
  for (std::uint32_t k = 0; k < 3; ++k) {
    Attitude a;
    a.time_boot_ms = 100 + 20 * k;
    a.roll = 0.1f;
    a.pitch = -0.2f;
    a.yaw = 0.3f;
    a.yawspeed = 0.05f;
    (void)link.to_robot.write(std::span(frame.data(), encode_message(FrameHeader{2, 0, 0, static_cast<std::uint8_t>(1 + k), 1, 1, 0}, a, frame)));
  }
  clock.set(kNsPerS);
  rig.stage->step(clock.now());
  rig.stage->step(clock.now() + 20 * kNsPerMs);
  const AutopilotCounters& c = rig.stage->counters();
  EXPECT_EQ(c.heartbeats, 1u);
  EXPECT_EQ(c.attitude, 3u);
  EXPECT_EQ(c.published, 3u);
  const AttitudeMsg& m = rig.stage->last_attitude();
  EXPECT_NEAR(m.roll, 0.1, 1e-7);
  EXPECT_NEAR(m.pitch, 0.2, 1e-7);
  EXPECT_NEAR(m.yaw, kPi / 2 - 0.3, 1e-6);
  EXPECT_NEAR(m.yaw_rate, -0.05, 1e-7);
  EXPECT_GT(link.from_robot.size(), 0u) << "the stage asked the autopilot for ATTITUDE at 50 Hz";
  // And the simulator's frames convert back: FRD / NED -> FLU / ENU is its own inverse.
  const EulerAttitude e{0.1, -0.2, 0.3, 0.01, 0.02, 0.03};
  const EulerAttitude back = flu_enu_to_frd_ned(frd_ned_to_flu_enu(e));
  EXPECT_NEAR(back.roll, e.roll, 1e-12);
  EXPECT_NEAR(back.pitch, e.pitch, 1e-12);
  EXPECT_NEAR(back.yaw, e.yaw, 1e-12);
  EXPECT_NEAR(back.yaw_rate, e.yaw_rate, 1e-12);
}

}  // namespace
}  // namespace ag::mavlink
