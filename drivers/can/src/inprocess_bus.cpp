// In-process CAN link.
#include "airground/drivers/can/inprocess_bus.hpp"

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
  if (down_ || q.size == 0) return CanResult::kWouldBlock;
  out = q.frames[q.head];
  q.head = (q.head + 1) % kCapacity;
  --q.size;
  ++c_.rx;
  return CanResult::kOk;
}

}  // namespace ag::can
