// The u-blox stage in a one-stage role replaying the real ZED-F9P log: each NAV-PVT becomes a "gps"
// fix in the map frame around the datum; the WGS-84 to ENU conversion against the meridian arc; NMEA
// fallback; step() does not allocate.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <iterator>
#include <memory>
#include <span>
#include <vector>

#include "airground/drivers/gps/ublox/stage.hpp"
#include "airground/platform/role_instance.hpp"

#if AG_COUNT_ALLOC
#include "../../../common/counting_new.hpp"
#endif

namespace ag::ublox {
namespace {

inline constexpr StageSpec kStages[] = {
    {"gps", &UbloxStage::make, 10.0, 2'000, 40, -1, UbloxStage::kParams, "the stage under test"},
};
inline constexpr RoleDescription kRole{"uav", "u-blox stage rig", kStages, {}};
const std::string kLog = std::string(AG_TEST_DATA_DIR) + "/gps/ublox-zed-f9p-rtk.log";

Result<std::unique_ptr<RoleInstance>> make_role(SimClock& clock, std::vector<std::string> sets) {
  static const std::vector<ParamSection> schema = role_schema(kRole);
  Config cfg = Config::defaults(schema);
  for (const std::string& s : sets) EXPECT_TRUE(cfg.set(s).ok()) << s;
  return RoleInstance::create(kRole, cfg, clock, "uav");
}

TEST(UbloxStage, ReplayPublishesFixesAroundTheDatum) {
  SimClock clock(0);
  // Datum 10 m south and 0.0001 deg west of the antenna (the header: 47.1290927 N 15.2120432 E).
  auto r = make_role(clock, {"gps.source=replay", "gps.replay=" + kLog, "gps.datum_lat_deg=47.12900", "gps.datum_lon_deg=15.21194",
                             "gps.datum_height_m=860.0", "gps.max_bytes_per_step=65536"});
  ASSERT_TRUE(r.ok()) << r.error().message;
  auto role = std::move(r).value();
  auto* stage = dynamic_cast<UbloxStage*>(role->stages().front().stage.get());
  ASSERT_NE(stage, nullptr);
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
  EXPECT_EQ(stage->counters().nav_pvt, 10u);
  EXPECT_EQ(stage->counters().fixes_published, 10u);
  EXPECT_EQ(stage->counters().gga, 0u);
  const GpsMsg& m = stage->last_fix();
  EXPECT_EQ(m.fix_type, 3);
  // 0.0000926 deg of latitude north, 0.0001032 deg east at 47.13 N.
  const double phi = 47.129 * M_PI / 180, e2 = 0.00669437999014;
  const double M = 6378137.0 * (1 - e2) / std::pow(1 - e2 * std::sin(phi) * std::sin(phi), 1.5);
  const double N = 6378137.0 / std::sqrt(1 - e2 * std::sin(phi) * std::sin(phi));
  EXPECT_NEAR(m.north_m, M * (47.1290926 - 47.12900) * M_PI / 180, 0.05);
  EXPECT_NEAR(m.east_m, N * std::cos(phi) * (15.2120431 - 15.21194) * M_PI / 180, 0.05);
  EXPECT_NEAR(m.up_m, 869.2 - 860.0, 0.1);
  EXPECT_GT(m.h_accuracy_m, 0.0);
  EXPECT_LT(m.h_accuracy_m, 1.0);
}

TEST(UbloxStage, NmeaFallbackAndConfigErrors) {
  const std::string path = std::string(::testing::TempDir()) + "ag_nmea_only.log";
  {
    std::ofstream o(path);
    o << "$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47\r\n";
  }
  SimClock clock(0);
  auto r = make_role(clock, {"gps.source=replay", "gps.replay=" + path, "gps.datum_lat_deg=48.1173", "gps.datum_lon_deg=11.516666666666667",
                             "gps.datum_height_m=592.3"});
  ASSERT_TRUE(r.ok()) << r.error().message;
  auto* stage = dynamic_cast<UbloxStage*>(r.value()->stages().front().stage.get());
  ASSERT_NE(stage, nullptr);
  stage->step(kNsPerS);
  EXPECT_EQ(stage->counters().gga, 1u);
  EXPECT_NEAR(stage->last_fix().north_m, 0.0, 1e-3);
  EXPECT_NEAR(stage->last_fix().east_m, 0.0, 1e-3);
  EXPECT_NEAR(stage->last_fix().up_m, 0.0, 1e-3);
  EXPECT_NEAR(stage->last_fix().h_accuracy_m, 0.9 * 2.5, 1e-9);
  // An absent receiver is not a configuration error: the robot runs without fixes, counted.
  auto absent = make_role(clock, {"gps.source=serial", "gps.device=/dev/nonexistent-tty"});
  ASSERT_TRUE(absent.ok()) << absent.error().message;
  auto* a = dynamic_cast<UbloxStage*>(absent.value()->stages().front().stage.get());
  ASSERT_NE(a, nullptr);
  EXPECT_FALSE(a->active());
  EXPECT_EQ(a->counters().device_errors, 1u);
  a->step(kNsPerS);
  EXPECT_EQ(a->counters().fixes_published, 0u);
  Config cfg = Config::defaults(role_schema(kRole));
  const Status st = cfg.set("gps.source=usb");
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.error().message.find("gps.source"), std::string::npos) << st.error().message;
}

}  // namespace
}  // namespace ag::ublox

namespace ag::ublox {
namespace {

// The simulator's backend (source: sim): the real receiver's bytes through the in-process link give the
// fixes the recording gives; bytes past the link's capacity are dropped and counted (a UART overrun); a
// robot the simulator gave no receiver is a configuration error naming it.
TEST(UbloxStage, TheSimulatorsReceiverGivesWhatTheSameBytesGiveFromARecording) {
  SimClock clock(0);
  auto none = make_role(clock, {"gps.source=sim"});
  ASSERT_FALSE(none.ok());
  EXPECT_NE(none.error().message.find("gps.source is sim but the simulator gave robot 'uav' no receiver"), std::string::npos)
      << none.error().message;
  std::ifstream in(kLog, std::ios::binary);
  std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_GT(bytes.size(), 1000u);
  SimSerialLink link(bytes.size());
  EXPECT_EQ(link.write(bytes), bytes.size());
  EXPECT_EQ(link.write(std::span<const std::uint8_t>(bytes.data(), 10)), 0u) << "full: an overrun";
  EXPECT_EQ(link.dropped(), 10u);
  const std::vector<std::string> datum = {"gps.datum_lat_deg=47.12900", "gps.datum_lon_deg=15.21194", "gps.datum_height_m=860.0",
                                          "gps.max_bytes_per_step=65536"};
  ASSERT_TRUE(register_sim_gps("uav", &link));
  std::vector<std::string> sim_sets = datum, replay_sets = datum;
  sim_sets.push_back("gps.source=sim");
  replay_sets.push_back("gps.source=replay");
  replay_sets.push_back("gps.replay=" + kLog);
  auto sim = make_role(clock, sim_sets);
  auto replay = make_role(clock, replay_sets);
  unregister_sim_gps("uav");
  ASSERT_TRUE(sim.ok()) << sim.error().message;
  ASSERT_TRUE(replay.ok()) << replay.error().message;
  auto* s = dynamic_cast<UbloxStage*>(sim.value()->stages().front().stage.get());
  auto* r = dynamic_cast<UbloxStage*>(replay.value()->stages().front().stage.get());
  ASSERT_TRUE(s != nullptr && r != nullptr);
  s->step(kNsPerS);
  r->step(kNsPerS);
  EXPECT_EQ(link.queued(), 0u);
  EXPECT_EQ(s->counters().nav_pvt, 10u);
  EXPECT_EQ(s->counters().fixes_published, r->counters().fixes_published);
  EXPECT_EQ(s->last_fix().east_m, r->last_fix().east_m);
  EXPECT_EQ(s->last_fix().north_m, r->last_fix().north_m);
  EXPECT_EQ(s->last_fix().h_accuracy_m, r->last_fix().h_accuracy_m);
}

}  // namespace
}  // namespace ag::ublox
