// Devices the simulator (or a test) provides for a robot's device stages, by name: the in-process CAN
// link of a base stage, the simulated Ouster, camera, u-blox and autopilot, the fake GPIO lines. One
// registry per device type; a stage finds its device by its robot's name (StageContext::instance) in
// init(). Only set-up and tear-down touch it (a mutex guards them); no real-time path does.
#pragma once

#include <functional>
#include <map>
#include <mutex>
#include <string>
#include <string_view>

namespace ag {

template <class Device>
class DeviceRegistry {
 public:
  // The registry of this device type (one per program).
  static DeviceRegistry& instance() {
    static DeviceRegistry r;
    return r;
  }
  // False (and nothing changed) when `name` already has a device: two teams in one process.
  [[nodiscard]] bool add(std::string_view name, Device* d) {
    std::lock_guard<std::mutex> g(mu_);
    return devices_.emplace(std::string(name), d).second;
  }
  void remove(std::string_view name) {
    std::lock_guard<std::mutex> g(mu_);
    if (const auto it = devices_.find(name); it != devices_.end()) devices_.erase(it);
  }
  // Every name starting with `prefix` ("ugv1/": a robot's lines).
  void remove_prefix(std::string_view prefix) {
    std::lock_guard<std::mutex> g(mu_);
    for (auto it = devices_.begin(); it != devices_.end();) it = it->first.starts_with(prefix) ? devices_.erase(it) : std::next(it);
  }
  // Null when `name` has none.
  [[nodiscard]] Device* find(std::string_view name) const {
    std::lock_guard<std::mutex> g(mu_);
    const auto it = devices_.find(name);
    return it == devices_.end() ? nullptr : it->second;
  }

 private:
  mutable std::mutex mu_;
  std::map<std::string, Device*, std::less<>> devices_;
};

}  // namespace ag
