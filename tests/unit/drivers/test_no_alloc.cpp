// The base driver and the base stage never allocate in their real-time calls (operator new counted by
// tests/common/counting_new.hpp): commands, frames, faults, odometry, e-stop, LED.
#include <gtest/gtest.h>

#include "base_rig.hpp"

#include "../../common/counting_new.hpp"

namespace ag::base {
namespace {
using test_alloc::AllocationWindow;

TEST(DriversNoAllocation, TheCounterSeesAllocations) {
  AllocationWindow w;
  std::vector<int> v(100);
  EXPECT_GE(w.allocations(), 1U);
}

TEST(DriversNoAllocation, DriverStepsFaultsAndOdometry) {
  test::BaseRig rig;
  rig.arm_and_wait();
  WheelOdometryMsg m;
  std::uint64_t samples = 0;
  {
    AllocationWindow window;
    for (int k = 0; k < 600; ++k) {
      double l = 0, r = 0;
      test::scripted_wheels(k * 0.01, l, r);
      rig.base->command(l, r, rig.clock.now());
      if (k == 300) rig.sim->inject_error(0, 0x40U);
      if (k == 400) rig.base->arm(rig.clock.now());
      rig.tick();
      while (rig.base->take_odometry(m)) ++samples;
    }
    EXPECT_EQ(window.allocations(), 0U) << "allocations in DiffDriveBase";
  }
  EXPECT_GT(samples, 500U);
  EXPECT_GE(rig.base->counters().faults, 1U);
}

}  // namespace
}  // namespace ag::base
