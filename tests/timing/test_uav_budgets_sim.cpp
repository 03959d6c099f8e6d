// Timing: the quadrotor's stages keep their budgets in the lockstep runner while it maps a generated
// world at 5 m/s with keyframes every 2 m (issue 4). Thread CPU time of each step(), p99 against the
// role table's budget scaled by the calibration workload timed in the same process (README.md here).
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "airground/aerial_mapping/stages.hpp"
#include "airground/platform/calibration.hpp"
#include "airground/platform/perf_counters.hpp"
#include "airground/platform/role_instance.hpp"
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

TEST(UavBudgetsInTheRunner, EveryStageP99IsWithinItsScaledBudgetWhileMapping) {
  const char* b = std::getenv("AG_BINARY_DIR");
  const fs::path root = fs::path(b != nullptr ? b : fs::temp_directory_path().string()) / "timing-uav";
  fs::create_directories(root);
  GeneratorOptions g;
  g.seed = 11;
  g.size_m = 200;
  auto w = generate_world(g);
  ASSERT_TRUE(w.ok()) << w.error().message;
  ASSERT_TRUE(save_world(w.value(), (root / "world").string()).ok());

  RunOptions o;
  o.world = (root / "world").string();
  o.out_dir = (root / "run").string();
  o.ugvs = 0;
  o.duration_s = 90;            // half the survey: a full window of keyframes and many solves
  o.uav_speed_mps = 5;
  o.record = RecordLevel::kNone;
  o.progress = false;
  std::vector<Measured> measured;
  std::uint64_t keyframes = 0, pairs = 0;
  o.inspect = [&](const RunInspection& in) -> Status {
    for (auto& slot : in.uav->stages()) {
      measured.push_back(Measured{std::string(slot.spec->name), snapshot(*slot.perf)});
      if (auto* pg = dynamic_cast<const mapping::PoseGraphStage*>(slot.stage.get())) keyframes = pg->keyframes();
      if (auto* om = dynamic_cast<const mapping::OrthoMapStage*>(slot.stage.get())) pairs = om->counters().pairs_matched;
    }
    return ok_status();
  };
  auto run = run_team(o);
  ASSERT_TRUE(run.ok()) << run.error().message;
  const Calibration cal = calibrate();

  // The stages did the real work: ~300 m flown after take-off and initialisation, keyframes every 2 m.
  EXPECT_GT(keyframes, 120u);
  EXPECT_GT(pairs, 100u);
  std::printf("uav stages in the runner: calibration median %.2f ms, scale %.2f\n", to_seconds(cal.median_ns) * 1e3, cal.scale);
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

}  // namespace
}  // namespace ag::sim
