// A capture decoded end to end for a person to read (capture_info.hpp).
#include "airground/drivers/lidar/ouster/capture_info.hpp"

#include <cmath>
#include <cstdio>
#include <memory>

#include "airground/drivers/lidar/ouster/packet_source.hpp"

namespace ag::ouster {

namespace {
std::uint32_t count_returns(const std::vector<std::uint32_t>& range) {
  std::uint32_t n = 0;
  for (std::uint32_t r : range) n += r != 0 ? 1u : 0u;
  return n;
}
}  // namespace

std::string CaptureInfo::problem() const {
  if (frames() != 0) return "";
  const PacketFormat fmt(sensor);
  if (lidar_packets == 0 && imu_packets == 0)
    return "no packets to UDP ports " + std::to_string(sensor.udp_port_lidar) + "/" + std::to_string(sensor.udp_port_imu) + " (" +
           std::to_string(other_ports) + " datagrams to other ports): the metadata's ports are not the capture's";
  if (lidar_packets == 0) return "IMU packets but no lidar packets on port " + std::to_string(sensor.udp_port_lidar);
  if (wrong_size != 0)
    return std::to_string(wrong_size) + " lidar packets of " + std::to_string(wrong_size_seen) + " B, but profile " + to_string(sensor.profile) +
           " with " + std::to_string(sensor.pixels_per_column) + " beams expects " + std::to_string(fmt.lidar_packet_size()) +
           " B: the metadata is not this capture's sensor or names the wrong profile";
  if (bad_type != 0) return std::to_string(bad_type) + " packets are not lidar packets (packet_type is not 1)";
  return "every lidar column was flagged invalid";
}

Result<CaptureInfo> read_capture_info(const std::string& pcap_path, const std::string& metadata_path) {
  auto meta = read_metadata_file(metadata_path);
  if (!meta) return meta.error();
  auto src = PcapPacketSource::open(pcap_path, meta.value().udp_port_lidar, meta.value().udp_port_imu);
  if (!src) return src.error();
  CaptureInfo ci;
  ci.sensor = meta.value();
  const PacketFormat fmt(ci.sensor);
  FrameAssembler assembler(ci.sensor);
  auto pkt = std::make_unique<LidarPacket>();
  std::vector<std::uint8_t> buf(kMaxPacketSize);
  const auto take = [&](const LidarFrame& f) {
    ci.returns_per_frame.push_back(count_returns(f.range_mm));
    if (f.has_second_return()) ci.second_returns_per_frame.push_back(count_returns(f.range2_mm));
    if (!ci.have_frame) {
      ci.first_frame = f;
      ci.have_frame = true;
    }
  };
  for (;;) {
    std::size_t n = 0;
    TimeNs t = 0;
    const PacketKind k = src.value()->next(buf, n, t);
    if (k == PacketKind::kEnd) break;
    if (k == PacketKind::kError) {
      ++ci.source_errors;
      if (!src.value()->error().empty()) break;  // a corrupt record ends the reading
      continue;
    }
    if (k == PacketKind::kImu) {
      ++ci.imu_packets;
      continue;
    }
    if (k != PacketKind::kLidar) continue;
    ++ci.lidar_packets;
    ci.lidar_bytes += n;
    const DecodeStatus st = fmt.decode_lidar(std::span<const std::uint8_t>(buf.data(), n), *pkt);
    if (st == DecodeStatus::kWrongSize) {
      ++ci.wrong_size;
      ci.wrong_size_seen = n;
      continue;
    }
    if (st == DecodeStatus::kBadPacketType) {
      ++ci.bad_type;
      continue;
    }
    if (st == DecodeStatus::kNoValidColumn) ++ci.no_valid_column;
    if (!ci.have_header && ci.sensor.profile != UdpProfile::kLegacy) {
      ci.have_header = true;
      ci.serial = pkt->serial();
      ci.init_id = pkt->init_id();
    }
    if (st != DecodeStatus::kOk) continue;
    if (const LidarFrame* f = assembler.add(*pkt)) take(*f);
  }
  while (const LidarFrame* f = assembler.flush()) take(*f);
  ci.assembly = assembler.counters();
  ci.other_ports = src.value()->other_ports();
  ci.capture_error = src.value()->error();
  return ci;
}

std::vector<std::size_t> destagger_index(const SensorInfo& info, int width, int height) {
  std::vector<std::size_t> idx(static_cast<std::size_t>(width) * static_cast<std::size_t>(height));
  const bool shift = static_cast<int>(info.pixel_shift_by_row.size()) == height;
  for (int r = 0; r < height; ++r) {
    const int s = shift ? info.pixel_shift_by_row[static_cast<std::size_t>(r)] : 0;
    for (int c = 0; c < width; ++c) {
      const int src = ((c - s) % width + width) % width;
      idx[static_cast<std::size_t>(r) * static_cast<std::size_t>(width) + static_cast<std::size_t>(c)] =
          static_cast<std::size_t>(r) * static_cast<std::size_t>(width) + static_cast<std::size_t>(src);
    }
  }
  return idx;
}

Status write_ply(const std::string& path, const LidarFrame& f, const XyzLut& lut) {
  std::vector<float> xyz(3 * f.range_mm.size());
  lut.cartesian(f, xyz.data());
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> out(std::fopen(path.c_str(), "w"), &std::fclose);
  if (!out) return Error::make(ErrorCode::kIo, "cannot write " + path);
  const std::uint32_t n = count_returns(f.range_mm);
  std::fprintf(out.get(),
               "ply\nformat ascii 1.0\ncomment Ouster frame %u, sensor frame, metres\nelement vertex %u\n"
               "property float x\nproperty float y\nproperty float z\nproperty float range\nproperty uchar reflectivity\nend_header\n",
               static_cast<unsigned>(f.frame_id), n);
  for (std::size_t k = 0; k < f.range_mm.size(); ++k) {
    if (f.range_mm[k] == 0) continue;
    std::fprintf(out.get(), "%.4f %.4f %.4f %.3f %u\n", static_cast<double>(xyz[3 * k]), static_cast<double>(xyz[3 * k + 1]),
                 static_cast<double>(xyz[3 * k + 2]), static_cast<double>(f.range_mm[k]) * 1e-3,
                 static_cast<unsigned>(f.reflectivity[k] > 255 ? 255 : f.reflectivity[k]));
  }
  if (std::ferror(out.get()) != 0) return Error::make(ErrorCode::kIo, "error writing " + path);
  return ok_status();
}

}  // namespace ag::ouster
