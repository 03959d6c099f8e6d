// Frame assembly: columns into a staggered image, one frame in progress plus the one handed out.
#include "airground/drivers/ouster/frame.hpp"

#include <algorithm>
#include <utility>

namespace ag::ouster {

LidarFrame::LidarFrame(int w, int h)
    : width(w),
      height(h),
      range_mm(static_cast<std::size_t>(w) * static_cast<std::size_t>(h)),
      reflectivity(range_mm.size()),
      signal(range_mm.size()),
      nir(range_mm.size()),
      column_timestamp_ns(static_cast<std::size_t>(w)),
      column_valid(static_cast<std::size_t>(w)) {}

void LidarFrame::clear() noexcept {
  std::fill(range_mm.begin(), range_mm.end(), 0u);
  std::fill(reflectivity.begin(), reflectivity.end(), std::uint16_t{0});
  std::fill(signal.begin(), signal.end(), std::uint16_t{0});
  std::fill(nir.begin(), nir.end(), std::uint16_t{0});
  std::fill(column_timestamp_ns.begin(), column_timestamp_ns.end(), std::uint64_t{0});
  std::fill(column_valid.begin(), column_valid.end(), std::uint8_t{0});
  columns_received = 0;
}

FrameAssembler::FrameAssembler(const SensorInfo& info)
    : cur_(info.mode.columns, std::min(info.pixels_per_column, kMaxPixelsPerColumn)),
      done_(info.mode.columns, std::min(info.pixels_per_column, kMaxPixelsPerColumn)) {}

void FrameAssembler::emit() noexcept {
  std::swap(cur_, done_);  // swaps the vectors' storage, no allocation
  if (done_.complete()) ++c_.frames_complete;
  else ++c_.frames_incomplete;
  last_emitted_ = done_.frame_id;
  have_last_ = true;
  have_cur_ = false;
}

const LidarFrame* FrameAssembler::add(const LidarPacket& p) noexcept {
  ++c_.packets;
  bool emitted = false;
  for (int i = 0; i < p.columns; ++i) {
    const Column& col = p.column[static_cast<std::size_t>(i)];
    if (!col.valid) {
      ++c_.columns_invalid;
      continue;
    }
    if (have_cur_ && col.frame_id != cur_.frame_id) {
      if (have_last_ && col.frame_id == last_emitted_) {
        ++c_.packets_late;
        return emitted ? &done_ : nullptr;
      }
      if (emitted) return &done_;  // cannot hand out two frames at once: cannot happen for whole packets
      emit();
      emitted = true;
    } else if (!have_cur_ && have_last_ && col.frame_id == last_emitted_) {
      ++c_.packets_late;
      return emitted ? &done_ : nullptr;
    }
    if (!have_cur_) {
      cur_.clear();
      cur_.frame_id = col.frame_id;
      have_cur_ = true;
    }
    const int m = col.measurement_id;
    if (m >= cur_.width) {
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
    }
    if (cur_.complete() && !emitted) {
      emit();
      emitted = true;
    }
  }
  return emitted ? &done_ : nullptr;
}

const LidarFrame* FrameAssembler::flush() noexcept {
  if (!have_cur_) return nullptr;
  emit();
  return &done_;
}

}  // namespace ag::ouster
