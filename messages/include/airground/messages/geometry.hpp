// Poses and grid geometry in the shared map frame (local ENU, metres, radians).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

namespace ag {

inline constexpr double kPi = 3.14159265358979323846;

[[nodiscard]] inline double wrap_angle(double a) noexcept {  // to (-pi, pi]
  a = std::fmod(a + kPi, 2.0 * kPi);
  if (a < 0) a += 2.0 * kPi;
  return a - kPi;
}

// A planar pose: position [m] in the map frame (x east, y north) and yaw [rad] from east, CCW.
struct Pose2 {
  double x{0}, y{0}, yaw{0};
};

// A 6-DoF pose: position [m] and roll/pitch/yaw [rad] (REP-103 body frame: x forward, y left, z up;
// R = Rz(yaw) * Ry(pitch) * Rx(roll)).
struct Pose3 {
  double x{0}, y{0}, z{0};
  double roll{0}, pitch{0}, yaw{0};
};

// A north-up raster over the map frame: cell (col, row), row 0 at the north edge (image order, as in
// GeoTIFF). origin_x is the west edge, origin_y the north edge [m].
struct GridGeometry {
  double resolution{0.5};  // [m/cell]
  std::int32_t width{0};   // cells (x)
  std::int32_t height{0};  // cells (y)
  double origin_x{0};      // [m] west edge
  double origin_y{0};      // [m] north edge

  [[nodiscard]] double size_x() const noexcept { return width * resolution; }
  [[nodiscard]] double size_y() const noexcept { return height * resolution; }
  [[nodiscard]] double col_f(double x) const noexcept { return (x - origin_x) / resolution; }
  [[nodiscard]] double row_f(double y) const noexcept { return (origin_y - y) / resolution; }
  [[nodiscard]] std::int32_t col(double x) const noexcept { return static_cast<std::int32_t>(std::floor(col_f(x))); }
  [[nodiscard]] std::int32_t row(double y) const noexcept { return static_cast<std::int32_t>(std::floor(row_f(y))); }
  [[nodiscard]] double x_of(double col_centre) const noexcept { return origin_x + (col_centre + 0.5) * resolution; }
  [[nodiscard]] double y_of(double row_centre) const noexcept { return origin_y - (row_centre + 0.5) * resolution; }
  [[nodiscard]] bool contains(std::int32_t c, std::int32_t r) const noexcept { return c >= 0 && r >= 0 && c < width && r < height; }
};

// A map-frame rectangle [m]: a mission area, a geofence. The default is the whole plane.
struct MapRect {
  double x0{-std::numeric_limits<double>::infinity()}, y0{-std::numeric_limits<double>::infinity()};
  double x1{std::numeric_limits<double>::infinity()}, y1{std::numeric_limits<double>::infinity()};
  [[nodiscard]] bool contains(double x, double y) const noexcept { return x >= x0 && x <= x1 && y >= y0 && y <= y1; }
};

// Aerial-map tiles [tile_x0, tile_x0 + tiles_x) x [tile_y0, tile_y0 + tiles_y); tile (0, 0) starts at
// the map-frame origin.
struct TileExtent {
  std::int32_t tile_x0{0}, tile_y0{0};
  std::int32_t tiles_x{0}, tiles_y{0};
};

// The fewest tiles of tile_cells x tile_cells cells of resolution_m [m] that cover the rectangle r.
[[nodiscard]] inline TileExtent tiles_covering(const MapRect& r, double resolution_m, int tile_cells) noexcept {
  const double tile_m = resolution_m * tile_cells;
  const auto tile = [tile_m](double v) { return static_cast<std::int32_t>(std::floor(v / tile_m)); };
  TileExtent e;
  e.tile_x0 = tile(std::min(r.x0, r.x1));
  e.tile_y0 = tile(std::min(r.y0, r.y1));
  e.tiles_x = tile(std::max(r.x0, r.x1)) - e.tile_x0 + 1;
  e.tiles_y = tile(std::max(r.y0, r.y1)) - e.tile_y0 + 1;
  return e;
}

}  // namespace ag
