// Where Ouster packets come from, one interface for live and recorded (like the SDK's PacketSource):
// UdpPacketSource (non-blocking sockets on the lidar and IMU ports) and PcapPacketSource (a capture).
// The caller owns the buffer; next() never blocks and never allocates; wait() blocks up to a deadline.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "airground/drivers/lidar/ouster/pcap_reader.hpp"
#include "airground/platform/result.hpp"
#include "airground/platform/time.hpp"

namespace ag::ouster {

enum class PacketKind : std::uint8_t {
  kNone = 0,   // nothing ready now
  kLidar = 1,
  kImu = 2,
  kEnd = 3,    // a recording is over
  kError = 4,  // a socket error or a corrupt record (counted; error() says what)
};

struct SourceCounters {
  std::uint64_t lidar{0}, imu{0};
  std::uint64_t truncated{0};   // datagram larger than the caller's buffer (dropped)
  std::uint64_t errors{0};
};

class PacketSource {
 public:
  PacketSource() = default;
  PacketSource(const PacketSource&) = delete;
  PacketSource& operator=(const PacketSource&) = delete;
  virtual ~PacketSource() = default;
  // The next packet into `buf` (size in `size`, receive or capture time in `stamp`).
  [[nodiscard]] virtual PacketKind next(std::span<std::uint8_t> buf, std::size_t& size, TimeNs& stamp) noexcept = 0;
  // Blocks until a packet may be ready or `timeout` passes; false on timeout.
  virtual bool wait(TimeNs timeout) noexcept = 0;
  [[nodiscard]] virtual const SourceCounters& counters() const noexcept = 0;
  [[nodiscard]] virtual const std::string& error() const noexcept = 0;
};

struct UdpSourceConfig {
  std::string bind_address{"0.0.0.0"};
  std::uint16_t lidar_port{7502};   // 0 = any free port (tests)
  std::uint16_t imu_port{7503};
  int receive_buffer_bytes{1 << 22};  // SO_RCVBUF: a frame at 2048x10 is ~1.6 MB
};

class UdpPacketSource final : public PacketSource {
 public:
  static Result<std::unique_ptr<UdpPacketSource>> open(const UdpSourceConfig& cfg);
  ~UdpPacketSource() override;
  [[nodiscard]] PacketKind next(std::span<std::uint8_t> buf, std::size_t& size, TimeNs& stamp) noexcept override;
  bool wait(TimeNs timeout) noexcept override;
  [[nodiscard]] const SourceCounters& counters() const noexcept override { return c_; }
  [[nodiscard]] const std::string& error() const noexcept override { return error_; }
  [[nodiscard]] std::uint16_t lidar_port() const noexcept { return lidar_port_; }
  [[nodiscard]] std::uint16_t imu_port() const noexcept { return imu_port_; }
  [[nodiscard]] int lidar_fd() const noexcept { return fd_lidar_; }
  [[nodiscard]] int imu_fd() const noexcept { return fd_imu_; }

 private:
  UdpPacketSource() = default;
  PacketKind recv_one(int fd, PacketKind kind, std::span<std::uint8_t> buf, std::size_t& size, TimeNs& stamp) noexcept;
  int fd_lidar_{-1}, fd_imu_{-1};
  std::uint16_t lidar_port_{0}, imu_port_{0};
  bool imu_first_{false};
  SourceCounters c_;
  std::string error_;
};

// Replays a capture's UDP payloads sent to the lidar and IMU ports, as fast as they are asked for.
class PcapPacketSource final : public PacketSource {
 public:
  static Result<std::unique_ptr<PcapPacketSource>> open(const std::string& path, std::uint16_t lidar_port = 7502,
                                                        std::uint16_t imu_port = 7503);
  [[nodiscard]] PacketKind next(std::span<std::uint8_t> buf, std::size_t& size, TimeNs& stamp) noexcept override;
  bool wait(TimeNs) noexcept override { return true; }
  [[nodiscard]] const SourceCounters& counters() const noexcept override { return c_; }
  [[nodiscard]] const std::string& error() const noexcept override { return reader_.error(); }
  [[nodiscard]] const PcapCounters& pcap_counters() const noexcept { return reader_.counters(); }
  [[nodiscard]] std::uint64_t other_ports() const noexcept { return other_ports_; }
  void rewind() noexcept { reader_.rewind(); }

 private:
  PcapPacketSource(PcapReader r, std::uint16_t lp, std::uint16_t ip) : reader_(std::move(r)), lidar_port_(lp), imu_port_(ip) {}
  PcapReader reader_;
  std::uint16_t lidar_port_, imu_port_;
  std::uint64_t other_ports_{0};
  SourceCounters c_;
};

}  // namespace ag::ouster
