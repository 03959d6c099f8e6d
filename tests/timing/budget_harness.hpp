// The stage-budget harness: runs a role in lockstep on (optionally recorded) inputs, measures every step
// in thread CPU time and compares each stage's p99 with its budget scaled by the calibration workload.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include "airground/platform/calibration.hpp"
#include "airground/platform/channels.hpp"
#include "airground/platform/clock.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/executor.hpp"
#include "airground/platform/log.hpp"
#include "airground/platform/result.hpp"
#include "airground/platform/role_instance.hpp"
#include "airground/platform/role_table.hpp"
#include "airground/platform/stage.hpp"

namespace ag::timing {

// A role's table with test-only stages in front (a replay stage publishing recorded inputs, say): at
// each instant the lockstep executor runs stages in table order, so the replayed message is already on
// its channel when the role's own stages step.
class TestTable {
 public:
  TestTable(const RoleDescription& role, std::vector<StageSpec> first, std::vector<ParamSection> extra_sections = {})
      : stages_(std::move(first)), sections_(std::move(extra_sections)) {
    for (const StageSpec& s : stages_) test_only_.emplace_back(s.name);
    stages_.insert(stages_.end(), role.stages.begin(), role.stages.end());
    sections_.insert(sections_.end(), role.extra_sections.begin(), role.extra_sections.end());
    role_ = RoleDescription{role.name, role.summary, stages_, sections_};
  }
  TestTable(const TestTable&) = delete;
  TestTable& operator=(const TestTable&) = delete;

  [[nodiscard]] const RoleDescription& role() const noexcept { return role_; }
  // The stages this table added: not the role's, so their budgets are not checked.
  [[nodiscard]] const std::vector<std::string>& test_only() const noexcept { return test_only_; }

 private:
  std::vector<StageSpec> stages_;
  std::vector<ParamSection> sections_;
  std::vector<std::string> test_only_;
  RoleDescription role_{};
};

// Publishes recorded messages at their sample times. `Source` supplies:
//   using Message = ...;                          // a message with `TimeNs sample_time_ns`
//   static constexpr std::string_view kChannel;   // where to publish
//   static constexpr std::size_t kRingCapacity;   // 0: latest-value channel, else ring of that capacity
//   static std::span<const Message> messages();   // sorted by sample_time_ns
// At each step every message with sample_time_ns <= now goes out, in order (on a latest channel the
// readers see the newest of them, as they would live).
template <typename Source>
class ReplayStage final : public Stage {
 public:
  using Message = typename Source::Message;
  static constexpr std::size_t kCapacity = Source::kRingCapacity;
  static std::unique_ptr<Stage> make() { return std::make_unique<ReplayStage>(); }

  Status init(StageContext& ctx) override {
    messages_ = Source::messages();
    if constexpr (kCapacity == 0) {
      auto w = ctx.channels.latest_writer<Message>(Source::kChannel);
      if (!w) return w.error();
      out_ = w.value();
    } else {
      auto w = ctx.channels.ring_writer<Message, kCapacity>(Source::kChannel);
      if (!w) return w.error();
      out_ = w.value();
    }
    return ok_status();
  }
  void step(TimeNs now) noexcept override {
    while (next_ < messages_.size() && messages_[next_].sample_time_ns <= now) {
      if constexpr (kCapacity == 0) out_.publish(messages_[next_]);
      else refused_ += out_.push(messages_[next_]);
      ++next_;
    }
  }
  [[nodiscard]] std::size_t replayed() const noexcept { return next_; }

 private:
  using Writer = std::conditional_t<kCapacity == 0, LatestWriter<Message>, RingWriter<Message, kCapacity>>;
  std::span<const Message> messages_;
  std::size_t next_{0};
  std::size_t refused_{0};
  Writer out_{};
};

struct BudgetCase {
  const RoleDescription* role{nullptr};
  std::vector<std::string> overrides;   // "section.key=value", as with --set
  TimeNs duration{60 * kNsPerS};        // [ns] simulated
  std::vector<std::string> unchecked;   // stages measured but not held to a budget (replay stages)
  // Called before each release instant with its time and the robot: the other way to feed recorded
  // inputs (e.g. into a stage's queue), or to change conditions mid-run.
  std::function<void(TimeNs t, RoleInstance& robot)> before_tick{};
};

struct StageBudget {
  std::string stage;
  std::uint64_t runs{0};
  TimeNs p50{0}, p99{0}, max{0};  // [ns] thread CPU time of step()
  TimeNs budget{0};               // [ns] from the table: the robot CPU
  TimeNs scaled{0};               // [ns] budget * max(1, calibration scale): this machine
  bool checked{true};
  [[nodiscard]] bool within() const noexcept { return !checked || p99 <= scaled; }
};

struct BudgetReport {
  std::string role;
  Calibration calibration{};
  std::vector<StageBudget> stages;
  [[nodiscard]] const StageBudget* find(std::string_view name) const noexcept {
    for (const auto& s : stages)
      if (s.stage == name) return &s;
    return nullptr;
  }
};

[[nodiscard]] inline TimeNs scaled_budget(TimeNs budget, const Calibration& cal) noexcept {
  return static_cast<TimeNs>(static_cast<double>(budget) * std::max(1.0, cal.scale));
}

// Keeps log records off the stage's thread for the run, as on the robot (where the writer thread runs).
class AsyncLogScope {
 public:
  AsyncLogScope() { log::start_writer(); }
  ~AsyncLogScope() { log::stop_writer(); }
  AsyncLogScope(const AsyncLogScope&) = delete;
  AsyncLogScope& operator=(const AsyncLogScope&) = delete;
};

// Runs the case in lockstep (thread CPU timer), then calibrates in the same process, right after, so
// both see the same machine state.
inline Result<BudgetReport> run_budget_case(const BudgetCase& c) {
  if (c.role == nullptr) return Error::make(ErrorCode::kInvalidArgument, "budget case without a role");
  const std::vector<ParamSection> schema = role_schema(*c.role);
  Config config = Config::defaults(schema);
  for (const auto& s : c.overrides)
    if (Status st = config.set(s, "budget case"); !st) return st.error();

  SimClock clock(0);
  auto created = RoleInstance::create(*c.role, config, clock, std::string(c.role->name));
  if (!created) return created.error();
  RoleInstance& robot = *created.value();
  {
    AsyncLogScope async_log;
    LockstepExecutor ex(clock, ExecTimer::kThreadCpu);
    ex.add(robot);
    ex.start(0);
    for (TimeNs t = ex.next_release(); t <= c.duration; t = ex.next_release()) {
      if (c.before_tick) c.before_tick(t, robot);
      ex.run_until(t);
    }
    ex.run_until(c.duration);
  }
  robot.stop_all();

  BudgetReport rep;
  rep.role = std::string(c.role->name);
  rep.calibration = calibrate();
  for (std::size_t i = 0; i < robot.perf().size(); ++i) {
    const StagePerf& p = robot.perf().at(i);
    const StagePerfSnapshot s = snapshot(p);
    StageBudget b;
    b.stage = p.name;
    b.runs = s.runs;
    b.p50 = s.exec_p50;
    b.p99 = s.exec_p99;
    b.max = s.exec_max;
    b.budget = s.budget_ns;
    b.scaled = scaled_budget(s.budget_ns, rep.calibration);
    b.checked = std::find(c.unchecked.begin(), c.unchecked.end(), p.name) == c.unchecked.end();
    rep.stages.push_back(std::move(b));
  }
  return rep;
}

inline std::string format_table(const BudgetReport& r) {
  std::string out;
  char line[192];
  std::snprintf(line, sizeof line, "role %s: calibration median %.2f ms (reference %.2f ms), scale %.2f\n",
                r.role.c_str(), to_seconds(r.calibration.median_ns) * 1e3, to_seconds(kCalibrationReferenceNs) * 1e3,
                r.calibration.scale);
  out += line;
  std::snprintf(line, sizeof line, "  %-24s %8s %10s %10s %10s %10s %12s  %s\n", "stage", "runs", "p50_us", "p99_us",
                "max_us", "budget_us", "scaled_us", "verdict");
  out += line;
  for (const auto& s : r.stages) {
    std::snprintf(line, sizeof line, "  %-24s %8llu %10.1f %10.1f %10.1f %10.0f %12.0f  %s\n", s.stage.c_str(),
                  static_cast<unsigned long long>(s.runs), to_us(s.p50), to_us(s.p99), to_us(s.max), to_us(s.budget),
                  to_us(s.scaled), !s.checked ? "not checked" : s.within() ? "ok" : "OVER BUDGET");
    out += line;
  }
  return out;
}

}  // namespace ag::timing
