// The gossip transport on the robots' IP mesh: one non-blocking UDP socket, broadcast to the link's
// neighbours plus an optional list of unicast peers (for routed meshes where broadcast stops at one hop).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "airground/drivers/net/link/datagram_link.hpp"
#include "airground/platform/result.hpp"

namespace ag::net {

struct UdpLinkConfig {
  std::string bind_address{"0.0.0.0"};             // IPv4 to bind
  std::uint16_t port{47100};                        // the team's gossip port (same on every robot)
  std::string broadcast_address{"255.255.255.255"}; // "" = no broadcast (peers only)
  std::vector<std::string> peers;                   // "a.b.c.d" or "a.b.c.d:port": digests go to each too
  std::string device;                               // SO_BINDTODEVICE, "" = any (needs CAP_NET_RAW)
  std::size_t mtu{1200};                            // [B] largest datagram sent
  int receive_buffer_bytes{1 << 20};                // SO_RCVBUF
};

// A LinkAddress for UDP: IPv4 address (host order) << 16 | port.
constexpr LinkAddress udp_address(std::uint32_t ipv4_host_order, std::uint16_t port) noexcept {
  return LinkAddress{(static_cast<std::uint64_t>(ipv4_host_order) << 16) | port, false};
}
Result<LinkAddress> parse_udp_address(const std::string& text, std::uint16_t default_port);
std::string format_udp_address(const LinkAddress& a);

struct UdpLinkStats {
  std::uint64_t sent{0}, received{0};
  std::uint64_t would_block{0};   // the socket's send buffer was full
  std::uint64_t send_errors{0};   // unreachable network, link down, ...
  std::uint64_t receive_errors{0};
  int last_errno{0};
};

class UdpLink final : public DatagramLink {
 public:
  enum class State { kOpen, kClosed };

  // Opens, binds and configures the socket (SO_BROADCAST, SO_REUSEADDR, non-blocking). The error names
  // the address and the system's reason.
  static Result<std::unique_ptr<UdpLink>> open(const UdpLinkConfig& cfg);
  ~UdpLink() override;

  SendStatus send(TimeNs now, const LinkAddress& to, std::span<const std::uint8_t> bytes) noexcept override;
  std::size_t receive(TimeNs now, LinkAddress& from, std::span<std::uint8_t> buf, bool& truncated) noexcept override;
  [[nodiscard]] std::size_t mtu() const noexcept override { return cfg_.mtu; }

  [[nodiscard]] const UdpLinkStats& stats() const noexcept { return stats_; }
  [[nodiscard]] State state() const noexcept { return fd_ >= 0 ? State::kOpen : State::kClosed; }
  [[nodiscard]] std::uint16_t local_port() const noexcept { return local_port_; }

 private:
  UdpLink(const UdpLinkConfig& cfg, int fd, std::uint16_t port) : cfg_(cfg), fd_(fd), local_port_(port) {}
  SendStatus send_to(const LinkAddress& to, std::span<const std::uint8_t> bytes) noexcept;

  UdpLinkConfig cfg_;
  int fd_{-1};
  std::uint16_t local_port_{0};
  bool have_broadcast_{false};
  LinkAddress broadcast_{};
  std::vector<LinkAddress> peers_;
  UdpLinkStats stats_;
};

}  // namespace ag::net
