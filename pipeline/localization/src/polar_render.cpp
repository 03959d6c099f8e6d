// The top-down polar render of a labelled scan.
#include "airground/localization/polar_render.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace ag::loc {

PolarRenderParams load_polar_render_params(const SectionView& s) {
  PolarRenderParams p = load_params(s, kPolarRenderFields);
  const PolarRenderMount m = load_params(s, kPolarRenderMountFields);
  p.sensor_in_body = Pose2{m.render_sensor_x_m, m.render_sensor_y_m, m.render_sensor_yaw_rad};
  return p;
}

ScanRenderPolar::ScanRenderPolar(const PolarRenderParams& params, const LocalizationChannels& channels)
    : p_(params), channels_(channels) {
  if (p_.angle_bins < 1 || p_.range_bins < 1 || p_.angle_bins > 65535 || p_.range_bins > 65535)
    throw std::invalid_argument("ScanRenderPolar: angle_bins and range_bins must be in 1..65535");
  if (channels_.count() < 1) throw std::invalid_argument("ScanRenderPolar: no channels");
  const auto cells = static_cast<std::size_t>(p_.angle_bins) * static_cast<std::size_t>(p_.range_bins);
  counts_.assign(cells * static_cast<std::size_t>(channels_.count()), 0);
  bins_.resize(cells);
  entries_.resize(cells * static_cast<std::size_t>(channels_.count()));
}

std::uint16_t ScanRenderPolar::count(int angle, int range, int channel) const noexcept {
  if (angle < 0 || range < 0 || channel < 0 || angle >= p_.angle_bins || range >= p_.range_bins || channel >= channels_.count())
    return 0;
  const auto i = (static_cast<std::size_t>(angle) * static_cast<std::size_t>(p_.range_bins) + static_cast<std::size_t>(range)) *
                     static_cast<std::size_t>(channels_.count()) +
                 static_cast<std::size_t>(channel);
  return counts_[i];
}

void ScanRenderPolar::render(std::span<const ScanPoint> points, double range_bin_m) noexcept {
  range_bin_m_ = range_bin_m > 0.0 ? range_bin_m : 1.0;
  std::fill(counts_.begin(), counts_.end(), std::uint16_t{0});
  const auto n_ch = static_cast<std::size_t>(channels_.count());
  const auto n_r = static_cast<std::size_t>(p_.range_bins);
  const float c = static_cast<float>(std::cos(p_.sensor_in_body.yaw)), s = static_cast<float>(std::sin(p_.sensor_in_body.yaw));
  const auto mx = static_cast<float>(p_.sensor_in_body.x), my = static_cast<float>(p_.sensor_in_body.y);
  const auto inv_r = static_cast<float>(1.0 / range_bin_m_);
  const auto inv_a = static_cast<float>(p_.angle_bins / (2.0 * kPi));
  const auto two_pi = static_cast<float>(2.0 * kPi);
  const auto min_r = static_cast<float>(p_.min_range_m), max_z = static_cast<float>(p_.max_height_m);
  const auto cap = p_.max_count_per_bin > 0 ? static_cast<std::uint16_t>(std::min(p_.max_count_per_bin, 65535)) : std::uint16_t{65535};
  points_counted_ = 0;
  const bool fine = range_bin_m_ <= channels_.fine_max_bin_m();
  for (const ScanPoint& p : points) {
    const int ch = fine ? channels_.fine_scan_channel(p.cls) : channels_.scan_channel(p.cls);
    if (ch < 0 || p.z > max_z) continue;
    const float bx = mx + c * p.x - s * p.y, by = my + s * p.x + c * p.y;
    const float r = std::sqrt(bx * bx + by * by);
    if (r < min_r) continue;
    const auto rb = static_cast<std::size_t>(r * inv_r);
    if (rb >= n_r) continue;
    float a = std::atan2(by, bx);
    if (a < 0.0F) a += two_pi;
    auto ab = static_cast<std::size_t>(a * inv_a);
    if (ab >= static_cast<std::size_t>(p_.angle_bins)) ab = 0;
    std::uint16_t& k = counts_[(ab * n_r + rb) * n_ch + static_cast<std::size_t>(ch)];
    if (k < cap) {
      ++k;
      ++points_counted_;
    }
  }
  n_bins_ = 0;
  n_entries_ = 0;
  used_range_bins_ = 0;
  total_weight_ = 0.0;
  for (std::size_t a = 0; a < static_cast<std::size_t>(p_.angle_bins); ++a)
    for (std::size_t r = 0; r < n_r; ++r) {
      const std::uint16_t* k = &counts_[(a * n_r + r) * n_ch];
      Bin bin;
      bin.angle = static_cast<std::uint16_t>(a);
      bin.range = static_cast<std::uint16_t>(r);
      bin.first = static_cast<std::uint32_t>(n_entries_);
      for (std::size_t ch = 0; ch < n_ch; ++ch) {
        if (k[ch] == 0) continue;
        const float v = static_cast<float>(k[ch]) * channels_.weight(static_cast<int>(ch));
        if (v <= 0.0F) continue;
        entries_[n_entries_++] = Entry{static_cast<std::uint32_t>(ch), v};
        bin.weight += v;
      }
      bin.entries = static_cast<std::uint32_t>(n_entries_) - bin.first;
      if (bin.entries == 0) continue;
      bins_[n_bins_++] = bin;
      total_weight_ += static_cast<double>(bin.weight);
      used_range_bins_ = std::max(used_range_bins_, static_cast<int>(r) + 1);
    }
}

}  // namespace ag::loc
