// Field mode in the simulator (issue 27): every simulated robot runs its shipped configuration
// (firmware_host/<role>/<role>.yaml) with only the keys the simulator must set changed, and its sensors
// give what real ones give — LiDAR points without classes — unless the user names the labels oracle.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include "airground/messages/messages.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/role_instance.hpp"
#include "airground/sim/runner.hpp"
#include "roles.hpp"
#include "saved_world.hpp"

namespace ag::sim {
namespace {

namespace fs = std::filesystem;

std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string shipped_path(std::string_view role) {
  return std::string(AG_SOURCE_DIR) + "/firmware_host/" + std::string(role) + "/" + std::string(role) + ".yaml";
}

// The keys the simulator may set, and why. Everything else must be the shipped file's value.
bool sim_may_set(const std::string& key, bool runner_feeds_map) {
  const std::string section = key.substr(0, key.find('.'));
  // A device stage on its simulated device: only the keys of its backend (role table: sim_backend). Its
  // mount, wheel geometry and everything else are the shipped file's: the simulated robot is the one the
  // file describes. A device stage without a sim backend the simulator replaces (any of its keys).
  for (const RoleDescription* role : {&uav_role(), &ugv_role(), &base_role()})
    for (const StageSpec& st : role->stages) {
      if (!st.device || st.name != section) continue;
      if (st.sim_backend.empty()) return true;
      for (std::string_view rest = st.sim_backend; !rest.empty();) {
        const auto comma = rest.find(',');
        const std::string_view kv = rest.substr(0, comma);
        if (key == section + "." + std::string(kv.substr(0, kv.find('=')))) return true;
        rest = comma == std::string_view::npos ? std::string_view{} : rest.substr(comma + 1);
      }
    }
  static const std::set<std::string> keys = {
      "robot.id", "robot.name",  // who the robot is in this team
      "status.log_counters",     // the runner reports the counters itself
      // the comms transport: the simulated radio (inproc), a key written for the run, no journal file
      "comms.transport", "comms.key_file", "comms.journal", "comms.epoch_from_clock",
      // the base station's page and log on the simulating machine
      "web.port", "web.bind", "web.log_path",
      // the mission area (the world's) and each robot's start and place in the team
      "regions.area_x0_m", "regions.area_y0_m", "regions.area_x1_m", "regions.area_y1_m",  //
      "planner.area_x0_m", "planner.area_y0_m", "planner.area_x1_m", "planner.area_y1_m",  //
      "localization.area_x0_m", "localization.area_y0_m", "localization.area_x1_m", "localization.area_y1_m",
      "mission.start_x_m", "mission.start_y_m", "mission.priority", "mission.survey_end_s",
      // the mission's datum (the world's), the map frame the receiver's fixes are given in
      "gps.datum_lat_deg", "gps.datum_lon_deg", "gps.datum_height_m"};
  if (keys.count(key) != 0) return true;
  // Without gossip the runner is the ground robots' map link (it writes their map_tiles).
  return runner_feeds_map && key == "comms.deliver_map_tiles";
}

std::string value_text(const Config& c, const std::string& key, ParamType t) {
  switch (t) {
    case ParamType::kBool: return c.get_bool(key) ? "true" : "false";
    case ParamType::kInt: return std::to_string(c.get_int(key));
    case ParamType::kReal: {
      std::ostringstream s;
      s.precision(17);
      s << c.get_real(key);
      return s.str();
    }
    case ParamType::kText: return c.get_text(key);
  }
  return {};
}

// Every key of the shipped file (read from the source tree) against the configuration the simulator gave
// the robot; returns the number of keys compared.
int expect_shipped(const RoleDescription& role, const Config& sim, bool runner_feeds_map, const std::string& robot) {
  const std::vector<ParamSection> schema = role_schema(role);
  auto shipped = Config::load_file(schema, shipped_path(role.name));
  EXPECT_TRUE(shipped.ok()) << shipped.error().message;
  if (!shipped.ok()) return 0;
  int compared = 0;
  for (const ParamSection& sec : schema)
    for (const ParamSpec& p : sec.params) {
      const std::string key = std::string(sec.name) + "." + std::string(p.key);
      EXPECT_TRUE(sim.has(key)) << robot << ": the simulator's configuration lacks " << key;
      if (!sim.has(key)) continue;
      const std::string want = value_text(shipped.value(), key, p.type), got = value_text(sim, key, p.type);
      if (key == "segmentation.weights") {  // the same file: the installed one, or the source tree's copy the package installs
        EXPECT_EQ(read_file(got), read_file(std::string(AG_SOURCE_DIR) + "/config/erfnet/erfnet_c7.agw")) << robot << ": " << got;
        EXPECT_FALSE(read_file(got).empty()) << got;
        continue;
      }
      if (sim_may_set(key, runner_feeds_map)) continue;
      ++compared;
      EXPECT_EQ(got, want) << robot << ": " << key << " differs from " << shipped_path(role.name);
    }
  return compared;
}

class ShippedConfig : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    saved_ = new test::SavedWorld("shipped_config");
    ASSERT_TRUE(saved_->ok()) << saved_->error();
  }
  static void TearDownTestSuite() {
    delete saved_;
    saved_ = nullptr;
  }
  // A mission's team (gossip over the radio, the robots' own stages drive) for a moment.
  static RunOptions mission(const std::string& out) {
    RunOptions o;
    o.world = saved_->dir();
    o.out_dir = (fs::path(::testing::TempDir()) / ("shipped_config_" + out)).string();
    o.ugvs = 2;
    o.seed = 2;
    o.duration_s = 0.5;
    o.lidar_columns = 512;
    o.record = RecordLevel::kNone;
    o.threads = 2;
    o.progress = false;
    o.gossip = true;
    o.drive_by_stages = true;
    o.uav_return_home = true;
    o.ugv_survey_end = true;
    o.ugv_config_for = [](int i, const Pose2& start) {
      return std::vector<std::string>{"mission.priority=" + std::to_string(i + 1), "mission.start_x_m=" + std::to_string(start.x),
                                      "mission.start_y_m=" + std::to_string(start.y)};
    };
    return o;
  }
  static inline test::SavedWorld* saved_{nullptr};
};

TEST_F(ShippedConfig, TheBuiltInFilesAreTheSourceTreesFiles) {
  for (const char* role : {"uav", "ugv", "base"}) {
    const std::string file = read_file(shipped_path(role));
    ASSERT_FALSE(file.empty()) << shipped_path(role);
    EXPECT_EQ(std::string(shipped_config_yaml(role)), file) << role << ": rebuild airground-sim (the file is embedded at configure time)";
  }
  EXPECT_TRUE(shipped_config_yaml("rover").empty());
}

TEST_F(ShippedConfig, EveryRobotRunsTheShippedFileExceptTheKeysTheSimulatorMustSet) {
  for (const bool gossip : {true, false}) {
    RunOptions o = mission(gossip ? "mission" : "runner_map");
    o.gossip = gossip;
    if (!gossip) o.ugv_map = UgvMapSource::kGroundTruth;  // the runner is the map link (as eval localization)
    std::vector<Config> got;
    o.inspect = [&](const RunInspection& in) {
      if (in.role_configs != nullptr) got = *in.role_configs;
      return ok_status();
    };
    auto r = run_team(o);
    ASSERT_TRUE(r.ok()) << r.error().message;
    ASSERT_EQ(got.size(), 4u) << "the quadrotor, two ground robots, the base station";
    const bool feeds = !gossip;
    EXPECT_GT(expect_shipped(uav_role(), got[0], feeds, "uav"), 100);
    EXPECT_GT(expect_shipped(ugv_role(), got[1], feeds, "ugv1"), 100);
    EXPECT_GT(expect_shipped(ugv_role(), got[2], feeds, "ugv2"), 100);
    EXPECT_GT(expect_shipped(base_role(), got[3], feeds, "base"), 20);
    // Field mode: classes from the robots' own ErfNet and geometric labeller.
    EXPECT_EQ(got[0].get_text("segmentation.labels"), "erfnet");
    EXPECT_EQ(got[0].get_text("ortho_map.keyframes_channel"), "keyframes_labelled");
    EXPECT_EQ(got[0].get_text("camera.source"), "sim") << "the quadrotor's own camera stage reads the simulated camera (RGB only)";
    EXPECT_EQ(got[1].get_text("localization.labels"), "geometric");
    EXPECT_EQ(got[1].get_text("lidar.classes"), "none");
    EXPECT_EQ(got[1].get_text("lidar.source"), "sim") << "the robot's own lidar stage runs on the simulated Ouster";
    EXPECT_EQ(got[0].get_text("gps.source"), "sim") << "the quadrotor's own gps stage reads the simulated u-blox";
    EXPECT_EQ(got[0].get_text("autopilot.source"), "sim") << "and its autopilot stage the simulated PX4's MAVLink";
    EXPECT_EQ(got[1].get_text("base.can_backend"), "sim") << "the robot's own base stage drives the simulated ODrives over CAN";
    EXPECT_EQ(got[1].get_real("lidar.mount_z_m"), RunOptions{}.lidar_mount_height_m) << "the simulated LiDAR is mounted where the file says";
    if (gossip) {
      EXPECT_EQ(got[1].get_text("comms.transport"), "inproc");
      EXPECT_TRUE(got[1].get_bool("comms.deliver_map_tiles"));
    } else {
      EXPECT_EQ(got[1].get_text("comms.transport"), "none");
      EXPECT_FALSE(got[1].get_bool("comms.deliver_map_tiles")) << "the runner writes the map tiles";
    }
    EXPECT_EQ(got[1].get_int("robot.id"), 1);
    EXPECT_EQ(got[2].get_text("robot.name"), "ugv2");
    // The mission area is the world's for the regions (not the shipped +-500 m, which would drop a bigger
    // map's tiles); the localizer's and the planner's geofence are the area the quadrotor surveys, where
    // its map is (the world less the 20 m survey margin), and the world's when the runner hands the
    // robots the true map.
    const GridGeometry& g = saved_->world()->grid();
    const double in = gossip ? RunOptions{}.survey_margin_m : 0.0;
    for (const auto& [cfg, section, m] : {std::tuple{&got[1], "localization", in}, std::tuple{&got[1], "planner", in}, std::tuple{&got[0], "regions", 0.0}}) {
      EXPECT_NEAR(cfg->get_real(std::string(section) + ".area_x0_m"), g.origin_x + m, 1e-3) << section;
      EXPECT_NEAR(cfg->get_real(std::string(section) + ".area_x1_m"), g.origin_x + g.size_x() - m, 1e-3) << section;
      EXPECT_NEAR(cfg->get_real(std::string(section) + ".area_y0_m"), g.origin_y - g.size_y() + m, 1e-3) << section;
      EXPECT_NEAR(cfg->get_real(std::string(section) + ".area_y1_m"), g.origin_y - m, 1e-3) << section;
    }
  }
}

// The LiDAR gives range, XYZ and reflectivity, never a class; --oracle labels hands over the world's.
TEST_F(ShippedConfig, ScansCarryNoClassesUnlessTheLabelsOracleIsNamed) {
  for (const bool oracle : {false, true}) {
    RunOptions o = mission(oracle ? "oracle_scans" : "field_scans");
    if (oracle) o.oracles = {"labels"};
    std::uint64_t scans = 0, points = 0, classed = 0;
    o.ugv_tap.scan = [&](int, const LidarScanMsg& m) {
      ++scans;
      EXPECT_EQ(m.labels, oracle ? LabelSource::kGroundTruth : LabelSource::kNone);
      for (std::uint32_t k = 0; k < m.count; ++k) classed += m.points[k].cls != 255 ? 1u : 0u;
      points += m.count;
    };
    std::vector<Config> got;
    o.inspect = [&](const RunInspection& in) {
      got = *in.role_configs;
      return ok_status();
    };
    auto r = run_team(o);
    ASSERT_TRUE(r.ok()) << r.error().message;
    ASSERT_GT(scans, 0u);
    ASSERT_GT(points, 1000u);
    if (oracle) {
      EXPECT_GT(classed, points / 2) << "the world's classes on most returns";
      EXPECT_EQ(got[0].get_text("segmentation.labels"), "gt");
      EXPECT_EQ(got[1].get_text("localization.labels"), "gt");
      EXPECT_EQ(got[1].get_text("lidar.classes"), "reflectivity") << "the oracle's class rides in the reflectivity byte";
    } else {
      EXPECT_EQ(classed, 0u) << "no class in field mode";
    }
  }
}

// A configuration the simulated robot's sensors cannot serve is refused at start, naming the keys.
TEST_F(ShippedConfig, LabelsTheSensorsCannotGiveAreRefusedAtStart) {
  RunOptions o = mission("refused_ugv");
  o.ugv_config = {"localization.labels=gt"};
  auto r = run_team(o);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("localization.labels: gt"), std::string::npos) << r.error().message;
  EXPECT_NE(r.error().message.find("lidar.classes: none"), std::string::npos) << r.error().message;
  EXPECT_NE(r.error().message.find("ugv.yaml"), std::string::npos) << r.error().message;
  RunOptions u = mission("refused_uav");
  u.uav_config = {"segmentation.labels=gt"};
  auto ru = run_team(u);
  ASSERT_FALSE(ru.ok());
  EXPECT_NE(ru.error().message.find("segmentation.labels: gt"), std::string::npos) << ru.error().message;
  RunOptions ok = mission("oracle_gt");
  ok.oracles = {"labels"};
  ok.ugv_config = {"localization.labels=gt"};
  EXPECT_TRUE(run_team(ok).ok()) << "with the labels oracle the scans carry classes";
}

// A mission's guesses are up to init_error_m off (uniform per robot); the localizer is told a sigma that
// makes that bound 2 sigma, not a sigma as wide as the bound (which put a wrong mode 34 m up the imported
// world's road within the filter's reach: docs/localization.md), unless the caller names one.
TEST_F(ShippedConfig, AGuessUpTo16mOffIsGivenWithSigma8mUnlessOneIsNamed) {
  for (const double named : {0.0, 5.0}) {
    RunOptions o = mission(named > 0 ? "named_sigma" : "guess_sigma");
    o.init_error_m = 16;
    o.init_error_uniform = true;
    o.init_sigma_m = named;
    std::map<int, InitialPoseMsg> inits;
    o.ugv_tap.initial_pose = [&](int ugv, const InitialPoseMsg& m) { inits[ugv] = m; };
    std::map<int, Pose2> start;
    o.sample = [&](const UgvSample& s) { start.emplace(s.ugv, s.truth); };
    auto r = run_team(o);
    ASSERT_TRUE(r.ok()) << r.error().message;
    ASSERT_EQ(inits.size(), 2u);
    ASSERT_EQ(start.size(), 2u);
    for (const auto& [ugv, m] : inits) {
      EXPECT_DOUBLE_EQ(m.sigma_xy_m, named > 0 ? named : 8.0) << "robot " << ugv;
      EXPECT_LE(std::hypot(m.pose.x - start[ugv].x, m.pose.y - start[ugv].y), 16.0 + 1e-9) << "robot " << ugv;
    }
  }
}

}  // namespace
}  // namespace ag::sim
