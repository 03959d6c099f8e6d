// Compute time in lockstep: how long each robot stage's step takes on the robot's own CPU, so its
// outputs show late and its next releases slip as they would on the robot (docs/simulator.md).
#pragma once

#include <cstddef>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "airground/platform/executor.hpp"
#include "airground/platform/role_table.hpp"
#include "airground/platform/result.hpp"
#include "airground/platform/time.hpp"

namespace ag::sim {

// The robot computers: how much longer a step takes there than on the reference CPU of the timing
// suite (platform/calibration.hpp), from single-thread benchmark scores (sources in docs/simulator.md).
enum class TargetCpu { kNuc, kRyzen, kXavierNx };
struct TargetCpuInfo {
  TargetCpu cpu;
  std::string_view name;   // as on the command line
  double factor;           // time there / time on the reference CPU
  std::string_view what;
};
[[nodiscard]] std::span<const TargetCpuInfo> target_cpus() noexcept;
[[nodiscard]] const TargetCpuInfo& target_cpu_info(TargetCpu cpu) noexcept;
// "nuc", "ryzen", "xavier-nx"; anything else is an error naming the choices.
[[nodiscard]] Result<TargetCpu> parse_target_cpu(std::string_view name);

// model: from the cost table and the work each step reported (deterministic, the default);
// measured: this machine's thread CPU time, scaled by the calibration workload and the target's factor
// (for profiling: results then depend on this machine); off: outputs at the release instant.
enum class ComputeTimeMode { kOff, kModel, kMeasured };
[[nodiscard]] Result<ComputeTimeMode> parse_compute_time(std::string_view name);
[[nodiscard]] std::string_view compute_time_name(ComputeTimeMode m) noexcept;

// A stage's cost on the reference CPU: the `cost` of its row in the role tables (ugv, uav, base; the
// first row of that name), nullptr for a stage no role has (the simulator's own probes cost nothing).
[[nodiscard]] const StageCost* find_stage_cost(std::string_view stage) noexcept;

// One step a robot stage ran (bench_compute_time fits the cost table to these).
struct StepSample {
  std::string_view runnable;  // "<robot>/<stage>"
  double work;
  TimeNs measured_ns;          // thread CPU time here
};

// Binds an executor's robot runnables to their costs; outlives the executor's runs.
class ComputeTime {
 public:
  // robot_of(runnable) names the robot a runnable belongs to ("" for the simulator's own stages) and
  // target_of(robot) gives its CPU. Calibrates this machine (for kMeasured) once.
  ComputeTime(ComputeTimeMode mode, const std::vector<Runnable>& runs, const std::function<std::string(const Runnable&)>& robot_of,
              const std::function<TargetCpu(std::string_view robot)>& target_of);
  // Installs the model on the executor (nothing for kOff).
  void attach(LockstepExecutor& exec) noexcept;
  // Every robot step is passed here too (benchmarks); set before the run, called on executor threads.
  void set_sampler(std::function<void(const StepSample&)> fn) { sampler_ = std::move(fn); }
  [[nodiscard]] ComputeTimeMode mode() const noexcept { return mode_; }
  [[nodiscard]] double calibration_scale() const noexcept { return scale_; }
  // The compute time [ns] of a step of `runnable` that reported `work` and took `measured` here.
  [[nodiscard]] static TimeNs evaluate(const ComputeTime& self, std::size_t runnable, double work, TimeNs measured) noexcept;

 private:
  static TimeNs cost(void* user, std::size_t runnable, double work, TimeNs measured) noexcept;
  struct Row {
    double idle_ns{0}, per_unit_ns{0}, factor{1};
    std::string_view name;
    bool robot{false};
  };
  ComputeTimeMode mode_;
  std::vector<Row> rows_;  // per runnable
  double scale_{1};
  std::function<void(const StepSample&)> sampler_;
};

}  // namespace ag::sim
