// Compute time in lockstep: the target CPUs, the cost table and the executor's cost function.
#include "airground/sim/compute_time.hpp"

#include <algorithm>
#include <array>

#include "airground/platform/calibration.hpp"
#include "roles.hpp"

namespace ag::sim {

namespace {

// Time there / time on the reference CPU of platform/calibration.hpp (a NUC-class core). Approximate
// single-thread ratios from public benchmark medians (docs/simulator.md, "Compute time"); a team with the
// computer on the bench replaces them with its calibration median / kCalibrationReferenceNs.
constexpr std::array<TargetCpuInfo, 3> kTargets{{
    {TargetCpu::kNuc, "nuc", 1.0, "Intel NUC, Core i7-10710U (the paper's quadrotor computer; the reference)"},
    {TargetCpu::kRyzen, "ryzen", 0.9, "AMD Ryzen 5 3600 (the paper's ground robot computer)"},
    {TargetCpu::kXavierNx, "xavier-nx", 2.8, "NVIDIA Jetson Xavier NX, Carmel ARMv8.2 at 1.9 GHz (CPU only)"},
}};

}  // namespace

std::span<const TargetCpuInfo> target_cpus() noexcept { return kTargets; }

const TargetCpuInfo& target_cpu_info(TargetCpu cpu) noexcept {
  for (const auto& t : kTargets)
    if (t.cpu == cpu) return t;
  return kTargets[0];
}

Result<TargetCpu> parse_target_cpu(std::string_view name) {
  for (const auto& t : kTargets)
    if (t.name == name) return t.cpu;
  return Error::make(ErrorCode::kInvalidArgument, "unknown target CPU '" + std::string(name) + "' (known: nuc, ryzen, xavier-nx)");
}

Result<ComputeTimeMode> parse_compute_time(std::string_view name) {
  if (name == "model") return ComputeTimeMode::kModel;
  if (name == "measured") return ComputeTimeMode::kMeasured;
  if (name == "off") return ComputeTimeMode::kOff;
  return Error::make(ErrorCode::kInvalidArgument, "unknown compute-time mode '" + std::string(name) + "' (known: model, measured, off)");
}

std::string_view compute_time_name(ComputeTimeMode m) noexcept {
  switch (m) {
    case ComputeTimeMode::kModel: return "model";
    case ComputeTimeMode::kMeasured: return "measured";
    case ComputeTimeMode::kOff: return "off";
  }
  return "off";
}

const StageCost* find_stage_cost(std::string_view stage) noexcept {
  for (const RoleDescription* role : {&ugv_role(), &uav_role(), &base_role()})
    for (const StageSpec& s : role->stages)
      if (s.name == stage) return &s.cost;
  return nullptr;
}

ComputeTime::ComputeTime(ComputeTimeMode mode, const std::vector<Runnable>& runs, const std::function<std::string(const Runnable&)>& robot_of,
                         const std::function<TargetCpu(std::string_view robot)>& target_of)
    : mode_(mode) {
  rows_.resize(runs.size());
  for (std::size_t i = 0; i < runs.size(); ++i) {
    Row& row = rows_[i];
    row.name = runs[i].name;
    if (runs[i].channels == nullptr) continue;  // the simulator's own stages cost nothing
    row.robot = true;
    const std::string_view full = runs[i].name;
    const std::size_t slash = full.rfind('/');
    const std::string_view stage = slash == std::string_view::npos ? full : full.substr(slash + 1);
    row.factor = target_cpu_info(target_of(robot_of(runs[i]))).factor;
    if (const StageCost* c = find_stage_cost(stage)) {
      row.idle_ns = c->idle_us * 1e3;
      row.per_unit_ns = c->per_unit_us * 1e3;
    }
  }
  if (mode_ == ComputeTimeMode::kMeasured) scale_ = calibrate().scale;
}

void ComputeTime::attach(LockstepExecutor& exec) noexcept {
  if (mode_ != ComputeTimeMode::kOff || sampler_) exec.set_compute_time(&ComputeTime::cost, this);
}

TimeNs ComputeTime::cost(void* user, std::size_t runnable, double work, TimeNs measured) noexcept {
  const auto& self = *static_cast<ComputeTime*>(user);
  if (self.sampler_) self.sampler_(StepSample{self.rows_[runnable].name, work, measured});
  return evaluate(self, runnable, work, measured);
}

TimeNs ComputeTime::evaluate(const ComputeTime& self, std::size_t runnable, double work, TimeNs measured) noexcept {
  if (runnable >= self.rows_.size() || !self.rows_[runnable].robot) return 0;
  const Row& row = self.rows_[runnable];
  switch (self.mode_) {
    case ComputeTimeMode::kOff: return 0;
    case ComputeTimeMode::kMeasured: return static_cast<TimeNs>(static_cast<double>(measured) / self.scale_ * row.factor);
    case ComputeTimeMode::kModel: break;
  }
  return static_cast<TimeNs>((row.idle_ns + row.per_unit_ns * work) * row.factor);
}

}  // namespace ag::sim
