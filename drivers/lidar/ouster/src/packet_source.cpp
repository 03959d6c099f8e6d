// The UDP client and the pcap replay source.
#include "airground/drivers/lidar/ouster/packet_source.hpp"

#include <arpa/inet.h>
#include <cerrno>
#include <cstring>
#include <ctime>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

namespace ag::ouster {

namespace {
TimeNs monotonic_now() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<TimeNs>(ts.tv_sec) * kNsPerS + ts.tv_nsec;
}

Result<int> open_udp(const std::string& addr, std::uint16_t port, int rcvbuf, std::uint16_t& bound) {
  const int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (fd < 0) return Error::make(ErrorCode::kIo, std::string("ouster: socket(): ") + std::strerror(errno));
  const int one = 1;
  (void)::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  (void)::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof rcvbuf);
  sockaddr_in sa{};
  sa.sin_family = AF_INET;
  sa.sin_port = htons(port);
  if (::inet_pton(AF_INET, addr.c_str(), &sa.sin_addr) != 1) {
    ::close(fd);
    return Error::make(ErrorCode::kConfig, "ouster: bind address '" + addr + "' is not an IPv4 address");
  }
  if (::bind(fd, reinterpret_cast<const sockaddr*>(&sa), sizeof sa) != 0) {
    const int e = errno;
    ::close(fd);
    return Error::make(ErrorCode::kIo, "ouster: bind " + addr + ":" + std::to_string(port) + ": " + std::strerror(e));
  }
  socklen_t len = sizeof sa;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&sa), &len);
  bound = ntohs(sa.sin_port);
  return fd;
}
}  // namespace

Result<std::unique_ptr<UdpPacketSource>> UdpPacketSource::open(const UdpSourceConfig& cfg) {
  std::unique_ptr<UdpPacketSource> s(new UdpPacketSource());
  auto l = open_udp(cfg.bind_address, cfg.lidar_port, cfg.receive_buffer_bytes, s->lidar_port_);
  if (!l) return Error::make(l.error().code, l.error().message + " (lidar port)");
  s->fd_lidar_ = l.value();
  auto i = open_udp(cfg.bind_address, cfg.imu_port, 1 << 16, s->imu_port_);
  if (!i) return Error::make(i.error().code, i.error().message + " (IMU port)");
  s->fd_imu_ = i.value();
  return s;
}

UdpPacketSource::~UdpPacketSource() {
  if (fd_lidar_ >= 0) ::close(fd_lidar_);
  if (fd_imu_ >= 0) ::close(fd_imu_);
}

PacketKind UdpPacketSource::recv_one(int fd, PacketKind kind, std::span<std::uint8_t> buf, std::size_t& size, TimeNs& stamp) noexcept {
  const ssize_t n = ::recv(fd, buf.data(), buf.size(), MSG_DONTWAIT | MSG_TRUNC);
  if (n < 0) {
    if (errno == EAGAIN || errno == EINTR) return PacketKind::kNone;  // EWOULDBLOCK == EAGAIN on Linux
    ++c_.errors;
    if (error_.empty()) error_ = std::string("ouster: recv: ") + std::strerror(errno);
    return PacketKind::kError;
  }
  if (static_cast<std::size_t>(n) > buf.size()) {
    ++c_.truncated;
    return PacketKind::kError;
  }
  size = static_cast<std::size_t>(n);
  stamp = monotonic_now();
  if (kind == PacketKind::kLidar) ++c_.lidar;
  else ++c_.imu;
  return kind;
}

PacketKind UdpPacketSource::next(std::span<std::uint8_t> buf, std::size_t& size, TimeNs& stamp) noexcept {
  // Alternate which port is read first so a lidar flood cannot starve the IMU.
  imu_first_ = !imu_first_;
  const int a = imu_first_ ? fd_imu_ : fd_lidar_, b = imu_first_ ? fd_lidar_ : fd_imu_;
  const PacketKind ka = imu_first_ ? PacketKind::kImu : PacketKind::kLidar, kb = imu_first_ ? PacketKind::kLidar : PacketKind::kImu;
  const PacketKind r = recv_one(a, ka, buf, size, stamp);
  if (r != PacketKind::kNone) return r;
  return recv_one(b, kb, buf, size, stamp);
}

bool UdpPacketSource::wait(TimeNs timeout) noexcept {
  pollfd p[2] = {{fd_lidar_, POLLIN, 0}, {fd_imu_, POLLIN, 0}};
  const int ms = timeout <= 0 ? 0 : static_cast<int>((timeout + kNsPerMs - 1) / kNsPerMs);
  return ::poll(p, 2, ms) > 0;
}

Result<std::unique_ptr<PcapPacketSource>> PcapPacketSource::open(const std::string& path, std::uint16_t lidar_port, std::uint16_t imu_port) {
  auto r = PcapReader::open(path);
  if (!r) return r.error();
  return std::unique_ptr<PcapPacketSource>(new PcapPacketSource(std::move(r.value()), lidar_port, imu_port));
}

PacketKind PcapPacketSource::next(std::span<std::uint8_t> buf, std::size_t& size, TimeNs& stamp) noexcept {
  UdpDatagram d;
  for (;;) {
    if (!reader_.next(d)) {
      if (!reader_.error().empty()) {
        ++c_.errors;
        return PacketKind::kError;
      }
      return PacketKind::kEnd;
    }
    PacketKind k;
    if (d.dst_port == lidar_port_) k = PacketKind::kLidar;
    else if (d.dst_port == imu_port_) k = PacketKind::kImu;
    else {
      ++other_ports_;
      continue;
    }
    if (d.payload.size() > buf.size()) {
      ++c_.truncated;
      continue;
    }
    std::memcpy(buf.data(), d.payload.data(), d.payload.size());
    size = d.payload.size();
    stamp = d.stamp;
    if (k == PacketKind::kLidar) ++c_.lidar;
    else ++c_.imu;
    return k;
  }
}

}  // namespace ag::ouster
