// The simulated Ouster OS-1, shared by the lockstep runner (packets into the lidar stage's `source: sim`)
// and HIL (packets over UDP to airground-ugv): the sensor's metadata at the chosen mode and packet
// profile, and a cast revolution turned into the packets the sensor sends.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <span>
#include <string>
#include <vector>

#include "airground/drivers/lidar/ouster/frame.hpp"
#include "airground/drivers/lidar/ouster/metadata.hpp"
#include "airground/drivers/lidar/ouster/packet_format.hpp"
#include "airground/messages/geometry.hpp"
#include "airground/platform/result.hpp"
#include "airground/platform/time.hpp"
#include "airground/sim/lidar.hpp"
#include "airground/sim/world.hpp"

namespace ag::sim {

// The packet profile the simulated sensor sends in lockstep (HIL takes --lidar-profile): the OS-1's
// default since firmware 2.2.
inline constexpr const char* kSimLidarProfile = "RNG19_RFL8_SIG16_NIR16";

// The OS-1-64 of the fixture metadata (config/sensors/ouster/) at `columns` x 10 Hz in `profile` (any
// profile the driver decodes; every one has an 8-bit reflectivity).
Result<nlohmann::json> ouster_metadata(int columns, const std::string& profile);
Result<ouster::SensorInfo> ouster_sensor_info(int columns, const std::string& profile);

// The Ouster reflectivity byte of a surface (calibrated reflectivity, 0-100 for diffuse targets): the
// world's albedo under the point, grey, scaled to 0-100; 0 outside the world.
std::uint8_t albedo_reflectivity(const World& w, double x, double y) noexcept;

class OusterPackets {
 public:
  explicit OusterPackets(const ouster::SensorInfo& info);
  // One revolution cast from `sensor_pose` (points in the sensor frame, in parts) as the sensor sends it:
  // frame id, column times spread over `period` from `now`, range in mm, reflectivity from the albedo
  // (the class id only with the labels oracle); `send` gets each packet; returns the packets it took.
  std::uint64_t send_revolution(std::span<const std::vector<LidarPoint>> parts, const Pose3& sensor_pose, TimeNs now,
                                TimeNs period, bool labels_oracle, const World& w,
                                const std::function<bool(std::span<const std::uint8_t>)>& send);
  [[nodiscard]] const ouster::SensorInfo& info() const noexcept { return info_; }
  [[nodiscard]] std::size_t packet_size() const noexcept { return fmt_->lidar_packet_size(); }
  [[nodiscard]] int packets_per_revolution() const noexcept;

 private:
  ouster::SensorInfo info_;
  std::unique_ptr<ouster::PacketFormat> fmt_;
  ouster::LidarFrame frame_;
  std::uint16_t frame_id_{0};
  std::vector<std::uint8_t> pkt_;
};

}  // namespace ag::sim
