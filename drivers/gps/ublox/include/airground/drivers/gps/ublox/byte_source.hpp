// Where the receiver's bytes come from, live or recorded, behind one interface: a serial port
// (termios, raw 8N1, non-blocking) or a replay file (gpsd's test-log format: leading '#' comment lines,
// then the raw stream).
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "airground/drivers/serial/byte_ring.hpp"
#include "airground/platform/result.hpp"
#include "airground/platform/time.hpp"

namespace ag::ublox {

class ByteSource {
 public:
  ByteSource() = default;
  ByteSource(const ByteSource&) = delete;
  ByteSource& operator=(const ByteSource&) = delete;
  virtual ~ByteSource() = default;
  // Bytes available now, up to buf.size(); 0 when none; -1 on an error (error() says what) or at the end
  // of a recording (at_end()). Never blocks.
  [[nodiscard]] virtual long read(std::span<std::uint8_t> buf) noexcept = 0;
  // Blocks until bytes may be ready or `timeout` passes; false on timeout.
  virtual bool wait(TimeNs timeout) noexcept = 0;
  [[nodiscard]] virtual bool at_end() const noexcept { return false; }
  [[nodiscard]] virtual const std::string& error() const noexcept = 0;
};

class SerialPort final : public ByteSource {
 public:
  // Opens `device` ("/dev/ttyACM0", a pty) raw at `baud` (9600 ... 921600).
  static Result<std::unique_ptr<SerialPort>> open(const std::string& device, int baud);
  ~SerialPort() override;
  [[nodiscard]] long read(std::span<std::uint8_t> buf) noexcept override;
  bool wait(TimeNs timeout) noexcept override;
  [[nodiscard]] const std::string& error() const noexcept override { return error_; }
  [[nodiscard]] int fd() const noexcept { return fd_; }
  // Sends bytes (configuration messages); returns the count written, -1 on error.
  long write(std::span<const std::uint8_t> bytes) noexcept;

 private:
  explicit SerialPort(int fd, std::string dev) : fd_(fd), device_(std::move(dev)) {}
  int fd_{-1};
  std::string device_, error_;
};

class ReplayFile final : public ByteSource {
 public:
  // Loads the file; `chunk` bytes are handed out per read() (a serial port delivers in pieces too).
  static Result<std::unique_ptr<ReplayFile>> open(const std::string& path, std::size_t chunk = 64);
  static std::unique_ptr<ReplayFile> from_bytes(std::vector<std::uint8_t> bytes, std::size_t chunk = 64);
  [[nodiscard]] long read(std::span<std::uint8_t> buf) noexcept override;
  bool wait(TimeNs) noexcept override { return true; }
  [[nodiscard]] bool at_end() const noexcept override { return pos_ >= data_.size(); }
  [[nodiscard]] const std::string& error() const noexcept override { return error_; }
  [[nodiscard]] std::size_t comment_bytes() const noexcept { return start_; }

 private:
  ReplayFile(std::vector<std::uint8_t> d, std::size_t chunk);
  std::vector<std::uint8_t> data_;
  std::size_t start_{0}, pos_{0}, chunk_{64};
  std::string error_;
};

// The simulator's receiver (the stage's `source: sim`): what the simulated receiver writes on its UART
// (a serial::ByteRing: allocated once, an overrun counted), handed to the robot's gps stage in-process.
class SimSerialLink {
 public:
  explicit SimSerialLink(std::size_t capacity = 16384) : uart_(capacity) {}
  SimSerialLink(const SimSerialLink&) = delete;
  SimSerialLink& operator=(const SimSerialLink&) = delete;
  // The receiver sends these bytes; returns how many fitted.
  std::size_t write(std::span<const std::uint8_t> bytes) noexcept { return uart_.write(bytes); }
  // The stage's side (it must not outlive the link).
  [[nodiscard]] std::unique_ptr<ByteSource> open_source();
  [[nodiscard]] std::uint64_t dropped() const noexcept { return uart_.dropped(); }
  [[nodiscard]] std::size_t queued() const noexcept { return uart_.size(); }

 private:
  friend class SimSerialSource;
  serial::ByteRing uart_;
};

// Links the simulator provides for its robots' gps stages, by robot name; false when taken.
[[nodiscard]] bool register_sim_gps(std::string_view robot, SimSerialLink* link);
void unregister_sim_gps(std::string_view robot);
[[nodiscard]] SimSerialLink* find_sim_gps(std::string_view robot);

}  // namespace ag::ublox
