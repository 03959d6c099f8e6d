// The libgpiod 1.6 backend: the only file that includes gpiod.h. Built without libgpiod (AG_HAVE_GPIOD
// unset), open_gpiod_line() fails with a message saying so.
#include "airground/drivers/gpio/edge_events.hpp"
#include "airground/drivers/gpio/gpio_line.hpp"

#if defined(AG_HAVE_GPIOD)
#include <gpiod.h>

#include <algorithm>
#include <array>

#include <fcntl.h>

#include <cerrno>
#include <cstring>
#endif

namespace ag::gpio {

#if defined(AG_HAVE_GPIOD)
namespace {
class GpiodLine final : public DigitalLine {
 public:
  GpiodLine(gpiod_chip* chip, gpiod_line* line) noexcept : chip_(chip), line_(line) {}
  ~GpiodLine() override {
    gpiod_line_release(line_);
    gpiod_chip_close(chip_);
  }
  [[nodiscard]] LineResult get(bool& active) noexcept override {
    const int v = gpiod_line_get_value(line_);  // logical value: libgpiod applies active-low
    if (v < 0) return LineResult::kError;
    active = v != 0;
    return LineResult::kOk;
  }
  [[nodiscard]] LineResult set(bool active) noexcept override {
    return gpiod_line_set_value(line_, active ? 1 : 0) == 0 ? LineResult::kOk : LineResult::kError;
  }

 private:
  gpiod_chip* chip_;
  gpiod_line* line_;
};
}  // namespace

bool gpiod_available() noexcept { return true; }

Result<std::unique_ptr<DigitalLine>> open_gpiod_line(const std::string& chip, unsigned offset, Direction dir, bool active_low,
                                                     const std::string& consumer) {
  const std::string where = "GPIO " + chip + " line " + std::to_string(offset);
  gpiod_chip* c = gpiod_chip_open_lookup(chip.c_str());
  if (c == nullptr) return Error::make(ErrorCode::kUnavailable, where + ": cannot open the chip: " + std::strerror(errno));
  gpiod_line* l = gpiod_chip_get_line(c, offset);
  if (l == nullptr) {
    const int e = errno;
    gpiod_chip_close(c);
    return Error::make(ErrorCode::kUnavailable, where + ": no such line: " + std::strerror(e));
  }
  gpiod_line_request_config cfg{};
  cfg.consumer = consumer.c_str();
  cfg.request_type = dir == Direction::kInput ? GPIOD_LINE_REQUEST_DIRECTION_INPUT : GPIOD_LINE_REQUEST_DIRECTION_OUTPUT;
  cfg.flags = active_low ? GPIOD_LINE_REQUEST_FLAG_ACTIVE_LOW : 0;
  if (gpiod_line_request(l, &cfg, 0) != 0) {
    const int e = errno;
    gpiod_chip_close(c);
    return Error::make(e == EBUSY ? ErrorCode::kUnavailable : ErrorCode::kIo, where + ": request failed (busy or no permission): " + std::strerror(e));
  }
  return std::unique_ptr<DigitalLine>(new GpiodLine(c, l));
}

namespace {
class GpiodEdgeLine final : public EdgeSource {
 public:
  GpiodEdgeLine(gpiod_chip* chip, gpiod_line* line, int fd) noexcept : chip_(chip), line_(line), fd_(fd) {}
  ~GpiodEdgeLine() override {
    gpiod_line_release(line_);
    gpiod_chip_close(chip_);
  }
  [[nodiscard]] int event_fd() const noexcept override { return fd_; }
  [[nodiscard]] int read_events(std::span<EdgeEvent> out) noexcept override {
    std::array<gpiod_line_event, 16> ev{};
    const auto want = static_cast<unsigned>(std::min(out.size(), ev.size()));
    if (want == 0) return 0;
    const int n = gpiod_line_event_read_fd_multiple(fd_, ev.data(), want);
    if (n < 0) return errno == EAGAIN ? 0 : -1;
    for (int i = 0; i < n; ++i) {
      const gpiod_line_event& e = ev[static_cast<std::size_t>(i)];
      // Logical edges: with ACTIVE_LOW requested, libgpiod already reports a press as rising.
      out[static_cast<std::size_t>(i)] = EdgeEvent{e.event_type == GPIOD_LINE_EVENT_RISING_EDGE ? Edge::kRising : Edge::kFalling,
                                                   static_cast<TimeNs>(e.ts.tv_sec) * kNsPerS + e.ts.tv_nsec};
    }
    return n;
  }

 private:
  gpiod_chip* chip_;
  gpiod_line* line_;
  int fd_;
};
}  // namespace

Result<std::unique_ptr<EdgeSource>> open_gpiod_edge_line(const std::string& chip, unsigned offset, bool active_low,
                                                         const std::string& consumer) {
  const std::string where = "GPIO " + chip + " line " + std::to_string(offset);
  gpiod_chip* c = gpiod_chip_open_lookup(chip.c_str());
  if (c == nullptr) return Error::make(ErrorCode::kUnavailable, where + ": cannot open the chip: " + std::strerror(errno));
  gpiod_line* l = gpiod_chip_get_line(c, offset);
  if (l == nullptr || gpiod_line_request_both_edges_events_flags(l, consumer.c_str(), active_low ? GPIOD_LINE_REQUEST_FLAG_ACTIVE_LOW : 0) != 0) {
    const int e = errno;
    gpiod_chip_close(c);
    return Error::make(ErrorCode::kUnavailable, where + ": edge-event request failed (busy, no such line or no permission): " + std::strerror(e));
  }
  const int fd = gpiod_line_event_get_fd(l);
  if (fd < 0 || ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) | O_NONBLOCK) != 0) {
    const int e = errno;
    gpiod_line_release(l);
    gpiod_chip_close(c);
    return Error::make(ErrorCode::kIo, where + ": event fd: " + std::strerror(e));
  }
  return std::unique_ptr<EdgeSource>(new GpiodEdgeLine(c, l, fd));
}
#else
bool gpiod_available() noexcept { return false; }

Result<std::unique_ptr<DigitalLine>> open_gpiod_line(const std::string& chip, unsigned offset, Direction, bool, const std::string&) {
  return Error::make(ErrorCode::kUnavailable, "GPIO " + chip + " line " + std::to_string(offset) +
                                                  ": this build has no libgpiod (install libgpiod-dev for the target and rebuild)");
}

Result<std::unique_ptr<EdgeSource>> open_gpiod_edge_line(const std::string& chip, unsigned offset, bool, const std::string&) {
  return Error::make(ErrorCode::kUnavailable, "GPIO " + chip + " line " + std::to_string(offset) +
                                                  ": this build has no libgpiod (install libgpiod-dev for the target and rebuild)");
}
#endif

}  // namespace ag::gpio
