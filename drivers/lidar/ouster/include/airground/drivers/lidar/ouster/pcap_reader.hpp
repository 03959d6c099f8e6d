// A small pcap reader for replaying sensor captures: classic pcap (both byte orders, micro- and
// nanosecond stamps) and pcapng (SHB, IDB, EPB, SPB), link types Ethernet (1), raw IPv4 (101, 228) and
// Linux cooked (113); yields the UDP payloads of unfragmented IPv4 datagrams. What it skips is counted.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "airground/platform/result.hpp"
#include "airground/platform/time.hpp"

namespace ag::ouster {

struct UdpDatagram {
  TimeNs stamp{0};          // capture time [ns since the epoch]
  std::uint32_t src_ip{0}, dst_ip{0};  // host order
  std::uint16_t src_port{0}, dst_port{0};
  std::span<const std::uint8_t> payload;  // into the reader's buffer
};

struct PcapCounters {
  std::uint64_t records{0};
  std::uint64_t udp{0};
  std::uint64_t not_udp{0};        // other link, network or transport protocols
  std::uint64_t fragments{0};      // IPv4 fragments (not reassembled)
  std::uint64_t truncated{0};      // snap length cut the datagram
};

class PcapReader {
 public:
  // Reads the whole file (init-time); the error names the file and what is wrong with its header.
  static Result<PcapReader> open(const std::string& path);
  static Result<PcapReader> from_bytes(std::vector<std::uint8_t> bytes, std::string origin);
  // The next UDP datagram; false at the end, or on a corrupt record (error() then says where).
  bool next(UdpDatagram& out) noexcept;
  void rewind() noexcept;
  [[nodiscard]] const PcapCounters& counters() const noexcept { return c_; }
  [[nodiscard]] const std::string& error() const noexcept { return error_; }
  [[nodiscard]] bool pcapng() const noexcept { return ng_; }

 private:
  PcapReader() = default;
  bool next_classic(std::span<const std::uint8_t>& frame, TimeNs& stamp) noexcept;
  bool next_ng(std::span<const std::uint8_t>& frame, TimeNs& stamp, std::uint32_t& link) noexcept;
  bool parse_frame(std::span<const std::uint8_t> frame, std::uint32_t link, TimeNs stamp, UdpDatagram& out) noexcept;
  void fail(const char* what) noexcept;

  std::vector<std::uint8_t> data_;
  std::string origin_, error_;
  bool ng_{false}, swap_{false}, nanos_{false};
  std::uint32_t link_{1};
  std::size_t start_{0}, pos_{0};
  std::vector<std::uint32_t> ng_links_;  // per interface
  std::vector<std::uint64_t> ng_tsres_;  // ticks per second per interface
  PcapCounters c_;
};

}  // namespace ag::ouster
