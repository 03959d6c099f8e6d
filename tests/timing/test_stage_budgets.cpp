// Timing tests: every stage of every role keeps its p99 step time within its (calibrated) budget.
#include <gtest/gtest.h>

#include <cstdint>
#include <cstdio>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "roles.hpp"
#include "budget_harness.hpp"

namespace ag {

namespace {

using timing::BudgetCase;
using timing::BudgetReport;
using timing::run_budget_case;

void expect_within_budgets(const BudgetReport& r) {
  std::fputs(timing::format_table(r).c_str(), stdout);
  testing::Test::RecordProperty("calibration_median_ns", std::to_string(r.calibration.median_ns));
  testing::Test::RecordProperty("calibration_scale", std::to_string(r.calibration.scale));
  ASSERT_FALSE(r.stages.empty());
  for (const auto& s : r.stages) {
    testing::Test::RecordProperty(s.stage + "_p99_ns", std::to_string(s.p99));
    EXPECT_GT(s.runs, 0u) << s.stage << " never ran";
    EXPECT_TRUE(s.within()) << s.stage << ": p99 " << to_us(s.p99) << " us > scaled budget " << to_us(s.scaled)
                            << " us (budget " << to_us(s.budget) << " us x scale " << r.calibration.scale << ")";
  }
}

// ------------------------------------------------------------------------------------------------ roles

struct RoleCase {
  const char* name;
  const RoleDescription& (*role)();
};

class RoleBudgets : public testing::TestWithParam<RoleCase> {};

TEST_P(RoleBudgets, EveryStageP99IsWithinItsScaledBudget) {
  BudgetCase c;
  c.role = &GetParam().role();
  c.duration = 60 * kNsPerS;
  auto rep = run_budget_case(c);
  ASSERT_TRUE(rep.ok()) << rep.error().message;
  expect_within_budgets(rep.value());
}

INSTANTIATE_TEST_SUITE_P(Roles, RoleBudgets,
                         testing::Values(RoleCase{"uav", &uav_role}, RoleCase{"ugv", &ugv_role},
                                         RoleCase{"base", &base_role}),
                         [](const testing::TestParamInfo<RoleCase>& i) { return std::string(i.param.name); });

// ----------------------------------------------------------------------------- the harness checks itself

// Burns thread CPU time in proportion to the calibrated budget, so it is over budget on any machine.
Calibration g_cal{};
TimeNs g_burn = 0;

class CpuHog final : public Stage {
 public:
  static std::unique_ptr<Stage> make() { return std::make_unique<CpuHog>(); }
  Status init(StageContext&) override { return ok_status(); }
  void step(TimeNs) noexcept override {
    const TimeNs until = thread_cpu_now() + g_burn;
    while (thread_cpu_now() < until) {
    }
  }
};

class Idle final : public Stage {
 public:
  static std::unique_ptr<Stage> make() { return std::make_unique<Idle>(); }
  Status init(StageContext&) override { return ok_status(); }
  void step(TimeNs) noexcept override {}
};

TEST(BudgetHarness, FlagsAStageOverItsScaledBudget) {
  g_cal = calibrate();
  constexpr std::uint32_t kBudgetUs = 500;
  g_burn = 3 * timing::scaled_budget(kBudgetUs * kNsPerUs, g_cal);
  static constexpr StageSpec kStages[] = {
      {"hog", &CpuHog::make, 10.0, kBudgetUs, 10, -1, {}, "over budget on purpose"},
      {"idle", &Idle::make, 10.0, kBudgetUs, 10, -1, {}, "well within"},
  };
  static_assert(role_table_ok(kStages));
  static const RoleDescription role{"selftest", "harness self-test", kStages, {}};
  BudgetCase c;
  c.role = &role;
  c.duration = 2 * kNsPerS;
  auto rep = run_budget_case(c);
  ASSERT_TRUE(rep.ok()) << rep.error().message;
  std::fputs(timing::format_table(rep.value()).c_str(), stdout);
  const auto* hog = rep.value().find("hog");
  const auto* idle = rep.value().find("idle");
  ASSERT_TRUE(hog != nullptr && idle != nullptr);
  EXPECT_EQ(hog->runs, 21u);
  EXPECT_FALSE(hog->within());
  EXPECT_TRUE(idle->within());
}

// Recorded inputs: a replay stage placed in front of a role's stages publishes them at their times.
struct RangeSample {
  TimeNs sample_time_ns{0};  // [ns]
  float range_m{0};          // [m]
};

struct RecordedRanges {
  using Message = RangeSample;
  static constexpr std::string_view kChannel = "range";
  static constexpr std::size_t kRingCapacity = 16;
  static std::span<const Message> messages() {
    static const std::vector<RangeSample> log = [] {
      std::vector<RangeSample> v;
      for (int i = 0; i < 200; ++i) v.push_back({i * 25 * kNsPerMs, 1.0f + 0.01f * static_cast<float>(i)});  // 40 Hz
      return v;
    }();
    return log;
  }
};

std::uint64_t g_ranges_consumed = 0;

class RangeConsumer final : public Stage {
 public:
  static std::unique_ptr<Stage> make() { return std::make_unique<RangeConsumer>(); }
  Status init(StageContext& ctx) override {
    auto r = ctx.channels.ring_reader<RangeSample, 16>("range");
    if (!r) return r.error();
    in_ = r.value();
    return ok_status();
  }
  void step(TimeNs) noexcept override {
    while (in_.front() != nullptr) {
      in_.pop();
      ++g_ranges_consumed;
    }
  }

 private:
  RingReader<RangeSample, 16> in_;
};

TEST(BudgetHarness, ReplayStageInFrontFeedsRecordedInputsAndIsNotHeldToABudget) {
  static constexpr StageSpec kRoleStages[] = {
      {"ranger", &RangeConsumer::make, 10.0, 1'000, 10, -1, {}, "consumes ranges"},
  };
  static const RoleDescription role{"replaytest", "replay self-test", kRoleStages, {}};
  timing::TestTable table(role, {StageSpec{"replay_range", &timing::ReplayStage<RecordedRanges>::make, 100.0, 1'000,
                                           90, -1, {}, "recorded ranges"}});
  std::uint64_t ticks = 0;
  BudgetCase c;
  c.role = &table.role();
  c.duration = 5 * kNsPerS;
  c.unchecked = table.test_only();
  c.before_tick = [&ticks](TimeNs, RoleInstance&) { ++ticks; };
  g_ranges_consumed = 0;
  auto rep = run_budget_case(c);
  ASSERT_TRUE(rep.ok()) << rep.error().message;
  std::fputs(timing::format_table(rep.value()).c_str(), stdout);
  EXPECT_EQ(g_ranges_consumed, 200u);  // 0 .. 4.975 s at 40 Hz, all within the 5 s run
  EXPECT_EQ(ticks, 501u);              // one call per release instant (the 100 Hz replay's)
  const auto* replay = rep.value().find("replay_range");
  const auto* ranger = rep.value().find("ranger");
  ASSERT_TRUE(replay != nullptr && ranger != nullptr);
  EXPECT_FALSE(replay->checked);
  EXPECT_TRUE(ranger->checked);
  EXPECT_EQ(rep.value().stages.front().stage, "replay_range");  // first in the table
}

}  // namespace
}  // namespace ag
