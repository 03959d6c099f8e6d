// The Ouster stage in a one-stage role (real config, real channels) replaying the real OS-1-64 capture:
// one step publishes the revolution as a "lidar_scan"; config errors name the key; the step does not
// allocate.
#include <gtest/gtest.h>

#include <memory>

#include "airground/drivers/ouster/stage.hpp"
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

}  // namespace
}  // namespace ag::ouster
