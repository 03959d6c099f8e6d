// SocketCAN backend.
#include "airground/drivers/can/socketcan_bus.hpp"

#include <fcntl.h>
#include <linux/can.h>
#include <linux/can/netlink.h>
#include <linux/can/raw.h>
#include <linux/netlink.h>
#include <linux/rtnetlink.h>
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
  return std::unique_ptr<SocketCanBus>(new SocketCanBus(fd, ifname, ifr.ifr_ifindex));
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
    if (n == static_cast<ssize_t>(sizeof k) && (k.can_id & CAN_ERR_FLAG) != 0) {
      std::array<std::uint8_t, 8> d{};
      std::memcpy(d.data(), k.data, 8);
      errors_.apply(decode_error_frame(k.can_id, d), c_);  // counted by class, state followed
      ++c_.rx_errors;
      continue;
    }
    if (n != static_cast<ssize_t>(sizeof k) || k.len > 8) {
      ++c_.rx_errors;  // truncated read: counted, skipped
      continue;
    }
    CanFrame f;
    f.extended = (k.can_id & CAN_EFF_FLAG) != 0;
    f.rtr = (k.can_id & CAN_RTR_FLAG) != 0;
    f.id = k.can_id & (f.extended ? CAN_EFF_MASK : CAN_SFF_MASK);
    f.dlc = k.len;
    std::memcpy(f.data.data(), k.data, 8);
    f.stamp = monotonic_now();
    if (!accepts(f)) {
      ++c_.rx_filtered;
      continue;
    }
    if (errors_.state() == CanBusState::kBusOff) errors_.reset();  // frames flow again: the controller is back
    out = f;
    ++c_.rx;
    return CanResult::kOk;
  }
}

bool SocketCanBus::set_filters(std::span<const CanFilter> filters) noexcept {
  if (!CanBus::set_filters(filters)) return false;
  std::array<can_filter, kMaxCanFilters> k{};
  for (std::size_t i = 0; i < filters.size(); ++i) {
    const CanFilter& f = filters[i];
    k[i].can_id = (f.id & (f.extended ? CAN_EFF_MASK : CAN_SFF_MASK)) | (f.extended ? CAN_EFF_FLAG : 0U);
    k[i].can_mask = (f.mask & (f.extended ? CAN_EFF_MASK : CAN_SFF_MASK)) | CAN_EFF_FLAG;  // the format must match
  }
  // No filters: one that passes everything (an empty CAN_RAW_FILTER would pass nothing).
  can_filter all{0, 0};
  const void* p = filters.empty() ? static_cast<const void*>(&all) : static_cast<const void*>(k.data());
  const auto len = static_cast<socklen_t>(sizeof(can_filter) * (filters.empty() ? 1 : filters.size()));
  return ::setsockopt(fd_, SOL_CAN_RAW, CAN_RAW_FILTER, p, len) == 0;
}

bool SocketCanBus::restart() noexcept {
  const int nl = ::socket(AF_NETLINK, SOCK_RAW | SOCK_CLOEXEC, NETLINK_ROUTE);
  if (nl < 0) return false;
  // RTM_NEWLINK { ifinfomsg, IFLA_LINKINFO { IFLA_INFO_KIND "can", IFLA_INFO_DATA { IFLA_CAN_RESTART u32 1 } } }
  alignas(nlmsghdr) std::uint8_t buf[256]{};
  auto* h = reinterpret_cast<nlmsghdr*>(buf);
  h->nlmsg_type = RTM_NEWLINK;
  h->nlmsg_flags = NLM_F_REQUEST | NLM_F_ACK;
  h->nlmsg_seq = 1;
  auto* ifi = reinterpret_cast<ifinfomsg*>(buf + NLMSG_HDRLEN);
  ifi->ifi_family = AF_UNSPEC;
  ifi->ifi_index = ifindex_;
  std::size_t len = NLMSG_HDRLEN + NLMSG_ALIGN(sizeof(ifinfomsg));
  auto put = [&](std::uint16_t type, const void* data, std::size_t n) {
    auto* a = reinterpret_cast<rtattr*>(buf + len);
    a->rta_type = type;
    a->rta_len = static_cast<unsigned short>(RTA_LENGTH(n));
    if (n > 0) std::memcpy(RTA_DATA(a), data, n);
    len += RTA_ALIGN(a->rta_len);
    return a;
  };
  rtattr* linkinfo = put(IFLA_LINKINFO, nullptr, 0);
  put(IFLA_INFO_KIND, "can", 3);
  rtattr* info = put(IFLA_INFO_DATA, nullptr, 0);
  const std::uint32_t one = 1;
  put(IFLA_CAN_RESTART, &one, sizeof one);
  info->rta_len = static_cast<unsigned short>(buf + len - reinterpret_cast<std::uint8_t*>(info));
  linkinfo->rta_len = static_cast<unsigned short>(buf + len - reinterpret_cast<std::uint8_t*>(linkinfo));
  h->nlmsg_len = static_cast<std::uint32_t>(len);
  sockaddr_nl to{};
  to.nl_family = AF_NETLINK;
  bool ok = ::sendto(nl, buf, len, 0, reinterpret_cast<sockaddr*>(&to), sizeof to) == static_cast<ssize_t>(len);
  if (ok) {
    std::uint8_t reply[512];
    const ssize_t n = ::recv(nl, reply, sizeof reply, 0);
    ok = false;
    if (n >= static_cast<ssize_t>(NLMSG_HDRLEN + sizeof(nlmsgerr))) {
      const auto* rh = reinterpret_cast<const nlmsghdr*>(reply);
      if (rh->nlmsg_type == NLMSG_ERROR) {
        const auto* e = reinterpret_cast<const nlmsgerr*>(reply + NLMSG_HDRLEN);
        ok = e->error == 0;
        if (!ok) errno = -e->error;
      }
    }
  }
  ::close(nl);
  if (ok) errors_.reset();
  return ok;
}

}  // namespace ag::can
