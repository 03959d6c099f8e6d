// The lockstep team runner: repeatable bit for bit by seed, sensor streams at their rates, robots move.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <utility>

#include "airground/sim/runner.hpp"

namespace ag::sim {
namespace {

namespace fs = std::filesystem;

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

RunOptions small_run(const std::string& dir, std::uint64_t seed) {
  RunOptions o;
  o.out_dir = (fs::path(::testing::TempDir()) / dir).string();
  o.seed = seed;
  o.ugvs = 2;
  o.duration_s = 6;
  o.camera_scale = 0.25;
  o.camera_hz = 2;
  o.lidar_columns = 512;
  o.record = RecordLevel::kLight;
  o.threads = 2;
  o.progress = false;
  return o;
}

// The same run on one thread (into `o.out_dir`) and on two (into the temp folder `dir2`).
std::pair<RunSummary, RunSummary> on_one_thread_and_two(RunOptions o, const std::string& dir2) {
  o.threads = 1;
  auto one = run_team(o);
  EXPECT_TRUE(one.ok()) << one.error().message;
  o.out_dir = (fs::path(::testing::TempDir()) / dir2).string();
  o.threads = 2;
  auto two = run_team(o);
  EXPECT_TRUE(two.ok()) << two.error().message;
  return {one.ok() ? one.value() : RunSummary{}, two.ok() ? two.value() : RunSummary{}};
}

const char* kStreams[] = {"truth_uav.csv", "gps_uav.csv", "vo_uav.csv", "camera_frames.csv", "truth_ugv1.csv",
                          "odom_ugv1.csv", "lidar_ugv1.csv", "truth_ugv2.csv", "odom_ugv2.csv", "lidar_ugv2.csv"};

TEST(TeamRunner, SameSeedGivesByteIdenticalRecordings) {
  auto a = run_team(small_run("run_a", 7));
  ASSERT_TRUE(a.ok()) << a.error().message;
  auto b = run_team(small_run("run_b", 7));
  ASSERT_TRUE(b.ok()) << b.error().message;
  for (const char* f : kStreams) {
    const std::string ta = slurp(fs::path(::testing::TempDir()) / "run_a" / f);
    ASSERT_GT(ta.size(), 40u) << f << " was recorded";
    EXPECT_EQ(ta, slurp(fs::path(::testing::TempDir()) / "run_b" / f)) << f << " differs between two runs of one seed";
  }
  // The camera frame the light recording keeps is identical too.
  EXPECT_EQ(slurp(fs::path(::testing::TempDir()) / "run_a" / "camera" / "frame_000001_rgb.png"),
            slurp(fs::path(::testing::TempDir()) / "run_b" / "camera" / "frame_000001_rgb.png"));
}

// With two threads the camera's next frame is rendered ahead, on a thread of its own, from a copy of the
// quadrotor stepped to the next exposure; with one, every frame renders when due. Every recording,
// the full camera frames and the binary scans included, is the same either way.
TEST(TeamRunner, FramesRenderedAheadEqualFramesRenderedWhenDue) {
  RunOptions o = small_run("ahead1", 4);
  o.record = RecordLevel::kFull;
  o.duration_s = 3;
  o.camera_hz = 3;  // a period off the 50 Hz physics grid: the exposure falls on the next physics step
  const auto [one_s, two_s] = on_one_thread_and_two(o, "ahead2");
  ASSERT_FALSE(HasFailure());
  const RunSummary* one = &one_s;
  const RunSummary* two = &two_s;
  ASSERT_EQ(one->camera_frames, two->camera_frames);
  ASSERT_GE(one->camera_frames, 9u);
  EXPECT_EQ(one->camera_frames_ahead, 0u);
  EXPECT_EQ(two->camera_frames_ahead, two->camera_frames - 1) << "every frame after the first was rendered ahead";
  const fs::path a = fs::path(::testing::TempDir()) / "ahead1", b = fs::path(::testing::TempDir()) / "ahead2";
  std::size_t files = 0;
  for (const auto& e : fs::recursive_directory_iterator(a)) {
    if (!e.is_regular_file()) continue;
    const fs::path rel = fs::relative(e.path(), a);
    const std::string name = rel.filename().string();
    if (name.rfind("summary", 0) == 0 || name == "report.md" || name.find("mission_log") != std::string::npos) continue;  // wall time, CPU
    ASSERT_TRUE(fs::exists(b / rel)) << rel;
    EXPECT_EQ(slurp(e.path()), slurp(b / rel)) << rel << " differs between one thread and two";
    ++files;
  }
  EXPECT_GE(files, 2u * one->camera_frames + 10u) << "every frame's PNGs, the CSVs and the scans were compared";
}

TEST(TeamRunner, DifferentSeedsGiveDifferentNoise) {
  auto a = run_team(small_run("seed_a", 1));
  auto b = run_team(small_run("seed_b", 2));
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_NE(slurp(fs::path(::testing::TempDir()) / "seed_a" / "gps_uav.csv"),
            slurp(fs::path(::testing::TempDir()) / "seed_b" / "gps_uav.csv"));
  EXPECT_NE(slurp(fs::path(::testing::TempDir()) / "seed_a" / "odom_ugv1.csv"),
            slurp(fs::path(::testing::TempDir()) / "seed_b" / "odom_ugv1.csv"));
}

TEST(TeamRunner, SensorsRunAtTheirRatesAndRobotsMove) {
  auto r = run_team(small_run("rates", 3));
  ASSERT_TRUE(r.ok()) << r.error().message;
  const RunSummary& s = r.value();
  EXPECT_EQ(s.camera_frames, 13u) << "2 Hz for 6 s, from t = 0";
  EXPECT_GE(s.gps_fixes, 25u) << "5 Hz minus any dropout";
  EXPECT_LE(s.gps_fixes, 31u);
  // Field mode: the quadrotor's own vo stage publishes one odometry per camera frame (the 10 Hz VO model
  // is the --oracle vo ablation).
  // The frame at 6 s is still being tracked when the run ends (its VO message shows after the stage's
  // compute time, docs/simulator.md): one message per frame, the last one possibly not yet out.
  EXPECT_LE(s.vo_samples, s.camera_frames) << "one VO message per frame";
  EXPECT_GE(s.vo_samples + 1, s.camera_frames) << "one VO message per frame";
  ASSERT_EQ(s.ugvs.size(), 2u);
  for (const auto& u : s.ugvs) {
    EXPECT_EQ(u.scans, 61u) << u.name;
    EXPECT_GT(u.distance_m, 1.0) << u.name << " drove its scripted route";
    EXPECT_EQ(u.collisions, 0u) << u.name << " follows roads without hitting anything";
  }
  EXPECT_GT(s.uav_distance_m, 5.0);
  EXPECT_GT(s.radio_delivered, 0u) << "robots on the staging pad hear each other";
  EXPECT_TRUE(fs::exists(fs::path(::testing::TempDir()) / "rates" / "trajectories.png"));
  EXPECT_TRUE(fs::exists(fs::path(::testing::TempDir()) / "rates" / "report.md"));
}

// The CPU figures count every thread: the sensor jobs run on the workers as well as the caller, so
// the LiDAR's CPU is the same work whether one thread or two run it, and the parts fit in the whole.
TEST(TeamRunner, CpuFiguresCountEveryThread) {
  RunOptions o = small_run("cpu1", 5);
  o.record = RecordLevel::kNone;
  o.lidar_columns = 1024;
  o.camera_hz = 5;
  const auto [one_s, two_s] = on_one_thread_and_two(o, "cpu2");
  ASSERT_FALSE(HasFailure());
  const RunSummary* one = &one_s;
  const RunSummary* two = &two_s;
  for (const RunSummary* s : {one, two}) {
    EXPECT_GT(s->camera_cpu_s, 0.0);
    EXPECT_GT(s->lidar_cpu_s, 0.0);
    EXPECT_DOUBLE_EQ(s->sensor_cpu_s, s->camera_cpu_s + s->lidar_cpu_s);
    ASSERT_EQ(s->robot_cpu_s.size(), 4u) << "uav, ugv1, ugv2, base";
    EXPECT_EQ(s->robot_cpu_s[0].first, "uav");
    EXPECT_EQ(s->robot_cpu_s[1].first, "ugv1");
    EXPECT_EQ(s->robot_cpu_s[3].first, "base");
    double parts = s->sensor_cpu_s;
    for (const auto& [name, cpu] : s->robot_cpu_s) {
      EXPECT_GT(cpu, 0.0) << name << " ran its stages";
      parts += cpu;
    }
    EXPECT_LE(parts, 1.02 * s->process_cpu_s + 0.01) << "the parts cannot exceed the process's CPU";
    EXPECT_GT(parts, 0.5 * s->process_cpu_s) << "sensors and stages are most of the work";
  }
  // Two threads share the scans; counting the caller's share alone would report about half.
  const double ratio = two->lidar_cpu_s / one->lidar_cpu_s;
  EXPECT_GT(ratio, 0.7) << "LiDAR CPU with 2 threads " << two->lidar_cpu_s << " s, with 1 " << one->lidar_cpu_s << " s";
  EXPECT_LT(ratio, 1.43);
}

TEST(TeamRunner, TheCapGrowsWithTheSurveyWhenAskedTo) {
  RunOptions o = small_run("cap", 1);
  o.ugvs = 0;
  o.record = RecordLevel::kNone;
  o.duration_s = 2;
  o.duration_survey_factor = 0.005;  // of a survey of the 400 m world: several seconds
  auto r = run_team(o);
  ASSERT_TRUE(r.ok()) << r.error().message;
  const RunSummary& s = r.value();
  ASSERT_GT(s.uav_route_estimate_s, 600.0) << "a lawnmower over the 400 m world at 40 m takes many minutes";
  EXPECT_NEAR(s.duration_cap_s, 0.005 * s.uav_route_estimate_s, 1e-9);
  EXPECT_NEAR(s.sim_s, s.duration_cap_s, 1e-6) << "the run went on past duration_s to the survey's share";
  o.duration_s = 1.5 * s.duration_cap_s;  // a longer duration_s still wins
  o.duration_survey_factor = 0.005;
  o.camera_hz = 1;
  auto longer = run_team(o);
  ASSERT_TRUE(longer.ok());
  EXPECT_NEAR(longer->sim_s, o.duration_s, 1e-6);
}

TEST(TeamRunner, RejectsBadOptionsAndMissingWorlds) {
  RunOptions o = small_run("bad", 1);
  o.lidar_columns = 700;
  EXPECT_FALSE(run_team(o).ok());
  o = small_run("bad", 1);
  o.world = "/nonexistent/world";
  auto r = run_team(o);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("/nonexistent/world"), std::string::npos) << r.error().message;
}

}  // namespace
}  // namespace ag::sim
