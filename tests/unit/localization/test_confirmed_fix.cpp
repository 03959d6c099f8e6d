// A confirmed fix (tracked confirm_distance_m since it converged) is judged by the room from the obstacle
// classes alone (ParticleFilterParams::confirmed_room_obstacles_only): the planner's stall marks widen the
// way round a spot it could not pass onto grass, so a robot out on the grass is where its own planner sent
// it. On gen6 a robot tracking 0.5 m from the truth 2.5 m out on the grass by a parking lot was called lost
// by the room from the planner's classes, could not converge where it stood (the same check), and, lost,
// stood there for the remaining 4000 s of the mission.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <vector>

#include "airground/localization/semantic_localizer.hpp"
#include "scenario.hpp"

namespace ag::loc {
namespace {

using test::LidarModel;
using test::SyntheticWorld;

struct OffRoad {
  bool lost_on_grass{false};     // lost at any time after leaving the road
  FilterStatus final_status{FilterStatus::kUninitialised};
  double final_error_m{-1.0};
  double room_m{0.0};            // the last update's room (from the channels in force)
  bool new_fix_blocked{false};   // a new fix at the grass spot fails the pose check (room from the planner's classes)
};

// A robot tracks 70+ m north along a road, turns east, drives 3 m out onto open grass and stands there 40 s.
OffRoad drive_onto_grass(bool obstacles_only) {
  SyntheticWorld w = test::make_world(8, 8, 5);
  const double x_road = w.road_x[1];
  const double ym = 0.5 * (w.road_y[2] + w.road_y[3]);
  double edge = x_road;
  while (w.class_at(edge, ym) == raw(ClassId::kRoad) || w.class_at(edge, ym) == raw(ClassId::kVehicle)) edge += 0.25;
  w.fill_rect(x_road - 4.0, ym - 6.0, edge, ym + 6.0, ClassId::kRoad, 0.0F);  // no car parked where it leaves
  w.fill_rect(edge, ym - 10.0, edge + 12.0, ym + 10.0, ClassId::kGrass, 0.0F);  // open grass beyond
  const std::vector<std::pair<int, int>> route{{1, 1}, {1, 3}};
  std::vector<test::TruthSample> truth = test::drive_route(w, route);
  while (truth.back().pose.y > ym) truth.pop_back();
  const std::size_t left_road = truth.size();
  Pose2 p = truth.back().pose;
  TimeNs t = truth.back().stamp;
  const TimeNs dt = from_seconds(0.1);
  while (p.yaw > 1e-9) {  // turn east in place
    p.yaw = std::max(0.0, p.yaw - 0.08);
    truth.push_back({t += dt, p});
  }
  while (p.x < edge + 3.0) {  // 1 m/s onto the grass
    p.x = std::min(edge + 3.0, p.x + 0.1);
    truth.push_back({t += dt, p});
  }
  test::stand(truth, 40.0);

  LocalizerParams params;
  params.filter.confirmed_room_obstacles_only = obstacles_only;
  LocalizationChannels ch = LocalizationChannels::two_class();
  ch.add_off_route(params.filter.obstacle_traversable);
  ClassDistanceFields fields(DistanceFieldParams{}, ch, w.extent());
  test::load_world(w, fields);
  const std::vector<Pose2> odom = test::odometry(truth, test::OdometryNoise{}, 9);
  GeometricLabeller labeller(params.label, 64, 1024);
  SemanticLocalizer loc(params, ch, 21);
  loc.on_odometry(odom[0], truth[0].stamp);
  loc.initialise_gaussian(truth[0].pose, 1.0, 0.05, truth[0].stamp);
  std::vector<ScanPoint> scan;
  OffRoad out;
  for (std::size_t k = 1; k < truth.size(); ++k) {
    if (k == left_road) {
      EXPECT_EQ(loc.filter().status(), FilterStatus::kTracking) << "it tracked along the road";
    }
    loc.on_odometry(odom[k], truth[k].stamp);
    if (!loc.wants_scan(fields)) continue;
    test::ray_cast(w, truth[k].pose, LidarModel{}, k, scan);
    labeller.label(scan, LidarModel{}.rings, LidarModel{}.columns);
    loc.on_scan(scan, fields, truth[k].stamp);
    if (k >= left_road && loc.filter().status() == FilterStatus::kLost) out.lost_on_grass = true;
  }
  const Pose2& end = truth.back().pose;
  out.final_status = loc.filter().status();
  out.final_error_m = std::hypot(loc.pose().pose.x - end.x, loc.pose().pose.y - end.y);
  out.room_m = loc.filter().estimate().room_m;
  // A new fix there (a fresh filter's room channels are the planner's classes).
  ParticleFilter fresh(params.filter, PolarRenderParams{}, 1);
  fresh.initialise_gaussian(end, 0.1, 0.01);
  out.new_fix_blocked = fresh.pose_blocked(fields);
  return out;
}

}  // namespace

TEST(ConfirmedFix, ARobotThePlannerTookOntoTheGrassKeepsItsFixThereAndANewFixWouldNot) {
  for (const bool obstacles_only : {true, false}) {
    const OffRoad r = drive_onto_grass(obstacles_only);
    std::printf("room from %s: lost on the grass %s, final status %d, error %.2f m, room %.1f m\n",
                obstacles_only ? "the obstacles (confirmed fix)" : "the planner's classes", r.lost_on_grass ? "yes" : "no",
                static_cast<int>(r.final_status), r.final_error_m, r.room_m);
    EXPECT_TRUE(r.new_fix_blocked) << "the spot is beyond the margin from the planner's free space: a new fix is refused there";
    if (obstacles_only) {
      EXPECT_FALSE(r.lost_on_grass);
      EXPECT_EQ(r.final_status, FilterStatus::kTracking);
      EXPECT_LT(r.final_error_m, 1.0);
      EXPECT_LE(r.room_m, ParticleFilterParams{}.obstacle_margin_m);
    } else {
      EXPECT_TRUE(r.lost_on_grass) << "the old rule: a robot out on the grass is no robot";
      EXPECT_GT(r.final_error_m, 1.0) << "and its re-spread settles back toward the road, where the planner's classes give room";
    }
  }
}

}  // namespace ag::loc
