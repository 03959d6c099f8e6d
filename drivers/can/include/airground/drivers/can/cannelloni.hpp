// CAN over UDP in cannelloni's frame format (github.com/mguentner/cannelloni, doc/udp_format.md,
// version 2), so a simulator or a remote bus (cannelloni on another host's SocketCAN) can stand in for
// the robot's CAN interface. A datagram is
//   u8 version (2), u8 op code (0 = DATA), u8 sequence number, u16 count   (network byte order)
// then `count` frames: u32 can_id (linux/can.h flags: EFF 0x80000000, RTR 0x40000000, ERR 0x20000000),
// u8 len (0x80 set = CAN FD, then a u8 flags byte), len data bytes (none for a remote request).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "airground/drivers/can/can_bus.hpp"
#include "airground/drivers/can/can_error.hpp"
#include "airground/platform/result.hpp"

namespace ag::can::cannelloni {

inline constexpr std::uint8_t kVersion = 2;
inline constexpr std::uint8_t kOpData = 0, kOpAck = 1, kOpNack = 2;
inline constexpr std::size_t kHeaderSize = 5;
inline constexpr std::uint32_t kEffFlag = 0x80000000U, kRtrFlag = 0x40000000U, kErrFlag = 0x20000000U;

enum class DecodeStatus : std::uint8_t {
  kOk = 0,
  kShort = 1,          // shorter than the header
  kBadVersion = 2,
  kNotData = 3,        // ACK/NACK or an unknown op code (nothing to deliver)
  kTruncated = 4,      // fewer frames than `count` (the frames before the cut are delivered)
  kBadLength = 5,      // a classic frame with len > 8, an FD frame with len > 64
  kTrailingBytes = 6,  // bytes after `count` frames (the frames are delivered)
};
const char* to_string(DecodeStatus s) noexcept;

struct WireFrame {
  CanFrame frame;          // data frames (id, format, rtr, dlc, data)
  bool error{false};       // an error frame: frame.id holds the class bits, frame.data the details
  bool fd{false};          // a CAN FD frame (not delivered: classic CAN only; counted)
};

struct Decoded {
  std::uint8_t seq{0};
  std::uint16_t count{0};
  std::size_t frames{0};   // written to `out`
};

// Decodes one datagram into `out` (frames beyond out.size() are counted in `count` but not written).
[[nodiscard]] DecodeStatus decode(std::span<const std::uint8_t> datagram, std::span<WireFrame> out, Decoded& d) noexcept;
// Encodes classic frames into one datagram; returns its size, 0 when `out` is too small.
std::size_t encode(std::uint8_t seq, std::span<const CanFrame> frames, std::span<std::uint8_t> out) noexcept;
[[nodiscard]] constexpr std::size_t encoded_size(const CanFrame& f) noexcept { return 5 + (f.rtr ? 0 : f.dlc); }

}  // namespace ag::can::cannelloni

namespace ag::can {

struct CannelloniConfig {
  std::string bind_address{"0.0.0.0"};
  std::uint16_t local_port{20000};       // 0 = any (tests)
  std::string remote_address{"127.0.0.1"};
  std::uint16_t remote_port{20000};
  bool learn_remote{false};              // answer whoever sent the last datagram (a simulator's ephemeral port)
};

struct CannelloniCounters {
  std::uint64_t datagrams_tx{0}, datagrams_rx{0};
  std::uint64_t sequence_gaps{0};        // datagrams lost or reordered on the way (by sequence number)
  std::uint64_t decode_errors{0};        // malformed datagrams (see DecodeStatus)
  std::uint64_t fd_frames{0};            // CAN FD frames refused
  std::uint64_t queue_overflow{0};       // frames dropped because the receive queue was full
};

// A CanBus over UDP: each send() is one datagram (lowest latency; cannelloni itself batches on a
// timer, which its receivers accept the same); received datagrams are queued, filtered and handed
// out one frame per receive(). Error frames arriving over the bridge drive the bus state like
// SocketCAN's. Non-blocking; the socket's fd can sit in an event loop.
class CannelloniBus final : public CanBus {
 public:
  static constexpr std::size_t kQueue = 256;
  static Result<std::unique_ptr<CannelloniBus>> open(const CannelloniConfig& cfg);
  ~CannelloniBus() override;
  [[nodiscard]] CanResult send(const CanFrame& f) noexcept override;
  [[nodiscard]] CanResult receive(CanFrame& out) noexcept override;
  [[nodiscard]] const CanBusCounters& counters() const noexcept override { return c_; }
  [[nodiscard]] const CannelloniCounters& bridge_counters() const noexcept { return b_; }
  [[nodiscard]] CanBusState state() const noexcept { return errors_.state(); }
  [[nodiscard]] const CanErrorReport& last_error() const noexcept { return errors_.last(); }
  [[nodiscard]] std::uint16_t local_port() const noexcept { return port_; }
  [[nodiscard]] int fd() const noexcept { return fd_; }
  // Sends frames of any kind batched in one datagram (tests, the simulator's side of the bridge).
  CanResult send_batch(std::span<const CanFrame> frames, std::span<const std::uint32_t> raw_ids = {}) noexcept;

 private:
  CannelloniBus(int fd, std::uint16_t port, std::uint32_t remote_ip, std::uint16_t remote_port, bool learn)
      : fd_(fd), port_(port), remote_ip_(remote_ip), remote_port_(remote_port), learn_(learn) {}
  void pump() noexcept;
  int fd_{-1};
  std::uint16_t port_{0};
  std::uint32_t remote_ip_{0};
  std::uint16_t remote_port_{0};
  bool learn_{false};
  std::uint8_t tx_seq_{0}, rx_seq_{0};
  bool rx_seq_known_{false};
  std::array<CanFrame, kQueue> q_{};
  std::size_t head_{0}, size_{0};
  std::array<cannelloni::WireFrame, 128> scratch_{};
  CanBusCounters c_;
  CannelloniCounters b_;
  CanErrorTracker errors_;
};

}  // namespace ag::can
