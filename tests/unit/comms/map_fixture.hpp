// A synthetic aerial map like the ortho-mapper's: roads, buildings, trees, vehicles, grass; elevation
// from a rolling terrain plus object heights, quantised to 1 cm with ±3 cm stereo noise; NaN/unknown
// outside the mapped area. Deterministic.
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>

#include "airground/messages/messages.hpp"

namespace ag::comms::test {

inline std::uint64_t cell_hash(std::int64_t x, std::int64_t y, std::uint64_t salt) {
  std::uint64_t h = static_cast<std::uint64_t>(x) * 0x9E3779B97F4A7C15ULL ^ static_cast<std::uint64_t>(y) * 0xC2B2AE3D27D4EB4FULL ^ salt;
  h ^= h >> 31;
  h *= 0xbf58476d1ce4e5b9ULL;
  h ^= h >> 29;
  return h;
}

// Fills tile (tx, ty) of a map that covers [0, size_m)^2 of the map frame.
inline void make_tile(MapTileMsg& t, std::int32_t tx, std::int32_t ty, double size_m, std::uint64_t version) {
  t.tx = tx;
  t.ty = ty;
  t.version = version;
  t.stamp = static_cast<TimeNs>(version) * kNsPerS;
  for (int r = 0; r < kTileCells; ++r)
    for (int c = 0; c < kTileCells; ++c) {
      const std::size_t i = static_cast<std::size_t>(r) * kTileCells + static_cast<std::size_t>(c);
      const double x = (tx * kTileCells + c + 0.5) * kMapResolutionM, y = (ty * kTileCells + r + 0.5) * kMapResolutionM;
      if (x < 0 || y < 0 || x >= size_m || y >= size_m) {
        t.cls[i] = 255;
        t.elevation[i] = std::numeric_limits<float>::quiet_NaN();
        continue;
      }
      const double ground = 3.0 * std::sin(x / 90.0) + 2.0 * std::cos(y / 70.0);
      const auto bx = static_cast<std::int64_t>(x / 40.0), by = static_cast<std::int64_t>(y / 40.0);
      const double lx = std::fmod(x, 40.0), ly = std::fmod(y, 40.0);
      std::uint8_t cls = 2;  // grass
      double h = 0;
      if (lx < 6.0 || ly < 6.0) {
        cls = 0;  // road grid every 40 m
        if (cell_hash(bx, by, 1) % 7 == 0 && lx < 6 && ly > 12 && ly < 17 && lx > 1 && lx < 3) { cls = 5; h = 1.5; }
      } else {
        const std::uint64_t kind = cell_hash(bx, by, 2) % 4;
        if (kind == 0 && lx > 12 && lx < 32 && ly > 10 && ly < 30) { cls = 4; h = 6.0 + static_cast<double>(cell_hash(bx, by, 3) % 8); }
        else if (kind == 1) {
          const double dx = lx - 22, dy = ly - 22;
          if (dx * dx + dy * dy < 100) { cls = 3; h = 8.0 - 0.05 * (dx * dx + dy * dy); }
        } else if (kind == 2 && lx > 8) cls = 1;  // dirt
      }
      t.cls[i] = cls;
      const double noise = (static_cast<double>(cell_hash(static_cast<std::int64_t>(x * 2), static_cast<std::int64_t>(y * 2), version) % 7) - 3.0) * 0.01;
      t.elevation[i] = static_cast<float>(std::round((ground + h) * 100.0) / 100.0 + noise);
    }
}

}  // namespace ag::comms::test
