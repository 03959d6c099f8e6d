// The live backend: a raw SocketCAN socket (PF_CAN, SOCK_RAW, CAN_RAW) bound to one interface,
// non-blocking; frames are stamped with the monotonic clock when read; error frames are counted.
#pragma once

#include <memory>
#include <string>

#include "airground/drivers/can/can_bus.hpp"
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

 private:
  SocketCanBus(int fd, std::string ifname) : fd_(fd), ifname_(std::move(ifname)) {}
  int fd_{-1};
  std::string ifname_;
  CanBusCounters c_;
};

}  // namespace ag::can
