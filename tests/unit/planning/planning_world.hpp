// Helpers of the planning tests: a roadmap loaded from a synthetic world (the localization tests' seeded
// road grid with buildings, trees, parked vehicles and dirt yards) and random reachable start/goal pairs.
#pragma once

#include <cstdlib>
#include <memory>
#include <utility>
#include <vector>

#include "../localization/synthetic_world.hpp"
#include "airground/planning/grid_reference.hpp"
#include "airground/planning/roadmap.hpp"

namespace ag::plan::test {

using loc::test::SyntheticWorld;
using loc::test::TestRng;

inline TileExtent extent_of(const SyntheticWorld& w) { return TileExtent{0, 0, w.tiles_x(), w.tiles_y()}; }

inline std::unique_ptr<Roadmap> load_roadmap(const SyntheticWorld& w, RoadmapParams p = RoadmapParams{}) {
  if (const char* e = std::getenv("AG_PLAN_GAIN")) p.clearance_gain_m = std::atof(e);
  if (const char* e = std::getenv("AG_PLAN_SC")) p.shortcut_clearance_m = std::atof(e);
  auto rm = std::make_unique<Roadmap>(p, ClassTable::builtin(), extent_of(w));
  for (int ty = 0; ty < w.tiles_y(); ++ty)
    for (int tx = 0; tx < w.tiles_x(); ++tx) (void)rm->set_tile(tx, ty, 1, w.tile(tx, ty));
  rm->rebuild();
  return rm;
}

inline GridReference reference_of(const SyntheticWorld& w, const RoadmapParams& p = RoadmapParams{}) {
  return GridReference(w.cls, w.width, w.height, w.resolution, 0.0, 0.0, ClassTable::builtin(), p.max_level, p.min_clearance_m);
}

// Random pairs of cell centres that keep the clearance and are connected in the reference grid, at
// least min_dist_m apart.
inline std::vector<std::pair<Point2, Point2>> reachable_pairs(const SyntheticWorld& w, const GridReference& ref, int n, std::uint64_t seed,
                                                               double min_dist_m = 40.0) {
  const auto& comp = ref.components();
  TestRng rng(seed);
  std::vector<std::pair<Point2, Point2>> out;
  auto pick = [&]() {
    for (;;) {
      const int c = static_cast<int>(rng.uniform() * w.width), r = static_cast<int>(rng.uniform() * w.height);
      if (ref.keeps_clearance(c, r)) return std::pair<int, int>{c, r};
    }
  };
  int guard = 0;
  while (static_cast<int>(out.size()) < n && guard++ < 100000) {
    const auto [ac, ar] = pick();
    const auto [bc, br] = pick();
    if (comp[w.index(ac, ar)] != comp[w.index(bc, br)]) continue;
    const Point2 a{(ac + 0.5) * w.resolution, (ar + 0.5) * w.resolution}, b{(bc + 0.5) * w.resolution, (br + 0.5) * w.resolution};
    if (std::hypot(a.x - b.x, a.y - b.y) < min_dist_m) continue;
    out.emplace_back(a, b);
  }
  return out;
}

}  // namespace ag::plan::test
