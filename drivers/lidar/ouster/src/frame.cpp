// Frame assembly: columns into a staggered image, one frame in progress plus the one handed out.
#include "airground/drivers/lidar/ouster/frame.hpp"

#include <algorithm>
#include <cstring>
#include <utility>

namespace ag::ouster {

LidarFrame::LidarFrame(int w, int h, bool second_return)
    : width(w),
      height(h),
      columns_expected(w),
      range_mm(static_cast<std::size_t>(w) * static_cast<std::size_t>(h)),
      reflectivity(range_mm.size()),
      signal(range_mm.size()),
      nir(range_mm.size()),
      flags(range_mm.size()),
      range2_mm(second_return ? range_mm.size() : 0),
      signal2(range2_mm.size()),
      reflectivity2(range2_mm.size()),
      flags2(range2_mm.size()),
      column_timestamp_ns(static_cast<std::size_t>(w)),
      column_valid(static_cast<std::size_t>(w)) {}

void LidarFrame::clear() noexcept {
  std::fill(range_mm.begin(), range_mm.end(), 0u);
  std::fill(reflectivity.begin(), reflectivity.end(), std::uint16_t{0});
  std::fill(signal.begin(), signal.end(), std::uint16_t{0});
  std::fill(nir.begin(), nir.end(), std::uint16_t{0});
  std::fill(flags.begin(), flags.end(), std::uint8_t{0});
  std::fill(range2_mm.begin(), range2_mm.end(), 0u);
  std::fill(signal2.begin(), signal2.end(), std::uint16_t{0});
  std::fill(reflectivity2.begin(), reflectivity2.end(), std::uint8_t{0});
  std::fill(flags2.begin(), flags2.end(), std::uint8_t{0});
  std::fill(column_timestamp_ns.begin(), column_timestamp_ns.end(), std::uint64_t{0});
  std::fill(column_valid.begin(), column_valid.end(), std::uint8_t{0});
  columns_received = 0;
}

FrameAssembler::FrameAssembler(const SensorInfo& info)
    : cur_(info.mode.columns, std::min(info.pixels_per_column, kMaxPixelsPerColumn), has_second_return(info.profile)),
      done_(info.mode.columns, std::min(info.pixels_per_column, kMaxPixelsPerColumn), has_second_return(info.profile)),
      second_return_(has_second_return(info.profile)) {
  const int window = std::clamp(info.columns_in_window(), 1, info.mode.columns);
  cur_.columns_expected = done_.columns_expected = window;
}

void FrameAssembler::emit() noexcept {
  std::swap(cur_, done_);  // swaps the vectors' storage, no allocation
  if (done_.complete()) ++c_.frames_complete;
  else ++c_.frames_incomplete;
  last_emitted_ = done_.frame_id;
  have_last_ = true;
  have_cur_ = false;
}

void FrameAssembler::start(std::uint16_t frame_id) noexcept {
  cur_.clear();
  cur_.frame_id = frame_id;
  have_cur_ = true;
}

void FrameAssembler::fill(const LidarPacket& p) noexcept {
  if (cur_.columns_received == 0) {
    cur_.packet_header = p.header;
    cur_.packet_footer = p.footer;
  }
  for (int i = 0; i < p.columns; ++i) {
    const Column& col = p.column[static_cast<std::size_t>(i)];
    const int m = col.measurement_id;
    if (!col.valid || m >= cur_.width) {
      ++c_.columns_invalid;
      continue;
    }
    const auto mc = static_cast<std::size_t>(m);
    if (cur_.column_valid[mc] != 0) {
      ++c_.columns_duplicate;
    } else {
      cur_.column_valid[mc] = 1;
      ++cur_.columns_received;
    }
    cur_.column_timestamp_ns[mc] = col.timestamp_ns;
    for (int r = 0; r < cur_.height; ++r) {
      const std::size_t k = cur_.index(r, m);
      const Pixel& px = col.pixels[static_cast<std::size_t>(r)];
      cur_.range_mm[k] = px.range_mm;
      cur_.reflectivity[k] = px.reflectivity;
      cur_.signal[k] = px.signal;
      cur_.nir[k] = px.nir;
      cur_.flags[k] = px.flags;
    }
    if (second_return_) {
      for (int r = 0; r < cur_.height; ++r) {
        const std::size_t k = cur_.index(r, m);
        const Pixel& px = col.pixels[static_cast<std::size_t>(r)];
        cur_.range2_mm[k] = px.range2_mm;
        cur_.signal2[k] = px.signal2;
        cur_.reflectivity2[k] = px.reflectivity2;
        cur_.flags2[k] = px.flags2;
      }
    }
  }
}

void FrameAssembler::start_pending() noexcept {
  if (!have_pending_) return;
  start(pending_.frame_id);
  fill(pending_);
  have_pending_ = false;
}

const LidarFrame* FrameAssembler::add(const LidarPacket& p) noexcept {
  ++c_.packets;
  bool any_valid = false;
  for (int i = 0; i < p.columns; ++i) any_valid = any_valid || p.column[static_cast<std::size_t>(i)].valid;
  if (!any_valid) {
    c_.columns_invalid += static_cast<std::uint64_t>(p.columns);
    return nullptr;
  }
  const std::uint16_t fid = p.frame_id;
  if (have_cur_ && fid == cur_.frame_id) {
    fill(p);
    if (!cur_.complete()) return nullptr;
    emit();
    start_pending();  // the next frame's early packet begins the new frame
    return &done_;
  }
  if (have_last_ && fid == last_emitted_) {  // a straggler of a frame already handed out
    ++c_.packets_late;
    return nullptr;
  }
  if (!have_cur_) {
    start(fid);
    fill(p);
    if (!cur_.complete()) return nullptr;
    emit();
    return &done_;
  }
  // A packet of a newer frame. The first one is held back, so a packet of the current frame that it
  // overtook still lands; a second one means the current frame is over.
  if (!have_pending_) {
    pending_ = p;
    have_pending_ = true;
    return nullptr;
  }
  emit();
  start_pending();
  if (fid == cur_.frame_id) fill(p);
  else {
    pending_ = p;
    have_pending_ = true;
  }
  return &done_;
}

const LidarFrame* FrameAssembler::flush() noexcept {
  if (!have_cur_ && !have_pending_) return nullptr;
  if (!have_cur_) start_pending();
  emit();
  start_pending();
  return &done_;
}

namespace {
template <typename T>
void put(std::uint8_t* p, T v) noexcept {
  std::memcpy(p, &v, sizeof v);
}
}  // namespace

std::size_t encode_lidar_packet(const PacketFormat& fmt, const LidarFrame& f, int first_column, std::span<std::uint8_t> out) noexcept {
  const int cols = fmt.columns_per_packet(), ppc = fmt.pixels_per_column();
  if (out.size() < fmt.lidar_packet_size() || first_column < 0 || first_column + cols > f.width || ppc > f.height) return 0;
  const UdpProfile prof = fmt.profile();
  const bool legacy = prof == UdpProfile::kLegacy;
  const bool second = f.has_second_return();
  std::uint8_t* p = out.data();
  std::memset(p, 0, fmt.lidar_packet_size());
  const std::size_t header = fmt.header_size(), col_header = fmt.column_header_size(), psz = fmt.pixel_size();
  if (!legacy) {
    put(p, std::uint16_t{1});
    put(p + 2, f.frame_id);
    std::memcpy(p + 4, f.packet_header.data(), f.packet_header.size());
    std::memcpy(p + fmt.lidar_packet_size() - kPacketFooterSize, f.packet_footer.data(), f.packet_footer.size());
  }
  for (int c = 0; c < cols; ++c) {
    const int m = first_column + c;
    const auto mc = static_cast<std::size_t>(m);
    std::uint8_t* col = p + header + static_cast<std::size_t>(c) * fmt.column_size();
    put(col, f.column_timestamp_ns[mc]);
    put(col + 8, static_cast<std::uint16_t>(m));
    const bool valid = f.column_valid[mc] != 0;
    if (legacy) {
      put(col + 10, f.frame_id);
      put(col + 12, static_cast<std::uint32_t>(static_cast<std::uint64_t>(m) * 90112u / static_cast<std::uint64_t>(f.width)));
      put(col + col_header + psz * static_cast<std::size_t>(ppc), valid ? 0xFFFFFFFFu : 0u);
    } else {
      put(col + 10, static_cast<std::uint16_t>(valid ? 1 : 0));
    }
    std::uint8_t* px = col + col_header;
    for (int r = 0; r < ppc; ++r, px += psz) {
      const std::size_t k = f.index(r, m);
      const std::uint32_t rfl = std::min<std::uint16_t>(f.reflectivity[k], 255);
      switch (prof) {
        case UdpProfile::kLegacy:
          put(px, (f.range_mm[k] & 0x000FFFFFu) | static_cast<std::uint32_t>(f.flags[k] & 0x0Fu) << 28);
          put(px + 4, f.reflectivity[k]);
          put(px + 6, f.signal[k]);
          put(px + 8, f.nir[k]);
          break;
        case UdpProfile::kRng19Rfl8Sig16Nir16:
          put(px, (f.range_mm[k] & 0x0007FFFFu) | static_cast<std::uint32_t>(f.flags[k] & 0x1Fu) << 19);
          px[4] = static_cast<std::uint8_t>(rfl);
          put(px + 6, f.signal[k]);
          put(px + 8, f.nir[k]);
          break;
        case UdpProfile::kRng19Rfl8Sig16Nir16Dual:
          put(px, (f.range_mm[k] & 0x0007FFFFu) | static_cast<std::uint32_t>(f.flags[k] & 0x1Fu) << 19 | rfl << 24);
          if (second)
            put(px + 4, (f.range2_mm[k] & 0x0007FFFFu) | static_cast<std::uint32_t>(f.flags2[k] & 0x1Fu) << 19 |
                            static_cast<std::uint32_t>(f.reflectivity2[k]) << 24);
          put(px + 8, f.signal[k]);
          if (second) put(px + 10, f.signal2[k]);
          put(px + 12, f.nir[k]);
          break;
        case UdpProfile::kRng15Rfl8Nir8: {
          const std::uint32_t units = std::min<std::uint32_t>((f.range_mm[k] + 4u) >> 3, 0x7FFFu);  // 8 mm, nearest
          put(px, static_cast<std::uint16_t>(units | static_cast<std::uint32_t>(f.flags[k] & 1u) << 15));
          px[2] = static_cast<std::uint8_t>(rfl);
          px[3] = static_cast<std::uint8_t>(std::min<std::uint32_t>((f.nir[k] + 8u) >> 4, 255u));
          break;
        }
      }
    }
  }
  return fmt.lidar_packet_size();
}

std::size_t encode_imu_packet(const ImuSample& s, std::span<std::uint8_t> out) noexcept {
  if (out.size() < kImuPacketSize) return 0;
  std::uint8_t* p = out.data();
  put(p, s.sys_ts_ns);
  put(p + 8, s.accel_ts_ns);
  put(p + 16, s.gyro_ts_ns);
  for (std::size_t i = 0; i < 3; ++i) {
    put(p + 24 + 4 * i, s.accel_g[i]);
    put(p + 36 + 4 * i, s.gyro_deg_s[i]);
  }
  return kImuPacketSize;
}

}  // namespace ag::ouster
