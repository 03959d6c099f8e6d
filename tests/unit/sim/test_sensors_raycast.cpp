// HeightfieldRaycaster: exact hits on walls and tops, world bounds, and agreement with brute-force marching.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "airground/sim/raycast.hpp"
#include "test_sensors_world.hpp"

namespace ag::sim {
namespace {

using testing::fill_cells;
using testing::flat_world;

// A rough town: undulating terrain with per-cell jitter, buildings, trees, cars and curbs.
World random_town(std::uint32_t seed) {
  World w = flat_world(300, 230, 0.25, -20.0, 40.0, ClassId::kGrass);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> jitter(-0.02f, 0.02f);
  const GridGeometry& g = w.grid();
  for (std::int32_t r = 0; r < g.height; ++r)
    for (std::int32_t c = 0; c < g.width; ++c)
      w.terrain.at<float>(r, c) = static_cast<float>(1.5 * std::sin(g.x_of(c) / 7.0) + 0.8 * std::cos(g.y_of(r) / 5.0)) +
                                  jitter(rng);
  const auto uni = [&](int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(rng); };
  const auto unf = [&](double lo, double hi) { return static_cast<float>(std::uniform_real_distribution<double>(lo, hi)(rng)); };
  for (int i = 0; i < 25; ++i) {
    const int c = uni(0, g.width - 1), r = uni(0, g.height - 1);
    fill_cells(w, c, r, c + uni(8, 40), r + uni(8, 40), ClassId::kBuilding, unf(4, 30), {90, 90, 100});
  }
  for (int i = 0; i < 80; ++i) {
    const int c = uni(0, g.width - 1), r = uni(0, g.height - 1), s = uni(3, 8);
    for (int dr = 0; dr < s; ++dr)
      for (int dc = 0; dc < s; ++dc) fill_cells(w, c + dc, r + dr, c + dc + 1, r + dr + 1, ClassId::kTree, unf(3, 12), {20, 100, 30});
  }
  for (int i = 0; i < 60; ++i) {
    const int c = uni(0, g.width - 1), r = uni(0, g.height - 1);
    fill_cells(w, c, r, c + 6, r + 10, ClassId::kVehicle, 1.5f, {230, 40, 40});
  }
  for (int i = 0; i < 6; ++i) {
    const int r = uni(0, g.height - 1);
    fill_cells(w, 0, r, g.width, r + 1, ClassId::kRoad, 0.15f, {128, 64, 128});
  }
  return w;
}

struct RefHit {
  bool hit{false};
  double range{0};
  std::int32_t col{-1}, row{-1};
};

// Brute force: march in fixed small steps, then bisect the first step that ends inside a column.
RefHit march(const World& w, float zmax, const Eigen::Vector3d& o, const Eigen::Vector3d& d, double max_range,
             double step) {
  const GridGeometry& g = w.grid();
  const auto inside = [&](double t, std::int32_t& c, std::int32_t& r) {
    const Eigen::Vector3d p = o + t * d;
    c = g.col(p.x());
    r = g.row(p.y());
    return g.contains(c, r) && p.z() <= static_cast<double>(w.surface_at(c, r));
  };
  RefHit out;
  std::int32_t c = 0, r = 0;
  if (inside(0.0, c, r)) return RefHit{true, 0.0, c, r};
  double prev = 0.0;
  for (double t = step;; t += step) {
    const double tt = std::min(t, max_range);
    if (inside(tt, c, r)) {
      double lo = prev, hi = tt;
      for (int i = 0; i < 80; ++i) {
        const double mid = 0.5 * (lo + hi);
        std::int32_t mc = 0, mr = 0;
        (inside(mid, mc, mr) ? hi : lo) = mid;
      }
      inside(hi, c, r);
      return RefHit{true, hi, c, r};
    }
    if (tt >= max_range) return out;
    if (d.z() >= 0.0 && o.z() + tt * d.z() > static_cast<double>(zmax)) return out;
    prev = tt;
  }
}

// Exact entry/exit of the ray into one column [t_in, t_out] within [0, max_range]; t_in > t_out if none.
std::pair<double, double> column_interval(const World& w, std::int32_t c, std::int32_t r, const Eigen::Vector3d& o,
                                          const Eigen::Vector3d& d, double max_range) {
  const GridGeometry& g = w.grid();
  double t_in = 0.0, t_out = max_range;
  const auto slab = [&](double p, double dp, double lo, double hi) {
    if (dp == 0.0) {
      if (p < lo || p > hi) t_in = 1.0, t_out = 0.0;
      return;
    }
    double a = (lo - p) / dp, b = (hi - p) / dp;
    if (a > b) std::swap(a, b);
    t_in = std::max(t_in, a);
    t_out = std::min(t_out, b);
  };
  slab(o.x(), d.x(), g.origin_x + c * g.resolution, g.origin_x + (c + 1) * g.resolution);
  slab(o.y(), d.y(), g.origin_y - (r + 1) * g.resolution, g.origin_y - r * g.resolution);
  const double s = static_cast<double>(w.surface_at(c, r));
  if (d.z() > 0.0) t_out = std::min(t_out, (s - o.z()) / d.z());
  if (d.z() < 0.0) t_in = std::max(t_in, (s - o.z()) / d.z());
  if (d.z() == 0.0 && o.z() > s) t_in = 1.0, t_out = 0.0;
  return {t_in, t_out};
}

// Exact first hit over every column of the world, with the length of the ray inside that column.
struct Exact {
  bool hit{false};
  double range{std::numeric_limits<double>::infinity()};
  double chord{0};
};
Exact exact_first_hit(const World& w, const Eigen::Vector3d& o, const Eigen::Vector3d& d, double max_range) {
  Exact e;
  for (std::int32_t r = 0; r < w.grid().height; ++r) {
    for (std::int32_t c = 0; c < w.grid().width; ++c) {
      const auto [a, b] = column_interval(w, c, r, o, d, max_range);
      if (a <= b && a < e.range) e = Exact{true, a, b - a};
    }
  }
  return e;
}

struct Ray {
  Eigen::Vector3d o, d;
  double max_range;
};

std::vector<Ray> random_rays(const World& w, std::uint32_t seed) {
  std::mt19937 rng(seed);
  const GridGeometry& g = w.grid();
  const auto unf = [&](double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng); };
  std::vector<Ray> rays;
  const double x0 = g.origin_x, x1 = g.origin_x + g.size_x(), y1 = g.origin_y, y0 = g.origin_y - g.size_y();
  for (int i = 0; i < 700; ++i) {  // LiDAR-like: just above the surface, near horizontal
    const double x = unf(x0, x1), y = unf(y0, y1);
    const double z = static_cast<double>(w.surface_at(g.col(x), g.row(y))) + unf(0.3, 2.0);
    const double el = unf(-0.35, 0.35), az = unf(0.0, 2.0 * kPi);
    rays.push_back({{x, y, z}, {std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el)}, 120.0});
  }
  for (int i = 0; i < 500; ++i) {  // camera-like: from 35-60 m within 45 deg of nadir
    const double off = unf(0.0, 0.785), az = unf(0.0, 2.0 * kPi);
    rays.push_back({{unf(x0 - 10, x1 + 10), unf(y0 - 10, y1 + 10), unf(35, 60)},
                    {std::sin(off) * std::cos(az), std::sin(off) * std::sin(az), -std::cos(off)},
                    500.0});
  }
  for (int i = 0; i < 500; ++i) {  // anything: origins around the world, uniform directions, random reach
    Eigen::Vector3d d(unf(-1, 1), unf(-1, 1), unf(-1, 1));
    if (d.norm() < 1e-3) continue;
    rays.push_back({{unf(x0 - 20, x1 + 20), unf(y0 - 20, y1 + 20), unf(-5, 60)}, d.normalized(), unf(1.0, 150.0)});
  }
  for (int i = 0; i < 200; ++i) {  // degenerate: along grid lines, axis-aligned, vertical, from cell corners
    const double x = g.origin_x + std::floor(unf(0, g.width)) * g.resolution;
    const double y = g.origin_y - std::floor(unf(0, g.height)) * g.resolution;
    const double z = unf(0, 40);
    const double el = unf(-0.5, 0.2);
    const int dir = i % 6;
    const double h = std::cos(el);
    const Eigen::Vector3d d = dir == 5   ? Eigen::Vector3d(0, 0, -1)
                              : dir == 0 ? Eigen::Vector3d(h, 0, std::sin(el))
                              : dir == 1 ? Eigen::Vector3d(-h, 0, std::sin(el))
                              : dir == 2 ? Eigen::Vector3d(0, h, std::sin(el))
                              : dir == 3 ? Eigen::Vector3d(0, -h, std::sin(el))
                                         : Eigen::Vector3d(h * std::sqrt(0.5), h * std::sqrt(0.5), std::sin(el));
    rays.push_back({{x, y, z}, d, 100.0});
  }
  return rays;
}

// The hit is geometrically a face of the reported column: on its top, or on one of its sides below the top.
void expect_on_face(const World& w, const RayHit& h) {
  const GridGeometry& g = w.grid();
  const double s = static_cast<double>(w.surface_at(h.col, h.row));
  if (h.range == 0.0) return;
  if (!h.vertical_face) {
    EXPECT_NEAR(h.point.z(), s, 1e-6);
    EXPECT_EQ(h.normal, Eigen::Vector3d::UnitZ());
    return;
  }
  EXPECT_LE(h.point.z(), s + 1e-9);
  const double u = (h.point.x() - g.origin_x) / g.resolution, v = (g.origin_y - h.point.y()) / g.resolution;
  if (h.normal.x() != 0.0) {
    EXPECT_NEAR(u, h.col + (h.normal.x() < 0 ? 0.0 : 1.0), 1e-6);
  } else {
    EXPECT_NEAR(v, h.row + (h.normal.y() > 0 ? 0.0 : 1.0), 1e-6);
  }
}

TEST(Raycast, AgreesWithBruteForceMarchingOnRandomRays) {
  const World w = random_town(7);
  const HeightfieldRaycaster fast(w);
  const HeightfieldRaycaster plain(w, RaycastOptions{false});
  const double step = 0.002;
  float zmax = -std::numeric_limits<float>::infinity();
  for (std::int32_t r = 0; r < w.grid().height; ++r)
    for (std::int32_t c = 0; c < w.grid().width; ++c) zmax = std::max(zmax, w.surface_at(c, r));
  int hits = 0, walls = 0, grazing = 0, ties = 0;
  const auto rays = random_rays(w, 11);
  for (std::size_t i = 0; i < rays.size(); ++i) {
    const Ray& ray = rays[i];
    const RayHit f = fast.cast(ray.o, ray.d, ray.max_range);
    const RayHit p = plain.cast(ray.o, ray.d, ray.max_range);
    const RefHit ref = march(w, zmax, ray.o, ray.d, ray.max_range, step);
    SCOPED_TRACE("ray " + std::to_string(i));
    // The pyramid only skips: it must give exactly what cell-by-cell traversal gives.
    ASSERT_EQ(f.hit, p.hit);
    if (f.hit) {
      EXPECT_NEAR(f.range, p.range, 1e-9);
      EXPECT_EQ(f.col, p.col);
      EXPECT_EQ(f.row, p.row);
      EXPECT_EQ(f.vertical_face, p.vertical_face);
      expect_on_face(w, f);
      ++hits;
      walls += f.vertical_face ? 1 : 0;
    }
    const bool same = f.hit == ref.hit && (!f.hit || (std::abs(f.range - ref.range) < 1e-6 && f.col == ref.col && f.row == ref.row));
    if (same) continue;
    // Disagreement: the exact column-by-column answer must side with the raycaster, and marching may only
    // have stepped over a sliver of a column shorter than its step, or picked another column at a corner.
    const Exact e = exact_first_hit(w, ray.o, ray.d, ray.max_range);
    ASSERT_EQ(f.hit, e.hit) << "ref hit " << ref.hit << " at " << ref.range;
    ASSERT_NEAR(f.range, e.range, 1e-7);
    const auto [a, b] = column_interval(w, f.col, f.row, ray.o, ray.d, ray.max_range);
    ASSERT_NEAR(a, f.range, 1e-7) << "the reported cell is not where the ray enters a column";
    if (ref.hit && std::abs(ref.range - f.range) < 1e-6) {
      ++ties;
    } else {
      ASSERT_LT(e.chord, step) << "marching missed a column it should have seen";
      ++grazing;
    }
  }
  RecordProperty("rays", static_cast<int>(rays.size()));
  std::printf("rays %zu, hits %d (walls %d), corner ties %d, slivers under the march step %d\n", rays.size(), hits, walls,
              ties, grazing);
  EXPECT_GT(hits, 900);
  EXPECT_GT(walls, 100);
  EXPECT_LT(grazing + ties, static_cast<int>(rays.size()) / 100);
}

// cast_from() promises the same hit once told a part of the ray that meets nothing; with `near` (plain
// cell stepping for a few cells, then blocks again from where it stopped) too, face and normal included.
TEST(Raycast, CastFromAFreeStartGivesTheSameHit) {
  const World w = random_town(7);
  const HeightfieldRaycaster rc(w);
  int hits = 0;
  for (const Ray& ray : random_rays(w, 12)) {
    const RayHit full = rc.cast(ray.o, ray.d, ray.max_range);
    const double free_until = full.hit ? full.range : ray.max_range;
    for (const double f : {0.0, 0.3, 0.9, 0.999}) {
      for (const bool near : {false, true}) {
        const RayHit h = rc.cast_from(ray.o, ray.d, ray.max_range, f * free_until, near);
        ASSERT_EQ(h.hit, full.hit);
        if (!h.hit) continue;
        EXPECT_NEAR(h.range, full.range, 1e-9);
        EXPECT_EQ(h.col, full.col);
        EXPECT_EQ(h.row, full.row);
        if (f > 0.0 && h.range > 0.0) {
          EXPECT_EQ(h.vertical_face, full.vertical_face);
          EXPECT_EQ(h.normal, full.normal);
        }
      }
    }
    hits += full.hit ? 1 : 0;
  }
  EXPECT_GT(hits, 900);
}

// A wall two cells thick across the whole world: columns [40, 60) are 10 m tall.
World wall_world() {
  World w = flat_world(120, 80, 0.25, 0.0, 20.0, ClassId::kRoad);
  fill_cells(w, 40, 0, 60, 80, ClassId::kBuilding, 10.0f, {90, 90, 100});
  return w;
}

TEST(Raycast, HitsWallsWithTheWallCellAndFaceNormal) {
  const World w = wall_world();
  const HeightfieldRaycaster rc(w);
  // From x = 5.125 (col 20) eastward at 1 m: the west face of col 40 at x = 10.
  RayHit h = rc.cast({5.125, 10.0, 1.0}, {1, 0, 0}, 100.0);
  ASSERT_TRUE(h.hit);
  EXPECT_NEAR(h.range, 10.0 - 5.125, 1e-12);
  EXPECT_EQ(h.col, 40);
  EXPECT_EQ(h.row, w.grid().row(10.0));
  EXPECT_TRUE(h.vertical_face);
  EXPECT_EQ(h.normal, Eigen::Vector3d(-1, 0, 0));
  EXPECT_EQ(w.class_at(h.col, h.row), ClassId::kBuilding);
  // From the east going west: the east face of col 59 at x = 15.
  h = rc.cast({25.0, 10.0, 3.0}, {-1, 0, 0}, 100.0);
  ASSERT_TRUE(h.hit);
  EXPECT_NEAR(h.range, 10.0, 1e-12);
  EXPECT_EQ(h.col, 59);
  EXPECT_EQ(h.normal, Eigen::Vector3d(1, 0, 0));
  // Slanted: at 45 degrees the ray covers 4.875 m horizontally before the wall, still below 10 m.
  const Eigen::Vector3d d = Eigen::Vector3d(1, 1, 0).normalized();
  h = rc.cast({5.125, 1.0, 1.0}, d, 100.0);
  ASSERT_TRUE(h.hit);
  EXPECT_NEAR(h.point.x(), 10.0, 1e-9);
  EXPECT_NEAR(h.range, 4.875 * std::sqrt(2.0), 1e-9);
  // Over the wall: the ray rising past 10 m before reaching it sees nothing and leaves the world.
  h = rc.cast({5.125, 10.0, 1.0}, Eigen::Vector3d(1, 0, 2).normalized(), 500.0);
  EXPECT_FALSE(h.hit);
  // Descending onto the roof: a top hit with an upward normal.
  h = rc.cast({12.0, 10.0, 30.0}, {0, 0, -1}, 100.0);
  ASSERT_TRUE(h.hit);
  EXPECT_NEAR(h.range, 20.0, 1e-12);
  EXPECT_FALSE(h.vertical_face);
  EXPECT_EQ(h.normal, Eigen::Vector3d::UnitZ());
}

TEST(Raycast, RowFacesAndDiagonalDescent) {
  World w = flat_world(100, 100, 0.5, -25.0, 25.0, ClassId::kGrass);
  fill_cells(w, 0, 40, 100, 50, ClassId::kBuilding, 8.0f, {90, 90, 100});  // a band y in (0, 5]
  const HeightfieldRaycaster rc(w);
  // From the north going south: the band's north face at y = 5, normal +y.
  RayHit h = rc.cast({0.3, 15.0, 2.0}, {0, -1, 0}, 100.0);
  ASSERT_TRUE(h.hit);
  EXPECT_NEAR(h.range, 10.0, 1e-12);
  EXPECT_EQ(h.row, 40);
  EXPECT_EQ(h.normal, Eigen::Vector3d(0, 1, 0));
  // From the south going north: the south face at y = 0, normal -y.
  h = rc.cast({0.3, -7.0, 2.0}, {0, 1, 0}, 100.0);
  ASSERT_TRUE(h.hit);
  EXPECT_NEAR(h.range, 7.0, 1e-12);
  EXPECT_EQ(h.row, 49);
  EXPECT_EQ(h.normal, Eigen::Vector3d(0, -1, 0));
  // Descending at 45 degrees from z = 4 over flat grass: meets the ground 4 m further.
  h = rc.cast({-20.0, 20.0, 4.0}, Eigen::Vector3d(1, 0, -1).normalized(), 100.0);
  ASSERT_TRUE(h.hit);
  EXPECT_NEAR(h.point.x(), -16.0, 1e-9);
  EXPECT_NEAR(h.point.z(), 0.0, 1e-9);
  EXPECT_EQ(w.class_at(h.col, h.row), ClassId::kGrass);
}

TEST(Raycast, WorldBoundsRangeLimitAndStartInside) {
  const World w = wall_world();
  const HeightfieldRaycaster rc(w);
  EXPECT_FALSE(rc.cast({2.0, 10.0, 1.0}, {-1, 0, 0}, 1000.0).hit);  // leaves the world westward over flat road
  EXPECT_FALSE(rc.cast({2.0, 10.0, 1.0}, {0, 0, 1}, 1000.0).hit);   // up
  EXPECT_FALSE(rc.cast({-5.0, 10.0, 1.0}, {-1, 0, 0}, 1000.0).hit); // outside, going away
  EXPECT_FALSE(rc.cast({2.0, 10.0, 1.0}, {0, 1, 0}, 1000.0).hit);   // along the road to the north edge
  // From outside the world, descending into it.
  RayHit h = rc.cast({-5.0, 10.0, 5.0}, Eigen::Vector3d(1, 0, -0.5).normalized(), 1000.0);
  ASSERT_TRUE(h.hit);
  EXPECT_NEAR(h.point.x(), 5.0, 1e-9);
  EXPECT_NEAR(h.point.z(), 0.0, 1e-9);
  // From outside at 5 m toward the wall's side edge of the world: the world's border column is a cliff.
  h = rc.cast({12.0, 25.0, 5.0}, {0, -1, 0}, 1000.0);
  ASSERT_TRUE(h.hit);
  EXPECT_NEAR(h.range, 5.0, 1e-12);
  EXPECT_TRUE(h.vertical_face);
  EXPECT_EQ(h.row, 0);
  // The range limit: the wall is 4.875 m away.
  EXPECT_FALSE(rc.cast({5.125, 10.0, 1.0}, {1, 0, 0}, 4.87).hit);
  EXPECT_TRUE(rc.cast({5.125, 10.0, 1.0}, {1, 0, 0}, 4.88).hit);
  // A ray starting inside a column hits at once.
  h = rc.cast({12.0, 10.0, 5.0}, {1, 0, 0}, 100.0);
  ASSERT_TRUE(h.hit);
  EXPECT_EQ(h.range, 0.0);
  EXPECT_EQ(h.col, 48);
}

TEST(Raycast, RejectsLayersThatDoNotMatchTheGrid) {
  World w = wall_world();
  w.height = cv::Mat(10, 10, CV_32FC1, cv::Scalar(0));
  EXPECT_THROW(HeightfieldRaycaster{w}, std::invalid_argument);
  World v = wall_world();
  v.terrain.at<float>(3, 3) = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW(HeightfieldRaycaster{v}, std::invalid_argument);
}

}  // namespace
}  // namespace ag::sim
