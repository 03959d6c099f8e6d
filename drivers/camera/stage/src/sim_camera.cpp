// The simulator's camera link.
#include "airground/drivers/camera/stage/sim_camera.hpp"
#include "airground/platform/device_registry.hpp"

#include <string>

namespace ag::camera {

SimCameraLink::SimCameraLink(std::size_t capacity) {
  slots_.resize(capacity == 0 ? 1 : capacity);
  for (auto& s : slots_) s = std::make_unique<CameraImageMsg>();
}

CameraImageMsg* SimCameraLink::begin_frame() noexcept {
  if (size_ == slots_.size()) {
    ++dropped_;
    open_ = false;
    return nullptr;
  }
  open_ = true;
  return slots_[(head_ + size_) % slots_.size()].get();
}

void SimCameraLink::commit() noexcept {
  if (!open_) return;
  open_ = false;
  ++size_;
  ++frames_;
}

const CameraImageMsg* SimCameraLink::front() const noexcept { return size_ == 0 ? nullptr : slots_[head_].get(); }

void SimCameraLink::pop() noexcept {
  if (size_ == 0) return;
  head_ = (head_ + 1) % slots_.size();
  --size_;
}

bool register_sim_camera(std::string_view robot, SimCameraLink* link) { return DeviceRegistry<SimCameraLink>::instance().add(robot, link); }
void unregister_sim_camera(std::string_view robot) { DeviceRegistry<SimCameraLink>::instance().remove(robot); }
SimCameraLink* find_sim_camera(std::string_view robot) { return DeviceRegistry<SimCameraLink>::instance().find(robot); }

}  // namespace ag::camera
