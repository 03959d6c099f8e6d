// Aerial class distance fields: equal to a brute-force truncated Euclidean distance, an incremental tile
// update equals a full recompute, unknown cells stay unknown, and the memory of a 1 km^2 map.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <vector>

#include "airground/localization/class_distance_fields.hpp"
#include "synthetic_world.hpp"

namespace ag::loc {
namespace {

using test::SyntheticWorld;
using test::TestRng;

// Brute force: the quantised truncated distance from cell (c, r) to the nearest source of `channel`
// (unknown and outside cells are sources when unknown_is_source; of a surface channel, only the faces).
std::uint8_t brute_force(const SyntheticWorld& w, const std::vector<std::uint8_t>& cls, const LocalizationChannels& ch,
                         const DistanceFieldParams& p, int c, int r, int channel) {
  const int m = static_cast<int>(std::ceil(p.truncation_m / p.resolution_m - 1e-9));
  const bool surface = ((static_cast<unsigned>(ch.surface_channels()) >> static_cast<unsigned>(channel)) & 1U) != 0;
  auto member = [&](int cc, int rr) {
    const std::uint8_t k = w.inside(cc, rr) ? cls[w.index(cc, rr)] : std::uint8_t{255};
    return k == 255 ? p.unknown_is_source : ((static_cast<unsigned>(ch.map_sources(k)) >> static_cast<unsigned>(channel)) & 1U) != 0;
  };
  double best2 = 1e30;
  for (int dr = -m; dr <= m; ++dr)
    for (int dc = -m; dc <= m; ++dc) {
      const int cc = c + dc, rr = r + dr;
      const std::uint8_t k = w.inside(cc, rr) ? cls[w.index(cc, rr)] : std::uint8_t{255};
      bool src = member(cc, rr);
      // a surface channel: a known member with members on all four sides is inside, not a face
      if (src && surface && k != 255 && member(cc - 1, rr) && member(cc + 1, rr) && member(cc, rr - 1) && member(cc, rr + 1)) src = false;
      if (src) best2 = std::min(best2, static_cast<double>(dc * dc + dr * dr));
    }
  const double t = p.truncation_m / p.resolution_m;
  if (best2 > std::floor(t * t)) return 255;
  const double q = p.truncation_m / 255.0;
  return static_cast<std::uint8_t>(std::min(255.0, std::round(std::sqrt(best2) * p.resolution_m / q)));
}

SyntheticWorld random_blocks(int tiles, std::uint64_t seed, double unknown_share) {
  SyntheticWorld w = test::make_world(tiles, tiles, seed);
  TestRng rng(seed + 7);
  // Punch unknown holes (the quadrotor has not seen everything yet).
  const int holes = static_cast<int>(unknown_share * w.width * w.height / 400.0);
  for (int i = 0; i < holes; ++i) {
    const double x = rng.uniform(0, w.width * w.resolution), y = rng.uniform(0, w.height * w.resolution);
    w.fill_rect(x, y, x + rng.uniform(2, 15), y + rng.uniform(2, 15), ClassId::kUnknown, 0.0F);
  }
  return w;
}

void expect_equal_to_brute_force(const SyntheticWorld& w, const ClassDistanceFields& f, const LocalizationChannels& ch,
                                 const DistanceFieldParams& p, int stride_cells) {
  int checked = 0, nonzero = 0, truncated = 0;
  for (int r = 0; r < w.height; r += stride_cells)
    for (int c = (r * 7) % stride_cells; c < w.width; c += stride_cells)
      for (int k = 0; k < ch.count(); ++k) {
        const double x = (c + 0.5) * w.resolution, y = (r + 0.5) * w.resolution;
        const std::uint8_t want = brute_force(w, w.cls, ch, p, c, r, k);
        const std::uint8_t got = f.cells()[f.index_at(x, y) * static_cast<std::size_t>(f.stride()) + static_cast<std::size_t>(k)];
        ASSERT_EQ(got, want) << "cell " << c << "," << r << " channel " << k;
        ++checked;
        nonzero += want > 0 && want < 255 ? 1 : 0;
        truncated += want == 255 ? 1 : 0;
      }
  EXPECT_GT(checked, 1000);
  EXPECT_GT(nonzero, checked / 4) << "the test map must exercise real distances";
  if (!p.unknown_is_source) {
    EXPECT_GT(truncated, 0) << "and truncation";
  }
}

TEST(ClassDistanceFields, EqualsBruteForceTruncatedEuclideanDistance) {
  for (const bool unknown_source : {false, true}) {
    const SyntheticWorld w = random_blocks(4, 11, 0.1);
    DistanceFieldParams p;
    p.truncation_m = 12.0;  // 24 cells: brute force stays quick
    p.unknown_is_source = unknown_source;
    const LocalizationChannels ch = LocalizationChannels::per_class();
    ClassDistanceFields f(p, ch, w.extent());
    test::load_world(w, f);
    expect_equal_to_brute_force(w, f, ch, p, 3);
  }
}

TEST(ClassDistanceFields, ClassGroupsOfTheGeometricLabelling) {
  const SyntheticWorld w = random_blocks(3, 5, 0.05);
  DistanceFieldParams p;
  p.truncation_m = 10.0;
  p.unknown_is_source = false;
  for (const bool faces : {false, true}) {
    const LocalizationChannels ch = LocalizationChannels::two_class(1.0, 1.5, faces);
    ASSERT_EQ(ch.count(), faces ? 3 : 2);  // ground, obstacle regions, and their faces
    EXPECT_EQ(ch.surface_channels(), faces ? 4U : 0U);
    ClassDistanceFields f(p, ch, w.extent());
    test::load_world(w, f);
    expect_equal_to_brute_force(w, f, ch, p, 2);
    // On a road: ground. On a building: an obstacle region, and with faces its wall (the edge cells) and,
    // inside, the distance to the nearest wall.
    int inside = 0;
    for (int r = 1; r + 1 < w.height; r += 3)
      for (int c = 1; c + 1 < w.width; c += 3) {
        const std::uint8_t k = w.cls[w.index(c, r)];
        const double x = (c + 0.5) * w.resolution, y = (r + 0.5) * w.resolution;
        if (k == raw(ClassId::kRoad)) {
          EXPECT_EQ(f.distance_m(x, y, 0), 0.0);
        }
        if (k != raw(ClassId::kBuilding)) continue;
        const auto obstacle = [&](int cc, int rr) { return (ch.map_sources(w.cls[w.index(cc, rr)]) & 2U) != 0; };
        const bool face = !obstacle(c - 1, r) || !obstacle(c + 1, r) || !obstacle(c, r - 1) || !obstacle(c, r + 1);
        EXPECT_EQ(f.distance_m(x, y, 1), 0.0) << c << "," << r;
        if (!faces) continue;
        if (face) {
          EXPECT_EQ(f.distance_m(x, y, 2), 0.0) << c << "," << r;
        } else {
          EXPECT_GE(f.distance_m(x, y, 2), 0.45) << c << "," << r;
          ++inside;
        }
      }
    if (faces) {
      EXPECT_GT(inside, 50) << "the map must have building insides";
    }
  }
}

void incremental_updates_equal_a_full_recompute(const LocalizationChannels& ch);

TEST(ClassDistanceFields, IncrementalTileUpdatesEqualAFullRecompute) {
  // per class, and the geometric grouping with its obstacle faces (a tile's change moves faces in the
  // cells just beyond it)
  for (const LocalizationChannels& ch : {LocalizationChannels::per_class(), LocalizationChannels::two_class()})
    incremental_updates_equal_a_full_recompute(ch);
}

void incremental_updates_equal_a_full_recompute(const LocalizationChannels& ch) {
  SyntheticWorld w = random_blocks(6, 21, 0.05);
  DistanceFieldParams p;
  p.truncation_m = 25.0;
  ClassDistanceFields inc(p, ch, w.extent());
  test::load_world(w, inc);
  TestRng rng(99);
  std::uint64_t version = 2;
  for (int round = 0; round < 12; ++round) {
    // change a few tiles (new buildings, newly seen ground, cells becoming unknown again)
    const int changes = 1 + round % 3;
    for (int k = 0; k < changes; ++k) {
      const int tx = static_cast<int>(rng.uniform() * w.tiles_x()), ty = static_cast<int>(rng.uniform() * w.tiles_y());
      const double x0 = tx * 32.0, y0 = ty * 32.0;
      const double bx = x0 + rng.uniform(0, 24), by = y0 + rng.uniform(0, 24);
      const auto id = static_cast<ClassId>(static_cast<int>(rng.uniform() * 6.0));
      w.fill_rect(bx, by, std::min(bx + rng.uniform(2, 10), x0 + 32.0), std::min(by + rng.uniform(2, 10), y0 + 32.0),
                  round % 4 == 3 ? ClassId::kUnknown : id, 0.0F);
      const std::vector<std::uint8_t> t = w.tile(tx, ty);
      EXPECT_TRUE(inc.set_tile(tx, ty, version++, t));
    }
    EXPECT_GT(inc.pending_tiles(), 0U);
    inc.update();
    EXPECT_EQ(inc.pending_tiles(), 0U);
    ClassDistanceFields full(p, ch, w.extent());
    test::load_world(w, full);
    const std::size_t bytes = (inc.outside_index() + 1) * static_cast<std::size_t>(inc.stride());
    ASSERT_EQ(0, std::memcmp(inc.cells(), full.cells(), bytes)) << "round " << round;
  }
}

TEST(ClassDistanceFields, NeighbouringChangedTilesGoTogetherWithinTheBudgetAndEqualAFullRecompute) {
  SyntheticWorld w = random_blocks(10, 31, 0.05);
  DistanceFieldParams p;  // 64-cell tiles, 25 m truncation, groups within 4 x 4 tiles
  const LocalizationChannels ch = LocalizationChannels::per_class();
  ClassDistanceFields inc(p, ch, w.extent());
  test::load_world(w, inc);
  std::uint64_t version = 2;
  const auto change = [&](int tx, int ty, ClassId id) {
    w.fill_rect(tx * 32.0 + 4, ty * 32.0 + 4, tx * 32.0 + 14, ty * 32.0 + 12, id, 4.0F);
    ASSERT_TRUE(inc.set_tile(tx, ty, version++, w.tile(tx, ty)));
  };
  // A 2 x 2 square of tiles (as a survey line and its neighbour change), then two far apart.
  change(2, 2, ClassId::kBuilding);
  change(3, 2, ClassId::kRoad);
  change(8, 8, ClassId::kWater);
  change(2, 3, ClassId::kGrass);
  change(3, 3, ClassId::kBuilding);
  change(0, 9, ClassId::kRoad);
  ASSERT_EQ(inc.pending_tiles(), 6U);
  // The work of two lone tiles does the whole square: one pass shares the four tiles' margins.
  EXPECT_EQ(inc.update(2), 4U);
  EXPECT_EQ(inc.pending_tiles(), 2U);
  // The far ones are not grouped (a rectangle spanning them costs more than two passes): one each.
  EXPECT_EQ(inc.update(1), 1U);
  EXPECT_EQ(inc.update(1), 1U);
  EXPECT_EQ(inc.pending_tiles(), 0U);
  ClassDistanceFields full(p, ch, w.extent());
  test::load_world(w, full);
  const std::size_t bytes = (inc.outside_index() + 1) * static_cast<std::size_t>(inc.stride());
  ASSERT_EQ(0, std::memcmp(inc.cells(), full.cells(), bytes));

  // Many tiles at once, folded in with small budgets: the same fields again.
  TestRng rng(4);
  for (int k = 0; k < 30; ++k)
    change(static_cast<int>(rng.uniform() * 10), static_cast<int>(rng.uniform() * 10), static_cast<ClassId>(static_cast<int>(rng.uniform() * 6.0)));
  while (inc.pending_tiles() > 0) {
    const std::size_t before = inc.pending_tiles();
    EXPECT_GE(inc.update(3), 1U);
    EXPECT_LT(inc.pending_tiles(), before);
  }
  ClassDistanceFields full2(p, ch, w.extent());
  test::load_world(w, full2);
  ASSERT_EQ(0, std::memcmp(inc.cells(), full2.cells(), bytes));
}

TEST(ClassDistanceFields, ANewVersionWithTheSameClassesChangesNothing) {
  SyntheticWorld w = random_blocks(4, 9, 0.0);
  DistanceFieldParams p;
  const LocalizationChannels ch = LocalizationChannels::per_class();
  ClassDistanceFields f(p, ch, w.extent());
  test::load_world(w, f);
  ASSERT_TRUE(f.set_tile(1, 2, 7, w.tile(1, 2)));  // accepted: the version is new
  EXPECT_EQ(f.tile_version(1, 2), 7U);
  EXPECT_EQ(f.pending_tiles(), 0U);  // but nothing to recompute
  // One cell differs: pending.
  std::vector<std::uint8_t> t = w.tile(1, 2);
  t[100] = t[100] == raw(ClassId::kRoad) ? raw(ClassId::kGrass) : raw(ClassId::kRoad);
  ASSERT_TRUE(f.set_tile(1, 2, 8, t));
  EXPECT_EQ(f.pending_tiles(), 1U);
}

TEST(ClassDistanceFields, OnlyTheChangedTileAndItsMarginAreRewritten) {
  SyntheticWorld w = random_blocks(8, 3, 0.0);
  DistanceFieldParams p;
  p.truncation_m = 10.0;
  const LocalizationChannels ch = LocalizationChannels::per_class();
  ClassDistanceFields f(p, ch, w.extent());
  test::load_world(w, f);
  std::vector<std::uint8_t> before(f.cells(), f.cells() + (f.outside_index() + 1) * 8);
  // A building appears in the middle of tile (4, 4).
  w.fill_rect(4 * 32.0 + 10, 4 * 32.0 + 10, 4 * 32.0 + 20, 4 * 32.0 + 20, ClassId::kBuilding, 5.0F);
  ASSERT_TRUE(f.set_tile(4, 4, 2, w.tile(4, 4)));
  ASSERT_EQ(f.update(), 1U);
  int changed = 0;
  for (int r = 0; r < f.height(); ++r)
    for (int c = 0; c < f.width(); ++c) {
      const std::size_t i = static_cast<std::size_t>(r) * static_cast<std::size_t>(f.width()) + static_cast<std::size_t>(c);
      if (std::memcmp(&before[i * 8], f.cells() + i * 8, 8) == 0) continue;
      ++changed;
      // at most the truncation distance outside the tile
      EXPECT_GE(c, 4 * 64 - 20);
      EXPECT_LT(c, 5 * 64 + 20);
      EXPECT_GE(r, 4 * 64 - 20);
      EXPECT_LT(r, 5 * 64 + 20);
    }
  EXPECT_GT(changed, 400);
  // the same version again is refused
  EXPECT_FALSE(f.set_tile(4, 4, 2, w.tile(4, 4)));
  EXPECT_EQ(f.tile_version(4, 4), 2U);
  // outside the extent, or the wrong size: refused
  EXPECT_FALSE(f.set_tile(8, 0, 3, w.tile(0, 0)));
  EXPECT_FALSE(f.set_tile(0, 0, 3, std::vector<std::uint8_t>(10, 0)));
}

TEST(ClassDistanceFields, UnknownCellsAndOutsideAreUnknown) {
  DistanceFieldParams p;
  const LocalizationChannels ch = LocalizationChannels::per_class();
  ClassDistanceFields f(p, ch, TileExtent{-1, -1, 2, 2});  // tiles -1..0: the map origin in the middle
  EXPECT_DOUBLE_EQ(f.origin_x(), -32.0);
  EXPECT_DOUBLE_EQ(f.origin_y(), -32.0);
  EXPECT_EQ(f.class_at(0.1, 0.1), 255);  // nothing known yet
  std::vector<std::uint8_t> tile(64 * 64, raw(ClassId::kRoad));
  tile[0] = 255;  // one unknown cell at the south-west corner of tile (0, 0)
  ASSERT_TRUE(f.set_tile(0, 0, 1, tile));
  f.update();
  EXPECT_EQ(f.class_at(0.1, 0.1), 255);
  EXPECT_EQ(f.class_at(0.6, 0.1), raw(ClassId::kRoad));
  EXPECT_EQ(f.class_at(31.9, 31.9), raw(ClassId::kRoad));
  EXPECT_EQ(f.class_at(-0.1, 0.1), 255);   // tile (-1, 0) never arrived
  EXPECT_EQ(f.class_at(40.0, 0.1), 255);   // outside the extent
  EXPECT_EQ(f.index_at(40.0, 0.1), f.outside_index());
  EXPECT_EQ(f.index_at(-32.01, 0.0), f.outside_index());
  // Road at distance 0; building (none known) at the optimistic distance to the unknown next door.
  EXPECT_EQ(f.distance_m(10.25, 10.25, 0), 0.0);
  EXPECT_NEAR(f.distance_m(10.25, 10.25, 4), 10.5, f.quantum_m());  // nearest unknown: tile (-1, 0) at x < 0
  ClassDistanceFields strict(DistanceFieldParams{0.5, 64, 25.0, false, 4}, ch, TileExtent{-1, -1, 2, 2});
  ASSERT_TRUE(strict.set_tile(0, 0, 1, tile));
  strict.update();
  EXPECT_NEAR(strict.distance_m(10.25, 10.25, 4), 25.0, 1e-9);  // no building anywhere: truncated
}

TEST(ClassDistanceFields, MemoryOfAOneSquareKilometreMap) {
  DistanceFieldParams p;
  const LocalizationChannels ch = LocalizationChannels::per_class();
  const TileExtent e = tiles_covering(MapRect{0, 0, 1000, 1000}, 0.5, 64);
  EXPECT_EQ(e.tiles_x, 32);
  ClassDistanceFields f(p, ch, e);
  const double mb = static_cast<double>(f.memory_bytes()) / (1024.0 * 1024.0);
  std::printf("distance fields for 1 km^2 at 0.5 m (%d x %d cells, %d channels): %.1f MiB\n", f.width(), f.height(),
              ch.count(), mb);
  EXPECT_LT(mb, 64.0);
}

}  // namespace
}  // namespace ag::loc
