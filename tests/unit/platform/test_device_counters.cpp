// A device stage's own counters beside the scheduler's: filled through StageContext::device, published
// by the status stage (unit, rate over the report period, complete / incomplete, errors, bytes), and
// the silence detector that tells a device stage when to warn.
#include <gtest/gtest.h>

#include <cstring>
#include <memory>

#include "airground/platform/executor.hpp"
#include "airground/platform/status_stage.hpp"
#include "test_robot.hpp"

namespace ag {
namespace {

// Ten "frames" a second, every fifth incomplete; 100 bytes each; one decode error a step.
class FakeDevice final : public Stage {
 public:
  static std::unique_ptr<Stage> make() { return std::make_unique<FakeDevice>(); }
  Status init(StageContext& ctx) override {
    if (ctx.device == nullptr) return Error::make(ErrorCode::kInternal, "no device counters in the context");
    d_ = ctx.device;
    d_->describe("frames", {"wrong_size", "bad_type"});
    return ok_status();
  }
  void step(TimeNs now) noexcept override {
    ++n_;
    d_->unit_received(n_ % 5 != 0, now);
    d_->received_bytes(100);
    d_->error(1);
  }

 private:
  DeviceCounters* d_{nullptr};
  std::uint64_t n_{0};
};

constexpr StageSpec kStages[] = {
    {"lidar", &FakeDevice::make, 10.0, 1'000, 30, -1, {}, "a device stage"},
    {"status", &StatusStage::make, 1.0, 2'000, 10, -1, StatusStage::kParams, "scheduler counters"},
};
static_assert(role_table_ok(kStages));
const RoleDescription kRole{"dev", "a device stage and the status stage", kStages, {}};

TEST(DeviceCounters, TheStatusStagePublishesWhatADeviceStageReceived) {
  SimClock clock;
  auto r = test::build(kRole, clock, "dev");
  ASSERT_TRUE(r);
  LockstepExecutor ex(clock);
  ex.add(*r->robot);
  ex.start(0);
  ex.run_until(5 * kNsPerS + kNsPerS / 2);
  const auto* status = dynamic_cast<const StatusStage*>(r->robot->stages()[1].stage.get());
  ASSERT_NE(status, nullptr);
  const SchedulerStatus& s = status->last();
  ASSERT_EQ(s.stage_count, 2u);
  const auto& lidar = s.stages[0];
  EXPECT_STREQ(lidar.device_unit.data(), "frames");
  EXPECT_EQ(lidar.device_complete + lidar.device_incomplete, 51u) << "released at 0, 0.1, ... 5.0 s";
  EXPECT_EQ(lidar.device_incomplete, 10u);
  EXPECT_EQ(lidar.device_errors, 51u);
  EXPECT_EQ(lidar.device_bytes, 5100u);
  EXPECT_NEAR(lidar.device_rate_hz, 10.0f, 0.01f);
  EXPECT_EQ(s.stages[1].device_unit[0], '\0') << "the status stage is no device";
  const DeviceCounters& d = r->robot->perf().at(0).device;
  EXPECT_EQ(d.errors[1].load(), 56u) << "the stage ran on to 5.5 s after the last report";
  EXPECT_STREQ(d.error_name[0].data(), "wrong_size");
  EXPECT_EQ(d.last_unit_ns.load(), 5 * kNsPerS + kNsPerS / 2);
}

TEST(DeviceCounters, SilenceFiresOnceAfterItsTimeAndRearmsWhenUnitsComeBack) {
  DeviceCounters d;
  DeviceSilence s(3 * kNsPerS);
  EXPECT_FALSE(s.check(d, 0));
  EXPECT_FALSE(s.check(d, 2 * kNsPerS));
  EXPECT_TRUE(s.check(d, 3 * kNsPerS));
  EXPECT_FALSE(s.check(d, 4 * kNsPerS)) << "once";
  EXPECT_FALSE(s.check(d, 60 * kNsPerS));
  d.unit_received(true, 61 * kNsPerS);
  EXPECT_FALSE(s.check(d, 61 * kNsPerS));
  EXPECT_FALSE(s.check(d, 63 * kNsPerS));
  EXPECT_TRUE(s.check(d, 64 * kNsPerS)) << "a new silence after units came back";
  EXPECT_EQ(s.silent_for(64 * kNsPerS), 3 * kNsPerS);
}

}  // namespace
}  // namespace ag
