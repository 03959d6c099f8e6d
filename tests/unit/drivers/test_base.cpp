// The differential-drive base against two simulated ODrive controllers over the in-process CAN link:
// arming, commands, the 200 ms watchdog, axis errors and silent controllers, wheel odometry.
#include <gtest/gtest.h>

#include <cmath>

#include "base_rig.hpp"

namespace ag::base {
namespace {
using test::BaseRig;

TEST(Base, ArmsAndDrivesBothWheels) {
  BaseRig rig;
  EXPECT_EQ(rig.base->status().state, BaseState::kDisarmed);
  rig.arm_and_wait();
  ASSERT_EQ(rig.base->status().state, BaseState::kRunning);
  EXPECT_EQ(rig.sim->axis_state(0), 8U);
  for (int i = 0; i < 100; ++i) {
    rig.base->command(0.5, 1.0, rig.clock.now());
    rig.tick();
  }
  EXPECT_NEAR(rig.wheel_mps(0), 0.5, 1e-6);
  EXPECT_NEAR(rig.wheel_mps(1), 1.0, 1e-6);
  EXPECT_LT(rig.sim->input_vel(0), 0.0) << "left motor mirrored (left_sign -1)";
  // Odometry turns left at (vr - vl) / track.
  EXPECT_NEAR(rig.base->odometry().w_radps, 0.5 / rig.params.track_m, 1e-4);
  EXPECT_NEAR(rig.base->odometry().v_mps, 0.75, 1e-4);
}

TEST(Base, WatchdogStopsTheWheelsWithin200msOfTheLastCommand) {
  BaseRig rig;
  rig.arm_and_wait();
  for (int i = 0; i < 50; ++i) {
    rig.base->command(1.0, 1.0, rig.clock.now());
    rig.tick();
  }
  ASSERT_NE(rig.base->sent_velocity(1), 0.0F);
  const TimeNs last = rig.clock.now();  // the planner stalls here
  TimeNs zero_at = -1;
  for (int i = 0; i < 40 && zero_at < 0; ++i) {
    rig.tick();
    if (rig.base->sent_velocity(0) == 0.0F && rig.base->sent_velocity(1) == 0.0F) zero_at = rig.clock.now();
  }
  ASSERT_GE(zero_at, 0) << "never stopped";
  EXPECT_LE(zero_at - last, 200 * kNsPerMs + test::kTick);
  EXPECT_GT(zero_at - last, 150 * kNsPerMs) << "not before the timeout";
  EXPECT_EQ(rig.base->counters().watchdog_trips, 1U);
  EXPECT_EQ(rig.base->status().state, BaseState::kRunning) << "a stale command is not a fault";
  for (int i = 0; i < 60; ++i) rig.tick();
  EXPECT_NEAR(rig.wheel_mps(0), 0.0, 1e-9) << "the wheels came to rest";
  rig.base->command(0.3, 0.3, rig.clock.now());
  rig.tick();
  EXPECT_NE(rig.base->sent_velocity(1), 0.0F) << "a fresh command drives again";
}

TEST(Base, AnAxisErrorStopsAndIsReported) {
  BaseRig rig;
  rig.arm_and_wait();
  for (int i = 0; i < 20; ++i) {
    rig.base->command(0.8, 0.8, rig.clock.now());
    rig.tick();
  }
  rig.sim->inject_error(1, 0x00000200U);
  int ticks = 0;
  while (rig.base->status().state != BaseState::kFault && ticks++ < 30) {
    rig.base->command(0.8, 0.8, rig.clock.now());
    rig.tick();
  }
  ASSERT_EQ(rig.base->status().state, BaseState::kFault);
  EXPECT_EQ(rig.base->status().fault, BaseFault::kAxisError);
  EXPECT_EQ(rig.base->status().fault_node, rig.params.right_node);
  EXPECT_EQ(rig.base->status().fault_axis_error, 0x200U);
  EXPECT_LE(ticks, 11) << "within one heartbeat period";
  rig.base->command(0.8, 0.8, rig.clock.now());
  rig.tick();
  EXPECT_EQ(rig.base->sent_velocity(0), 0.0F) << "the healthy side is stopped too";
  EXPECT_EQ(rig.base->sent_velocity(1), 0.0F);
  EXPECT_EQ(rig.base->counters().faults, 1U);
}

TEST(Base, ASilentControllerStopsAndIsReportedThenReArmingRecovers) {
  BaseRig rig;
  rig.arm_and_wait();
  for (int i = 0; i < 20; ++i) {
    rig.base->command(0.5, 0.5, rig.clock.now());
    rig.tick();
  }
  rig.sim->set_silent(0, true);
  const TimeNs cut = rig.clock.now();
  while (rig.base->status().state != BaseState::kFault && rig.clock.now() - cut < kNsPerS) {
    rig.base->command(0.5, 0.5, rig.clock.now());
    rig.tick();
  }
  ASSERT_EQ(rig.base->status().fault, BaseFault::kControllerSilent);
  EXPECT_EQ(rig.base->status().fault_node, rig.params.left_node);
  EXPECT_LE(rig.clock.now() - cut, from_seconds(rig.params.heartbeat_timeout_s + 0.1) + test::kTick);
  EXPECT_EQ(rig.base->sent_velocity(1), 0.0F);
  // Commands do not drive a faulted base ...
  rig.sim->set_silent(0, false);
  for (int i = 0; i < 20; ++i) {
    rig.base->command(0.5, 0.5, rig.clock.now());
    rig.tick();
  }
  EXPECT_EQ(rig.base->status().state, BaseState::kFault);
  EXPECT_EQ(rig.base->sent_velocity(1), 0.0F);
  // ... until it is armed again.
  rig.arm_and_wait();
  EXPECT_EQ(rig.base->status().state, BaseState::kRunning);
  rig.base->command(0.5, 0.5, rig.clock.now());
  rig.tick();
  EXPECT_NE(rig.base->sent_velocity(1), 0.0F);
}

TEST(Base, ArmingTimesOutWhenAControllerNeverClosesTheLoop) {
  BaseRig rig;
  rig.sim->inject_error(0, 0x1U);  // an axis in error refuses closed loop
  rig.base->arm(rig.clock.now());
  for (int i = 0; i < 300 && rig.base->status().state == BaseState::kArming; ++i) rig.tick();
  EXPECT_EQ(rig.base->status().state, BaseState::kFault);
  EXPECT_EQ(rig.base->status().fault, BaseFault::kAxisError) << "the heartbeat already carries the error";
}

TEST(Base, OdometryFollowsTheWheelsAndForeignFramesAreCounted) {
  BaseRig rig;
  rig.arm_and_wait();
  // Ground truth: the exact (double) axis positions of the simulator, integrated finely.
  double x = 0, y = 0, yaw = 0;
  const double per_turn = 2.0 * kPi * rig.params.wheel_radius_m;
  double pl = rig.sim->pos_turns(0), pr = rig.sim->pos_turns(1);
  WheelOdometryMsg first{};
  bool have_first = false;
  for (TimeNs k = 0; k < 1000; ++k) {
    double l = 0, r = 0;
    test::scripted_wheels(static_cast<double>(k) * 0.01, l, r);
    rig.base->command(l, r, rig.clock.now());
    rig.tick();
    const double nl = rig.sim->pos_turns(0), nr = rig.sim->pos_turns(1);
    const double dl = -(nl - pl) * per_turn, dr = (nr - pr) * per_turn;
    pl = nl;
    pr = nr;
    const double th = (dr - dl) / rig.params.track_m;
    x += 0.5 * (dl + dr) * std::cos(yaw + 0.5 * th);
    y += 0.5 * (dl + dr) * std::sin(yaw + 0.5 * th);
    yaw += th;
    WheelOdometryMsg m;
    while (rig.base->take_odometry(m))
      if (!have_first) {
        first = m;
        have_first = true;
      }
  }
  ASSERT_TRUE(have_first);
  const Pose2 p = rig.base->odometry().pose;
  EXPECT_GT(std::hypot(x, y), 2.5) << "the script drove somewhere";
  EXPECT_NEAR(p.x - first.pose.x, x, 0.02);
  EXPECT_NEAR(p.y - first.pose.y, y, 0.02);
  EXPECT_NEAR(wrap_angle(p.yaw - yaw), 0.0, 0.01);
  // A frame of another node and a short frame of ours are counted, not used.
  can::CanFrame f = odrive::encode_encoder_estimates(9, {100.0F, 0.0F});
  ASSERT_EQ(rig.link.device().send(f), can::CanResult::kOk);
  f = odrive::encode_encoder_estimates(rig.params.left_node, {100.0F, 0.0F});
  f.dlc = 3;
  ASSERT_EQ(rig.link.device().send(f), can::CanResult::kOk);
  f = odrive::encode_encoder_estimates(rig.params.left_node, {std::nanf(""), 0.0F});
  ASSERT_EQ(rig.link.device().send(f), can::CanResult::kOk);
  const std::uint64_t foreign = rig.base->counters().rx_foreign, bad = rig.base->counters().rx_malformed;
  rig.tick();
  EXPECT_EQ(rig.base->counters().rx_foreign, foreign + 1);
  EXPECT_EQ(rig.base->counters().rx_malformed, bad + 1);
  EXPECT_EQ(rig.base->counters().non_finite_estimates, 1U);
  EXPECT_NEAR(rig.base->odometry().pose.x, p.x, 0.05) << "the bad frames did not move the odometry";
}

// Random frames from the bus (any id, dlc, bytes, flags) never crash the driver, never move the
// odometry by more than what real estimates among them say, and are all accounted for.
TEST(Base, RandomFramesAreCountedAndNeverCrash) {
  BaseRig rig;
  rig.arm_and_wait();
  std::uint64_t x = 0x9E3779B97F4A7C15ULL;
  auto next = [&]() {
    x ^= x << 13;
    x ^= x >> 7;
    x ^= x << 17;
    return x;
  };
  const BaseCounters before = rig.base->counters();
  std::uint64_t sent = 0;
  for (int k = 0; k < 5000; ++k) {
    can::CanFrame f;
    f.extended = next() % 8 == 0;
    f.id = static_cast<std::uint32_t>(next() & (f.extended ? can::kExtendedIdMask : 0x7FU));  // nodes 0..3: ours and others
    f.rtr = next() % 16 == 0;
    f.dlc = static_cast<std::uint8_t>(next() % 9);
    for (auto& b : f.data) b = static_cast<std::uint8_t>(next());
    if (rig.link.device().send(f) == can::CanResult::kOk) ++sent;
    if (k % 100 == 99) rig.tick();
  }
  rig.tick();
  const BaseCounters& c = rig.base->counters();
  const std::uint64_t accounted = (c.heartbeats - before.heartbeats) + (c.encoder_frames - before.encoder_frames) + (c.rx_foreign - before.rx_foreign) +
                                  (c.rx_malformed - before.rx_malformed) + (c.non_finite_estimates - before.non_finite_estimates);
  // The simulated controllers' own frames are counted too: at least every random frame is accounted for.
  EXPECT_GE(accounted, sent);
  EXPECT_GT(c.rx_foreign - before.rx_foreign, 1000U);
  EXPECT_GT(c.rx_malformed - before.rx_malformed, 10U);
  EXPECT_TRUE(std::isfinite(rig.base->odometry().pose.x));
}

}  // namespace
}  // namespace ag::base
