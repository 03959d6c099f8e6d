// In-process CAN link.
#include "airground/drivers/can/inprocess_bus.hpp"
#include "airground/platform/device_registry.hpp"

#include <string>

namespace ag::can {

CanResult InProcessCanLink::Endpoint::send(const CanFrame& f) noexcept {
  if (!valid(f)) return CanResult::kInvalid;
  Endpoint& other = side_ == 0 ? link_.b_ : link_.a_;
  if (down_ || other.down_) {
    ++c_.tx_dropped;
    return CanResult::kDown;
  }
  Queue& q = link_.q_[static_cast<std::size_t>(1 - side_)];
  if (q.size >= kCapacity) {
    ++c_.tx_dropped;
    return CanResult::kWouldBlock;
  }
  CanFrame& slot = q.frames[(q.head + q.size) % kCapacity];
  slot = f;
  slot.stamp = link_.clock_.now();
  ++q.size;
  ++c_.tx;
  return CanResult::kOk;
}

CanResult InProcessCanLink::Endpoint::receive(CanFrame& out) noexcept {
  Queue& q = link_.q_[static_cast<std::size_t>(side_)];
  while (!down_ && q.size > 0) {
    const CanFrame& f = q.frames[q.head];
    q.head = (q.head + 1) % kCapacity;
    --q.size;
    if (!accepts(f)) {
      ++c_.rx_filtered;
      continue;
    }
    out = f;
    ++c_.rx;
    return CanResult::kOk;
  }
  return CanResult::kWouldBlock;
}

// A robot's link replaces the one it had (a test's rig made again under the same name).
void register_inprocess_link(std::string_view robot, InProcessCanLink* link) {
  auto& r = DeviceRegistry<InProcessCanLink>::instance();
  r.remove(robot);
  (void)r.add(robot, link);
}
void unregister_inprocess_link(std::string_view robot) { DeviceRegistry<InProcessCanLink>::instance().remove(robot); }
InProcessCanLink* find_inprocess_link(std::string_view robot) { return DeviceRegistry<InProcessCanLink>::instance().find(robot); }

}  // namespace ag::can
