// The e-stop latch and the status LED pattern. An asserted e-stop (or a line that cannot be read:
// fail-safe) stops the robot on the cycle it is seen; the robot stays stopped until the button is
// released AND a re-arm is requested after the release.
#pragma once

#include <cstdint>

#include "airground/platform/time.hpp"

namespace ag::gpio {

enum class EStopState : std::uint8_t {
  kArmed = 0,        // released, re-armed: the robot may drive
  kAsserted = 1,     // the button is pressed
  kLatched = 2,      // released, waiting for a re-arm
  kLineFault = 3,    // the line cannot be read: treated as pressed
};
const char* to_string(EStopState s) noexcept;

class EStopLatch {
 public:
  // start_armed: false means the robot starts stopped (a re-arm is needed after power-up).
  explicit EStopLatch(bool start_armed = false) noexcept : state_(start_armed ? EStopState::kArmed : EStopState::kLatched) {}
  // One cycle: line_ok false = read error. rearm: a re-arm request arrived this cycle. Returns true when
  // the robot must not drive.
  bool update(bool line_ok, bool asserted, bool rearm) noexcept;
  [[nodiscard]] EStopState state() const noexcept { return state_; }
  [[nodiscard]] bool stopped() const noexcept { return state_ != EStopState::kArmed; }
  [[nodiscard]] std::uint64_t assertions() const noexcept { return assertions_; }
  [[nodiscard]] std::uint64_t line_faults() const noexcept { return line_faults_; }

 private:
  EStopState state_;
  std::uint64_t assertions_{0}, line_faults_{0};
};

enum class LedPattern : std::uint8_t { kOff = 0, kOn = 1, kSlowBlink = 2, kFastBlink = 3, kDoubleFlash = 4 };
// LED level at time `now` for a pattern (slow: 1 Hz, fast: 4 Hz, 50 % duty; double flash: two 100 ms
// flashes 200 ms apart every second).
[[nodiscard]] bool led_level(LedPattern p, TimeNs now) noexcept;

// What a role's status LED shows: booting slow blink, localizing fast blink, tracking steady, fault
// double flash (distinct at a glance and by duty cycle).
enum class RoleState : std::uint8_t { kBooting = 0, kLocalizing = 1, kTracking = 2, kFault = 3 };
const char* to_string(RoleState s) noexcept;
[[nodiscard]] LedPattern led_pattern_for(RoleState s) noexcept;

}  // namespace ag::gpio
