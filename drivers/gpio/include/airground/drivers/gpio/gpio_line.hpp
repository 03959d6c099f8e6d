// One digital line (the e-stop input, the status LED output) behind one interface: the libgpiod 1.6
// backend on the robot (gpiod_line.hpp, the only code that touches libgpiod) and a fake line for the
// tests and the simulator (this machine has no GPIO chip). Values are logical: true = active (an
// active-low line's electrical level is inverted by the backend).
#pragma once

#include <memory>
#include <string>
#include <string_view>

#include "airground/platform/result.hpp"

namespace ag::gpio {

enum class LineResult : std::uint8_t { kOk = 0, kError = 1 };

class DigitalLine {
 public:
  DigitalLine() = default;
  DigitalLine(const DigitalLine&) = delete;
  DigitalLine& operator=(const DigitalLine&) = delete;
  virtual ~DigitalLine() = default;
  // Reads the line; never blocks.
  [[nodiscard]] virtual LineResult get(bool& active) noexcept = 0;
  // Drives an output line; never blocks.
  [[nodiscard]] virtual LineResult set(bool active) noexcept = 0;
};

// A line in memory: tests and the simulator press the button or read the LED; failures can be injected.
class FakeLine final : public DigitalLine {
 public:
  explicit FakeLine(bool initial = false) noexcept : value_(initial) {}
  [[nodiscard]] LineResult get(bool& active) noexcept override {
    if (failing_) return LineResult::kError;
    active = value_;
    return LineResult::kOk;
  }
  [[nodiscard]] LineResult set(bool active) noexcept override {
    if (failing_) return LineResult::kError;
    value_ = active;
    ++writes_;
    return LineResult::kOk;
  }
  void press(bool active) noexcept { value_ = active; }
  void fail(bool failing) noexcept { failing_ = failing; }
  [[nodiscard]] bool value() const noexcept { return value_; }
  [[nodiscard]] std::uint64_t writes() const noexcept { return writes_; }

 private:
  bool value_{false};
  bool failing_{false};
  std::uint64_t writes_{0};
};

// Fake lines the simulator (or a test) provides for a robot's stages, by "<robot>/<line>" ("ugv1/estop").
void register_fake_line(std::string_view robot, std::string_view line, FakeLine* l);
void unregister_fake_lines(std::string_view robot);
[[nodiscard]] FakeLine* find_fake_line(std::string_view robot, std::string_view line);

enum class Direction : std::uint8_t { kInput, kOutput };
// A libgpiod line: chip by name, path or number ("gpiochip0", "/dev/gpiochip0", "0"), line offset.
// Fails with a message naming chip and line when libgpiod is not in this build or the line is busy.
Result<std::unique_ptr<DigitalLine>> open_gpiod_line(const std::string& chip, unsigned offset, Direction dir, bool active_low,
                                                     const std::string& consumer);
[[nodiscard]] bool gpiod_available() noexcept;

}  // namespace ag::gpio
