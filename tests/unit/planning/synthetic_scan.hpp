// Synthetic 32-beam LiDAR scans of flat ground with boxes, for the local tracker's tests.
#pragma once

#include <algorithm>
#include <cmath>
#include <vector>

#include "airground/messages/messages.hpp"
#include "airground/messages/pose_math.hpp"

namespace ag::plan::test {

struct Box {
  double x0, x1, y0, y1, h;  // body frame [m], from the ground up
};

// A `beams`-beam scan (-22.5..22.5 deg, 1 deg azimuth; 32 beams unless asked) from a sensor `hs` above
// flat ground, tilted by (roll, pitch) relative to the ground: points in the sensor frame. Ground inside
// a `water` box (x0..x1, y0..y1 of the level frame) gives no return, as a pond does not.
inline std::vector<ScanReturn> scan(const std::vector<Box>& boxes, double hs = 0.6, double roll = 0.0, double pitch = 0.0, int az_step_deg = 1,
                                    int beams = 32, const std::vector<Box>& water = {}) {
  const Eigen::Matrix3d r = rotation_matrix(roll, pitch, 0.0);  // sensor -> level
  std::vector<ScanReturn> out;
  for (int b = 0; b < beams; ++b) {
    const double el = (-22.5 + 45.0 * b / (beams - 1)) * kPi / 180.0;
    for (int a = 0; a < 360; a += az_step_deg) {
      const double az = a * kPi / 180.0;
      const Eigen::Vector3d ds(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el));
      const Eigen::Vector3d d = r * ds;  // level frame, sensor at (0, 0, hs) above the ground at z = 0
      double t = d.z() < -1e-6 ? -hs / d.z() : 1e9;
      for (const Box& bx : boxes) {  // slab test
        double t0 = 0, t1 = 1e9;
        const double lo[3] = {bx.x0, bx.y0, 0.0}, hi[3] = {bx.x1, bx.y1, bx.h}, o[3] = {0, 0, hs};
        bool hit = true;
        for (int k = 0; k < 3 && hit; ++k) {
          if (std::fabs(d[k]) < 1e-12) {
            if (o[k] < lo[k] || o[k] > hi[k]) hit = false;
            continue;
          }
          double ta = (lo[k] - o[k]) / d[k], tb = (hi[k] - o[k]) / d[k];
          if (ta > tb) std::swap(ta, tb);
          t0 = std::max(t0, ta);
          t1 = std::min(t1, tb);
          if (t0 > t1) hit = false;
        }
        if (hit && t0 < t) t = t0;
      }
      if (t > 30.0) continue;
      const Eigen::Vector3d lv = d * t;  // level frame, from the sensor
      bool wet = false;
      for (const Box& wb : water) wet = wet || (lv.z() < -hs + 1e-6 && lv.x() >= wb.x0 && lv.x() <= wb.x1 && lv.y() >= wb.y0 && lv.y() <= wb.y1);
      if (wet) continue;
      const Eigen::Vector3d p = ds * t;
      ScanReturn s;
      s.x = static_cast<float>(p.x());
      s.y = static_cast<float>(p.y());
      s.z = static_cast<float>(p.z());
      s.range = static_cast<float>(t);
      out.push_back(s);
    }
  }
  return out;
}

}  // namespace ag::plan::test
