// bench_compute_time: measures the cost table of the simulator's compute-time model
// (sim/runner/compute_time.cpp). Runs a field-mode mission on the default world with compute time off,
// records every robot step's thread CPU time and the work it reported, and per stage prints
//   idle_us      median time of the steps that reported no work,
//   per_unit_us  the mean time above idle per unit of work (sum over working steps / their units),
// both divided by the calibration workload's scale (platform/calibration.hpp), i.e. on the reference
// CPU, with the measured p50/p99 of working steps beside them and the rows to paste into the table.
//   bench_compute_time [SIM_SECONDS (240)] [OUT_DIR (bench-compute-time)]
// AG_BENCH_OUT=<file> appends the table as JSON lines.
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <mutex>
#include <string>
#include <vector>

#include "airground/platform/calibration.hpp"
#include "airground/sim/compute_time.hpp"
#include "airground/sim/eval_mission.hpp"

namespace {

struct Samples {
  std::vector<double> idle_ns;
  std::vector<double> work_ns;
  std::vector<double> units;
};

double quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(q * static_cast<double>(v.size() - 1))];
}

}  // namespace

int main(int argc, char** argv) {
  using namespace ag;
  using namespace ag::sim;
  const double sim_s = argc > 1 ? std::atof(argv[1]) : 240.0;
  const std::string out = argc > 2 ? argv[2] : "bench-compute-time";
  if (!(sim_s > 0)) {
    std::fprintf(stderr, "usage: bench_compute_time [SIM_SECONDS > 0] [OUT_DIR]\n");
    return 2;
  }
  const Calibration before = calibrate();
  std::mutex mu;
  std::map<std::string, Samples> by_stage;
  MissionOptions o;
  o.world = "default";
  o.out_dir = out;
  o.ugvs = 3;
  o.seed = 1;
  o.max_duration_s = sim_s;
  o.record = RecordLevel::kNone;
  o.compute_time = ComputeTimeMode::kOff;  // the steps as they come, whatever the table says
  o.step_sampler = [&](const StepSample& s) {
    const std::size_t slash = s.runnable.find('/');
    const std::string stage(slash == std::string_view::npos ? s.runnable : s.runnable.substr(slash + 1));
    const std::lock_guard<std::mutex> lock(mu);
    Samples& x = by_stage[stage];
    if (s.work > 0) {
      x.work_ns.push_back(static_cast<double>(s.measured_ns));
      x.units.push_back(s.work);
    } else {
      x.idle_ns.push_back(static_cast<double>(s.measured_ns));
    }
  };
  std::fprintf(stderr, "bench_compute_time: a field-mode mission on the default world, 3 ground robots, %.0f s simulated ...\n", sim_s);
  auto m = run_mission(o);
  if (!m) {
    std::fprintf(stderr, "bench_compute_time: %s\n", m.error().message.c_str());
    return 1;
  }
  // The mission's ground robots localize only once the quadrotor's map reaches them: a ground robot on
  // the world's map for a minute gives the localizer's scan updates in numbers.
  RunOptions ground;
  ground.world = "default";
  ground.out_dir = out + "/ground";
  ground.ugvs = 1;
  ground.uav = false;
  ground.seed = 1;
  ground.duration_s = std::min(60.0, sim_s);
  ground.ugv_map = UgvMapSource::kGroundTruth;
  ground.init_error_m = 4;
  ground.record = RecordLevel::kNone;
  ground.progress = false;
  ground.compute_time = ComputeTimeMode::kOff;
  ground.step_sampler = o.step_sampler;
  std::fprintf(stderr, "bench_compute_time: one ground robot on the world's map, %.0f s simulated ...\n", ground.duration_s);
  if (auto g = run_team(ground); !g) {
    std::fprintf(stderr, "bench_compute_time: %s\n", g.error().message.c_str());
    return 1;
  }
  const Calibration after = calibrate();
  const double scale = 0.5 * (before.scale + after.scale);
  std::printf("calibration: %.2f ms here against %.2f ms on the reference CPU: scale %.3f (before %.3f, after %.3f)\n",
              0.5e-6 * static_cast<double>(before.median_ns + after.median_ns), 1e-6 * static_cast<double>(kCalibrationReferenceNs), scale,
              before.scale, after.scale);
  std::printf("%-14s %8s %8s %10s %12s %12s %12s   (reference-CPU us; measured ms here)\n", "stage", "idle", "working", "idle_us", "per_unit_us",
              "work p50 ms", "work p99 ms");
  const char* json = std::getenv("AG_BENCH_OUT");
  FILE* jf = json != nullptr ? std::fopen(json, "a") : nullptr;
  std::string rows;
  for (auto& [stage, x] : by_stage) {
    const double idle_ns = quantile(x.idle_ns, 0.5);
    double above = 0, units = 0;
    std::vector<double> per_step;
    for (std::size_t i = 0; i < x.work_ns.size(); ++i) {
      above += std::max(0.0, x.work_ns[i] - idle_ns);
      units += x.units[i];
      per_step.push_back(x.work_ns[i]);
    }
    const double idle_us = idle_ns / scale / 1e3;
    const double per_unit_us = units > 0 ? above / units / scale / 1e3 : 0;
    std::printf("%-14s %8zu %8zu %10.1f %12.1f %12.2f %12.2f\n", stage.c_str(), x.idle_ns.size(), x.work_ns.size(), idle_us, per_unit_us,
                quantile(per_step, 0.5) / 1e6, quantile(per_step, 0.99) / 1e6);
    char row[160];
    std::snprintf(row, sizeof row, "    %s: {%.1f, %.1f, \"...\"},\n", stage.c_str(), idle_us, per_unit_us);
    rows += row;
    if (jf != nullptr)
      std::fprintf(jf, "{\"bench\": \"compute_time\", \"stage\": \"%s\", \"idle_us\": %.2f, \"per_unit_us\": %.2f, \"steps\": %zu, \"working_steps\": %zu, \"scale\": %.4f}\n",
                   stage.c_str(), idle_us, per_unit_us, x.idle_ns.size() + x.work_ns.size(), x.work_ns.size(), scale);
  }
  if (jf != nullptr) std::fclose(jf);
  std::printf("\nthe cost column of the role tables, firmware_host/*/role.cpp (stage: {idle_us, per_unit_us, unit}):\n%s", rows.c_str());
  std::printf("mission: %u of %u targets in %.0f s simulated (%.2fx real time)\n", m.value().targets_visited, m.value().targets_total, m.value().sim_s,
              m.value().realtime_factor);
  return 0;
}
