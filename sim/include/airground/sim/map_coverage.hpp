// How much of a robot's surroundings a map knows, counted over the mission area only: the runner holds a
// ground robot at its start until the quadrotor's map knows enough of them (RunOptions::ugv_wait_map_*).
#pragma once

#include <cstdint>

#include "airground/messages/geometry.hpp"

namespace ag::sim {

// The share of the cells of `resolution` within `radius` of (x, y) whose centre lies inside `area` (the
// mission area: what the quadrotor can ever map) that `known(cx, cy)` says have a class. Ground outside
// the area never counts, so a robot started near its edge is not held for cells nobody will map. 1 when
// no cell of the disc lies inside.
template <class Known>
double known_fraction(Known&& known, double x, double y, double radius, double resolution, const GridGeometry& area) {
  const double x0 = area.origin_x, x1 = area.origin_x + area.size_x(), y0 = area.origin_y - area.size_y(), y1 = area.origin_y;
  std::uint64_t hit = 0, total = 0;
  for (double dy = -radius; dy <= radius; dy += resolution)
    for (double dx = -radius; dx <= radius; dx += resolution) {
      if (dx * dx + dy * dy > radius * radius) continue;
      const double cx = x + dx, cy = y + dy;
      if (cx < x0 || cx >= x1 || cy < y0 || cy >= y1) continue;
      ++total;
      if (known(cx, cy)) ++hit;
    }
  return total == 0 ? 1.0 : static_cast<double>(hit) / static_cast<double>(total);
}

}  // namespace ag::sim
