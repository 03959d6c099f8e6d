// The live backend: a raw SocketCAN socket (PF_CAN, SOCK_RAW, CAN_RAW) bound to one interface,
// non-blocking; frames are stamped with the monotonic clock when read; error frames are counted.
#pragma once

#include <memory>
#include <string>

#include "airground/drivers/can/can_bus.hpp"
#include "airground/drivers/can/can_error.hpp"
#include "airground/platform/result.hpp"

namespace ag::can {

class SocketCanBus final : public CanBus {
 public:
  // Opens and binds `ifname` ("can0"); the error names the interface and the system call that failed.
  static Result<std::unique_ptr<SocketCanBus>> open(const std::string& ifname);
  ~SocketCanBus() override;

  [[nodiscard]] CanResult send(const CanFrame& f) noexcept override;
  [[nodiscard]] CanResult receive(CanFrame& out) noexcept override;
  [[nodiscard]] const CanBusCounters& counters() const noexcept override { return c_; }
  [[nodiscard]] const std::string& interface_name() const noexcept { return ifname_; }
  // Kernel filters (CAN_RAW_FILTER) plus the same check in receive().
  [[nodiscard]] bool set_filters(std::span<const CanFilter> filters) noexcept override;
  // The controller's state from the error frames seen so far; the last one decoded.
  [[nodiscard]] CanBusState state() const noexcept { return errors_.state(); }
  [[nodiscard]] const CanErrorReport& last_error() const noexcept { return errors_.last(); }
  // Restarts a bus-off controller (rtnetlink IFLA_CAN_RESTART, as `ip link set canX type can restart`;
  // needs CAP_NET_ADMIN). False with errno set when the kernel refused.
  bool restart() noexcept;
  [[nodiscard]] int fd() const noexcept { return fd_; }

 private:
  SocketCanBus(int fd, std::string ifname, int ifindex) : fd_(fd), ifindex_(ifindex), ifname_(std::move(ifname)) {}
  int fd_{-1};
  int ifindex_{0};
  std::string ifname_;
  CanBusCounters c_;
  CanErrorTracker errors_;
};

}  // namespace ag::can
