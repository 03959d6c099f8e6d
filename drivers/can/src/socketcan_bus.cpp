// SocketCAN backend.
#include "airground/drivers/can/socketcan_bus.hpp"

#include <fcntl.h>
#include <linux/can.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "airground/platform/clock.hpp"

namespace ag::can {

const char* to_string(CanResult r) noexcept {
  switch (r) {
    case CanResult::kOk: return "ok";
    case CanResult::kWouldBlock: return "would block";
    case CanResult::kDown: return "interface down";
    case CanResult::kInvalid: return "invalid frame";
  }
  return "?";
}

Result<std::unique_ptr<SocketCanBus>> SocketCanBus::open(const std::string& ifname) {
  auto fail = [&](const char* what, int err) {
    return Error::make(err == EACCES || err == EPERM ? ErrorCode::kPermission : ErrorCode::kUnavailable,
                       "SocketCAN " + ifname + ": " + what + ": " + std::strerror(err));
  };
  if (ifname.empty() || ifname.size() >= IFNAMSIZ) return Error::make(ErrorCode::kInvalidArgument, "SocketCAN: bad interface name '" + ifname + "'");
  const int fd = ::socket(PF_CAN, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, CAN_RAW);
  if (fd < 0) return fail("socket(PF_CAN, SOCK_RAW, CAN_RAW)", errno);
  ifreq ifr{};
  std::memcpy(ifr.ifr_name, ifname.c_str(), ifname.size() + 1);
  if (::ioctl(fd, SIOCGIFINDEX, &ifr) < 0) {
    const int e = errno;
    ::close(fd);
    return fail("no such interface (SIOCGIFINDEX)", e);
  }
  sockaddr_can addr{};
  addr.can_family = AF_CAN;
  addr.can_ifindex = ifr.ifr_ifindex;
  if (::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) < 0) {
    const int e = errno;
    ::close(fd);
    return fail("bind", e);
  }
  const int err_mask = CAN_ERR_MASK;
  (void)::setsockopt(fd, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &err_mask, sizeof err_mask);
  return std::unique_ptr<SocketCanBus>(new SocketCanBus(fd, ifname));
}

SocketCanBus::~SocketCanBus() {
  if (fd_ >= 0) ::close(fd_);
}

CanResult SocketCanBus::send(const CanFrame& f) noexcept {
  if (!valid(f)) return CanResult::kInvalid;
  can_frame k{};
  k.can_id = f.id | (f.extended ? CAN_EFF_FLAG : 0U) | (f.rtr ? CAN_RTR_FLAG : 0U);
  k.len = f.dlc;
  std::memcpy(k.data, f.data.data(), 8);
  const ssize_t n = ::send(fd_, &k, sizeof k, MSG_DONTWAIT);
  if (n == static_cast<ssize_t>(sizeof k)) {
    ++c_.tx;
    return CanResult::kOk;
  }
  ++c_.tx_dropped;
  return (errno == EAGAIN || errno == ENOBUFS) ? CanResult::kWouldBlock : CanResult::kDown;
}

CanResult SocketCanBus::receive(CanFrame& out) noexcept {
  for (;;) {
    can_frame k{};
    const ssize_t n = ::recv(fd_, &k, sizeof k, MSG_DONTWAIT);
    if (n < 0) return errno == EAGAIN ? CanResult::kWouldBlock : CanResult::kDown;  // EWOULDBLOCK == EAGAIN on Linux
    if (n != static_cast<ssize_t>(sizeof k) || (k.can_id & CAN_ERR_FLAG) != 0 || k.len > 8) {
      ++c_.rx_errors;  // error frame or truncated read: counted, skipped
      continue;
    }
    out.extended = (k.can_id & CAN_EFF_FLAG) != 0;
    out.rtr = (k.can_id & CAN_RTR_FLAG) != 0;
    out.id = k.can_id & (out.extended ? CAN_EFF_MASK : CAN_SFF_MASK);
    out.dlc = k.len;
    std::memcpy(out.data.data(), k.data, 8);
    out.stamp = monotonic_now();
    ++c_.rx;
    return CanResult::kOk;
  }
}

}  // namespace ag::can
