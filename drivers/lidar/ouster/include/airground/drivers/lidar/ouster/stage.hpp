// The Ouster stage: the ground robot's lidar. Every step it drains the packet source (UDP client on the
// robot, a pcap replay on the desk), assembles frames, and publishes each finished revolution as a
// "lidar_scan" (points in the sensor frame, x forward, y left, z up; pixels without a return absent).
// Incomplete frames are published too (their missing columns are simply absent) and counted.
#pragma once

#include <memory>
#include <span>
#include <string>
#include <vector>

#include "airground/messages/channels.hpp"
#include "airground/messages/messages.hpp"
#include "airground/drivers/lidar/ouster/frame.hpp"
#include "airground/drivers/lidar/ouster/packet_source.hpp"
#include "airground/drivers/lidar/ouster/xyz_lut.hpp"
#include "airground/platform/param_binding.hpp"
#include "airground/platform/stage.hpp"

namespace ag::ouster {

struct OusterSettings {
  std::string source{"udp"};
  std::string metadata;
  std::string pcap;
  std::string bind_address{"0.0.0.0"};
  int lidar_port{0};
  int imu_port{0};
  int max_packets_per_step{256};
  double mount_x_m{0.0};
  double mount_y_m{0.0};
  double mount_z_m{0.5};
  double mount_yaw_rad{0.0};
  std::string scan_channel{chan::kLidarScan.name};
  std::string classes{"none"};
};
inline constexpr ParamField<OusterSettings> kOusterStageFields[] = {
    field::text("source", &OusterSettings::source, "udp", "udp|pcap|sim|none", "packets from the sensor (UDP), a capture (pcap replay), the simulator's sensor (its metadata too), or no lidar"),
    field::text("metadata", &OusterSettings::metadata, "", "", "the sensor's metadata JSON (get_metadata / the SDK's .json)"),
    field::text("pcap", &OusterSettings::pcap, "", "", "capture to replay when source is pcap"),
    field::text("bind_address", &OusterSettings::bind_address, "0.0.0.0", "", "IPv4 address the UDP sockets bind"),
    field::integer("lidar_port", &OusterSettings::lidar_port, 0, 65535, "", "UDP lidar port; 0 = the metadata's udp_port_lidar"),
    field::integer("imu_port", &OusterSettings::imu_port, 0, 65535, "", "UDP IMU port; 0 = the metadata's udp_port_imu"),
    field::integer("max_packets_per_step", &OusterSettings::max_packets_per_step, 1, 4096, "", "packets drained per step (a 2048x10 sensor sends 1280/s)"),
    field::real("mount_x_m", &OusterSettings::mount_x_m, -5.0, 5.0, "m", "sensor origin in the body frame, forward"),
    field::real("mount_y_m", &OusterSettings::mount_y_m, -5.0, 5.0, "m", "sensor origin in the body frame, left"),
    field::real("mount_z_m", &OusterSettings::mount_z_m, -5.0, 5.0, "m", "sensor origin in the body frame, up"),
    field::real("mount_yaw_rad", &OusterSettings::mount_yaw_rad, -3.15, 3.15, "rad", "sensor yaw in the body frame"),
    field::text("scan_channel", &OusterSettings::scan_channel, chan::kLidarScan.name, "", "ring channel the scans are published on"),
    field::text("classes", &OusterSettings::classes, "none", "none|reflectivity", "point classes: none (255), or the reflectivity byte as a class id (the simulator's HIL mode codes ground truth there)"),
};
inline constexpr auto kOusterStageParams = param_specs(kOusterStageFields);

struct OusterStageCounters {
  std::uint64_t packets{0}, imu_packets{0};
  std::uint64_t decode_errors{0};      // wrong size, bad packet type, no valid column (by kind below)
  std::uint64_t wrong_size{0}, bad_type{0}, no_valid_column{0};
  std::uint64_t bytes{0};              // lidar and IMU payload bytes received
  std::uint64_t source_errors{0};
  std::uint64_t scans{0}, scans_incomplete{0};
  std::uint64_t ring_full{0};
  std::uint64_t device_errors{0};      // no metadata, no socket, no capture: the stage publishes nothing
  std::uint64_t silence_warnings{0};   // "no frames for a few seconds" warnings logged
  std::size_t last_wrong_size{0};      // [B] the last lidar datagram refused for its size
};

// Device-counter error kinds of the lidar stage, in DeviceCounters order.
enum class LidarError : std::size_t { kWrongSize = 0, kBadType = 1, kNoValidColumn = 2, kSource = 3 };

class OusterStage final : public Stage {
 public:
  static constexpr std::span<const ParamSpec> kParams{kOusterStageParams};
  static std::unique_ptr<Stage> make() { return std::make_unique<OusterStage>(); }

  Status init(StageContext& ctx) override;
  void step(TimeNs now) noexcept override;

  [[nodiscard]] const OusterStageCounters& counters() const noexcept { return c_; }
  [[nodiscard]] const AssemblerCounters& assembler_counters() const noexcept { return assembler_->counters(); }
  [[nodiscard]] const ImuSample& last_imu() const noexcept { return imu_; }
  [[nodiscard]] const LidarScanMsg& last_scan() const noexcept { return *scan_; }
  [[nodiscard]] PacketSource& source() noexcept { return *source_; }
  [[nodiscard]] bool active() const noexcept { return source_ != nullptr; }

 private:
  void publish(const LidarFrame& f, TimeNs now) noexcept;
  void warn_silence(TimeNs now) noexcept;
  std::unique_ptr<PacketSource> source_;
  std::unique_ptr<PacketFormat> fmt_;
  std::unique_ptr<FrameAssembler> assembler_;
  std::unique_ptr<XyzLut> lut_;
  std::unique_ptr<LidarPacket> pkt_;
  std::unique_ptr<LidarScanMsg> scan_;
  std::vector<float> xyz_;
  std::vector<std::uint8_t> buf_;
  RingWriter<LidarScanMsg, kLidarRing> out_;
  Pose3 mount_{};
  int max_packets_{256};
  bool classes_from_reflectivity_{false};
  ImuSample imu_{};
  OusterStageCounters c_;
  OusterStageCounters at_last_frame_;   // counters when the last frame came (what the silence saw)
  DeviceCounters own_device_;           // when the context has none (a stage built outside a role)
  DeviceCounters* device_{&own_device_};
  DeviceSilence silence_;
  bool replay_ended_{false};
  bool pcap_{false};
  std::uint16_t lidar_port_{0}, imu_port_{0};
  std::size_t expected_size_{0};
  UdpProfile profile_{UdpProfile::kLegacy};
};

}  // namespace ag::ouster
