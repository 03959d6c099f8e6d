// Timing: the ground robot's stages keep their budgets in the lockstep runner while it localizes from a
// guess 16 m / 30 deg off on the default world's roads with a 64x1024 LiDAR at 10 Hz (issue 5). Thread
// CPU time of each step(), p99 against the role table's budget scaled by the calibration workload timed
// in the same process (README.md here).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "airground/drivers/recording/recorder/recorder_stage.hpp"
#include "airground/localization/stage.hpp"
#include "airground/platform/calibration.hpp"
#include "airground/platform/perf_counters.hpp"
#include "airground/platform/role_instance.hpp"
#include "airground/sim/eval_localization.hpp"
#include "airground/sim/generator.hpp"
#include "airground/sim/runner.hpp"
#include "airground/sim/world.hpp"

namespace ag::sim {
namespace {

namespace fs = std::filesystem;

struct Measured {
  std::string stage;
  StagePerfSnapshot s;
};

// Runs one ground robot localizing for `duration_s` and checks every stage's p99 against its scaled
// budget; `config` overrides its parameters ("{root}": the test's folder); `recorder` (when given)
// receives the recorder stage's counters.
void check_ugv_budgets(const std::string& name, double duration_s, std::vector<std::string> config, std::uint64_t min_matched,
                       bool expect_tracking, recording::RecorderCounters* recorder = nullptr) {
  const char* b = std::getenv("AG_BINARY_DIR");
  const fs::path root = fs::path(b != nullptr ? b : fs::temp_directory_path().string()) / name;
  for (std::string& c : config)
    if (const std::size_t at = c.find("{root}"); at != std::string::npos) c.replace(at, 6, root.string());
  fs::remove_all(root / "recording");  // the recorder's files of an earlier run
  fs::create_directories(root);
  auto loop = plan_road_loop(default_world(), 300, 1);
  ASSERT_TRUE(loop.ok()) << loop.error().message;

  RunOptions o;
  o.world = "default";
  o.out_dir = (root / "run").string();
  o.uav = false;
  o.ugvs = 1;
  o.duration_s = duration_s;
  o.ugv_config = config;
  o.record = RecordLevel::kNone;
  o.compute_time = ComputeTimeMode::kOff;  // the stages' measured step times, not the simulator's model of them
  o.progress = false;
  o.ugv_map = UgvMapSource::kGroundTruth;
  o.init_error_m = 16;
  o.init_yaw_error_deg = 30;
  o.ugv_routes = {loop.value()};
  o.sample_hz = 1;
  std::vector<Measured> measured;
  std::uint64_t matched = 0;
  LocalizationStatus status = LocalizationStatus::kNoMap;
  o.sample = [&](const UgvSample& s) {  // the role dies with the run: take the counters at every sample
    measured.clear();
    for (auto& slot : s.role->stages()) {
      if (slot.spec->name == "sim_probe") continue;  // the simulator's reader, not the robot's
      measured.push_back(Measured{std::string(slot.spec->name), snapshot(*slot.perf)});
      if (auto* l = dynamic_cast<const loc::LocalizationStage*>(slot.stage.get())) matched = l->counters().scans_matched;
      if (auto* rec = dynamic_cast<const recording::RecorderStage*>(slot.stage.get()); rec != nullptr && recorder != nullptr)
        *recorder = rec->counters();
    }
    status = s.localization->status;
  };
  auto run = run_team(o);
  ASSERT_TRUE(run.ok()) << run.error().message;
  const Calibration cal = calibrate();

  // The localizer did the real work: ~70 m driven, an update every 0.5 m, and it converged.
  EXPECT_GT(matched, min_matched);
  if (expect_tracking) {
    EXPECT_EQ(status, LocalizationStatus::kTracking);
  }
  std::printf("ugv stages in the runner: calibration median %.2f ms, scale %.2f\n", to_seconds(cal.median_ns) * 1e3, cal.scale);
  std::printf("  %-12s %6s %10s %10s %10s %10s\n", "stage", "runs", "p50_ms", "p99_ms", "max_ms", "scaled_ms");
  ASSERT_FALSE(measured.empty());
  for (const Measured& m : measured) {
    const double scaled = to_seconds(m.s.budget_ns) * 1e3 * std::max(1.0, cal.scale);
    std::printf("  %-12s %6llu %10.2f %10.2f %10.2f %10.2f\n", m.stage.c_str(), static_cast<unsigned long long>(m.s.runs),
                to_seconds(m.s.exec_p50) * 1e3, to_seconds(m.s.exec_p99) * 1e3, to_seconds(m.s.exec_max) * 1e3, scaled);
    EXPECT_GT(m.s.runs, 0u) << m.stage;
    EXPECT_LE(to_seconds(m.s.exec_p99) * 1e3, scaled) << m.stage << " p99 over its scaled budget";
  }
}

TEST(UgvBudgetsInTheRunner, EveryStageP99IsWithinItsScaledBudgetWhileLocalizing) {
  check_ugv_budgets("timing-ugv", 60, {}, 80, true);
}

// The same with the robot's own recorder on (every 5th LiDAR revolution as a point cloud, wheel
// odometry, poses, map tiles into MCAP files on its own lowest-priority stage): every stage, the
// recorder included, keeps its budget (issue 29).
TEST(UgvBudgetsInTheRunner, TheStagesKeepTheirBudgetsWithTheRecorderOn) {
  recording::RecorderCounters rec;
  check_ugv_budgets("timing-ugv-recorder", 25, {"recorder.path={root}/recording", "recorder.scheduler_period_s=1"}, 20, false, &rec);
  std::printf("recorder: %llu poses, %llu odometry, %llu of %llu scans, %llu map tiles, %llu scheduler reports written; drops: %llu scans, %llu odometry; %llu write errors\n",
              static_cast<unsigned long long>(rec.pose.written), static_cast<unsigned long long>(rec.odometry.written),
              static_cast<unsigned long long>(rec.lidar.written), static_cast<unsigned long long>(rec.lidar.read),
              static_cast<unsigned long long>(rec.map_tiles.written), static_cast<unsigned long long>(rec.scheduler.written),
              static_cast<unsigned long long>(rec.lidar.drops), static_cast<unsigned long long>(rec.odometry.drops),
              static_cast<unsigned long long>(rec.write_errors));
  EXPECT_EQ(rec.write_errors, 0u);
  EXPECT_GT(rec.lidar.read, 200u);  // 10 Hz
  EXPECT_EQ(rec.lidar.written, (rec.lidar.read + 4) / 5);
  EXPECT_GT(rec.odometry.written, 1000u);  // 50 Hz
  EXPECT_GT(rec.pose.written, 100u);
  EXPECT_GE(rec.scheduler.written, 20u);
}

}  // namespace
}  // namespace ag::sim
