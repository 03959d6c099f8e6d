// The planner and drive stages on one robot (RoleInstance, real config and channels), fed a synthetic
// world tile by tile: a goal gives a route that keeps clearance; a robot integrating the wheel
// commands reaches the goal without entering a blocked cell; a changed tile re-plans around it;
// cancel, bad tiles and bad goals are counted; lost, it coasts slowly for a while, then stops.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>

#include "stage_rig.hpp"

namespace ag::plan {
namespace {
using test::Rig;

TEST(PlanningStages, AGoalIsPlannedAndDrivenToWithoutEnteringABlockedCell) {
  const auto w = loc::test::make_world(5, 5, 3);
  Rig rig(w);
  rig.load(w);
  EXPECT_EQ(rig.planner->counters().tiles_applied, 25U);
  EXPECT_EQ(rig.planner->roadmap().stats().full_builds, 0U) << "the stage folds tiles in one by one";
  const GridReference ref = test::reference_of(w);
  const auto pairs = test::reachable_pairs(w, ref, 1, 17, 60.0);
  ASSERT_EQ(pairs.size(), 1U);
  rig.pose = Pose2{pairs[0].first.x, pairs[0].first.y, 0.0};
  rig.goal(pairs[0].second.x, pairs[0].second.y, 1);
  rig.step_planner();
  const PlannedPathMsg& p = rig.planner->published();
  ASSERT_EQ(p.status, RouteStatus::kOk) << static_cast<int>(p.plan_status);
  EXPECT_GE(p.min_clearance_m, RoadmapParams{}.min_clearance_m - 1e-9);
  int blocked = 0, k = 0;
  double closest = 1e9;
  for (; k < 6000 && static_cast<FollowState>(rig.drive->published().follow_state) != FollowState::kArrived; ++k) {
    rig.tick(k);
    if (!ref.traversable(ref.col(rig.pose.x), ref.row(rig.pose.y))) ++blocked;
    closest = std::min(closest, ref.clearance_m(ref.col(rig.pose.x), ref.row(rig.pose.y), 3.0));
  }
  EXPECT_EQ(static_cast<FollowState>(rig.drive->published().follow_state), FollowState::kArrived) << "after " << k * 0.05 << " s";
  EXPECT_LT(std::hypot(rig.pose.x - pairs[0].second.x, rig.pose.y - pairs[0].second.y), 1.0);
  EXPECT_EQ(blocked, 0) << "ticks on a non-traversable cell";
  EXPECT_GT(closest, 0.25) << "closest approach to an obstacle [m]";
  EXPECT_GT(rig.planner->counters().plans, 1U) << "re-planned on the way";
}

// Lost, the robot goes on along its route slowly on the localizer's dead-reckoned pose for lost_coast_m
// (new views are how it finds itself again; in the study a robot that stopped there stood lost until the
// time cap), then stops; tracking again, it drives on at full speed.
TEST(PlanningStages, LostItCoastsSlowlyAlongTheRouteForAWhileThenStops) {
  const auto w = loc::test::make_world(5, 5, 3);
  Rig rig(w);
  rig.load(w);
  const GridReference ref = test::reference_of(w);
  const auto pairs = test::reachable_pairs(w, ref, 1, 17, 120.0);
  ASSERT_EQ(pairs.size(), 1U);
  rig.pose = Pose2{pairs[0].first.x, pairs[0].first.y, 0.0};
  rig.goal(pairs[0].second.x, pairs[0].second.y, 1);
  rig.step_planner();
  ASSERT_EQ(rig.planner->published().status, RouteStatus::kOk);
  int k = 0;
  double top = 0.0;
  for (; k < 300; ++k) {  // 15 s tracking
    rig.tick(k);
    top = std::max(top, rig.drive->published().v_mps);
  }
  const DriveSettings d{};
  EXPECT_GT(top, 1.5 * d.lost_speed_mps) << "tracking: faster than the lost speed";
  rig.status = LocalizationStatus::kLost;
  const Pose2 lost_at = rig.pose;
  double lost_top = 0.0, path = 0.0;
  for (int i = 0; i < 1200; ++i, ++k) {  // 60 s lost
    const Pose2 before = rig.pose;
    rig.tick(k);
    if (i > 40) lost_top = std::max(lost_top, rig.drive->published().v_mps);  // after the slow-down
    path += std::hypot(rig.pose.x - before.x, rig.pose.y - before.y);
  }
  std::printf("lost: coasted %.1f m (%.1f m from where it was lost), at most %.2f m/s\n", path,
              std::hypot(rig.pose.x - lost_at.x, rig.pose.y - lost_at.y), lost_top);
  EXPECT_LE(lost_top, d.lost_speed_mps + 1e-9);
  EXPECT_NEAR(path, d.lost_coast_m, 1.5) << "on along the route for lost_coast_m (and the stop), then standing";
  EXPECT_NEAR(rig.drive->published().v_mps, 0.0, 1e-9);
  EXPECT_NE(static_cast<FollowState>(rig.drive->published().follow_state), FollowState::kArrived);
  rig.status = LocalizationStatus::kTracking;  // found again: full speed
  double again = 0.0;
  for (int i = 0; i < 200; ++i, ++k) {
    rig.tick(k);
    again = std::max(again, rig.drive->published().v_mps);
  }
  EXPECT_GT(again, 1.5 * d.lost_speed_mps);
}

TEST(PlanningStages, CancelBadGoalsAndTilesOutsideTheAreaAreCounted) {
  const auto w = loc::test::make_world(3, 3, 5);
  Rig rig(w);
  rig.load(w);
  rig.push_tile(40, 40, 1, w.tile(0, 0));
  rig.goal(std::nan(""), 5.0, 1);
  rig.step_planner();
  EXPECT_EQ(rig.planner->counters().tiles_outside, 1U);
  EXPECT_EQ(rig.planner->counters().goals_non_finite, 1U);
  rig.pose = Pose2{w.road_x[0], w.road_y[0], 0};
  rig.goal(w.road_x[0], w.road_y[0] + 30.0, 2);
  rig.step_planner();
  EXPECT_EQ(rig.planner->published().status, RouteStatus::kOk);
  rig.goal(0, 0, 3, true);
  rig.step_planner();
  EXPECT_EQ(rig.planner->published().status, RouteStatus::kCancelled);
  for (int k = 0; k < 40; ++k) rig.tick(k + 1);
  EXPECT_NEAR(rig.drive->published().v_mps, 0.0, 1e-9) << "no route: stopped";
  rig.goal(-500, 5, 4);  // outside the map
  rig.step_planner();
  EXPECT_EQ(rig.planner->published().status, RouteStatus::kBadEnds);
}

TEST(PlanningStages, AGeofenceMarginThatLeavesNoMissionAreaIsRefusedAtStartUp) {
  static const std::vector<ParamSection> schema = role_schema(test::kRole);
  Config cfg = Config::defaults(schema);
  for (const char* s : {"planner.area_x0_m=0", "planner.area_y0_m=0", "planner.area_x1_m=30", "planner.area_y1_m=100",
                        "planner.geofence_margin_m=15"})
    ASSERT_TRUE(cfg.set(s).ok()) << s;
  SimClock clock{0};
  auto r = RoleInstance::create(test::kRole, cfg, clock, "ugv1");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("planner.geofence_margin_m"), std::string::npos) << r.error().message;
  ASSERT_TRUE(cfg.set("planner.geofence_margin_m=14").ok());
  EXPECT_TRUE(RoleInstance::create(test::kRole, cfg, clock, "ugv1").ok()) << "2 m of the area left inside the fence";
}

}  // namespace
}  // namespace ag::plan
