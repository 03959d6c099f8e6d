// The Ouster stage: packets to frames to scans.
#include "airground/drivers/lidar/ouster/stage.hpp"

#include <cmath>
#include <cstdio>
#include <string>

#include "airground/drivers/lidar/ouster/sim_source.hpp"
#include "airground/messages/channels.hpp"
#include "airground/platform/log.hpp"

namespace ag::ouster {

// A sensor that is absent (no metadata, a port taken, a capture missing) does not stop the robot: the
// stage logs why, counts it and publishes nothing, like the base stage with no CAN interface.
Status OusterStage::init(StageContext& ctx) {
  const OusterSettings cfg = load_params(ctx.params(), kOusterStageFields);
  const std::string where = std::string(ctx.stage_name) + ".";
  auto w = ctx.channels.ring_writer(chan::kLidarScan.with_name(cfg.scan_channel));
  if (!w) return w.error();
  out_ = w.value();
  const std::string& cls = cfg.classes;
  if (cls != "none" && cls != "reflectivity")
    return Error::make(ErrorCode::kConfig, "config error: " + where + "classes must be none or reflectivity, got '" + cls + "'");
  classes_from_reflectivity_ = cls == "reflectivity";
  const std::string& src = cfg.source;
  if (src != "udp" && src != "pcap" && src != "sim" && src != "none")
    return Error::make(ErrorCode::kConfig, "config error: " + where + "source must be udp, pcap, sim or none, got '" + src + "'");
  if (src == "none") return ok_status();
  if (ctx.device != nullptr) device_ = ctx.device;
  device_->describe("frames", {"wrong_size", "bad_type", "no_valid_column", "source"});
  auto absent = [&](const std::string& why) {
    ++c_.device_errors;
    AG_LOG_ERROR("lidar", "%s; no scans from this sensor (the robot keeps running)", why.c_str());
    source_.reset();
    return ok_status();
  };
  SimPacketLink* sim = nullptr;
  if (src == "sim") {  // the simulator's sensor: its packets in-process, and its metadata as get_metadata gives it
    sim = find_sim_lidar(ctx.instance);
    if (sim == nullptr)
      return Error::make(ErrorCode::kConfig, "config error: " + where + "source is sim but the simulator gave robot '" +
                                                 std::string(ctx.instance) + "' no lidar");
  } else if (cfg.metadata.empty()) {
    return absent(where + "metadata names no sensor metadata JSON");
  }
  auto info = sim != nullptr ? Result<SensorInfo>(sim->info()) : read_metadata_file(cfg.metadata);
  // A file that is not there or not JSON is an absent sensor; one that says what the decoder cannot
  // read (an unsupported profile, a bad mode) is a wrong configuration and stops the robot.
  if (!info && info.error().code == ErrorCode::kConfig) {
    // Also logged here in two lines: one log line holds 224 characters, the path and the list need more.
    const std::string& m = info.error().message;
    const auto cut = m.find(" (supported: ");
    AG_LOG_ERROR("lidar", "%smetadata: %s", where.c_str(), m.substr(0, cut).c_str());
    if (cut != std::string::npos) AG_LOG_ERROR("lidar", "supported packet profiles: %s", m.substr(cut + 13, m.size() - cut - 14).c_str());
    return Error::make(ErrorCode::kConfig, "config error: " + where + "metadata: " + m);
  }
  if (!info) return absent(where + "metadata: " + info.error().message);
  const SensorInfo& s = info.value();
  const auto lidar_port = static_cast<std::uint16_t>(cfg.lidar_port != 0 ? cfg.lidar_port : s.udp_port_lidar);
  const auto imu_port = static_cast<std::uint16_t>(cfg.imu_port != 0 ? cfg.imu_port : s.udp_port_imu);
  if (sim != nullptr) {
    source_ = sim->open_source();
  } else if (cfg.source == "pcap") {
    auto p = PcapPacketSource::open(cfg.pcap, lidar_port, imu_port);
    if (!p) return absent(where + "pcap: " + p.error().message);
    source_ = std::move(p).value();
  } else {
    UdpSourceConfig u;
    u.bind_address = cfg.bind_address;
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
  mount_ = Pose3{cfg.mount_x_m, cfg.mount_y_m, cfg.mount_z_m, 0, 0, cfg.mount_yaw_rad};
  max_packets_ = cfg.max_packets_per_step;
  pcap_ = src == "pcap";
  lidar_port_ = lidar_port;
  imu_port_ = imu_port;
  expected_size_ = fmt_->lidar_packet_size();
  profile_ = s.profile;
  char where_from[48];
  if (sim != nullptr) std::snprintf(where_from, sizeof where_from, "the simulator's sensor");
  else std::snprintf(where_from, sizeof where_from, "%s port %u", src.c_str(), static_cast<unsigned>(lidar_port));
  AG_LOG_INFO("lidar", "%s %s, %s, %dx%d, profile %s (%zu B packets), %s", s.prod_line.empty() ? "Ouster" : s.prod_line.c_str(),
              s.firmware.c_str(), s.layout.c_str(), s.mode.columns, s.mode.frequency_hz, to_string(s.profile), expected_size_, where_from);
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
  device_->unit_received(f.complete(), now);
  at_last_frame_ = c_;
  if (out_.push(m) != 0) ++c_.ring_full;
}

void OusterStage::step(TimeNs now) noexcept {
  if (!source_) return;
  for (int i = 0; i < max_packets_; ++i) {
    std::size_t n = 0;
    TimeNs t = 0;
    const PacketKind k = source_->next(buf_, n, t);
    if (k == PacketKind::kNone) break;
    if (k == PacketKind::kEnd) {
      if (!replay_ended_) {
        replay_ended_ = true;
        if (c_.scans == 0) warn_silence(now);  // a capture that gave nothing says why, once
        else
          AG_LOG_INFO("lidar", "capture replayed to its end: %llu frames (%llu incomplete), %llu decode errors",
                      static_cast<unsigned long long>(c_.scans), static_cast<unsigned long long>(c_.scans_incomplete),
                      static_cast<unsigned long long>(c_.decode_errors));
      }
      break;
    }
    if (k == PacketKind::kError) {
      ++c_.source_errors;
      device_->error(static_cast<std::size_t>(LidarError::kSource));
      continue;
    }
    c_.bytes += n;
    device_->received_bytes(n);
    const std::span<const std::uint8_t> bytes(buf_.data(), n);
    if (k == PacketKind::kImu) {
      ++c_.imu_packets;
      if (decode_imu(bytes, imu_) != DecodeStatus::kOk) {
        ++c_.decode_errors;
        ++c_.wrong_size;
        device_->error(static_cast<std::size_t>(LidarError::kWrongSize));
      }
      continue;
    }
    ++c_.packets;
    const DecodeStatus st = fmt_->decode_lidar(bytes, *pkt_);
    if (st != DecodeStatus::kOk) {
      ++c_.decode_errors;
      LidarError kind = LidarError::kNoValidColumn;
      if (st == DecodeStatus::kWrongSize) {
        ++c_.wrong_size;
        c_.last_wrong_size = n;
        kind = LidarError::kWrongSize;
      } else if (st == DecodeStatus::kBadPacketType) {
        ++c_.bad_type;
        kind = LidarError::kBadType;
      } else {
        ++c_.no_valid_column;
      }
      device_->error(static_cast<std::size_t>(kind));
      continue;
    }
    if (const LidarFrame* f = assembler_->add(*pkt_)) publish(*f, now);
  }
  if (!replay_ended_ && silence_.check(*device_, now)) warn_silence(now);
}

// One warning per silence, naming the likely cause from what did arrive since the last frame.
void OusterStage::warn_silence(TimeNs now) noexcept {
  ++c_.silence_warnings;
  char what[64];
  if (replay_ended_) std::snprintf(what, sizeof what, "the capture ended with no lidar frame");
  else std::snprintf(what, sizeof what, "no lidar frame for %.0f s", static_cast<double>(silence_.silent_for(now)) * 1e-9);
  const OusterStageCounters& b = at_last_frame_;
  const std::uint64_t lidar = c_.packets - b.packets, imu = c_.imu_packets - b.imu_packets;
  const std::uint64_t wrong = c_.wrong_size - b.wrong_size, bad_type = c_.bad_type - b.bad_type;
  if (lidar == 0 && imu == 0) {
    AG_LOG_WARN("lidar", "%s: no packets at all on UDP ports %u/%u (sensor off or not sending to this host: "
                "check its udp_dest, the cable, a firewall)", what, static_cast<unsigned>(lidar_port_), static_cast<unsigned>(imu_port_));
  } else if (lidar == 0) {
    AG_LOG_WARN("lidar", "%s: %llu IMU packets on port %u but no lidar packets on port %u "
                "(wrong lidar port: the sensor's udp_port_lidar or lidar.lidar_port)", what, static_cast<unsigned long long>(imu),
                static_cast<unsigned>(imu_port_), static_cast<unsigned>(lidar_port_));
  } else if (wrong != 0) {
    AG_LOG_WARN("lidar", "%s: %llu lidar packets of %zu B refused, profile %s expects %zu B "
                "(wrong profile or another sensor's metadata: fetch the sensor's own)", what, static_cast<unsigned long long>(wrong),
                c_.last_wrong_size, to_string(profile_), expected_size_);
  } else if (bad_type != 0) {
    AG_LOG_WARN("lidar", "%s: %llu packets on port %u are not lidar packets (wrong port?)", what,
                static_cast<unsigned long long>(bad_type), static_cast<unsigned>(lidar_port_));
  } else {
    AG_LOG_WARN("lidar", "%s: %llu lidar packets decoded but no revolution completed "
                "(columns flagged invalid: the sensor starting up or a column window)", what, static_cast<unsigned long long>(lidar));
  }
}

}  // namespace ag::ouster
