// The simulator's Ouster link.
#include "airground/drivers/lidar/ouster/sim_source.hpp"
#include "airground/platform/device_registry.hpp"

#include <cstring>

namespace ag::ouster {

class SimPacketSource final : public PacketSource {
 public:
  explicit SimPacketSource(SimPacketLink& link) : link_(link) {}
  [[nodiscard]] PacketKind next(std::span<std::uint8_t> buf, std::size_t& size, TimeNs& stamp) noexcept override {
    return link_.pop(buf, size, stamp, c_);
  }
  // The world stage sends before the lidar stage steps: there is nothing to wait for.
  bool wait(TimeNs) noexcept override { return link_.queued() > 0; }
  [[nodiscard]] const SourceCounters& counters() const noexcept override { return c_; }
  [[nodiscard]] const std::string& error() const noexcept override { return error_; }

 private:
  SimPacketLink& link_;
  SourceCounters c_;
  std::string error_;
};

SimPacketLink::SimPacketLink(SensorInfo info, std::size_t capacity, std::size_t max_packet)
    : info_(std::move(info)), capacity_(capacity == 0 ? 1 : capacity), max_packet_(max_packet),
      storage_(capacity_ * max_packet_), length_(capacity_, 0), stamp_(capacity_, 0) {}

bool SimPacketLink::send(std::span<const std::uint8_t> bytes, TimeNs stamp) noexcept {
  if (size_ == capacity_ || bytes.size() > max_packet_) {
    ++dropped_;
    return false;
  }
  const std::size_t slot = (head_ + size_) % capacity_;
  std::memcpy(storage_.data() + slot * max_packet_, bytes.data(), bytes.size());
  length_[slot] = bytes.size();
  stamp_[slot] = stamp;
  ++size_;
  ++sent_;
  return true;
}

PacketKind SimPacketLink::pop(std::span<std::uint8_t> buf, std::size_t& size, TimeNs& stamp, SourceCounters& c) noexcept {
  if (size_ == 0) return PacketKind::kNone;
  const std::size_t slot = head_;
  head_ = (head_ + 1) % capacity_;
  --size_;
  if (length_[slot] > buf.size()) {  // the stage's buffer holds any packet its metadata allows: never seen
    ++c.truncated;
    ++c.errors;
    return PacketKind::kError;
  }
  std::memcpy(buf.data(), storage_.data() + slot * max_packet_, length_[slot]);
  size = length_[slot];
  stamp = stamp_[slot];
  ++c.lidar;
  return PacketKind::kLidar;
}

std::unique_ptr<PacketSource> SimPacketLink::open_source() { return std::make_unique<SimPacketSource>(*this); }

bool register_sim_lidar(std::string_view robot, SimPacketLink* link) { return DeviceRegistry<SimPacketLink>::instance().add(robot, link); }
void unregister_sim_lidar(std::string_view robot) { DeviceRegistry<SimPacketLink>::instance().remove(robot); }
SimPacketLink* find_sim_lidar(std::string_view robot) { return DeviceRegistry<SimPacketLink>::instance().find(robot); }

}  // namespace ag::ouster
