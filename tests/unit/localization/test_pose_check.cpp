// The particle filter's pose check: with the obstacle prior on, a mean pose farther than the margin from
// the planner's free space (LocalizationChannels::add_off_route) is one the robot cannot hold. The filter
// does not converge there, and a tracking filter whose map fills in under it loses track, also when the
// robot stands (the standing updates: otherwise a standing, tracking robot is never matched again, and it
// stood "tracking" in a wood for the rest of a mission, its planner finding no free cell near the start).
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "airground/localization/semantic_localizer.hpp"
#include "scenario.hpp"

namespace ag::loc {
namespace {

using test::LidarModel;
using test::SyntheticWorld;

// A 30 m wood beside a road crossing with an 8 m grass clearing in its middle: room between the crowns,
// no road. The robot stands in the clearing (as the filter believed on the imported world).
struct Clearing {
  SyntheticWorld w = test::make_world(8, 8, 7);
  Pose2 at{};
  Clearing() {
    const double x0 = w.road_x[3] + 6.0, y0 = w.road_y[3] + 6.0;
    w.fill_rect(x0, y0, x0 + 30.0, y0 + 30.0, ClassId::kTree, 10.0F);
    w.fill_rect(x0 + 11.0, y0 + 11.0, x0 + 19.0, y0 + 19.0, ClassId::kGrass, 0.0F);
    at = Pose2{x0 + 15.0, y0 + 15.0, 0.4};
  }
};

// Forced updates of a filter started 0.3 m around the clearing's centre, with scans from there: the number
// of updates until it tracks (-1: never in `updates`), and its last estimate.
int updates_until_tracking(const Clearing& c, const LocalizationChannels& ch, int updates, FilterEstimate* last) {
  ClassDistanceFields fields(DistanceFieldParams{}, ch, c.w.extent());
  test::load_world(c.w, fields);
  std::vector<ScanPoint> scan;
  test::ray_cast(c.w, c.at, LidarModel{}, 11, scan);
  GeometricLabeller(GeometricLabelParams{}, 64, 1024).label(scan, LidarModel{}.rings, LidarModel{}.columns);
  ScanRenderPolar render(PolarRenderParams{}, ch);
  ParticleFilter filter(ParticleFilterParams{}, PolarRenderParams{}, 3);
  filter.initialise_gaussian(c.at, 0.3, 0.02);
  int tracking_at = -1;
  for (int k = 1; k <= updates && tracking_at < 0; ++k) {
    render.render(scan, filter.range_bin_m());
    EXPECT_TRUE(filter.update(render, fields, true).updated);
    if (filter.status() == FilterStatus::kTracking) tracking_at = k;
  }
  *last = filter.estimate();
  return tracking_at;
}

}  // namespace

TEST(PoseCheck, AFilterDoesNotConvergeWhereThePlannerCouldNotStart) {
  const Clearing c;
  const ParticleFilterParams p;
  LocalizationChannels routed = LocalizationChannels::two_class();
  routed.add_off_route(p.obstacle_traversable);
  FilterEstimate e;
  EXPECT_EQ(updates_until_tracking(c, routed, 20, &e), -1) << "a clearing in a wood is no place for the robot";
  EXPECT_LT(std::hypot(e.pose.x - c.at.x, e.pose.y - c.at.y), 1.0) << "the scan still fits there";
  EXPECT_GT(e.room_m, p.obstacle_margin_m);
  EXPECT_EQ(e.blocked_updates, 20U);
  // The obstacle classes alone (`pf_obstacle_traversable: any`) see the clearing's room: it tracks.
  const int obstacles_only = updates_until_tracking(c, LocalizationChannels::two_class(), 20, &e);
  EXPECT_GE(obstacles_only, p.converged_updates);
  EXPECT_LE(obstacles_only, p.converged_updates + 2);
  EXPECT_EQ(e.blocked_updates, 0U);
  EXPECT_LE(e.room_m, p.obstacle_margin_m);
}

// A robot tracks on a road and stops. The quadrotor's next tile says the ground around it is grass (no
// route: the planner could not start from there), and nothing else changes (grass and road are both
// "ground" to the scan). A standing, tracking robot is matched again once per lost_standing_update_s, and
// loses track after lost_updates such updates; with the old map it is never matched.
TEST(PoseCheck, TrackingIsLostWhenTheMapFillsInUnderAStandingRobot) {
  SyntheticWorld w = test::make_world(8, 8, 5);
  const std::vector<std::pair<int, int>> route{{1, 1}, {1, 3}};
  std::vector<test::TruthSample> truth = test::drive_route(w, route);
  const std::size_t stop = truth.size() - 1;
  test::stand(truth, 40.0);
  const std::vector<Pose2> odom = test::odometry(truth, test::OdometryNoise{}, 9);
  const LocalizerParams params;
  LocalizationChannels ch = LocalizationChannels::two_class();
  ch.add_off_route(params.filter.obstacle_traversable);
  ClassDistanceFields fields(DistanceFieldParams{}, ch, w.extent());
  test::load_world(w, fields);
  GeometricLabeller labeller(params.label, 64, 1024);
  SemanticLocalizer loc(params, ch, 21);
  loc.on_odometry(odom[0], truth[0].stamp);
  loc.initialise_gaussian(truth[0].pose, 1.0, 0.05, truth[0].stamp);
  std::vector<ScanPoint> scan;
  int matched_standing = 0, matched_after_fill = 0;
  std::size_t lost_at = 0;
  const std::size_t fill_at = stop + 100;  // 10 s after stopping
  for (std::size_t k = 1; k < truth.size(); ++k) {
    if (k == fill_at) {
      ASSERT_EQ(loc.filter().status(), FilterStatus::kTracking) << "it tracked on the road";
      const Pose2& at = truth[k].pose;
      const int tx = static_cast<int>(std::floor(at.x / w.resolution)) / w.tile_cells;
      const int ty = static_cast<int>(std::floor(at.y / w.resolution)) / w.tile_cells;
      const std::vector<std::uint8_t> grass(static_cast<std::size_t>(w.tile_cells * w.tile_cells), raw(ClassId::kGrass));
      ASSERT_TRUE(fields.set_tile(tx, ty, 2, grass));
      fields.update();
      EXPECT_TRUE(loc.filter().pose_blocked(fields));
    }
    loc.on_odometry(odom[k], truth[k].stamp);
    if (!loc.wants_scan(fields)) continue;
    if (k > stop + 5 && k < fill_at) ++matched_standing;
    if (k >= fill_at) ++matched_after_fill;
    test::ray_cast(w, truth[k].pose, LidarModel{}, k, scan);
    labeller.label(scan, LidarModel{}.rings, LidarModel{}.columns);
    loc.on_scan(scan, fields, truth[k].stamp);
    if (lost_at == 0 && k >= fill_at && loc.filter().status() == FilterStatus::kLost) lost_at = k;
  }
  EXPECT_EQ(matched_standing, 0) << "tracking and standing on room: no update";
  ASSERT_GT(lost_at, 0U) << "tracking was never lost";
  const double seconds = static_cast<double>(lost_at - fill_at) / 10.0;
  std::printf("lost %.1f s after the map filled in; %d standing updates in the %.0f s after it, %llu blocked in all\n", seconds,
              matched_after_fill, static_cast<double>(truth.size() - fill_at) / 10.0,
              static_cast<unsigned long long>(loc.filter().estimate().blocked_updates));
  EXPECT_LE(seconds, (params.filter.lost_updates + 1) * params.filter.lost_standing_update_s + 0.2);
  EXPECT_GE(seconds, (params.filter.lost_updates - 1) * params.filter.lost_standing_update_s);
  EXPECT_GE(loc.filter().estimate().blocked_updates, static_cast<std::uint64_t>(params.filter.lost_updates));
}

}  // namespace ag::loc
