// E-stop latch, LED patterns, fake-line registry.
#include "airground/drivers/gpio/estop.hpp"
#include "airground/platform/device_registry.hpp"

#include <string>

#include "airground/drivers/gpio/gpio_line.hpp"

namespace ag::gpio {

const char* to_string(EStopState s) noexcept {
  switch (s) {
    case EStopState::kArmed: return "armed";
    case EStopState::kAsserted: return "asserted";
    case EStopState::kLatched: return "latched (released, waiting for re-arm)";
    case EStopState::kLineFault: return "line fault (treated as asserted)";
  }
  return "?";
}

bool EStopLatch::update(bool line_ok, bool asserted, bool rearm) noexcept {
  if (!line_ok) {
    if (state_ != EStopState::kLineFault) ++line_faults_;
    state_ = EStopState::kLineFault;
  } else if (asserted) {
    if (state_ != EStopState::kAsserted) ++assertions_;
    state_ = EStopState::kAsserted;
  } else if (state_ == EStopState::kAsserted || state_ == EStopState::kLineFault) {
    state_ = EStopState::kLatched;  // released: a re-arm must come after this
  } else if (state_ == EStopState::kLatched && rearm) {
    state_ = EStopState::kArmed;
  }
  return stopped();
}

bool led_level(LedPattern p, TimeNs now) noexcept {
  switch (p) {
    case LedPattern::kOff: return false;
    case LedPattern::kOn: return true;
    case LedPattern::kSlowBlink: return (now / (500 * kNsPerMs)) % 2 == 0;
    case LedPattern::kFastBlink: return (now / (125 * kNsPerMs)) % 2 == 0;
    case LedPattern::kDoubleFlash: {
      const TimeNs t = ((now % kNsPerS) + kNsPerS) % kNsPerS;
      return t < 100 * kNsPerMs || (t >= 300 * kNsPerMs && t < 400 * kNsPerMs);
    }
  }
  return false;
}

const char* to_string(RoleState s) noexcept {
  switch (s) {
    case RoleState::kBooting: return "booting";
    case RoleState::kLocalizing: return "localizing";
    case RoleState::kTracking: return "tracking";
    case RoleState::kFault: return "fault";
  }
  return "?";
}

LedPattern led_pattern_for(RoleState s) noexcept {
  switch (s) {
    case RoleState::kBooting: return LedPattern::kSlowBlink;
    case RoleState::kLocalizing: return LedPattern::kFastBlink;
    case RoleState::kTracking: return LedPattern::kOn;
    case RoleState::kFault: return LedPattern::kDoubleFlash;
  }
  return LedPattern::kDoubleFlash;
}

// A robot's line replaces the one it had under that name (a test's rig made again).
void register_fake_line(std::string_view robot, std::string_view line, FakeLine* l) {
  auto& r = DeviceRegistry<FakeLine>::instance();
  const std::string name = std::string(robot) + "/" + std::string(line);
  r.remove(name);
  (void)r.add(name, l);
}
void unregister_fake_lines(std::string_view robot) { DeviceRegistry<FakeLine>::instance().remove_prefix(std::string(robot) + "/"); }
FakeLine* find_fake_line(std::string_view robot, std::string_view line) {
  return DeviceRegistry<FakeLine>::instance().find(std::string(robot) + "/" + std::string(line));
}

}  // namespace ag::gpio
