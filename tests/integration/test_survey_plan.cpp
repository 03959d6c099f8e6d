// airground-sim survey-plan: the exported QGroundControl .plan read back (JSON), its waypoints taken back
// to the map frame and checked against the route the simulator flies; run's own survey.plan; bad options.
#include <gtest/gtest.h>
#include <unistd.h>

#include <GeographicLib/LocalCartesian.hpp>
#include <nlohmann/json.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "airground/sim/camera.hpp"
#include "airground/sim/survey.hpp"
#include "airground/sim/survey_plan.hpp"
#include "airground/sim/world.hpp"
#include "process.hpp"

namespace ag::test {
namespace {

namespace fs = std::filesystem;

// The world's datum, given to the generator here so that the test knows it without the world's files:
// south and west of Greenwich, where a sign error in latitude or longitude shows.
constexpr double kLat = -34.6037, kLon = -58.3816, kHeight = 25.0;

std::string sim_bin() { return binary_dir() + "/sim/airground-sim"; }
std::string tmp(const std::string& name) { return (fs::path(::testing::TempDir()) / ("survey-plan-" + name)).string(); }

nlohmann::json read_json(const std::string& path) {
  std::ifstream f(path);
  std::string text;
  std::getline(f, text, '\0');
  nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  EXPECT_FALSE(j.is_discarded()) << path << " is not JSON";
  return j;
}

// The small world every test here uses (generated once per process, into a folder of its own: ctest runs
// each test as a process, two at once with -j2, and a shared folder raced: "height.png: cannot write").
const std::string& world_dir() {
  static const std::string w = [] {
    const std::string dir = tmp("world-" + std::to_string(::getpid()));
    fs::remove_all(dir);
    const auto gen = run({sim_bin(), "world", "generate", "--seed", "7", "--size", "200", "--targets", "2", "--datum",
                          std::to_string(kLat) + "," + std::to_string(kLon) + "," + std::to_string(kHeight), "--out", dir},
                         60);
    EXPECT_EQ(gen.exit_code, 0) << gen.err;
    return dir;
  }();
  return w;
}

// A plan's NAV_WAYPOINT items in the map frame (x east, y north, z up from the datum), in file order.
struct PlanPoint {
  double x, y, z;
};
std::vector<PlanPoint> waypoints_in_map_frame(const nlohmann::json& plan, double home_z) {
  const GeographicLib::LocalCartesian enu(kLat, kLon, kHeight);
  std::vector<PlanPoint> out;
  for (const auto& item : plan["mission"]["items"]) {
    if (item["command"] != 16) continue;
    EXPECT_EQ(item["frame"], 3) << "waypoints are relative to home (MAV_FRAME_GLOBAL_RELATIVE_ALT)";
    const auto& p = item["params"];
    // The altitude is above home: back above the ellipsoid (home's height) to take it through the ENU frame.
    double x = 0, y = 0, z = 0;
    enu.Forward(p[4].get<double>(), p[5].get<double>(), kHeight + home_z + p[6].get<double>(), x, y, z);
    out.push_back({x, y, z});
  }
  return out;
}

TEST(SurveyPlan, ExportedWaypointsAreTheRouteTheSimulatorFlies) {
  const std::string plan_file = tmp("export.plan");
  const auto r = run({sim_bin(), "survey-plan", "--world", world_dir(), "--altitude", "50", "--overlap", "0.5", "--speed", "7", "--firmware",
                      "ardupilot", "--out", plan_file});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json plan = read_json(plan_file);
  ASSERT_TRUE(plan.is_object());
  EXPECT_EQ(plan["fileType"], "Plan");
  EXPECT_EQ(plan["version"], 1);
  EXPECT_EQ(plan["groundStation"], "QGroundControl");
  const auto& m = plan["mission"];
  EXPECT_EQ(m["version"], 2);
  EXPECT_EQ(m["firmwareType"], 3) << "ArduPilot (MAV_AUTOPILOT_ARDUPILOTMEGA)";
  EXPECT_EQ(m["vehicleType"], 2) << "quadrotor";
  EXPECT_DOUBLE_EQ(m["cruiseSpeed"].get<double>(), 7.0);
  EXPECT_DOUBLE_EQ(m["hoverSpeed"].get<double>(), 7.0);
  EXPECT_EQ(plan["geoFence"]["version"], 2);
  EXPECT_TRUE(plan["geoFence"]["polygons"].empty() && plan["geoFence"]["circles"].empty());
  EXPECT_EQ(plan["rallyPoints"]["version"], 2);
  EXPECT_TRUE(plan["rallyPoints"]["points"].empty());

  // The simulator's route: the function the team runner builds its quadrotor's waypoints with.
  auto world = sim::load_world(world_dir());
  ASSERT_TRUE(world) << world.error().message;
  const sim::CameraModel cam;
  const double hfov = 2.0 * std::atan(0.5 * cam.width / cam.fx);
  sim::UavSurveyOptions so;
  so.altitude_m = 50;
  so.overlap = 0.5;
  so.speed_mps = 7;
  auto route = sim::uav_survey_route(world.value(), so, hfov);
  ASSERT_TRUE(route) << route.error().message;
  const auto& wps = route.value();
  const Pose3 home = sim::uav_launch_pose(world.value());

  // Home: the staging pad, at the datum's height plus the terrain's.
  const auto& hp = m["plannedHomePosition"];
  ASSERT_EQ(hp.size(), 3u);
  const GeographicLib::LocalCartesian enu(kLat, kLon, kHeight);
  double hx = 0, hy = 0, hz = 0;
  enu.Forward(hp[0].get<double>(), hp[1].get<double>(), hp[2].get<double>(), hx, hy, hz);
  EXPECT_NEAR(hx, world.value().header.staging.x, 0.05);
  EXPECT_NEAR(hy, world.value().header.staging.y, 0.05);
  EXPECT_NEAR(hp[2].get<double>(), kHeight + home.z, 1e-6);

  // Items: take-off, speed, one waypoint per route point in order, return to launch; jump ids 1..n.
  const auto& items = m["items"];
  ASSERT_EQ(items.size(), wps.size() + 3);
  for (std::size_t i = 0; i < items.size(); ++i) {
    EXPECT_EQ(items[i]["type"], "SimpleItem");
    EXPECT_EQ(items[i]["doJumpId"], i + 1);
    EXPECT_EQ(items[i]["autoContinue"], true);
    EXPECT_EQ(items[i]["params"].size(), 7u);
  }
  EXPECT_EQ(items[0]["command"], 22);
  EXPECT_NEAR(items[0]["params"][6].get<double>(), 50.0 - home.z, 1e-9) << "take-off to the survey height above home";
  EXPECT_EQ(items[1]["command"], 178);
  EXPECT_DOUBLE_EQ(items[1]["params"][1].get<double>(), 7.0);
  EXPECT_EQ(items.back()["command"], 20);
  for (std::size_t i = 2; i + 1 < items.size(); ++i) {
    EXPECT_EQ(items[i]["command"], 16);
    EXPECT_DOUBLE_EQ(items[i]["params"][1].get<double>(), 1.0) << "acceptance radius: the quadrotor model's waypoint tolerance";
    EXPECT_TRUE(items[i]["params"][3].is_null()) << "yaw left to the autopilot";
  }

  const auto pts = waypoints_in_map_frame(plan, home.z);
  ASSERT_EQ(pts.size(), wps.size());
  for (std::size_t i = 0; i < pts.size(); ++i) {
    EXPECT_NEAR(pts[i].x, wps[i].x, 0.05) << "waypoint " << i;
    EXPECT_NEAR(pts[i].y, wps[i].y, 0.05) << "waypoint " << i;
    EXPECT_NEAR(items[i + 2]["params"][6].get<double>() + home.z, wps[i].z, 1e-9) << "waypoint " << i << ": altitude above home";
  }
  // The route itself, independently of the runner: east-west lines over the world minus 20 m, spaced by
  // the footprint and the overlap, from the south-west corner.
  const auto& g = world.value().grid();
  const double spacing = sim::survey_line_spacing(50, 0.5, hfov);
  ASSERT_GE(pts.size(), 4u);
  EXPECT_NEAR(pts[0].x, g.origin_x + 20, 0.05);
  EXPECT_NEAR(pts[1].x, g.origin_x + g.size_x() - 20, 0.05);
  EXPECT_LT(pts[0].y, pts[2].y) << "lines from south to north";
  for (std::size_t i = 0; i + 1 < pts.size(); i += 2) {
    EXPECT_NEAR(pts[i].y, pts[i + 1].y, 0.05) << "line " << i / 2 << " runs east-west";
    if (i >= 2) {
      EXPECT_NEAR(pts[i].y - pts[i - 2].y, spacing, 0.05) << "line " << i / 2;
    }
  }
}

TEST(SurveyPlan, RunWritesTheSamePlanAndItsQuadrotorFliesTowardTheFirstWaypoint) {
  const std::string plan_file = tmp("px4.plan");
  ASSERT_EQ(run({sim_bin(), "survey-plan", "--world", world_dir(), "--altitude", "50", "--overlap", "0.5", "--speed", "7", "--no-rtl", "--out",
                 plan_file})
                .exit_code,
            0);
  const std::string out = tmp("run");
  fs::remove_all(out);
  const auto r = run({sim_bin(), "run", "--world", world_dir(), "--ugvs", "0", "--duration", "4", "--altitude", "50", "--overlap", "0.5",
                      "--uav-speed", "7", "--record", "light", "--quiet", "--out", out},
                     60);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  ASSERT_TRUE(fs::exists(out + "/survey.plan"));
  const nlohmann::json exported = read_json(plan_file), flown = read_json(out + "/survey.plan");
  EXPECT_EQ(exported, flown) << "run (PX4, no return to launch) writes the plan survey-plan --no-rtl writes";

  // The quadrotor's true track (truth_uav.csv) closes on the plan's first waypoint.
  auto world = sim::load_world(world_dir());
  ASSERT_TRUE(world);
  const auto pts = waypoints_in_map_frame(flown, sim::uav_launch_pose(world.value()).z);
  ASSERT_FALSE(pts.empty());
  std::ifstream truth(out + "/truth_uav.csv");
  std::string line;
  std::getline(truth, line);
  std::vector<double> dist;
  while (std::getline(truth, line)) {
    double t = 0, x = 0, y = 0, z = 0;
    if (std::sscanf(line.c_str(), "%lf,%lf,%lf,%lf", &t, &x, &y, &z) == 4) dist.push_back(std::hypot(x - pts[0].x, y - pts[0].y, z - pts[0].z));
  }
  ASSERT_GE(dist.size(), 10u);
  EXPECT_LT(dist.back(), dist.front() - 5.0) << "4 s toward the first waypoint";
}

// The small world's pad lies 21.4 m from its south edge: inside the default 20 m survey margin, outside a
// 25 m one, where the ground robots would start off their map; the plan is still written, with a warning.
TEST(SurveyPlan, APadOutsideTheSurveyedAreaIsNamedAtStart) {
  auto world = sim::load_world(world_dir());
  ASSERT_TRUE(world) << world.error().message;
  sim::UavSurveyOptions so;
  EXPECT_EQ(sim::staging_outside_survey(world.value(), so), "");
  so.margin_m = 25;
  const std::string off = sim::staging_outside_survey(world.value(), so);
  EXPECT_NE(off.find("staging pad (-70.0, -78.6) lies 3.6 m outside"), std::string::npos) << off;
  so.x0 = -60, so.x1 = 60, so.y0 = -90, so.y1 = 60;  // an area of the user's: the pad is west of it
  EXPECT_NE(sim::staging_outside_survey(world.value(), so).find("lies 10.0 m outside the area the quadrotor surveys (x -60.0..60.0"),
            std::string::npos);

  const auto inside = run({sim_bin(), "survey-plan", "--world", world_dir(), "--out", tmp("inside.plan")});
  ASSERT_EQ(inside.exit_code, 0) << inside.err;
  EXPECT_EQ(inside.err.find("warning"), std::string::npos) << inside.err;
  const auto outside = run({sim_bin(), "survey-plan", "--world", world_dir(), "--margin", "25", "--out", tmp("outside.plan")});
  ASSERT_EQ(outside.exit_code, 0) << outside.err;
  EXPECT_NE(outside.err.find("warning: the ground robots' staging pad"), std::string::npos) << outside.err;
  EXPECT_TRUE(fs::exists(tmp("outside.plan")));
}

TEST(SurveyPlan, BadOptionsAreUsageErrors) {
  const std::string out = tmp("bad.plan");
  const std::vector<std::vector<std::string>> bad = {
      {"--out", out, "--bogus", "1"},       {"--world", world_dir()},          {"--out", out, "--firmware", "inav"},
      {"--out", out, "--overlap", "1.5"},   {"--out", out, "--altitude", "x"}, {"--out", out, "--area", "10,10,5,20"},
      {"--out", out, "--speed", "0"},       {"stray", "--out", out},           {"--out", out, "--altitude"},
  };
  for (const auto& args : bad) {
    std::vector<std::string> argv = {sim_bin(), "survey-plan"};
    argv.insert(argv.end(), args.begin(), args.end());
    const auto r = run(argv);
    std::string joined;
    for (const auto& a : args) joined += a + " ";
    EXPECT_EQ(r.exit_code, 2) << joined << r.err;
    EXPECT_NE(r.err.find("airground-sim survey-plan: "), std::string::npos) << joined << r.err;
  }
  EXPECT_NE(run({sim_bin(), "survey-plan", "--out", out, "--bogus", "1"}).err.find("'--bogus'"), std::string::npos);
  EXPECT_NE(run({sim_bin(), "survey-plan", "--help"}).out.find("--firmware px4|ardupilot"), std::string::npos);
  // Runtime failures are exit 1 with the cause: no such world, a margin that leaves nothing, an unwritable file.
  const auto no_world = run({sim_bin(), "survey-plan", "--world", tmp("no-such-world"), "--out", out});
  EXPECT_EQ(no_world.exit_code, 1);
  EXPECT_NE(no_world.err.find("no-such-world"), std::string::npos) << no_world.err;
  const auto margin = run({sim_bin(), "survey-plan", "--world", world_dir(), "--margin", "150", "--out", out});
  EXPECT_EQ(margin.exit_code, 1);
  EXPECT_NE(margin.err.find("margin"), std::string::npos) << margin.err;
  const auto unwritable = run({sim_bin(), "survey-plan", "--world", world_dir(), "--out", tmp("no-such-dir") + "/x.plan"});
  EXPECT_EQ(unwritable.exit_code, 1);
  EXPECT_NE(unwritable.err.find("x.plan"), std::string::npos) << unwritable.err;
}

// The study's options are strict too, and --slurm writes one array task per mission of the grid.
TEST(SurveyPlan, StudySlurmScriptHasOneTaskPerMission) {
  const std::string out = tmp("study"), sdir = tmp("slurm");
  fs::remove_all(out);
  fs::remove_all(sdir);
  EXPECT_EQ(run({sim_bin(), "study", "--bogus", "1"}).exit_code, 2);
  EXPECT_EQ(run({sim_bin(), "study", "--cpus-per-task", "2", "--out", out}).exit_code, 2) << "--cpus-per-task needs --slurm";
  EXPECT_EQ(run({sim_bin(), "study", "--slurm", sdir, "--report-only", "--out", out}).exit_code, 2);
  const auto r = run({sim_bin(), "study", "--world", world_dir(), "--ugvs", "1,2", "--comm-range", "150", "--seeds", "2", "--max-duration", "30",
                      "--out", out, "--slurm", sdir, "--jobs", "2"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::ifstream f(sdir + "/study.sbatch");
  std::string s;
  std::getline(f, s, '\0');
  EXPECT_NE(s.find("#SBATCH --array=0-3%2\n"), std::string::npos) << s;
  for (const char* run_name : {"u1_r150_s1", "u1_r150_s2", "u2_r150_s1", "u2_r150_s2"})
    EXPECT_NE(s.find("/runs/" + std::string(run_name) + " --threads \"$threads\""), std::string::npos) << run_name;
  EXPECT_EQ(run({"/bin/bash", "-n", sdir + "/study.sbatch"}).exit_code, 0) << "the script parses";
  const auto no_task = run({"/bin/bash", sdir + "/study.sbatch"});
  EXPECT_NE(no_task.exit_code, 0) << "outside Slurm (no SLURM_ARRAY_TASK_ID) it refuses";
  EXPECT_FALSE(fs::exists(out + "/runs/u1_r150_s1")) << "writing the script runs nothing";
}

// --worlds: the grid on each world, each mission with its own --world and a folder tagged by world.
TEST(SurveyPlan, StudyOnSeveralWorldsRunsTheGridOnEach) {
  const std::string out = tmp("study-worlds"), sdir = tmp("slurm-worlds");
  fs::remove_all(out);
  fs::remove_all(sdir);
  const auto r = run({sim_bin(), "study", "--worlds", "default," + world_dir(), "--ugvs", "1", "--comm-range", "150", "--seeds", "2", "--out", out,
                      "--slurm", sdir});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::ifstream f(sdir + "/study.sbatch");
  std::string s;
  std::getline(f, s, '\0');
  EXPECT_NE(s.find("#SBATCH --array=0-3"), std::string::npos) << s;
  const std::string tag = fs::path(world_dir()).filename().string();
  for (const std::string& run_name : {std::string("default_u1_r150_s1"), std::string("default_u1_r150_s2"), tag + "_u1_r150_s1", tag + "_u1_r150_s2"})
    EXPECT_NE(s.find("/runs/" + run_name + " --threads"), std::string::npos) << run_name << "\n" << s;
  EXPECT_NE(s.find("--world default "), std::string::npos) << s;
  EXPECT_NE(s.find("--world " + fs::absolute(world_dir()).lexically_normal().string() + " "), std::string::npos) << s;
  EXPECT_EQ(run({sim_bin(), "study", "--worlds", "default,/no/such/world", "--out", out, "--slurm", sdir}).exit_code, 2);
  EXPECT_EQ(run({sim_bin(), "study", "--world", "default", "--worlds", "default", "--out", out, "--slurm", sdir}).exit_code, 2);
}

}  // namespace
}  // namespace ag::test
