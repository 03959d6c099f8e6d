// Team mission (issue 8): a quadrotor surveys a generated 200 m world with three parked-car clusters and
// finds them; two GPS-denied ground robots start with guesses up to 16 m off, get the map and each other's
// claims only over the simulated radio's gossip, claim, drive and visit through their real stages. Mid
// mission the base station is powered off, and then ground robot 2 while it drives to its claimed region:
// ground robot 1 must take that region over and the mission must still reach every target. While it runs,
// headless chromium loads the base station's live page (the browser test of issue 8).
#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>

#include "airground/sim/eval_mission.hpp"
#include "airground/sim/generator.hpp"
#include "mission_world.hpp"

namespace ag::sim {
namespace {

namespace fs = std::filesystem;

// The bars: every target reached, no false visit, localization error after convergence <= 1.5 m.
constexpr double kLocErrorBoundM = 1.5;
// When the kills happen [s] (this seed: robot 2 claims its first region at ~105 s and reaches it at ~200 s).
constexpr double kBaseOffS = 60;
constexpr double kUgv2OffS = 150;

// A TCP port free on loopback now (the base station's page binds it a moment later).
int free_port() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof a;
  int port = 0;
  if (fd >= 0 && ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0 && ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) == 0)
    port = ntohs(a.sin_port);
  if (fd >= 0) ::close(fd);
  return port;
}

std::string in_path(const std::string& exe) {
  const char* p = std::getenv("PATH");
  std::string path = p != nullptr ? p : "/usr/bin:/bin";
  for (std::size_t i = 0; i <= path.size();) {
    const std::size_t j = std::min(path.find(':', i), path.size());
    const fs::path c = fs::path(path.substr(i, j - i)) / exe;
    if (!c.empty() && ::access(c.c_str(), X_OK) == 0) return c.string();
    i = j + 1;
  }
  return {};
}

fs::path out_root() {
  const char* b = std::getenv("AG_BINARY_DIR");
  return fs::path(b != nullptr ? b : fs::temp_directory_path().string()) / "mission-team";
}

struct MissionRun {
  static void run() {
    const fs::path root = out_root();
    fs::create_directories(root);
    const fs::path world_dir = root / "world";
    const std::string saved = test::save_mission_world(world_dir.string());
    ASSERT_TRUE(saved.empty()) << saved;

    MissionOptions o;
    o.world = world_dir.string();
    o.out_dir = (root / "run").string();
    o.ugvs = 2;
    o.seed = 3;
    o.uav_altitude_m = 60;  // the paper's study altitude: a shorter survey
    o.lidar_columns = 512;
    o.max_duration_s = 1200;
    o.record = RecordLevel::kNone;
    o.threads = 2;
    o.progress = false;
    o.kills = {{-1, kBaseOffS}, {1, kUgv2OffS}};
    // Pinned to the labels ablation: this holds the comms, claims and takeover with the base station and
    // robot 2 powered off. In field mode (ErfNet map, geometric scan labels; issue 27, 2026-12-05) the same
    // mission measured targets 1 / 3, not completed at the 1200 s cap, failed goals 13, false visits 0,
    // map class accuracy 0.958, loc error mean 1.49 m (tracking only 0.83 m), ugv1 tracking 22 % of the
    // time: the geometric labeller on this 200 m world with a 512-column LiDAR is the open problem.
    // Field mode is held by LocalizationMission.GeometricTwoClassLabelsConverge and sim_test_runner_shipped_config.
    o.oracles = {"labels"};
    // The browser test during the mission: at 40 s (the base station is still on) headless chromium loads
    // the base station's live page and checks that the map and both robots are drawn.
    const char* src = std::getenv("AG_SOURCE_DIR");
    const std::string node = in_path("node"), chromium = in_path("chromium");
    const std::string script = std::string(src != nullptr ? src : AG_TEST_SOURCE_DIR) + "/tests/browser/check_base_page.mjs";
    if (node.empty() || chromium.empty() || !fs::exists(fs::path(script).parent_path() / "node_modules" / "playwright-core" / "package.json")) {
      browser_skip_ = "node, chromium or playwright-core missing (tools/install-deps.sh installs them)";
    } else {
      o.web_port = free_port();
      o.during = [&, node, script](double t) {
        if (browser_rc_ != -100 || t < 40) return;
        const std::string cmd = "AG_CHROMIUM=" + chromium + " " + node + " " + script + " --url http://127.0.0.1:" + std::to_string(o.web_port) +
                                "/ --out " + (root / "browser").string() + " --tiles 10 --robots 2 --timeout-s 60 > " + (root / "browser.log").string() + " 2>&1";
        browser_rc_ = std::system(cmd.c_str());
      };
    }
    auto m = run_mission(o);
    ASSERT_TRUE(m.ok()) << m.error().message;
    metrics_ = std::make_unique<MissionMetrics>(std::move(m).value());
    out_ = o.out_dir;
  }
  static inline std::unique_ptr<MissionMetrics> metrics_;
  static inline std::string out_;
  static inline int browser_rc_{-100};  // the page check's exit status (-100: not run)
  static inline std::string browser_skip_;
};

// One test case for the one mission: ctest runs every test case in a process of its own, and each would
// fly the whole mission again. Each part below is one of the claims.
TEST(TeamMission, RegionInvestigationWithTheBaseStationAndOneRobotPoweredOff) {
  MissionRun::run();
  ASSERT_NE(MissionRun::metrics_, nullptr) << "the mission did not run";
  const MissionMetrics& m = *MissionRun::metrics_;
  const std::string& out_ = MissionRun::out_;
  const int browser_rc_ = MissionRun::browser_rc_;
  const std::string& browser_skip_ = MissionRun::browser_skip_;
  {
    SCOPED_TRACE("EveryTargetIsReachedWithoutAFalseVisit");
    EXPECT_EQ(m.targets_total, 3U);
    EXPECT_EQ(m.targets_visited, m.targets_total);
    EXPECT_EQ(m.false_visits, 0U);
    EXPECT_TRUE(m.completed) << "the remaining robot returned to its start before the cap (" << m.mission_time_s << " s)";
    EXPECT_EQ(m.collisions, 0U);
  }
  {
    SCOPED_TRACE("LocalizationStaysWithinTheBoundWhileOdometryAloneDrifts");
    EXPECT_GE(m.loc_error_mean_m, 0) << "no tracking sample";
    EXPECT_LE(m.loc_error_mean_m, kLocErrorBoundM) << "every sample after each robot's first good one, tracking or not";
    EXPECT_LE(m.loc.tracking_mean_m, m.loc_error_mean_m + 1e-9) << "the tracking-only figure leaves the excursions out";
    EXPECT_GE(m.loc.within_fraction, 0.9) << "within 3 m of the truth most of the time once localized";
    EXPECT_GT(m.loc.tracking_fraction, 0.0);
    EXPECT_GT(m.odom_only_error_mean_m, 3 * m.loc_error_mean_m) << "the map is what keeps the robots localized";
    for (const MissionRobot& r : m.robots) EXPECT_GT(r.first_tracking_s, 0) << r.name << " never tracked";
  }
  {
    SCOPED_TRACE("TheRobotsOwnStagesDroveAndTheMapCameOverTheRadio");
    EXPECT_GT(m.robots.at(0).distance_m, 100);
    EXPECT_GT(m.bytes_on_air, 1'000'000U) << "tiles, poses and claims travel as gossip";
    EXPECT_GT(m.map_class_accuracy, 0.9);
    EXPECT_GE(m.regions_found, 3U);
  }
  {
    SCOPED_TRACE("EveryRobotStageKeepsItsBudgetOnItsTargetCpu");
    // Compute time in lockstep (docs/simulator.md): each stage's modelled time on the paper's computers.
    EXPECT_EQ(m.compute_time, "model");
    EXPECT_GT(m.stages.size(), 20U) << "the stages of the quadrotor, the ground robots and the base station";
    for (const auto& c : m.stages) {
      EXPECT_EQ(c.overruns, 0U) << c.name << ": p99 " << c.exec_p99_ms << " ms against " << c.budget_ms << " ms";
      EXPECT_EQ(c.slips, 0U) << c.name;
    }
  }
  {
    SCOPED_TRACE("WithTheBaseStationOffAndRobot2OffRobot1TakesOverItsRegion");
    EXPECT_EQ(m.robots.size(), 2U);
    if (m.robots.size() == 2) {
      EXPECT_NEAR(m.robots[1].killed_s, kUgv2OffS, 0.1);
      EXPECT_LT(m.robots[0].killed_s, 0);
      EXPECT_GE(m.robots[0].visited, 2U);
    }
    EXPECT_GE(m.takeovers, 1U) << "robot 1 should claim the region robot 2 held when it fell silent";
    EXPECT_EQ(m.targets_visited, m.targets_total) << "and nothing is lost with the base station off";
  }
  {
    SCOPED_TRACE("ChromiumDrewTheMapAndBothRobotsOnTheBaseStationsPageDuringTheMission");
    if (!browser_skip_.empty()) {
      std::cout << "[  SKIPPED ] the browser check: " << browser_skip_ << "\n";
    } else {
      EXPECT_NE(browser_rc_, -100) << "the mission never reached 40 s";
      std::ifstream log(out_root() / "browser.log");
      std::stringstream ss;
      ss << log.rdbuf();
      EXPECT_EQ(browser_rc_, 0) << ss.str();
      EXPECT_TRUE(fs::exists(out_root() / "browser" / "base_station_page.png")) << "the screenshot is kept as an artefact";
    }
  }
  {
    SCOPED_TRACE("TheReportFolderHoldsTheFiguresMapsAndPlots");
    const fs::path d(out_);
    for (const char* f : {"metrics.json", "report.md", "mission_map.png", "pose_error.png", "claims_timeline.png", "comms_traffic.png",
                          "visits.csv", "regions.csv", "targets.csv", "maps/map_class.tif", "maps/map_rgb.png", "maps/map_elevation.tif",
                          "mission_log.jsonl"})
      EXPECT_TRUE(fs::exists(d / f) && fs::file_size(d / f) > 0) << f;
    std::ifstream j(d / "metrics.json");
    std::stringstream ss;
    ss << j.rdbuf();
    for (const char* k : {"targets_total", "targets_visited", "mission_time_s", "loc_error_mean_m", "loc_error_p95_m", "odom_only_error_mean_m",
                          "collisions", "failed_goals", "false_visits", "map_class_accuracy", "bytes_on_air", "realtime_factor",
                          "non_target_visits", "loc_error_max_m", "loc_error_tracking_mean_m", "tracking_fraction", "within_3m_fraction",
                          "compute_time", "stage_overruns", "stage_slips", "stages", "world"})
      EXPECT_NE(ss.str().find(std::string("\"") + k + "\""), std::string::npos) << k;
  }
}

}  // namespace
}  // namespace ag::sim
