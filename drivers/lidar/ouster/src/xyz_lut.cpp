// XYZ lookup table (formula in xyz_lut.hpp).
#include "airground/drivers/lidar/ouster/xyz_lut.hpp"

#include <cmath>
#include <limits>
#include <numbers>

namespace ag::ouster {

XyzLut::XyzLut(const SensorInfo& info)
    : w_(info.mode.columns), h_(static_cast<int>(info.beam_altitude_deg.size())),
      dir_(3 * static_cast<std::size_t>(w_) * static_cast<std::size_t>(h_)), off_(dir_.size()) {
  const double pi = std::numbers::pi;
  const auto& b = info.beam_to_lidar;
  const auto& t = info.lidar_to_sensor;
  const double n = std::hypot(b[3], b[11]);
  for (int r = 0; r < h_; ++r) {
    const double phi = 2.0 * pi * info.beam_altitude_deg[static_cast<std::size_t>(r)] / 360.0;
    const double theta_a = -2.0 * pi * info.beam_azimuth_deg[static_cast<std::size_t>(r)] / 360.0;
    for (int m = 0; m < w_; ++m) {
      const double theta_e = 2.0 * pi * (1.0 - static_cast<double>(m) / static_cast<double>(w_));
      const double d[3] = {std::cos(theta_e + theta_a) * std::cos(phi), std::sin(theta_e + theta_a) * std::cos(phi), std::sin(phi)};
      const double o[3] = {b[3] * std::cos(theta_e) - n * d[0], b[3] * std::sin(theta_e) - n * d[1], b[11] - n * d[2]};
      const std::size_t k = 3 * (static_cast<std::size_t>(r) * static_cast<std::size_t>(w_) + static_cast<std::size_t>(m));
      for (int i = 0; i < 3; ++i) {
        const auto ii = static_cast<std::size_t>(i) * 4;
        dir_[k + static_cast<std::size_t>(i)] = (t[ii] * d[0] + t[ii + 1] * d[1] + t[ii + 2] * d[2]) * 1e-3;  // per mm of range, in m
        off_[k + static_cast<std::size_t>(i)] = (t[ii] * o[0] + t[ii + 1] * o[1] + t[ii + 2] * o[2] + t[ii + 3]) * 1e-3;
      }
    }
  }
}

void XyzLut::cartesian(const LidarFrame& f, float* xyz) const noexcept {
  const std::size_t n = static_cast<std::size_t>(w_) * static_cast<std::size_t>(h_);
  const bool same = f.width == w_ && f.height == h_;
  for (std::size_t k = 0; k < n; ++k) {
    const std::uint32_t r = same ? f.range_mm[k] : 0;
    for (std::size_t i = 0; i < 3; ++i) {
      xyz[3 * k + i] = r == 0 ? std::numeric_limits<float>::quiet_NaN()
                              : static_cast<float>(static_cast<double>(r) * dir_[3 * k + i] + off_[3 * k + i]);
    }
  }
}

}  // namespace ag::ouster
