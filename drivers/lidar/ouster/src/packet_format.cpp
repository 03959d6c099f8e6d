// Ouster packet decoders (layouts in packet_format.hpp).
#include "airground/drivers/ouster/packet_format.hpp"

#include <cstring>

namespace ag::ouster {

namespace {
template <typename T>
T le(const std::uint8_t* p) noexcept {
  T v;
  std::memcpy(&v, p, sizeof v);  // the targets (x86-64, aarch64) are little-endian, as the packets
  return v;
}
}  // namespace

const char* to_string(DecodeStatus s) noexcept {
  switch (s) {
    case DecodeStatus::kOk: return "ok";
    case DecodeStatus::kWrongSize: return "wrong packet size for the profile";
    case DecodeStatus::kBadPacketType: return "packet_type is not a lidar packet";
    case DecodeStatus::kNoValidColumn: return "no valid column";
  }
  return "?";
}

PacketFormat::PacketFormat(const SensorInfo& info) noexcept
    : profile_(info.profile),
      cols_(info.columns_per_packet > kMaxColumnsPerPacket ? kMaxColumnsPerPacket : info.columns_per_packet),
      ppc_(info.pixels_per_column > kMaxPixelsPerColumn ? kMaxPixelsPerColumn : info.pixels_per_column),
      cpf_(info.mode.columns) {
  const bool legacy = profile_ == UdpProfile::kLegacy;
  header_ = legacy ? 0 : 32;
  footer_ = legacy ? 0 : 32;
  col_header_ = legacy ? 16 : 12;
  column_size_ = col_header_ + 12 * static_cast<std::size_t>(ppc_) + (legacy ? 4 : 0);
  packet_size_ = header_ + column_size_ * static_cast<std::size_t>(cols_) + footer_;
}

DecodeStatus PacketFormat::decode_lidar(std::span<const std::uint8_t> bytes, LidarPacket& out, int* bad_ids) const noexcept {
  if (bytes.size() != packet_size_) return DecodeStatus::kWrongSize;
  const std::uint8_t* p = bytes.data();
  const bool legacy = profile_ == UdpProfile::kLegacy;
  std::uint16_t packet_frame = 0;
  if (!legacy) {
    if (le<std::uint16_t>(p) != 1) return DecodeStatus::kBadPacketType;
    packet_frame = le<std::uint16_t>(p + 2);
  }
  out.columns = cols_;
  int valid = 0, bad = 0;
  bool frame_set = !legacy;
  for (int c = 0; c < cols_; ++c) {
    const std::uint8_t* col = p + header_ + static_cast<std::size_t>(c) * column_size_;
    Column& o = out.column[static_cast<std::size_t>(c)];
    o.timestamp_ns = le<std::uint64_t>(col);
    o.measurement_id = le<std::uint16_t>(col + 8);
    if (legacy) {
      o.frame_id = le<std::uint16_t>(col + 10);
      o.encoder_count = le<std::uint32_t>(col + 12);
      o.valid = le<std::uint32_t>(col + col_header_ + 12 * static_cast<std::size_t>(ppc_)) == 0xFFFFFFFFu;
    } else {
      o.frame_id = packet_frame;
      o.encoder_count = 0;
      o.valid = (le<std::uint16_t>(col + 10) & 1u) != 0;
    }
    if (o.valid && o.measurement_id >= cpf_) {
      o.valid = false;
      ++bad;
    }
    const std::uint8_t* px = col + col_header_;
    for (int r = 0; r < ppc_; ++r, px += 12) {
      Pixel& q = o.pixels[static_cast<std::size_t>(r)];
      if (legacy) {
        q.range_mm = le<std::uint32_t>(px) & 0x000FFFFFu;
        q.reflectivity = le<std::uint16_t>(px + 4);
        q.signal = le<std::uint16_t>(px + 6);
        q.nir = le<std::uint16_t>(px + 8);
      } else {
        q.range_mm = le<std::uint32_t>(px) & 0x0007FFFFu;
        q.reflectivity = px[4];
        q.signal = le<std::uint16_t>(px + 6);
        q.nir = le<std::uint16_t>(px + 8);
      }
    }
    if (o.valid) {
      ++valid;
      if (!frame_set) {
        packet_frame = o.frame_id;
        frame_set = true;
      }
    }
  }
  out.frame_id = packet_frame;
  if (bad_ids != nullptr) *bad_ids = bad;
  return valid > 0 ? DecodeStatus::kOk : DecodeStatus::kNoValidColumn;
}

DecodeStatus decode_imu(std::span<const std::uint8_t> bytes, ImuSample& out) noexcept {
  if (bytes.size() != kImuPacketSize) return DecodeStatus::kWrongSize;
  const std::uint8_t* p = bytes.data();
  out.sys_ts_ns = le<std::uint64_t>(p);
  out.accel_ts_ns = le<std::uint64_t>(p + 8);
  out.gyro_ts_ns = le<std::uint64_t>(p + 16);
  for (std::size_t i = 0; i < 3; ++i) {
    out.accel_g[i] = le<float>(p + 24 + 4 * i);
    out.gyro_deg_s[i] = le<float>(p + 36 + 4 * i);
  }
  return DecodeStatus::kOk;
}

}  // namespace ag::ouster
