// The compute-time model's binding: each robot runnable costs its stage's row times its robot's CPU
// factor; the simulator's own stages cost nothing; the CLI names parse and wrong ones are refused.
#include <gtest/gtest.h>

#include <string>
#include <string_view>
#include <vector>

#include "airground/platform/channels.hpp"
#include "airground/platform/executor.hpp"
#include "airground/sim/compute_time.hpp"

namespace ag::sim {
namespace {

Runnable runnable(const char* name, ChannelRegistry* channels) {
  Runnable r{nullptr, nullptr, name, 100 * kNsPerMs, 50 * kNsPerMs, 10, -1};
  r.channels = channels;
  return r;
}

TEST(ComputeTimeModel, ARobotStepCostsItsRowTimesItsCpuFactor) {
  const StageCost* seg = find_stage_cost("segmentation");
  const StageCost* loc = find_stage_cost("localization");
  ASSERT_NE(seg, nullptr);
  ASSERT_NE(loc, nullptr);
  ChannelRegistry channels;
  const std::vector<Runnable> runs = {runnable("sim/world", nullptr), runnable("uav/segmentation", &channels),
                                      runnable("ugv1/localization", &channels), runnable("ugv1/unlisted", &channels)};
  const auto robot_of = [](const Runnable& r) { return std::string(r.name).substr(0, std::string(r.name).find('/')); };
  ComputeTime model(ComputeTimeMode::kModel, runs, robot_of, [](std::string_view robot) {
    return robot == "uav" ? TargetCpu::kXavierNx : TargetCpu::kRyzen;
  });
  const auto cost = [&model](std::size_t i, double work, TimeNs measured) { return ComputeTime::evaluate(model, i, work, measured); };
  const double nx = target_cpu_info(TargetCpu::kXavierNx).factor;
  const double ryzen = target_cpu_info(TargetCpu::kRyzen).factor;
  EXPECT_EQ(cost(0, 3.0, 5 * kNsPerMs), 0) << "the simulator's own stages cost nothing";
  EXPECT_NEAR(static_cast<double>(cost(1, 2.0, 123)), (seg->idle_us + 2.0 * seg->per_unit_us) * 1e3 * nx, 1.0);
  EXPECT_NEAR(static_cast<double>(cost(2, 1.0, 123)), (loc->idle_us + loc->per_unit_us) * 1e3 * ryzen, 1.0);
  EXPECT_NEAR(static_cast<double>(cost(2, 0.0, 123)), loc->idle_us * 1e3 * ryzen, 1.0) << "an idle step costs the idle time";
  EXPECT_EQ(cost(3, 4.0, 123), 0) << "a stage without a row costs nothing";
  EXPECT_GT(seg->per_unit_us, 10'000.0) << "a frame through ErfNet takes tens of ms or more on any robot CPU";
  EXPECT_GT(nx, 2.0 * ryzen) << "the Xavier NX's Carmel cores are much slower than the x86 computers";
}

TEST(ComputeTimeModel, MeasuredModeScalesThisMachinesTimeByCalibrationAndFactor) {
  ChannelRegistry channels;
  const std::vector<Runnable> runs = {runnable("uav/vo", &channels)};
  ComputeTime measured(ComputeTimeMode::kMeasured, runs, [](const Runnable&) { return std::string("uav"); }, [](std::string_view) { return TargetCpu::kXavierNx; });
  const double expect = 10e6 / measured.calibration_scale() * target_cpu_info(TargetCpu::kXavierNx).factor;
  EXPECT_NEAR(static_cast<double>(ComputeTime::evaluate(measured, 0, 0.0, 10 * kNsPerMs)), expect, 1.0);
  ComputeTime off(ComputeTimeMode::kOff, runs, [](const Runnable&) { return std::string("uav"); }, [](std::string_view) { return TargetCpu::kNuc; });
  EXPECT_EQ(ComputeTime::evaluate(off, 0, 5.0, 10 * kNsPerMs), 0);
}

TEST(ComputeTimeModel, NamesParseAndUnknownOnesAreRefusedNamingTheChoices) {
  ASSERT_TRUE(parse_target_cpu("xavier-nx").ok());
  EXPECT_EQ(parse_target_cpu("ryzen").value(), TargetCpu::kRyzen);
  const auto bad = parse_target_cpu("jetson");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("nuc, ryzen, xavier-nx"), std::string::npos);
  EXPECT_EQ(parse_compute_time("measured").value(), ComputeTimeMode::kMeasured);
  EXPECT_FALSE(parse_compute_time("fast").ok());
  EXPECT_EQ(compute_time_name(ComputeTimeMode::kModel), "model");
}

}  // namespace
}  // namespace ag::sim
