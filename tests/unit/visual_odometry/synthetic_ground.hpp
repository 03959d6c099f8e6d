// A textured flat ground seen by the quadrotor's nadir pinhole camera, without the simulator: value noise
// in three octaves, ray-cast per pixel. Enough texture for corners and flow, so the VO tests that do not
// need the simulator also run in the aarch64 cross build.
#pragma once

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "airground/messages/camera.hpp"

namespace ag::vo::test {

inline float lattice(std::int64_t x, std::int64_t y, std::uint64_t salt) {
  std::uint64_t h = static_cast<std::uint64_t>(x) * 0x9E3779B97F4A7C15ULL ^ (static_cast<std::uint64_t>(y) + salt) * 0xC2B2AE3D27D4EB4FULL;
  h ^= h >> 29;
  h *= 0xBF58476D1CE4E5B9ULL;
  h ^= h >> 32;
  return static_cast<float>(h & 0xFFFF) / 65535.0F;
}

// Bilinear value noise of cell size `cell` [m].
inline float value_noise(double x, double y, double cell, std::uint64_t salt) {
  const double u = x / cell, v = y / cell;
  const double fu = std::floor(u), fv = std::floor(v);
  const auto ix = static_cast<std::int64_t>(fu), iy = static_cast<std::int64_t>(fv);
  const auto a = static_cast<float>(u - fu), b = static_cast<float>(v - fv);
  const float l00 = lattice(ix, iy, salt), l10 = lattice(ix + 1, iy, salt), l01 = lattice(ix, iy + 1, salt), l11 = lattice(ix + 1, iy + 1, salt);
  return (1 - b) * ((1 - a) * l00 + a * l10) + b * ((1 - a) * l01 + a * l11);
}

inline std::uint8_t ground_grey(double x, double y) {
  const float v = 0.5F * value_noise(x, y, 3.0, 1) + 0.3F * value_noise(x, y, 1.1, 2) + 0.2F * value_noise(x, y, 0.45, 3);
  return static_cast<std::uint8_t>(std::lround(std::clamp(40.0F + 180.0F * v, 0.0F, 255.0F)));
}

// Renders RGB (grey in all three channels) of the ground z = 0 seen from body position `c` (ENU) with
// attitude R_wb (body FLU in ENU), through `cam` (no distortion assumed).
inline void render_ground(const PinholeCamera& cam, const Eigen::Vector3d& c, const Eigen::Matrix3d& R_wb, std::uint8_t* rgb) {
  const Eigen::Matrix3d R_wc = R_wb * nadir_body_from_camera();
  for (int v = 0; v < cam.height; ++v)
    for (int u = 0; u < cam.width; ++u) {
      const Eigen::Vector3d ray = R_wc * Eigen::Vector3d((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0);
      std::uint8_t g = 0;
      if (ray.z() < -1e-6) {
        const double s = -c.z() / ray.z();
        g = ground_grey(c.x() + s * ray.x(), c.y() + s * ray.y());
      }
      const std::size_t i = 3 * (static_cast<std::size_t>(v) * static_cast<std::size_t>(cam.width) + static_cast<std::size_t>(u));
      rgb[i] = rgb[i + 1] = rgb[i + 2] = g;
    }
}

inline Eigen::Matrix3d attitude(double roll, double pitch, double yaw) {
  return (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

}  // namespace ag::vo::test
