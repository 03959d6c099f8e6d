// The top-down polar render of a labelled scan: angle bins x range bins around the robot, each counting
// the points of every channel. The range-bin size is set per render (the filter widens it while
// uncertain); the filter matches the render's non-empty bins against the aerial distance fields.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "airground/messages/geometry.hpp"
#include "airground/localization/scan.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/param_binding.hpp"

namespace ag::loc {

struct PolarRenderParams {
  int angle_bins{100};        // bins over 360 deg (paper: 100, 3.6 deg)
  int range_bins{25};         // bins from the robot outwards (paper: 25)
  double min_range_m{1.0};    // [m] returns closer than this are the robot itself
  double max_height_m{25.0};  // [m] returns higher above the sensor are ignored (overhanging wires, birds)
  int max_count_per_bin{0};   // [points] cap of one channel's count in one bin; 0 = no cap
  Pose2 sensor_in_body{};     // LiDAR mount in the body frame [m, rad] (body x forward, y left)
};

inline constexpr ParamField<PolarRenderParams> kPolarRenderFields[] = {
    field::integer("render_angle_bins", &PolarRenderParams::angle_bins, 8, 720, "bins", "angle bins over 360 deg (paper: 100)"),
    field::integer("render_range_bins", &PolarRenderParams::range_bins, 2, 200, "bins", "range bins (paper: 25)"),
    field::real("render_min_range_m", &PolarRenderParams::min_range_m, 0.0, 20.0, "m", "returns closer than this are the robot itself"),
    field::real("render_max_height_m", &PolarRenderParams::max_height_m, 0.5, 200.0, "m", "returns higher above the sensor are ignored"),
    field::integer("render_max_count_per_bin", &PolarRenderParams::max_count_per_bin, 0, 65535, "points", "cap of one channel's count per bin; 0 = none"),
};
// The mount's three rows (PolarRenderParams::sensor_in_body is a Pose2, which a row cannot bind).
struct PolarRenderMount {
  double render_sensor_x_m{0.0}, render_sensor_y_m{0.0}, render_sensor_yaw_rad{0.0};
};
inline constexpr ParamField<PolarRenderMount> kPolarRenderMountFields[] = {
    field::real("render_sensor_x_m", &PolarRenderMount::render_sensor_x_m, -5.0, 5.0, "m", "LiDAR mount: forward offset in the body frame"),
    field::real("render_sensor_y_m", &PolarRenderMount::render_sensor_y_m, -5.0, 5.0, "m", "LiDAR mount: left offset in the body frame"),
    field::real("render_sensor_yaw_rad", &PolarRenderMount::render_sensor_yaw_rad, -3.15, 3.15, "rad", "LiDAR mount: yaw in the body frame"),
};
inline constexpr auto kPolarRenderParamSpecs = param_specs(kPolarRenderFields, kPolarRenderMountFields);
PolarRenderParams load_polar_render_params(const SectionView& s);

class ScanRenderPolar {
 public:
  // A non-empty (angle, range) bin of the render and its channel entries.
  struct Bin {
    std::uint16_t angle{0}, range{0};
    std::uint32_t first{0}, entries{0};  // its entries: entries()[first .. first + entries)
    float weight{0};                     // sum of the entries' count x channel weight
  };
  struct Entry {
    std::uint32_t channel{0};
    float value{0};  // count x channel weight
  };

  ScanRenderPolar(const PolarRenderParams& params, const LocalizationChannels& channels);

  // Replaces the render with `points` (labelled, sensor frame) at range bins of `range_bin_m`. Never
  // allocates. Points with an uncounted label, too close, too high or beyond the last bin are skipped.
  // A label counts into its fine_scan_channel when range_bin_m <= the channels' fine_max_bin_m.
  void render(std::span<const ScanPoint> points, double range_bin_m) noexcept;

  // Bin (a, r) covers body angles [a, a + 1) x 360 / angle_bins CCW from forward and ranges
  // [r, r + 1) x range_bin_m from the body origin.
  [[nodiscard]] std::uint16_t count(int angle, int range, int channel) const noexcept;
  [[nodiscard]] std::span<const Bin> bins() const noexcept { return {bins_.data(), n_bins_}; }
  [[nodiscard]] std::span<const Entry> entries() const noexcept { return {entries_.data(), n_entries_}; }
  [[nodiscard]] int angle_bins() const noexcept { return p_.angle_bins; }
  [[nodiscard]] int range_bins() const noexcept { return p_.range_bins; }
  [[nodiscard]] double range_bin_m() const noexcept { return range_bin_m_; }
  [[nodiscard]] double angle_bin_rad() const noexcept { return 2.0 * kPi / p_.angle_bins; }
  [[nodiscard]] int used_range_bins() const noexcept { return used_range_bins_; }  // 1 + last non-empty range bin
  [[nodiscard]] std::uint32_t points_counted() const noexcept { return points_counted_; }
  [[nodiscard]] double total_weight() const noexcept { return total_weight_; }  // sum of all entries' values
  [[nodiscard]] const LocalizationChannels& channels() const noexcept { return channels_; }
  [[nodiscard]] const PolarRenderParams& params() const noexcept { return p_; }
  [[nodiscard]] std::size_t memory_bytes() const noexcept {
    return sizeof(*this) + counts_.capacity() * sizeof(std::uint16_t) + bins_.capacity() * sizeof(Bin) +
           entries_.capacity() * sizeof(Entry);
  }

 private:
  PolarRenderParams p_;
  LocalizationChannels channels_;
  double range_bin_m_{1.0};
  std::vector<std::uint16_t> counts_;  // [angle][range][channel]
  std::vector<Bin> bins_;
  std::vector<Entry> entries_;
  std::size_t n_bins_{0}, n_entries_{0};
  int used_range_bins_{0};
  std::uint32_t points_counted_{0};
  double total_weight_{0};
};

}  // namespace ag::loc
