// The simulated Ouster: metadata and packets.
#include "ouster_device.hpp"

#include <opencv2/core.hpp>

#include <cmath>
#include <fstream>

namespace ag::sim {

using json = nlohmann::json;

Result<json> ouster_metadata(int columns, const std::string& profile) {
  json meta;
  {
    std::ifstream mf_in(OusterBeamModel::default_metadata_path());
    if (!mf_in) return Error::make(ErrorCode::kIo, "cannot read " + OusterBeamModel::default_metadata_path());
    try {
      mf_in >> meta;
    } catch (const std::exception& e) {
      return Error::make(ErrorCode::kMalformed, OusterBeamModel::default_metadata_path() + ": " + e.what());
    }
  }
  if (columns != 512 && columns != 1024 && columns != 2048)
    return Error::make(ErrorCode::kInvalidArgument, "--lidar-columns must be 512, 1024 or 2048");
  meta["lidar_mode"] = std::to_string(columns) + "x10";
  if (auto p = ouster::parse_udp_profile(profile); !p) return Error::make(ErrorCode::kInvalidArgument, "--lidar-profile: " + p.error().message);
  meta["udp_profile_lidar"] = profile;
  if (meta.contains("data_format")) {
    meta["data_format"]["udp_profile_lidar"] = profile;
    meta["data_format"]["columns_per_frame"] = columns;
    meta["data_format"]["column_window"] = json::array({0, columns - 1});
  }
  return meta;
}

Result<ouster::SensorInfo> ouster_sensor_info(int columns, const std::string& profile) {
  auto meta = ouster_metadata(columns, profile);
  if (!meta) return meta.error();
  return ouster::parse_metadata(meta.value().dump(), OusterBeamModel::default_metadata_path());
}

std::uint8_t albedo_reflectivity(const World& w, double x, double y) noexcept {
  const GridGeometry& g = w.header.grid;
  const auto c = g.col(x), r = g.row(y);
  if (!g.contains(c, r) || w.albedo.empty()) return 0;
  const cv::Vec3b a = w.albedo.at<cv::Vec3b>(r, c);
  return static_cast<std::uint8_t>((static_cast<int>(a[0]) + static_cast<int>(a[1]) + static_cast<int>(a[2])) * 100 / (3 * 255));
}

OusterPackets::OusterPackets(const ouster::SensorInfo& info)
    : info_(info), fmt_(std::make_unique<ouster::PacketFormat>(info_)),
      frame_(info_.mode.columns, static_cast<int>(info_.beam_altitude_deg.size()), ouster::has_second_return(info_.profile)),
      pkt_(fmt_->lidar_packet_size(), 0) {}

int OusterPackets::packets_per_revolution() const noexcept {
  const int cpp = fmt_->columns_per_packet();
  return (frame_.width + cpp - 1) / cpp;
}

std::uint64_t OusterPackets::send_revolution(std::span<const std::vector<LidarPoint>> parts, const Pose3& sp, TimeNs now, TimeNs period,
                                             bool labels_oracle, const World& w,
                                             const std::function<bool(std::span<const std::uint8_t>)>& send) {
  ouster::LidarFrame& f = frame_;
  f.clear();
  f.frame_id = frame_id_++;
  const TimeNs col_dt = period / f.width;
  for (int c = 0; c < f.width; ++c) {
    f.column_timestamp_ns[static_cast<std::size_t>(c)] = static_cast<std::uint64_t>(now + c * col_dt);
    f.column_valid[static_cast<std::size_t>(c)] = 1;
  }
  f.columns_received = f.width;
  const double cy = std::cos(sp.yaw), sy = std::sin(sp.yaw);
  for (const std::vector<LidarPoint>& part : parts)
    for (const LidarPoint& q : part) {
      if (q.ring >= f.height || q.col >= f.width) continue;
      const std::size_t k = f.index(q.ring, q.col);
      f.range_mm[k] = static_cast<std::uint32_t>(std::lround(q.range * 1000.0f));
      // An Ouster measures reflectivity, not class: the surface's albedo (the true class only with --oracle labels).
      f.reflectivity[k] = labels_oracle ? q.cls
                                        : albedo_reflectivity(w, sp.x + cy * static_cast<double>(q.x) - sy * static_cast<double>(q.y),
                                                              sp.y + sy * static_cast<double>(q.x) + cy * static_cast<double>(q.y));
      f.signal[k] = 200;
    }
  std::uint64_t sent = 0;
  const int cpp = fmt_->columns_per_packet();
  for (int c0 = 0; c0 < f.width; c0 += cpp) {
    const std::size_t len = ouster::encode_lidar_packet(*fmt_, f, c0, pkt_);
    if (len > 0 && send(std::span<const std::uint8_t>(pkt_.data(), len))) ++sent;
  }
  return sent;
}

}  // namespace ag::sim
