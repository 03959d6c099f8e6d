// The particle filter's obstacle prior: a particle deeper than the margin inside a mapped obstacle region
// loses obstacle_penalty_per_m of log weight per metre beyond it; on free ground, within the margin and on
// unknown cells it loses nothing. The depth is checked against a brute-force search of the class raster.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "airground/localization/semantic_localizer.hpp"
#include "scenario.hpp"

namespace ag::loc {
namespace {

using test::LidarModel;
using test::SyntheticWorld;

// [m] Distance from (x, y)'s cell centre to the nearest cell a ground robot can stand on, or unknown
// (the two-class "ground" channel with unknown cells as sources); 0 on such a cell or outside the raster.
double brute_depth(const SyntheticWorld& w, double x, double y) {
  const int c0 = static_cast<int>(std::floor(x / w.resolution)), r0 = static_cast<int>(std::floor(y / w.resolution));
  auto free_or_unknown = [&](int c, int r) {
    if (!w.inside(c, r)) return true;
    const auto k = static_cast<ClassId>(w.cls[w.index(c, r)]);
    return k == ClassId::kUnknown || k == ClassId::kRoad || k == ClassId::kDirt || k == ClassId::kGrass || k == ClassId::kWater;
  };
  if (free_or_unknown(c0, r0)) return 0.0;
  const int reach = 60;  // 30 m, beyond the fields' 25 m truncation
  double best = 1e9;
  for (int r = r0 - reach; r <= r0 + reach; ++r)
    for (int c = c0 - reach; c <= c0 + reach; ++c)
      if (free_or_unknown(c, r)) best = std::min(best, std::hypot(c - c0, r - r0) * w.resolution);
  return std::min(best, DistanceFieldParams{}.truncation_m);
}

}  // namespace

TEST(ObstaclePrior, FreeSpaceChannelsAreTheClassesARobotCanStandOn) {
  const LocalizationChannels two = LocalizationChannels::two_class();
  EXPECT_EQ(two.free_space_channels(), 1U) << "ground only, not obstacle or obstacle faces";
  const LocalizationChannels per = LocalizationChannels::per_class();
  for (int k = 0; k < per.count(); ++k) {
    const bool free = (per.free_space_channels() >> k) & 1U;
    const bool blocked = per.name(k) == "tree" || per.name(k) == "building" || per.name(k) == "vehicle" || per.name(k) == "water";
    EXPECT_NE(free, blocked) << per.name(k);
  }
}

// A 30 m building block and a 14 m unknown patch beside the robot's road; particles spread 25 m around it.
// One update from the same seed with and without the prior, no resampling and no uniform mix: each
// particle's log-weight change is the prior alone, -penalty x (depth - margin) beyond the margin.
TEST(ObstaclePrior, ADeepParticleLosesThePenaltyPerMetreBeyondTheMarginAndNoOtherLosesAny) {
  SyntheticWorld w = test::make_world(8, 8, 7);
  const Pose2 truth{w.road_x[3], w.road_y[3] + 4.0, 0.3};
  w.fill_rect(truth.x + 6.0, truth.y - 15.0, truth.x + 36.0, truth.y + 15.0, ClassId::kBuilding, 8.0F);
  SyntheticWorld aerial = w;
  aerial.fill_rect(truth.x - 20.0, truth.y - 7.0, truth.x - 6.0, truth.y + 7.0, ClassId::kUnknown, 0.0F);
  const LocalizationChannels ch = LocalizationChannels::two_class();
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
  std::vector<double> depth(where.size());
  double shift = 0.0;
  int free = 0, deep = 0, on_unknown = 0;
  for (std::size_t i = 0; i < where.size(); ++i) {
    depth[i] = brute_depth(aerial, where[i].x, where[i].y);
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
    // The fields quantise to 0.1 m; the depth sits on 0.5 m cells either way.
    worst = std::max(worst, std::abs(logw[1][i] - logw[0][i] - shift - expected));
    ASSERT_NEAR(logw[1][i] - logw[0][i] - shift, expected, 0.15)
        << "particle " << i << " at (" << where[i].x - truth.x << ", " << where[i].y - truth.y << ") from the robot, " << depth[i] << " m deep";
  }
  std::printf("%zu particles: %d on free ground or unknown, %d deeper than the margin + 0.3 m, %llu penalised; worst error %.3f\n",
              where.size(), free, deep, static_cast<unsigned long long>(counted), worst);
  ASSERT_GT(deep, 100) << "the building block holds particles well inside it";
  EXPECT_GE(counted, static_cast<std::uint64_t>(deep));
  EXPECT_LE(counted, where.size() - static_cast<std::size_t>(free));
}

}  // namespace ag::loc
