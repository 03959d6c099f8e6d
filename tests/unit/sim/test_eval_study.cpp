// The study summary: the table, the grids by team size and range, and the visit columns read from
// each run's metrics.json and visits.csv.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "airground/sim/eval_mission.hpp"

namespace ag::sim {
namespace {
namespace fs = std::filesystem;

void write(const fs::path& p, const std::string& text) {
  fs::create_directories(p.parent_path());
  std::ofstream(p) << text;
}

std::string read(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// A run's metrics.json with the keys the study reads; `visited` per robot.
std::string metrics(int ugvs, int range, int seed, double time, int regions_visited, std::initializer_list<int> visited) {
  std::ostringstream j;
  j << "{\"targets_total\": 3, \"targets_visited\": 3, \"regions_visited\": " << regions_visited << ", \"mission_time_s\": " << time
    << ", \"completed\": true, \"loc_error_mean_m\": 0.3, \"loc_error_p95_m\": 0.6, \"odom_only_error_mean_m\": 40, \"false_visits\": 0,"
    << " \"failed_goals\": 1, \"collisions\": 0, \"bytes_on_air\": 2e6, \"realtime_factor\": 2.5, \"ugvs\": " << ugvs
    << ", \"seed\": " << seed << ", \"comm_range_m\": " << range << ", \"robots\": [";
  bool first = true;
  for (const int v : visited) {
    j << (first ? "" : ", ") << "{\"visited\": " << v << "}";
    first = false;
  }
  j << "]}";
  return j.str();
}

TEST(Study, TablesCarryRepeatVisitsAndFirstAndLastVisitTimes) {
  const fs::path dir = fs::path(::testing::TempDir()) / "study-visits";
  fs::remove_all(dir);
  // Two robots at 50 m visit 3 regions 5 times (2 repeats); the two seeds' first visits average 1050 s.
  write(dir / "runs/u2_r50_s1/metrics.json", metrics(2, 50, 1, 2000, 3, {3, 2}));
  write(dir / "runs/u2_r50_s1/visits.csv",
        "t_s,robot,region,est_x_m,est_y_m,goal_x_m,goal_y_m,true_visit\n1100,ugv1,1,0,0,0,0,1\n1500.5,ugv2,2,0,0,0,0,1\n"
        "not-a-time,ugv2,3,0,0,0,0,1\n1300,ugv1,3,0,0,0,0,1\n");
  write(dir / "runs/u2_r50_s2/metrics.json", metrics(2, 50, 2, 1800, 3, {2, 1}));
  write(dir / "runs/u2_r50_s2/visits.csv", "t_s,robot,region,est_x_m,est_y_m,goal_x_m,goal_y_m,true_visit\n1000,ugv2,1,0,0,0,0,1\n");
  // One robot at 1000 m without visits.csv, nor a robots list: both unknown, not zero.
  write(dir / "runs/u1_r1000_s1/metrics.json",
        "{\"targets_total\": 3, \"targets_visited\": 3, \"mission_time_s\": 900, \"completed\": true, \"ugvs\": 1, \"seed\": 1, "
        "\"comm_range_m\": 1000}");

  auto s = summarise_study(dir.string());
  ASSERT_TRUE(s.ok()) << s.error().message;
  EXPECT_NE(s.value().find("3 missions"), std::string::npos) << s.value();

  const std::string csv = read(dir / "study.csv");
  EXPECT_NE(csv.find(",repeat_visits,first_visit_s,last_visit_s\n"), std::string::npos) << csv;
  EXPECT_NE(csv.find("u2_r50_s1,2,50,1,?,"), std::string::npos) << csv;  // oracles not recorded
  EXPECT_NE(csv.find(",2,1100,1500.5\n"), std::string::npos) << csv;  // the bad line is skipped
  EXPECT_NE(csv.find(",0,1000,1000\n"), std::string::npos) << csv;
  EXPECT_NE(csv.find(",-1,-1,-1\n"), std::string::npos) << csv;

  const std::string md = read(dir / "study.md");
  EXPECT_NE(md.find("| u2_r50_s1 | 2 | 50 | 1 | 3 / 3 | yes | 2000 | 0.30 / 0.60 | 40.0 | 0 | 2 | 1100 / 1500 | 1 | 0 | 2.0 | 2.50 |"),
            std::string::npos)
      << md;
  EXPECT_NE(md.find("| u1_r1000_s1 | 1 | 1000 | 1 | 3 / 3 | yes | 900 |"), std::string::npos) << md;
  EXPECT_NE(md.find("| – | – |"), std::string::npos) << md;  // unknown repeat visits and visit times
  // The grids: columns 50 m and 1000 m; the first-visit grid averages the seeds (1100, 1000), the
  // repeat grid too (2, 0); the one-robot row has no figure at 50 m.
  const auto first = md.find("First visit [s] by team size");
  const auto repeat = md.find("Repeat visits by team size");
  ASSERT_NE(first, std::string::npos) << md;
  ASSERT_NE(repeat, std::string::npos) << md;
  EXPECT_NE(md.find("| 2 | 1050 | – |", first), std::string::npos) << md;
  EXPECT_NE(md.find("| 1 | – | – |", first), std::string::npos) << md;
  EXPECT_NE(md.find("| 2 | 1.0 | – |", repeat), std::string::npos) << md;
  EXPECT_TRUE(fs::exists(dir / "mission_time.png"));
}

// Every table says which ground truth reached the robots: none (field mode) or the oracles named.
TEST(Study, TablesListTheOraclesOfEveryMission) {
  const fs::path dir = fs::path(::testing::TempDir()) / "study-oracles";
  fs::remove_all(dir);
  auto with = [](std::string m, const std::string& oracles) { return m.insert(1, "\"oracles\": " + oracles + ", "); };
  write(dir / "runs/u1_r150_s1/metrics.json", with(metrics(1, 150, 1, 1000, 3, {3}), "[]"));
  write(dir / "runs/u1_r150_s2/metrics.json", with(metrics(1, 150, 2, 1000, 3, {3}), "[]"));
  ASSERT_TRUE(summarise_study(dir.string()).ok());
  EXPECT_NE(read(dir / "study.csv").find("u1_r150_s1,1,150,1,none,"), std::string::npos) << read(dir / "study.csv");
  EXPECT_EQ(read(dir / "study.md").find("# airground study\n\nField mode: no ground truth reached a robot"), 0u) << read(dir / "study.md");

  write(dir / "runs/u1_r150_s2/metrics.json", with(metrics(1, 150, 2, 1000, 3, {3}), "[\"labels\", \"vo\"]"));
  ASSERT_TRUE(summarise_study(dir.string()).ok());
  const std::string csv = read(dir / "study.csv"), md = read(dir / "study.md");
  EXPECT_NE(csv.find("u1_r150_s2,1,150,2,labels+vo,"), std::string::npos) << csv;
  EXPECT_EQ(md.find("# airground study\n\nABLATION"), 0u) << md;
  EXPECT_NE(md.find("- oracles labels+vo: 1 mission (u1_r150_s2)"), std::string::npos) << md;
  EXPECT_NE(md.find("- oracles none: 1 mission (u1_r150_s1)"), std::string::npos) << md;
}

TEST(Study, SeveralWorldsGetATableByWorld) {
  const fs::path dir = fs::path(::testing::TempDir()) / "study-worlds";
  fs::remove_all(dir);
  auto in = [](std::string m, const std::string& world, int visited) {
    m.insert(1, "\"world\": \"" + world + "\", ");
    const std::string key = "\"targets_visited\": 3";
    return m.replace(m.find(key), key.size(), "\"targets_visited\": " + std::to_string(visited));
  };
  write(dir / "runs/default_u1_r150_s1/metrics.json", in(metrics(1, 150, 1, 1000, 3, {3}), "default", 3));
  write(dir / "runs/default_u1_r150_s2/metrics.json", in(metrics(1, 150, 2, 1200, 3, {3}), "default", 3));
  write(dir / "runs/w2_u1_r150_s1/metrics.json", in(metrics(1, 150, 1, 1400, 2, {2}), "/data/worlds/w2", 2));
  ASSERT_TRUE(summarise_study(dir.string()).ok());
  const std::string csv = read(dir / "study.csv"), md = read(dir / "study.md");
  EXPECT_NE(csv.find("w2_u1_r150_s1,1,150,1,?,/data/worlds/w2,3,2,"), std::string::npos) << csv;
  EXPECT_NE(md.find("By world:"), std::string::npos) << md;
  EXPECT_NE(md.find("| default | 2 | 2 | 6 / 6 | 2 |"), std::string::npos) << md;
  EXPECT_NE(md.find("| /data/worlds/w2 | 1 | 0 | 2 / 3 | 1 |"), std::string::npos) << md;
  EXPECT_TRUE(fs::exists(dir / "targets_by_world.png"));
  // One world: no table by world.
  fs::remove_all(dir / "runs/w2_u1_r150_s1");
  fs::remove(dir / "targets_by_world.png");
  ASSERT_TRUE(summarise_study(dir.string()).ok());
  EXPECT_EQ(read(dir / "study.md").find("By world:"), std::string::npos);
  EXPECT_FALSE(fs::exists(dir / "targets_by_world.png"));
}

}  // namespace
}  // namespace ag::sim
