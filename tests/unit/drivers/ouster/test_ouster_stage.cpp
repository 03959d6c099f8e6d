// The Ouster stage in a one-stage role (real config, real channels) replaying the real OS-1-64 capture:
// one step publishes the revolution as a "lidar_scan"; config errors name the key; the step does not
// allocate.
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <memory>
#include <sstream>

#include "airground/drivers/lidar/ouster/sim_source.hpp"
#include "airground/drivers/lidar/ouster/stage.hpp"
#include "airground/platform/role_instance.hpp"

#if AG_COUNT_ALLOC
#include "../../../common/counting_new.hpp"
#endif

namespace ag::ouster {
namespace {

inline constexpr StageSpec kStages[] = {
    {"ouster", &OusterStage::make, 20.0, 5'000, 40, -1, OusterStage::kParams, "the stage under test"},
};
inline constexpr RoleDescription kRole{"ugv", "ouster stage rig", kStages, {}};
const std::string kDir = std::string(AG_TEST_DATA_DIR) + "/ouster/";

struct Rig {
  SimClock clock{0};
  std::unique_ptr<RoleInstance> role;
  OusterStage* stage{nullptr};
};

Result<std::unique_ptr<RoleInstance>> make_role(SimClock& clock, std::vector<std::string> sets) {
  static const std::vector<ParamSection> schema = role_schema(kRole);
  Config cfg = Config::defaults(schema);
  for (const std::string& s : sets) {
    const Status st = cfg.set(s);
    EXPECT_TRUE(st.ok()) << s;
  }
  return RoleInstance::create(kRole, cfg, clock, "ugv1");
}

TEST(OusterStage, ReplayPublishesTheRevolution) {
  SimClock clock(0);
  auto r = make_role(clock, {"ouster.source=pcap", "ouster.metadata=" + kDir + "os1-64_legacy_metadata.json",
                             "ouster.pcap=" + kDir + "OS-1-64_1024x10_fw20.pcap", "ouster.mount_z_m=0.62"});
  ASSERT_TRUE(r.ok()) << r.error().message;
  auto role = std::move(r).value();
  auto* stage = dynamic_cast<OusterStage*>(role->stages().front().stage.get());
  ASSERT_NE(stage, nullptr);
  // (The channels are sealed after init: the published message is read through the stage.)
  clock.set(kNsPerS);
  {
#if AG_COUNT_ALLOC
    test_alloc::AllocationWindow w;
#endif
    stage->step(clock.now());
#if AG_COUNT_ALLOC
    EXPECT_EQ(w.allocations(), 0u) << "step() allocated";
#endif
  }
  EXPECT_EQ(stage->counters().packets, 64u);
  EXPECT_EQ(stage->counters().imu_packets, 11u);
  EXPECT_EQ(stage->counters().decode_errors, 0u);
  EXPECT_EQ(stage->counters().scans, 1u);
  EXPECT_EQ(stage->counters().scans_incomplete, 0u);
  const LidarScanMsg* m = &stage->last_scan();
  EXPECT_EQ(m->seq, 1u);
  EXPECT_EQ(m->rings, 64);
  EXPECT_EQ(m->columns, 1024);
  EXPECT_EQ(m->count, 16749u);
  EXPECT_DOUBLE_EQ(m->sensor_in_body.z, 0.62);
  EXPECT_EQ(m->stamp, kNsPerS);
  for (std::uint32_t i = 0; i < m->count; i += 97) {
    const ScanReturn& p = m->points[i];
    EXPECT_LT(p.ring, 64);
    EXPECT_LT(p.col, 1024);
    EXPECT_GT(p.range, 0.0f);
    // The point is its range away from the beam origin (within the 12 mm offset and the 36 mm lift).
    EXPECT_NEAR(std::hypot(p.x, p.y, p.z - 0.03618f), p.range, 0.02f);
  }
  stage->step(clock.now() + kNsPerS / 10);  // the recording is over: nothing more
  EXPECT_EQ(stage->counters().scans, 1u);
  EXPECT_EQ(stage->counters().source_errors, 0u);
}

// A sensor that is absent (no metadata, a capture missing, bad metadata) leaves the robot running with
// no scans and the fault counted; only a wrong key value is a configuration error.
TEST(OusterStage, AnAbsentSensorIsCountedNotFatalAndBadValuesNameTheKey) {
  SimClock clock(0);
  for (const std::vector<std::string>& sets :
       {std::vector<std::string>{"ouster.source=pcap"},
        {"ouster.source=pcap", "ouster.metadata=" + kDir + "os1-64_legacy_metadata.json", "ouster.pcap=/nonexistent.pcap"},
        {"ouster.source=pcap", "ouster.metadata=" + kDir + "LICENSE"}}) {
    auto r = make_role(clock, sets);
    ASSERT_TRUE(r.ok()) << r.error().message;
    auto* stage = dynamic_cast<OusterStage*>(r.value()->stages().front().stage.get());
    ASSERT_NE(stage, nullptr);
    EXPECT_FALSE(stage->active());
    EXPECT_EQ(stage->counters().device_errors, 1u) << sets.back();
    stage->step(kNsPerS);
    EXPECT_EQ(stage->counters().packets, 0u);
  }
  auto none = make_role(clock, {"ouster.source=none"});
  ASSERT_TRUE(none.ok()) << none.error().message;
  EXPECT_EQ(dynamic_cast<OusterStage*>(none.value()->stages().front().stage.get())->counters().device_errors, 0u);
  Config cfg = Config::defaults(role_schema(kRole));
  for (const char* bad : {"ouster.source=usb", "ouster.classes=rgb"}) {
    const Status st = cfg.set(bad);
    ASSERT_FALSE(st.ok()) << bad;
    EXPECT_NE(st.error().message.find(std::string(bad).substr(0, std::string(bad).find('='))), std::string::npos) << st.error().message;
  }
}

// The captures of current sensors (FW 2.2/2.3 flat metadata, profile under data_format) replayed
// through the stage: every return published, and the stage's own counters say what it received.
TEST(OusterStage, CurrentSensorsCapturesPublishEveryReturn) {
  struct Case {
    const char* name;
    std::uint32_t points;
    std::uint16_t rings;
  };
  for (const Case& k : {Case{"OS-0-128-U1_v2.3.0_1024x10", 97299u, 128}, Case{"OS-0-32-U1_v2.2.0_1024x10", 21631u, 32}}) {
    SCOPED_TRACE(k.name);
    SimClock clock(0);
    auto r = make_role(clock, {"ouster.source=pcap", "ouster.metadata=" + kDir + k.name + ".json", "ouster.pcap=" + kDir + k.name + ".pcap"});
    ASSERT_TRUE(r.ok()) << r.error().message;
    auto* stage = dynamic_cast<OusterStage*>(r.value()->stages().front().stage.get());
    ASSERT_NE(stage, nullptr);
    {
#if AG_COUNT_ALLOC
      test_alloc::AllocationWindow w;
#endif
      stage->step(kNsPerS);
#if AG_COUNT_ALLOC
      EXPECT_EQ(w.allocations(), 0u) << "step() allocated";
#endif
    }
    EXPECT_EQ(stage->counters().packets, 64u);
    EXPECT_EQ(stage->counters().decode_errors, 0u);
    EXPECT_EQ(stage->counters().scans, 1u);
    EXPECT_EQ(stage->last_scan().count, k.points);
    EXPECT_EQ(stage->last_scan().rings, k.rings);
    const DeviceCounters& d = r.value()->perf().at(0).device;
    EXPECT_TRUE(d.active.load());
    EXPECT_STREQ(d.unit.data(), "frames");
    EXPECT_EQ(d.complete.load(), 1u);
    EXPECT_EQ(d.incomplete.load(), 0u);
    EXPECT_EQ(d.error_total(), 0u);
    EXPECT_EQ(d.bytes.load(), 64u * 8448u + 10u * 48u);
    EXPECT_EQ(d.last_unit_ns.load(), kNsPerS);
    stage->step(5 * kNsPerS);  // the capture is over: not a silent sensor
    EXPECT_EQ(stage->counters().silence_warnings, 0u);
  }
}

std::string slurp(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string with_profile(const std::string& profile) {
  std::string j = slurp(kDir + "OS-0-128-U1_v2.3.0_1024x10.json");
  const std::string from = "\"RNG15_RFL8_NIR8\"";
  const auto at = j.find(from);
  EXPECT_NE(at, std::string::npos);
  j.replace(at, from.size(), "\"" + profile + "\"");
  const std::string path = ::testing::TempDir() + "ouster_" + profile + ".json";
  std::ofstream(path) << j;
  return path;
}

// An unsupported profile stops the robot at start-up, naming the profile, the file and the supported ones.
TEST(OusterStage, AnUnsupportedProfileStopsTheRobotNamingIt) {
  SimClock clock(0);
  const std::string meta = with_profile("RNG15_RFL8_NIR8_ZONE16");
  auto r = make_role(clock, {"ouster.source=pcap", "ouster.metadata=" + meta, "ouster.pcap=" + kDir + "OS-0-128-U1_v2.3.0_1024x10.pcap"});
  ASSERT_FALSE(r.ok());
  const std::string& m = r.error().message;
  EXPECT_EQ(r.error().code, ErrorCode::kConfig);
  EXPECT_NE(m.find("RNG15_RFL8_NIR8_ZONE16"), std::string::npos) << m;
  EXPECT_NE(m.find(meta), std::string::npos) << m;
  EXPECT_NE(m.find("ouster.metadata"), std::string::npos) << m;
  EXPECT_NE(m.find("RNG19_RFL8_SIG16_NIR16_DUAL"), std::string::npos) << m;
}

// Metadata naming another supported profile than the packets': every packet refused as the wrong size,
// counted by kind, and one warning that names the cause (here when the capture ends).
TEST(OusterStage, AWrongProfileIsCountedAndWarnedOnce) {
  SimClock clock(0);
  auto r = make_role(clock, {"ouster.source=pcap", "ouster.metadata=" + with_profile("RNG19_RFL8_SIG16_NIR16"),
                             "ouster.pcap=" + kDir + "OS-0-128-U1_v2.3.0_1024x10.pcap"});
  ASSERT_TRUE(r.ok()) << r.error().message;
  auto* stage = dynamic_cast<OusterStage*>(r.value()->stages().front().stage.get());
  ASSERT_NE(stage, nullptr);
  stage->step(kNsPerS);
  stage->step(5 * kNsPerS);
  EXPECT_EQ(stage->counters().scans, 0u);
  EXPECT_EQ(stage->counters().wrong_size, 64u);
  EXPECT_EQ(stage->counters().last_wrong_size, 8448u);
  EXPECT_EQ(stage->counters().silence_warnings, 1u);
  const DeviceCounters& d = r.value()->perf().at(0).device;
  EXPECT_EQ(d.errors[static_cast<std::size_t>(LidarError::kWrongSize)].load(), 64u);
  EXPECT_EQ(d.units(), 0u);
}

// A live sensor that sends nothing: one warning after a few seconds, not one per step.
TEST(OusterStage, ASilentSensorIsWarnedAboutOnce) {
  SimClock clock(0);
  auto r = make_role(clock, {"ouster.source=udp", "ouster.metadata=" + kDir + "OS-0-32-U1_v2.2.0_1024x10.json",
                             "ouster.bind_address=127.0.0.1", "ouster.lidar_port=39517", "ouster.imu_port=39518"});
  ASSERT_TRUE(r.ok()) << r.error().message;
  auto* stage = dynamic_cast<OusterStage*>(r.value()->stages().front().stage.get());
  ASSERT_NE(stage, nullptr);
  ASSERT_TRUE(stage->active());
  for (TimeNs t = kNsPerS; t <= 10 * kNsPerS; t += kNsPerS / 2) {
#if AG_COUNT_ALLOC
    test_alloc::AllocationWindow w;
#endif
    stage->step(t);
#if AG_COUNT_ALLOC
    EXPECT_EQ(w.allocations(), 0u) << "step() allocated while warning";
#endif
    if (t < 4 * kNsPerS) {
      EXPECT_EQ(stage->counters().silence_warnings, 0u) << t;
    }
  }
  EXPECT_EQ(stage->counters().silence_warnings, 1u);
}

}  // namespace
}  // namespace ag::ouster

namespace ag::ouster {
namespace {

// The simulator's backend (source: sim): the capture's packets handed over in-process give the same
// revolution as the capture itself, with the metadata the simulated sensor answers; a robot the
// simulator gave no sensor is a configuration error naming it; a full link drops and counts.
TEST(OusterStage, TheSimulatorsSensorGivesWhatTheSameBytesGiveFromACapture) {
  auto info = read_metadata_file(kDir + "os1-64_legacy_metadata.json");
  ASSERT_TRUE(info.ok()) << info.error().message;
  auto pcap = PcapPacketSource::open(kDir + "OS-1-64_1024x10_fw20.pcap");
  ASSERT_TRUE(pcap.ok()) << pcap.error().message;
  SimPacketLink link(info.value(), 64, kMaxPacketSize);
  std::vector<std::uint8_t> buf(kMaxPacketSize);
  std::size_t n = 0, lidar = 0;
  TimeNs t = 0;
  for (PacketKind k; (k = pcap.value()->next(buf, n, t)) != PacketKind::kEnd;)
    if (k == PacketKind::kLidar) lidar += link.send(std::span<const std::uint8_t>(buf.data(), n), t) ? 1u : 0u;
  ASSERT_EQ(lidar, 64u);
  EXPECT_FALSE(link.send(std::span<const std::uint8_t>(buf.data(), 100), 0)) << "a 65th packet finds the ring full";
  EXPECT_EQ(link.dropped(), 1u);

  SimClock clock(0);
  auto no_link = make_role(clock, {"ouster.source=sim"});
  ASSERT_FALSE(no_link.ok());
  EXPECT_NE(no_link.error().message.find("ouster.source is sim but the simulator gave robot 'ugv1' no lidar"), std::string::npos)
      << no_link.error().message;

  ASSERT_TRUE(register_sim_lidar("ugv1", &link));
  EXPECT_FALSE(register_sim_lidar("ugv1", &link)) << "one sensor per robot name";
  auto sim = make_role(clock, {"ouster.source=sim", "ouster.mount_z_m=0.62"});  // no metadata file: the sensor's own
  auto replay = make_role(clock, {"ouster.source=pcap", "ouster.metadata=" + kDir + "os1-64_legacy_metadata.json",
                                  "ouster.pcap=" + kDir + "OS-1-64_1024x10_fw20.pcap", "ouster.mount_z_m=0.62"});
  unregister_sim_lidar("ugv1");
  ASSERT_TRUE(sim.ok()) << sim.error().message;
  ASSERT_TRUE(replay.ok()) << replay.error().message;
  auto* s = dynamic_cast<OusterStage*>(sim.value()->stages().front().stage.get());
  auto* r = dynamic_cast<OusterStage*>(replay.value()->stages().front().stage.get());
  ASSERT_TRUE(s != nullptr && r != nullptr);
  {
#if AG_COUNT_ALLOC
    test_alloc::AllocationWindow w;
#endif
    s->step(kNsPerS);
#if AG_COUNT_ALLOC
    EXPECT_EQ(w.allocations(), 0u) << "step() allocated";
#endif
  }
  r->step(kNsPerS);
  EXPECT_EQ(link.queued(), 0u);
  EXPECT_EQ(s->counters().packets, 64u);
  EXPECT_EQ(s->counters().decode_errors, 0u);
  ASSERT_EQ(s->counters().scans, 1u);
  const LidarScanMsg& a = s->last_scan();
  const LidarScanMsg& b = r->last_scan();
  ASSERT_EQ(a.count, 16749u);
  ASSERT_EQ(a.count, b.count);
  for (std::uint32_t i = 0; i < a.count; ++i) {
    ASSERT_EQ(a.points[i].range, b.points[i].range) << i;
    ASSERT_EQ(a.points[i].x, b.points[i].x) << i;
    ASSERT_EQ(a.points[i].ring, b.points[i].ring) << i;
  }
  EXPECT_DOUBLE_EQ(a.sensor_in_body.z, 0.62);
  s->step(kNsPerS + kNsPerS / 20);  // nothing more sent: nothing more published, no error
  EXPECT_EQ(s->counters().scans, 1u);
  EXPECT_EQ(s->counters().source_errors, 0u);
}

}  // namespace
}  // namespace ag::ouster
