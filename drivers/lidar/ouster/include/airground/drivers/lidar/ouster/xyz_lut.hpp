// The XYZ lookup table of the Ouster manual ("Lidar Range to XYZ"): for beam i at measurement id m,
//   theta_e = 2 pi (1 - m / W), theta_a = -2 pi az_i / 360, phi = 2 pi alt_i / 360,
//   n = |beam_to_lidar translation| (lidar_origin_to_beam_origin_mm on OS-1),
//   x = (r - n) cos(theta_e + theta_a) cos(phi) + n cos(theta_e), y likewise with sin, z = (r - n) sin(phi)
// (+ the beam origin's z from beam_to_lidar), then lidar_to_sensor applied. Stored as point = r * dir + offset
// so a frame converts with one multiply-add per coordinate. Output in metres in the sensor frame.
#pragma once

#include <vector>

#include "airground/drivers/lidar/ouster/frame.hpp"

namespace ag::ouster {

class XyzLut {
 public:
  explicit XyzLut(const SensorInfo& info);
  // xyz: 3 * width * height floats (x, y, z per pixel, row-major like the frame), NaN where range is 0.
  void cartesian(const LidarFrame& f, float* xyz) const noexcept;
  [[nodiscard]] int width() const noexcept { return w_; }
  [[nodiscard]] int height() const noexcept { return h_; }

 private:
  int w_, h_;
  std::vector<double> dir_, off_;  // 3 per pixel; dir unitless, offset in m
};

}  // namespace ag::ouster
