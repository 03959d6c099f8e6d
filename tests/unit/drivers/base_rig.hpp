// A driver and two simulated controllers joined by the in-process CAN link, on a simulated clock; and
// the scripted drive the recorded log comes from.
#pragma once

#include <cmath>
#include <memory>

#include "airground/drivers/base/diff_drive_base.hpp"
#include "airground/drivers/base/odrive_sim.hpp"
#include "airground/drivers/can/inprocess_bus.hpp"
#include "airground/platform/clock.hpp"

namespace ag::base::test {

inline constexpr TimeNs kTick = 10 * kNsPerMs;  // the drive stage's 100 Hz

struct BaseRig {
  SimClock clock{0};
  can::InProcessCanLink link{clock};
  BaseParams params{};
  std::unique_ptr<DiffDriveBase> base;
  std::unique_ptr<OdriveSimulator> sim;
  can::CanBus* driver_bus{&link.robot()};

  explicit BaseRig(const BaseParams& p = BaseParams{}, const OdriveSimParams& sp = OdriveSimParams{}, can::CanBus* bus = nullptr) : params(p) {
    if (bus != nullptr) driver_bus = bus;
    base = std::make_unique<DiffDriveBase>(params, *driver_bus);
    sim = std::make_unique<OdriveSimulator>(link.device(), std::array<std::uint8_t, 2>{p.left_node, p.right_node}, sp);
  }
  // One tick: the controllers, then the driver (as the lockstep runner orders them).
  void tick() {
    clock.set(clock.now() + kTick);
    sim->step(clock.now());
    base->step(clock.now());
  }
  void arm_and_wait() {
    base->arm(clock.now());
    for (int i = 0; i < 50 && base->status().state != BaseState::kRunning; ++i) tick();
  }
  // Wheel speeds [m/s] of the simulated axes.
  [[nodiscard]] double wheel_mps(int axis) const {
    const double per_turn = 2.0 * kPi * params.wheel_radius_m / params.gear_ratio;
    return sim->vel_turns_s(axis) * per_turn * (axis == 0 ? params.left_sign : params.right_sign);
  }
};

// The scripted drive of the recorded run: wheel speeds [m/s] at time t [s].
inline void scripted_wheels(double t, double& l, double& r) {
  if (t < 3.0) { l = r = 0.8 * t / 3.0; }
  else if (t < 6.0) { l = 0.5; r = 1.0; }
  else if (t < 8.0) { l = 0.9; r = 0.3; }
  else if (t < 10.0) { l = -0.4; r = 0.4; }
  else { l = r = 0.0; }
}

}  // namespace ag::base::test
