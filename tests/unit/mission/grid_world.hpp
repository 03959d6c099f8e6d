// Synthetic class grids for the mission tests: a W x H tile area, cells painted with rectangles in metres.
#pragma once

#include <cstdint>
#include <vector>

#include "airground/messages/classes.hpp"
#include "airground/mission/regions.hpp"

namespace ag::mission::test {

struct GridWorld {
  int tiles_x{4}, tiles_y{4};
  static constexpr int kT = 64;
  static constexpr double kRes = 0.5;
  std::vector<std::uint8_t> cls;  // row-major over the whole area, row 0 south

  GridWorld(int tx, int ty, ClassId background) : tiles_x(tx), tiles_y(ty), cls(static_cast<std::size_t>(tx * kT) * static_cast<std::size_t>(ty * kT), raw(background)) {}
  [[nodiscard]] int w() const { return tiles_x * kT; }
  [[nodiscard]] int h() const { return tiles_y * kT; }
  // Paints [x0, x1) x [y0, y1) metres (cells whose centre falls inside).
  void rect(double x0, double y0, double x1, double y1, ClassId c) {
    for (int r = 0; r < h(); ++r)
      for (int col = 0; col < w(); ++col) {
        const double x = (col + 0.5) * kRes, y = (r + 0.5) * kRes;
        if (x >= x0 && x < x1 && y >= y0 && y < y1) cls[static_cast<std::size_t>(r * w() + col)] = raw(c);
      }
  }
  // A car: 4.5 m x 2 m, its south-west corner at (x, y).
  void car(double x, double y) { rect(x, y, x + 4.5, y + 2.0, ClassId::kVehicle); }
  [[nodiscard]] std::vector<std::uint8_t> tile(int tx, int ty) const {
    std::vector<std::uint8_t> t(static_cast<std::size_t>(kT * kT));
    for (int r = 0; r < kT; ++r)
      for (int c = 0; c < kT; ++c) t[static_cast<std::size_t>(r * kT + c)] = cls[static_cast<std::size_t>((ty * kT + r) * w() + tx * kT + c)];
    return t;
  }
  [[nodiscard]] TileExtent extent() const { return TileExtent{0, 0, tiles_x, tiles_y}; }
  void load(RegionExtractor& ex, std::uint64_t version, int max_tx = 1 << 20) const {
    for (int ty = 0; ty < tiles_y; ++ty)
      for (int tx = 0; tx < tiles_x && tx < max_tx; ++tx) ex.set_tile(tx, ty, version, tile(tx, ty));
  }
};

}  // namespace ag::mission::test
