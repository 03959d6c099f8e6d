// A calibrated pinhole camera with OpenCV's k1, k2, p1, p2, k3 distortion, and the quadrotor's nadir mount.
// Pixel centres are at integer coordinates (OpenCV convention).
#pragma once

#include <Eigen/Core>

namespace ag {

struct PinholeCamera {
  int width{640}, height{400};                      // [px]
  double fx{483.5}, fy{483.5}, cx{319.5}, cy{199.5};  // [px]
  double k1{0}, k2{0}, p1{0}, p2{0}, k3{0};          // [-]

  // The same lens on the sensor resampled by `factor` (0.5: 1280x800 -> 640x400).
  [[nodiscard]] PinholeCamera scaled(double factor) const noexcept {
    PinholeCamera c = *this;
    c.width = static_cast<int>(width * factor + 0.5);
    c.height = static_cast<int>(height * factor + 0.5);
    c.fx = fx * factor;
    c.fy = fy * factor;
    c.cx = (cx + 0.5) * factor - 0.5;
    c.cy = (cy + 0.5) * factor - 0.5;
    return c;
  }

  // Normalised undistorted (x/z, y/z) -> distorted pixel.
  [[nodiscard]] Eigen::Vector2d distort_to_pixel(double x, double y) const noexcept {
    const double r2 = x * x + y * y;
    const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
    const double xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
    const double yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
    return {fx * xd + cx, fy * yd + cy};
  }

  // Distorted pixel -> normalised undistorted (x/z, y/z), by fixed-point iteration as OpenCV's
  // undistortPoints does; converges for the mild lenses of mapping cameras.
  [[nodiscard]] Eigen::Vector2d undistort_pixel(double u, double v) const noexcept {
    const double xd = (u - cx) / fx, yd = (v - cy) / fy;
    double x = xd, y = yd;
    for (int i = 0; i < 20; ++i) {
      const double r2 = x * x + y * y;
      const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
      const double dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
      const double dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
      x = (xd - dx) / radial;
      y = (yd - dy) / radial;
    }
    return {x, y};
  }
};

// The quadrotor's nadir camera: image right = body right, image down = body backward, optical axis =
// body down. Columns are the camera's x, y, z axes in body (REP-103) coordinates.
[[nodiscard]] inline Eigen::Matrix3d nadir_body_from_camera() noexcept {
  Eigen::Matrix3d m;
  m << 0, -1, 0,  //
      -1, 0, 0,   //
      0, 0, -1;
  return m;
}

}  // namespace ag
