// Where the autopilot's MAVLink bytes come from, live or recorded, behind one interface: a serial port
// (termios, raw 8N1, non-blocking: PX4's TELEM2), a UDP socket (PX4's onboard link, one datagram per
// read) or a telemetry log (.tlog, QGroundControl / MAVProxy: every frame preceded by its arrival time,
// a big-endian u64 of microseconds since the UNIX epoch; one record per read).
#pragma once

#include <netinet/in.h>

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "airground/drivers/serial/byte_ring.hpp"
#include "airground/platform/result.hpp"
#include "airground/platform/time.hpp"

namespace ag::mavlink {

class Link {
 public:
  Link() = default;
  Link(const Link&) = delete;
  Link& operator=(const Link&) = delete;
  virtual ~Link() = default;
  // Bytes available now, up to buf.size(); 0 when none; -1 on an error (error() says what) or at the end
  // of a recording (at_end()). `recorded_ns` is when a recording logged them [ns since the UNIX epoch],
  // -1 for a live link. Never blocks.
  [[nodiscard]] virtual long read(std::span<std::uint8_t> buf, TimeNs& recorded_ns) noexcept = 0;
  // True when every read() is a whole datagram or record (a frame may not continue into the next).
  [[nodiscard]] virtual bool packetized() const noexcept = 0;
  // Replay: the recorded time of the next record (-1 when none or live), so a caller can pace it.
  [[nodiscard]] virtual TimeNs next_recorded() const noexcept { return -1; }
  // Sends bytes to the autopilot (requests); the count written, 0 when it cannot now, -1 on error.
  virtual long write(std::span<const std::uint8_t> bytes) noexcept = 0;
  // Blocks until bytes may be ready or `timeout` passes; false on timeout.
  virtual bool wait(TimeNs timeout) noexcept = 0;
  [[nodiscard]] virtual bool at_end() const noexcept { return false; }
  [[nodiscard]] virtual const std::string& error() const noexcept = 0;
};

class SerialLink final : public Link {
 public:
  // Opens `device` (/dev/ttyUSB0, /dev/ttyTHS1, a pty) raw at `baud` (57600 ... 3000000).
  static Result<std::unique_ptr<SerialLink>> open(const std::string& device, int baud);
  ~SerialLink() override;
  [[nodiscard]] long read(std::span<std::uint8_t> buf, TimeNs& recorded_ns) noexcept override;
  [[nodiscard]] bool packetized() const noexcept override { return false; }
  long write(std::span<const std::uint8_t> bytes) noexcept override;
  bool wait(TimeNs timeout) noexcept override;
  [[nodiscard]] const std::string& error() const noexcept override { return error_; }
  [[nodiscard]] int fd() const noexcept { return fd_; }

 private:
  SerialLink(int fd, std::string dev) : fd_(fd), device_(std::move(dev)) {}
  int fd_{-1};
  std::string device_, error_;
};

class UdpLink final : public Link {
 public:
  // Binds a non-blocking UDP socket on bind_address:port (port 0: any free port, see port()). Replies
  // go to whoever sent the last datagram (the autopilot's ephemeral port).
  static Result<std::unique_ptr<UdpLink>> open(const std::string& bind_address, int port);
  ~UdpLink() override;
  [[nodiscard]] long read(std::span<std::uint8_t> buf, TimeNs& recorded_ns) noexcept override;
  [[nodiscard]] bool packetized() const noexcept override { return true; }
  long write(std::span<const std::uint8_t> bytes) noexcept override;
  bool wait(TimeNs timeout) noexcept override;
  [[nodiscard]] const std::string& error() const noexcept override { return error_; }
  [[nodiscard]] int fd() const noexcept { return fd_; }
  [[nodiscard]] int port() const noexcept { return port_; }
  [[nodiscard]] bool has_peer() const noexcept { return have_peer_; }
  [[nodiscard]] std::uint64_t cut_datagrams() const noexcept { return cut_; }  // larger than the read buffer

 private:
  UdpLink(int fd, int port) : fd_(fd), port_(port) {}
  int fd_{-1}, port_{0};
  sockaddr_in peer_{};
  bool have_peer_{false};
  std::uint64_t cut_{0};
  std::string error_;
};

class TlogReplay final : public Link {
 public:
  static Result<std::unique_ptr<TlogReplay>> open(const std::string& path);
  static std::unique_ptr<TlogReplay> from_bytes(std::vector<std::uint8_t> bytes);
  [[nodiscard]] long read(std::span<std::uint8_t> buf, TimeNs& recorded_ns) noexcept override;
  [[nodiscard]] bool packetized() const noexcept override { return true; }
  [[nodiscard]] TimeNs next_recorded() const noexcept override;
  long write(std::span<const std::uint8_t>) noexcept override { return 0; }  // nobody to ask
  bool wait(TimeNs) noexcept override { return true; }
  [[nodiscard]] bool at_end() const noexcept override { return pos_ >= data_.size(); }
  [[nodiscard]] const std::string& error() const noexcept override { return error_; }
  [[nodiscard]] std::uint64_t records() const noexcept { return records_; }
  [[nodiscard]] std::uint64_t skipped_bytes() const noexcept { return bad_; }  // where no record starts (a corrupt log)

 private:
  explicit TlogReplay(std::vector<std::uint8_t> d) : data_(std::move(d)) {}
  std::size_t record_size(std::size_t at) const noexcept;  // 0 when no frame starts at `at` + 8
  std::vector<std::uint8_t> data_;
  std::size_t pos_{0};
  std::uint64_t records_{0}, bad_{0};
  std::string error_;
};

// The simulator's autopilot (the stage's `source: sim`): its TELEM2 UART in-process, both ways. The
// simulated autopilot writes frames to_robot; the stage's requests land in from_robot (serial::ByteRing:
// allocated once, an overrun counted). The stage reads a byte stream, as from a serial port.
class SimAutopilotLink {
 public:
  explicit SimAutopilotLink(std::size_t capacity = 16384) : to_robot(capacity), from_robot(capacity) {}
  SimAutopilotLink(const SimAutopilotLink&) = delete;
  SimAutopilotLink& operator=(const SimAutopilotLink&) = delete;
  // The stage's side (it must not outlive the link).
  [[nodiscard]] std::unique_ptr<Link> open_link();
  serial::ByteRing to_robot, from_robot;
};

// Links the simulator provides for its robots' autopilot stages, by robot name; false when taken.
[[nodiscard]] bool register_sim_autopilot(std::string_view robot, SimAutopilotLink* link);
void unregister_sim_autopilot(std::string_view robot);
[[nodiscard]] SimAutopilotLink* find_sim_autopilot(std::string_view robot);

// Appends one tlog record (the simulator's and the tests' writer).
void append_tlog_record(std::vector<std::uint8_t>& out, std::uint64_t unix_us, std::span<const std::uint8_t> frame);

}  // namespace ag::mavlink
