// The particle filter's obstacle prior: a particle farther than the margin from the nearest cell with the
// planner's clearance loses obstacle_penalty_per_m of log weight per metre beyond it; with room, within
// the margin and on unknown cells it loses nothing. The distance is checked against a brute-force search
// of the class raster.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "airground/localization/semantic_localizer.hpp"
#include "scenario.hpp"

namespace ag::loc {
namespace {

using test::LidarModel;
using test::SyntheticWorld;

bool routable(std::uint8_t k, Traversability level) {
  return static_cast<int>(ClassTable::builtin().info(static_cast<ClassId>(k)).traversability) <= static_cast<int>(level);
}

// The room a robot has on each cell, by brute force over the class raster: true on an unknown cell, and on
// a cell of a class up to `level` (the planner's traversable) at least `clearance` from every cell of a
// class above it and every unknown cell (the off-route channel, whose sources include the unknown), from
// the cell's centre to the other's edge, as the planner measures it: centre to centre, half a cell more.
std::vector<char> room_grid(const SyntheticWorld& w, double clearance, Traversability level) {
  std::vector<char> room(w.cls.size(), 0);
  const double centres = clearance + 0.5 * w.resolution;
  const int reach = static_cast<int>(std::ceil(centres / w.resolution));
  for (int r = 0; r < w.height; ++r)
    for (int c = 0; c < w.width; ++c) {
      const std::uint8_t k = w.cls[w.index(c, r)];
      bool ok = k == raw(ClassId::kUnknown) || routable(k, level);
      if (k != raw(ClassId::kUnknown))
        for (int dr = -reach; ok && dr <= reach; ++dr)
          for (int dc = -reach; ok && dc <= reach; ++dc) {
            if (std::hypot(dc, dr) * w.resolution >= centres - 1e-9) continue;
            const std::uint8_t n = w.inside(c + dc, r + dr) ? w.cls[w.index(c + dc, r + dr)] : raw(ClassId::kUnknown);
            if (n == raw(ClassId::kUnknown) || !routable(n, level)) ok = false;
          }
      room[w.index(c, r)] = ok ? 1 : 0;
    }
  return room;
}

// [m] From (x, y)'s cell to the nearest cell with room (outside the raster counts), capped at `cap`.
double brute_room_distance(const SyntheticWorld& w, const std::vector<char>& room, double x, double y, double cap) {
  const int c0 = static_cast<int>(std::floor(x / w.resolution)), r0 = static_cast<int>(std::floor(y / w.resolution));
  const int reach = static_cast<int>(std::ceil(cap / w.resolution));
  double best = cap;
  for (int r = r0 - reach; r <= r0 + reach; ++r)
    for (int c = c0 - reach; c <= c0 + reach; ++c)
      if (!w.inside(c, r) || room[w.index(c, r)]) best = std::min(best, std::hypot(c - c0, r - r0) * w.resolution);
  return best;
}

}  // namespace

TEST(ObstaclePrior, ObstacleChannelsAreTheRegionsOfTheClassesARobotCannotEnter) {
  const LocalizationChannels two = LocalizationChannels::two_class();
  EXPECT_EQ(two.obstacle_space_channels(), 2U) << "the obstacle regions, not ground or the obstacle faces";
  const LocalizationChannels per = LocalizationChannels::per_class();
  for (int k = 0; k < per.count(); ++k) {
    const bool obstacle = (per.obstacle_space_channels() >> k) & 1U;
    const bool blocked = per.name(k) == "tree" || per.name(k) == "building" || per.name(k) == "vehicle" || per.name(k) == "water";
    EXPECT_EQ(obstacle, blocked) << per.name(k);
  }
  // The planner's free space instead: one channel, off the route classes, replaces them.
  LocalizationChannels routed = LocalizationChannels::two_class();
  const int off = routed.add_off_route(Traversability::kRough);
  EXPECT_EQ(routed.obstacle_space_channels(), 1U << off);
  EXPECT_EQ(routed.weight(off), 0.0F) << "it is not matched against the scan";
  for (const ClassId id : {ClassId::kGrass, ClassId::kWater, ClassId::kTree, ClassId::kBuilding, ClassId::kVehicle})
    EXPECT_TRUE((routed.map_sources(raw(id)) >> off) & 1U) << "class " << static_cast<int>(raw(id));
  for (const ClassId id : {ClassId::kRoad, ClassId::kDirt}) EXPECT_FALSE((routed.map_sources(raw(id)) >> off) & 1U);
  for (std::uint8_t label = 0; label < 255; ++label) EXPECT_NE(routed.scan_channel(label), off);
}

// Beside the robot's road: a 30 m building block, a 28 m tree block that the map speckles with one-cell
// grass holes every 1.5 m (as ErfNet's map speckles the crowns of a dense wood: no hole has the room of a
// robot), and a 14 m unknown patch; particles spread 25 m around the robot. One update from the same seed
// with and without the prior, no resampling and no uniform mix: each particle's log-weight change is the
// prior alone, -penalty x (distance to room - margin) beyond the margin, the distance capped.
TEST(ObstaclePrior, AParticleFarFromRoomLosesThePenaltyPerMetreBeyondTheMarginAndNoOtherLosesAny) {
  SyntheticWorld w = test::make_world(8, 8, 7);
  const Pose2 truth{w.road_x[3], w.road_y[3] + 4.0, 0.3};
  w.fill_rect(truth.x + 6.0, truth.y - 15.0, truth.x + 36.0, truth.y + 15.0, ClassId::kBuilding, 8.0F);
  w.fill_rect(truth.x - 36.0, truth.y + 8.0, truth.x - 8.0, truth.y + 36.0, ClassId::kTree, 10.0F);
  for (double y = truth.y + 9.0; y < truth.y + 35.0; y += 1.5)
    for (double x = truth.x - 35.0; x < truth.x - 9.0; x += 1.5) w.fill_rect(x, y, x + 0.5, y + 0.5, ClassId::kGrass, 0.0F);
  SyntheticWorld aerial = w;
  aerial.fill_rect(truth.x - 20.0, truth.y - 7.0, truth.x - 6.0, truth.y + 7.0, ClassId::kUnknown, 0.0F);
  LocalizationChannels ch = LocalizationChannels::two_class();
  ch.add_off_route(ParticleFilterParams{}.obstacle_traversable);  // as the stage does
  ClassDistanceFields fields(DistanceFieldParams{}, ch, aerial.extent());
  test::load_world(aerial, fields);
  std::vector<ScanPoint> scan;
  test::ray_cast(w, truth, LidarModel{}, 3, scan);
  GeometricLabeller(GeometricLabelParams{}, 64, 1024).label(scan, LidarModel{}.rings, LidarModel{}.columns);
  ScanRenderPolar render(PolarRenderParams{}, ch);

  std::vector<double> logw[2];
  std::vector<Pose2> where;
  std::uint64_t counted = 0;
  ParticleFilterParams p;
  p.resample_ess_ratio = 0.0;
  p.uniform_mix = 0.0;
  for (const bool prior : {false, true}) {
    ParticleFilterParams q = p;
    if (!prior) q.obstacle_penalty_per_m = 0.0;
    ParticleFilter filter(q, PolarRenderParams{}, 5);
    filter.initialise_gaussian(truth, 25.0, 0.3);
    render.render(scan, filter.range_bin_m());
    ASSERT_TRUE(filter.update(render, fields, true).updated);
    for (std::size_t i = 0; i < filter.size(); ++i) logw[prior ? 1 : 0].push_back(std::log(filter.weight(i)));
    if (prior) {
      for (std::size_t i = 0; i < filter.size(); ++i) where.push_back(filter.particle(i));
      counted = filter.estimate().inside_obstacle;
    } else {
      EXPECT_EQ(filter.estimate().inside_obstacle, 0U);
    }
  }
  ASSERT_EQ(logw[0].size(), logw[1].size());
  // The normalisation moves every log weight by the same amount: measure it on the particles with no prior.
  const std::vector<char> room = room_grid(aerial, p.obstacle_clearance_m, p.obstacle_traversable);
  std::vector<double> depth(where.size());
  double shift = 0.0;
  int free = 0, deep = 0, on_unknown = 0, in_wood = 0;
  for (std::size_t i = 0; i < where.size(); ++i) {
    depth[i] = brute_room_distance(aerial, room, where[i].x, where[i].y, p.obstacle_max_depth_m);
    if (aerial.class_at(where[i].x, where[i].y) == raw(ClassId::kUnknown)) ++on_unknown;
    if (depth[i] == 0.0) {
      shift += logw[1][i] - logw[0][i];
      ++free;
    }
  }
  ASSERT_GT(free, 100);
  ASSERT_GT(on_unknown, 50) << "the unknown patch holds particles, and they lose nothing";
  shift /= free;
  double worst = 0.0;
  for (std::size_t i = 0; i < where.size(); ++i) {
    const double expected = -p.obstacle_penalty_per_m * std::max(0.0, depth[i] - p.obstacle_margin_m);
    if (depth[i] > p.obstacle_margin_m + 0.3) ++deep;
    if (depth[i] >= p.obstacle_max_depth_m && aerial.class_at(where[i].x, where[i].y) == raw(ClassId::kTree)) ++in_wood;
    // The fields quantise to 0.1 m, and both searches go cell to cell.
    worst = std::max(worst, std::abs(logw[1][i] - logw[0][i] - shift - expected));
    ASSERT_NEAR(logw[1][i] - logw[0][i] - shift, expected, 0.15)
        << "particle " << i << " at (" << where[i].x - truth.x << ", " << where[i].y - truth.y << ") from the robot, " << depth[i] << " m deep";
  }
  std::printf("%zu particles: %d with room or on unknown, %d beyond the margin + 0.3 m (%d in the wood at the cap), %llu penalised; worst error %.3f\n",
              where.size(), free, deep, in_wood, static_cast<unsigned long long>(counted), worst);
  ASSERT_GT(deep, 100) << "the building block holds particles well inside it";
  EXPECT_GT(in_wood, 20) << "the speckled wood's middle is as far from room as a solid block";
  EXPECT_GE(counted, static_cast<std::uint64_t>(deep));
  EXPECT_LE(counted, where.size() - static_cast<std::size_t>(free));
}

}  // namespace ag::loc
