// UDP transport: a non-blocking IPv4 socket with broadcast and a unicast peer list.
#include "airground/drivers/net/udp/udp_link.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

namespace ag::net {

namespace {
std::string err(const std::string& what) { return "udp: " + what + ": " + std::strerror(errno); }
sockaddr_in sockaddr_of(const LinkAddress& a) noexcept {
  sockaddr_in s{};
  s.sin_family = AF_INET;
  s.sin_addr.s_addr = htonl(static_cast<std::uint32_t>(a.value >> 16));
  s.sin_port = htons(static_cast<std::uint16_t>(a.value & 0xFFFF));
  return s;
}
}  // namespace

Result<LinkAddress> parse_udp_address(const std::string& text, std::uint16_t default_port) {
  std::string host = text;
  std::uint16_t port = default_port;
  const auto colon = text.rfind(':');
  if (colon != std::string::npos) {
    host = text.substr(0, colon);
    const std::string p = text.substr(colon + 1);
    char* end = nullptr;
    const long v = std::strtol(p.c_str(), &end, 10);
    if (p.empty() || *end != '\0' || v < 1 || v > 65535)
      return Error::make(ErrorCode::kConfig, "udp address '" + text + "': port must be 1..65535");
    port = static_cast<std::uint16_t>(v);
  }
  in_addr a{};
  if (::inet_pton(AF_INET, host.c_str(), &a) != 1)
    return Error::make(ErrorCode::kConfig, "udp address '" + text + "': not an IPv4 address (a.b.c.d[:port])");
  return udp_address(ntohl(a.s_addr), port);
}

std::string format_udp_address(const LinkAddress& a) {
  if (a.broadcast) return "broadcast";
  const sockaddr_in s = sockaddr_of(a);
  char buf[INET_ADDRSTRLEN] = {};
  ::inet_ntop(AF_INET, &s.sin_addr, buf, sizeof buf);
  return std::string(buf) + ":" + std::to_string(ntohs(s.sin_port));
}

Result<std::unique_ptr<UdpLink>> UdpLink::open(const UdpLinkConfig& cfg) {
  auto bind_addr = parse_udp_address(cfg.bind_address, cfg.port);
  if (!bind_addr) return bind_addr.error();
  std::vector<LinkAddress> peers;
  for (const auto& p : cfg.peers) {
    auto a = parse_udp_address(p, cfg.port);
    if (!a) return a.error();
    peers.push_back(a.value());
  }
  LinkAddress bcast{};
  const bool have_bcast = !cfg.broadcast_address.empty();
  if (have_bcast) {
    auto a = parse_udp_address(cfg.broadcast_address, cfg.port);
    if (!a) return a.error();
    bcast = a.value();
  }
  if (cfg.mtu < 128 || cfg.mtu > 65507)
    return Error::make(ErrorCode::kConfig, "udp: mtu " + std::to_string(cfg.mtu) + " outside [128, 65507]");
  const int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (fd < 0) return Error::make(ErrorCode::kIo, err("socket"));
  const int one = 1;
  ::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  if (have_bcast && ::setsockopt(fd, SOL_SOCKET, SO_BROADCAST, &one, sizeof one) != 0) {
    const auto e = err("SO_BROADCAST");
    ::close(fd);
    return Error::make(ErrorCode::kIo, e);
  }
  ::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &cfg.receive_buffer_bytes, sizeof cfg.receive_buffer_bytes);
  if (!cfg.device.empty() &&
      ::setsockopt(fd, SOL_SOCKET, SO_BINDTODEVICE, cfg.device.c_str(), static_cast<socklen_t>(cfg.device.size())) != 0) {
    const auto e = err("SO_BINDTODEVICE " + cfg.device + " (needs CAP_NET_RAW)");
    ::close(fd);
    return Error::make(ErrorCode::kPermission, e);
  }
  const sockaddr_in sa = sockaddr_of(bind_addr.value());
  if (::bind(fd, reinterpret_cast<const sockaddr*>(&sa), sizeof sa) != 0) {
    const auto e = err("bind " + format_udp_address(bind_addr.value()));
    ::close(fd);
    return Error::make(ErrorCode::kIo, e);
  }
  sockaddr_in got{};
  socklen_t len = sizeof got;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&got), &len);
  std::unique_ptr<UdpLink> link(new UdpLink(cfg, fd, ntohs(got.sin_port)));
  link->have_broadcast_ = have_bcast;
  link->broadcast_ = bcast;
  link->peers_ = std::move(peers);
  return link;
}

UdpLink::~UdpLink() {
  if (fd_ >= 0) ::close(fd_);
}

SendStatus UdpLink::send_to(const LinkAddress& to, std::span<const std::uint8_t> bytes) noexcept {
  const sockaddr_in sa = sockaddr_of(to);
  for (;;) {
    const ssize_t n = ::sendto(fd_, bytes.data(), bytes.size(), MSG_DONTWAIT | MSG_NOSIGNAL,
                               reinterpret_cast<const sockaddr*>(&sa), sizeof sa);
    if (n >= 0) {
      ++stats_.sent;
      return SendStatus::kSent;
    }
    if (errno == EINTR) continue;
    stats_.last_errno = errno;
    if (errno == EAGAIN || errno == ENOBUFS) {  // EWOULDBLOCK == EAGAIN on Linux
      ++stats_.would_block;
      return SendStatus::kWouldBlock;
    }
    ++stats_.send_errors;
    if (errno == EMSGSIZE) return SendStatus::kTooLarge;
    if (errno == ENETUNREACH || errno == EHOSTUNREACH || errno == ENETDOWN) return SendStatus::kUnreachable;
    return SendStatus::kError;
  }
}

SendStatus UdpLink::send(TimeNs, const LinkAddress& to, std::span<const std::uint8_t> bytes) noexcept {
  if (fd_ < 0) return SendStatus::kError;
  if (bytes.size() > cfg_.mtu) return SendStatus::kTooLarge;
  if (!to.broadcast) return send_to(to, bytes);
  // A broadcast reaches the link's neighbours and every listed peer; it left if any copy left.
  SendStatus result = SendStatus::kUnreachable;
  if (have_broadcast_) result = send_to(broadcast_, bytes);
  for (const auto& p : peers_)
    if (send_to(p, bytes) == SendStatus::kSent) result = SendStatus::kSent;
  return result;
}

std::size_t UdpLink::receive(TimeNs, LinkAddress& from, std::span<std::uint8_t> buf, bool& truncated) noexcept {
  truncated = false;
  if (fd_ < 0) return 0;
  for (int attempt = 0; attempt < 8; ++attempt) {
    sockaddr_in sa{};
    socklen_t len = sizeof sa;
    const ssize_t n = ::recvfrom(fd_, buf.data(), buf.size(), MSG_DONTWAIT | MSG_TRUNC, reinterpret_cast<sockaddr*>(&sa), &len);
    if (n < 0) {
      if (errno == EINTR) continue;
      if (errno != EAGAIN) {
        ++stats_.receive_errors;
        stats_.last_errno = errno;
        continue;  // ICMP errors surface here once each; the next datagram may be fine
      }
      return 0;
    }
    ++stats_.received;
    from = udp_address(ntohl(sa.sin_addr.s_addr), ntohs(sa.sin_port));
    const auto size = static_cast<std::size_t>(n);
    truncated = size > buf.size();
    return std::min(size, buf.size());
  }
  return 0;
}

}  // namespace ag::net
