// A role is one table: every stage once, with rate, budget, priority and CPU (ArduPilot-style), and a
// compile-time check that the budgets fit.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string_view>

#include "airground/platform/config.hpp"
#include "airground/platform/stage.hpp"
#include "airground/platform/time.hpp"

namespace ag {

using StageFactory = std::unique_ptr<Stage> (*)();

// What a step of the stage costs on the reference CPU of platform/calibration.hpp (a NUC-class core):
// idle_us every step, plus per_unit_us for each unit of work the step reports (Stage::add_work). The
// simulator's lockstep executor shows the stage's outputs that much later (scaled to the target CPU);
// `build/native/tests/bench/bench_compute_time 240` measures it and prints the rows to paste here.
struct StageCost {
  double idle_us{0};
  double per_unit_us{0};
  std::string_view unit{"-"};  // what one unit of work is
};

struct StageSpec {
  std::string_view name;   // also the config section of the stage's parameters
  StageFactory make;
  double rate_hz;
  std::uint32_t budget_us;  // on the robot CPU the role is written for
  int priority;             // SCHED_FIFO 1..98; stages of equal (priority, cpu) share one thread
  int cpu;                  // CPU to pin the thread to, -1 = any
  std::span<const ParamSpec> params{};
  std::string_view help{};
  StageCost cost{};
  // A device stage (camera, LiDAR, GNSS, autopilot, CAN) talks to hardware. In the simulator's lockstep it
  // runs on the simulated device when it has a sim_backend: the settings ("key=value[,key=value]", in its
  // own section) that plug it in, as ArduPilot's SITL swaps a HAL. A device stage without one does not run
  // there: the world writes its output channels and reads its inputs.
  bool device{false};
  std::string_view sim_backend{};
};

// The share of each thread's time the budgets may claim; the rest is headroom for jitter and drivers.
inline constexpr double kMaxThreadUtilisation = 0.75;

namespace table_check {
// Deliberately not constexpr: calling one in a constant expression makes the compiler name the problem.
void stage_rate_must_be_positive_and_at_most_1kHz();
void stage_budget_must_be_positive_and_below_its_period();
void stage_priority_must_be_in_1_to_98();
void stage_names_must_be_unique();
void budgets_of_one_thread_exceed_its_time();
void only_a_device_stage_has_a_sim_backend();

constexpr bool same_thread(const StageSpec& a, const StageSpec& b) { return a.priority == b.priority && a.cpu == b.cpu; }
}  // namespace table_check

// True when the table is sound; otherwise fails to compile, naming the rule that was broken.
template <std::size_t N>
consteval bool role_table_ok(const StageSpec (&t)[N]) {
  for (std::size_t i = 0; i < N; ++i) {
    const StageSpec& s = t[i];
    if (!(s.rate_hz > 0.0 && s.rate_hz <= 1000.0)) table_check::stage_rate_must_be_positive_and_at_most_1kHz();
    if (s.budget_us == 0 || static_cast<double>(s.budget_us) >= 1e6 / s.rate_hz)
      table_check::stage_budget_must_be_positive_and_below_its_period();
    if (s.priority < 1 || s.priority > 98) table_check::stage_priority_must_be_in_1_to_98();
    if (!s.device && !s.sim_backend.empty()) table_check::only_a_device_stage_has_a_sim_backend();
    for (std::size_t j = 0; j < i; ++j)
      if (t[j].name == s.name) table_check::stage_names_must_be_unique();
    double load = 0.0;  // µs of budget per second on this stage's thread
    for (std::size_t j = 0; j < N; ++j)
      if (table_check::same_thread(t[j], s)) load += static_cast<double>(t[j].budget_us) * t[j].rate_hz;
    if (load > kMaxThreadUtilisation * 1e6) table_check::budgets_of_one_thread_exceed_its_time();
  }
  return true;
}

// A role as the binaries and the simulator see it.
struct RoleDescription {
  std::string_view name;         // "uav", "ugv", "base"
  std::string_view summary;      // one line for --help
  std::span<const StageSpec> stages;
  std::span<const ParamSection> extra_sections{};  // role-wide sections besides the stages'
};

}  // namespace ag
