// Ouster packet decoders (layouts in packet_format.hpp).
#include "airground/drivers/lidar/ouster/packet_format.hpp"

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

namespace {
std::size_t pixel_size_of(UdpProfile p) noexcept {
  switch (p) {
    case UdpProfile::kLegacy:
    case UdpProfile::kRng19Rfl8Sig16Nir16: return 12;
    case UdpProfile::kRng19Rfl8Sig16Nir16Dual: return 16;
    case UdpProfile::kRng15Rfl8Nir8: return 4;
  }
  return 12;
}

// One column's pixels, one function per profile so the per-pixel loop has no profile branch.
template <UdpProfile P>
void decode_pixels(const std::uint8_t* px, int ppc, Pixel* out) noexcept {
  for (int r = 0; r < ppc; ++r) {
    Pixel& q = out[r];
    if constexpr (P == UdpProfile::kLegacy) {
      const auto w = le<std::uint32_t>(px);
      q.range_mm = w & 0x000FFFFFu;
      q.flags = static_cast<std::uint8_t>(w >> 28);
      q.reflectivity = le<std::uint16_t>(px + 4);
      q.signal = le<std::uint16_t>(px + 6);
      q.nir = le<std::uint16_t>(px + 8);
      px += 12;
    } else if constexpr (P == UdpProfile::kRng19Rfl8Sig16Nir16) {
      const auto w = le<std::uint32_t>(px);
      q.range_mm = w & 0x0007FFFFu;
      q.flags = static_cast<std::uint8_t>((w >> 19) & 0x1Fu);
      q.reflectivity = px[4];
      q.signal = le<std::uint16_t>(px + 6);
      q.nir = le<std::uint16_t>(px + 8);
      px += 12;
    } else if constexpr (P == UdpProfile::kRng19Rfl8Sig16Nir16Dual) {
      const auto w = le<std::uint32_t>(px);
      const auto w2 = le<std::uint32_t>(px + 4);
      q.range_mm = w & 0x0007FFFFu;
      q.flags = static_cast<std::uint8_t>((w >> 19) & 0x1Fu);
      q.reflectivity = static_cast<std::uint16_t>(w >> 24);
      q.range2_mm = w2 & 0x0007FFFFu;
      q.flags2 = static_cast<std::uint8_t>((w2 >> 19) & 0x1Fu);
      q.reflectivity2 = static_cast<std::uint8_t>(w2 >> 24);
      q.signal = le<std::uint16_t>(px + 8);
      q.signal2 = le<std::uint16_t>(px + 10);
      q.nir = le<std::uint16_t>(px + 12);
      px += 16;
    } else {
      const auto w = le<std::uint16_t>(px);
      q.range_mm = static_cast<std::uint32_t>(w & 0x7FFFu) << 3;  // units of 8 mm
      q.flags = static_cast<std::uint8_t>(w >> 15);
      q.reflectivity = px[2];
      q.signal = 0;
      q.nir = static_cast<std::uint16_t>(px[3] << 4);  // units of 16 photons
      px += 4;
    }
  }
}
}  // namespace

PacketFormat::PacketFormat(const SensorInfo& info) noexcept
    : profile_(info.profile),
      cols_(info.columns_per_packet > kMaxColumnsPerPacket ? kMaxColumnsPerPacket : info.columns_per_packet),
      ppc_(info.pixels_per_column > kMaxPixelsPerColumn ? kMaxPixelsPerColumn : info.pixels_per_column),
      cpf_(info.mode.columns) {
  const bool legacy = profile_ == UdpProfile::kLegacy;
  header_ = legacy ? 0 : kPacketHeaderSize;
  footer_ = legacy ? 0 : kPacketFooterSize;
  col_header_ = legacy ? 16 : 12;
  pixel_size_ = pixel_size_of(profile_);
  column_size_ = col_header_ + pixel_size_ * static_cast<std::size_t>(ppc_) + (legacy ? 4 : 0);
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
    std::memcpy(out.header.data(), p + 4, out.header.size());
    std::memcpy(out.footer.data(), p + packet_size_ - footer_, out.footer.size());
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
      o.valid = le<std::uint32_t>(col + col_header_ + pixel_size_ * static_cast<std::size_t>(ppc_)) == 0xFFFFFFFFu;
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
    switch (profile_) {
      case UdpProfile::kLegacy: decode_pixels<UdpProfile::kLegacy>(px, ppc_, o.pixels.data()); break;
      case UdpProfile::kRng19Rfl8Sig16Nir16: decode_pixels<UdpProfile::kRng19Rfl8Sig16Nir16>(px, ppc_, o.pixels.data()); break;
      case UdpProfile::kRng19Rfl8Sig16Nir16Dual: decode_pixels<UdpProfile::kRng19Rfl8Sig16Nir16Dual>(px, ppc_, o.pixels.data()); break;
      case UdpProfile::kRng15Rfl8Nir8: decode_pixels<UdpProfile::kRng15Rfl8Nir8>(px, ppc_, o.pixels.data()); break;
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
