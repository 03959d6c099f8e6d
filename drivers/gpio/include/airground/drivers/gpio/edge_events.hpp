// Edge events of an input line (the e-stop) delivered through a file descriptor, so the daemon's event
// loop (poll/epoll) wakes on a press instead of polling the level: the libgpiod 1.6 backend's line-event
// fd on the robot, an eventfd for the fake line in tests and the simulator.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "airground/drivers/gpio/gpio_line.hpp"
#include "airground/platform/result.hpp"
#include "airground/platform/time.hpp"

namespace ag::gpio {

enum class Edge : std::uint8_t { kRising = 0, kFalling = 1 };  // logical: rising = became active (pressed)
struct EdgeEvent {
  Edge edge{Edge::kRising};
  TimeNs stamp{0};  // [ns] CLOCK_MONOTONIC when the kernel saw the edge (libgpiod on kernels >= 5.7)
};

class EdgeSource {
 public:
  EdgeSource() = default;
  EdgeSource(const EdgeSource&) = delete;
  EdgeSource& operator=(const EdgeSource&) = delete;
  virtual ~EdgeSource() = default;
  // Readable (POLLIN) when events are pending.
  [[nodiscard]] virtual int event_fd() const noexcept = 0;
  // Pending events into `out`, oldest first; never blocks. Returns the count, -1 on an error.
  [[nodiscard]] virtual int read_events(std::span<EdgeEvent> out) noexcept = 0;
};

// A fake input line with edge events: press() changes the level and, on a change, queues an edge and
// signals an eventfd. Also a DigitalLine (its level), like the real line.
class FakeEdgeLine final : public EdgeSource, public DigitalLine {
 public:
  static constexpr std::size_t kQueue = 64;
  FakeEdgeLine();
  ~FakeEdgeLine() override;
  [[nodiscard]] int event_fd() const noexcept override { return efd_; }
  [[nodiscard]] int read_events(std::span<EdgeEvent> out) noexcept override;
  [[nodiscard]] LineResult get(bool& active) noexcept override {
    active = level_;
    return LineResult::kOk;
  }
  [[nodiscard]] LineResult set(bool) noexcept override { return LineResult::kError; }  // an input
  void press(bool active, TimeNs stamp) noexcept;
  [[nodiscard]] std::uint64_t overruns() const noexcept { return overruns_; }

 private:
  int efd_{-1};
  bool level_{false};
  std::array<EdgeEvent, kQueue> q_{};
  std::size_t head_{0}, size_{0};
  std::uint64_t overruns_{0};
};

// A libgpiod input line requesting both edges (its event fd set non-blocking). Fails like
// open_gpiod_line when libgpiod is not in this build or the line is busy.
Result<std::unique_ptr<EdgeSource>> open_gpiod_edge_line(const std::string& chip, unsigned offset, bool active_low,
                                                         const std::string& consumer);

// Reads an e-stop's edges from its fd and keeps the latest level; call when the fd is readable (or every
// cycle: it never blocks).
class EStopEdges {
 public:
  explicit EStopEdges(EdgeSource& src, bool initial_pressed = false) noexcept : src_(src), pressed_(initial_pressed) {}
  // Drains pending events; false when the source failed (treat as pressed: fail-safe).
  bool drain() noexcept;
  [[nodiscard]] bool pressed() const noexcept { return pressed_; }
  // Pressed at any time since the last drain, even if released again (a short tap still stops).
  [[nodiscard]] bool tapped() const noexcept { return tapped_; }
  [[nodiscard]] std::uint64_t edges() const noexcept { return edges_; }
  [[nodiscard]] TimeNs last_edge() const noexcept { return last_; }

 private:
  EdgeSource& src_;
  bool pressed_, tapped_{false};
  std::uint64_t edges_{0};
  TimeNs last_{0};
};

}  // namespace ag::gpio
