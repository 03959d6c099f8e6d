// The Ouster stage: packets to frames to scans.
#include "airground/drivers/ouster/stage.hpp"

#include <cmath>
#include <string>

#include "airground/platform/log.hpp"

namespace ag::ouster {

// A sensor that is absent (no metadata, a port taken, a capture missing) does not stop the robot: the
// stage logs why, counts it and publishes nothing, like the base stage with no CAN interface.
Status OusterStage::init(StageContext& ctx) {
  const SectionView v = ctx.params();
  const std::string where = std::string(ctx.stage_name) + ".";
  auto w = ctx.channels.ring_writer<LidarScanMsg, kLidarRing>(v.text("scan_channel"));
  if (!w) return w.error();
  out_ = w.value();
  const std::string& cls = v.text("classes");
  if (cls != "none" && cls != "reflectivity")
    return Error::make(ErrorCode::kConfig, "config error: " + where + "classes must be none or reflectivity, got '" + cls + "'");
  classes_from_reflectivity_ = cls == "reflectivity";
  const std::string& src = v.text("source");
  if (src != "udp" && src != "pcap" && src != "none")
    return Error::make(ErrorCode::kConfig, "config error: " + where + "source must be udp, pcap or none, got '" + src + "'");
  if (src == "none") return ok_status();
  auto absent = [&](const std::string& why) {
    ++c_.device_errors;
    AG_LOG_ERROR("lidar", "%s; no scans from this sensor (the robot keeps running)", why.c_str());
    source_.reset();
    return ok_status();
  };
  if (v.text("metadata").empty()) return absent(where + "metadata names no sensor metadata JSON");
  auto info = read_metadata_file(v.text("metadata"));
  if (!info) return absent(where + "metadata: " + info.error().message);
  const SensorInfo& s = info.value();
  const auto lidar_port = static_cast<std::uint16_t>(v.integer("lidar_port") != 0 ? v.integer("lidar_port") : s.udp_port_lidar);
  const auto imu_port = static_cast<std::uint16_t>(v.integer("imu_port") != 0 ? v.integer("imu_port") : s.udp_port_imu);
  if (v.text("source") == "pcap") {
    auto p = PcapPacketSource::open(v.text("pcap"), lidar_port, imu_port);
    if (!p) return absent(where + "pcap: " + p.error().message);
    source_ = std::move(p).value();
  } else {
    UdpSourceConfig u;
    u.bind_address = v.text("bind_address");
    u.lidar_port = lidar_port;
    u.imu_port = imu_port;
    auto p = UdpPacketSource::open(u);
    if (!p) return absent(where + "udp: " + p.error().message);
    source_ = std::move(p).value();
  }
  if (static_cast<std::size_t>(s.mode.columns) * s.beam_altitude_deg.size() > kMaxScanPoints)
    return Error::make(ErrorCode::kConfig, where + "metadata: " + std::to_string(s.mode.columns) + " x " +
                                               std::to_string(s.beam_altitude_deg.size()) + " exceeds a lidar_scan's points");
  fmt_ = std::make_unique<PacketFormat>(s);
  assembler_ = std::make_unique<FrameAssembler>(s);
  lut_ = std::make_unique<XyzLut>(s);
  pkt_ = std::make_unique<LidarPacket>();
  scan_ = std::make_unique<LidarScanMsg>();
  xyz_.assign(3 * static_cast<std::size_t>(s.mode.columns) * s.beam_altitude_deg.size(), 0.0f);
  buf_.assign(kMaxPacketSize, 0);
  mount_ = Pose3{v.real("mount_x_m"), v.real("mount_y_m"), v.real("mount_z_m"), 0, 0, v.real("mount_yaw_rad")};
  max_packets_ = static_cast<int>(v.integer("max_packets_per_step"));
  return ok_status();
}

void OusterStage::publish(const LidarFrame& f, TimeNs now) noexcept {
  lut_->cartesian(f, xyz_.data());
  LidarScanMsg& m = *scan_;
  // Stamp of the revolution: its middle column's sensor time is not on our clock, so the receive time.
  m.stamp = now;
  m.published = now;
  ++m.seq;
  m.rings = static_cast<std::uint16_t>(f.height);
  m.columns = static_cast<std::uint16_t>(f.width);
  m.labels = classes_from_reflectivity_ ? LabelSource::kGroundTruth : LabelSource::kNone;
  m.sensor_in_body = mount_;
  std::uint32_t n = 0;
  for (int r = 0; r < f.height; ++r)
    for (int col = 0; col < f.width; ++col) {
      const std::size_t k = f.index(r, col);
      if (f.range_mm[k] == 0 || n >= kMaxScanPoints) continue;
      ScanReturn& p = m.points[n++];
      p.x = xyz_[3 * k];
      p.y = xyz_[3 * k + 1];
      p.z = xyz_[3 * k + 2];
      p.range = static_cast<float>(f.range_mm[k]) * 1e-3f;
      p.cls = classes_from_reflectivity_ ? static_cast<std::uint8_t>(f.reflectivity[k]) : std::uint8_t{255};
      p.ring = static_cast<std::uint16_t>(r);
      p.col = static_cast<std::uint16_t>(col);
    }
  m.count = n;
  ++c_.scans;
  if (!f.complete()) ++c_.scans_incomplete;
  if (out_.push(m) != 0) ++c_.ring_full;
}

void OusterStage::step(TimeNs now) noexcept {
  if (!source_) return;
  for (int i = 0; i < max_packets_; ++i) {
    std::size_t n = 0;
    TimeNs t = 0;
    const PacketKind k = source_->next(buf_, n, t);
    if (k == PacketKind::kNone || k == PacketKind::kEnd) break;
    if (k == PacketKind::kError) {
      ++c_.source_errors;
      continue;
    }
    const std::span<const std::uint8_t> bytes(buf_.data(), n);
    if (k == PacketKind::kImu) {
      ++c_.imu_packets;
      if (decode_imu(bytes, imu_) != DecodeStatus::kOk) ++c_.decode_errors;
      continue;
    }
    ++c_.packets;
    if (fmt_->decode_lidar(bytes, *pkt_) != DecodeStatus::kOk) {
      ++c_.decode_errors;
      continue;
    }
    if (const LidarFrame* f = assembler_->add(*pkt_)) publish(*f, now);
  }
}

}  // namespace ag::ouster
