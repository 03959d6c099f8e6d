// The localization stage through its channels: it converges on a synthetic world from a guess 10 m off,
// reports no map / initialising before that, and counts bad input without losing track.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

#include "scenario.hpp"
#include "stage_rig.hpp"

namespace ag::loc {
namespace {

struct Drive {
  test::SyntheticWorld w = test::make_world(test::kSlowTarget ? 5 : 8, test::kSlowTarget ? 5 : 8, 5);
  std::vector<test::TruthSample> truth;
  std::vector<Pose2> odom;
  Drive() {
    const auto route = test::snake_route(w, 1);
    truth = test::drive_route(w, route);
    odom = test::odometry(truth, test::OdometryNoise{}, 4);
  }
};

// Steps the stage along the drive from sample `from` to `to`, a scan every third sample (~3 Hz).
void drive(test::StageRig& rig, const Drive& d, std::size_t from, std::size_t to, std::vector<ScanPoint>& scan) {
  const test::LidarModel lidar;
  for (std::size_t k = from; k < to; ++k) {
    rig.push_odometry(d.odom[k], d.truth[k].stamp);
    if (k % 3 == 0) {
      test::ray_cast(d.w, d.truth[k].pose, lidar, k, scan);
      rig.push_scan(scan, d.truth[k].stamp, lidar.rings, lidar.columns);
    }
    rig.step(d.truth[k].stamp);
  }
}

// The map, the first odometry sample and a guess 1 m off: the start of a drive that tracks at once.
void start_near_truth(test::StageRig& rig, const Drive& d) {
  rig.push_world(d.w, 0);
  rig.push_odometry(d.odom[0], d.truth[0].stamp);
  rig.step(d.truth[0].stamp);
  const Pose2& t0 = d.truth[0].pose;
  rig.initial_pose(Pose2{t0.x + 1.0, t0.y, t0.yaw}, 2.0, 0.1, 1);
}

TEST(LocalizationStage, ConvergesThroughItsChannelsFromAGuess10mOff) {
  Drive d;
  auto rig = test::StageRig::make(d.w);
  ASSERT_NE(rig, nullptr);
  std::vector<ScanPoint> scan;
  rig->step(0);
  EXPECT_EQ(rig->latest().status, LocalizationStatus::kNoMap);
  rig->push_world(d.w, 0);
  rig->step(0);
  EXPECT_EQ(rig->latest().status, LocalizationStatus::kInitialising) << "a map but no initial pose yet";
  const Pose2& t0 = d.truth[0].pose;
  rig->push_odometry(d.odom[0], d.truth[0].stamp);
  rig->step(d.truth[0].stamp);
  rig->initial_pose(Pose2{t0.x + 8.0, t0.y - 6.0, t0.yaw + 0.3}, 10.0, 0.4, 1);
  drive(*rig, d, 1, d.truth.size(), scan);

  const LocalizationMsg& m = rig->latest();
  const Pose2& t = d.truth.back().pose;
  EXPECT_EQ(m.status, LocalizationStatus::kTracking);
  EXPECT_EQ(m.stamp, d.truth.back().stamp) << "the pose is for the newest odometry sample";
  EXPECT_LT(std::hypot(m.pose.x - t.x, m.pose.y - t.y), 1.0);
  EXPECT_LT(std::fabs(wrap_angle(m.pose.yaw - t.yaw)), 0.05);
  EXPECT_GT(m.covariance[0], 0.0);
  const LocalizationStageCounters& c = rig->stage->counters();
  EXPECT_GT(c.scans_matched, 50U);
  EXPECT_EQ(c.tiles_applied, static_cast<std::uint64_t>(d.w.tiles_x() * d.w.tiles_y()));
  EXPECT_EQ(c.initial_poses, 1U);
  EXPECT_EQ(c.scans_malformed + c.odometry_non_finite + c.odometry_out_of_order + c.tiles_outside_area, 0U);
  EXPECT_EQ(rig->stage->fields().pending_tiles(), 0U);
}

// A robot started from its YAML alone: the guess comes from localization.set_initial_pose and the
// initial_* keys, applied once odometry flows; the filter converges from it as from a message.
TEST(LocalizationStage, TheConfiguredInitialPoseStartsTheFilter) {
  Drive d;
  const Pose2& t0 = d.truth[0].pose;
  auto rig = test::StageRig::make(d.w, {"localization.set_initial_pose=true", "localization.initial_x_m=" + std::to_string(t0.x + 6.0),
                                        "localization.initial_y_m=" + std::to_string(t0.y - 4.0),
                                        "localization.initial_yaw_rad=" + std::to_string(t0.yaw + 0.2), "localization.initial_sigma_m=8"});
  ASSERT_NE(rig, nullptr);
  rig->push_world(d.w, 0);
  rig->step(0);
  EXPECT_EQ(rig->stage->counters().initial_poses, 0U) << "no odometry yet: the guess waits";
  std::vector<ScanPoint> scan;
  drive(*rig, d, 0, d.truth.size(), scan);
  EXPECT_EQ(rig->stage->counters().initial_poses, 1U);
  const LocalizationMsg& m = rig->latest();
  const Pose2& t = d.truth.back().pose;
  EXPECT_EQ(m.status, LocalizationStatus::kTracking);
  EXPECT_LT(std::hypot(m.pose.x - t.x, m.pose.y - t.y), 1.0);
}

TEST(LocalizationStage, BadInputIsCountedAndTrackingSurvives) {
  Drive d;
  auto rig = test::StageRig::make(d.w);
  ASSERT_NE(rig, nullptr);
  std::vector<ScanPoint> scan;
  rig->push_world(d.w, 0);
  rig->push_odometry(d.odom[0], d.truth[0].stamp);
  rig->step(d.truth[0].stamp);
  const Pose2& t0 = d.truth[0].pose;
  rig->initial_pose(Pose2{t0.x + 2.0, t0.y + 1.0, t0.yaw}, 3.0, 0.1, 1);
  const std::size_t half = d.truth.size() / 2;
  drive(*rig, d, 1, half, scan);
  ASSERT_EQ(rig->latest().status, LocalizationStatus::kTracking);

  const TimeNs t = d.truth[half - 1].stamp;
  // a scan claiming more points than a message holds, and one without organisation
  rig->scan->count = static_cast<std::uint32_t>(kMaxScanPoints + 1);
  rig->scan->rings = 64;
  rig->scan->columns = 1024;
  EXPECT_EQ(rig->scan_w.push(*rig->scan), 0U);
  rig->scan->count = 10;
  rig->scan->rings = 0;
  EXPECT_EQ(rig->scan_w.push(*rig->scan), 0U);
  // odometry: NaN, then a sample older than the last
  const double nan = std::numeric_limits<double>::quiet_NaN();
  rig->push_odometry(Pose2{nan, 0.0, 0.0}, t + 1);
  rig->push_odometry(d.odom[half - 5], d.truth[half - 5].stamp);
  // a tile far outside the area, a stale re-send, and an initial pose with an infinite sigma
  rig->push_tile(500, 500, 1, d.w.tile(0, 0));
  rig->push_tile(0, 0, 1, d.w.tile(0, 0));
  InitialPoseMsg bad;
  bad.stamp = 99;
  bad.pose = Pose2{0, 0, 0};
  bad.sigma_xy_m = std::numeric_limits<double>::infinity();
  rig->init_w.publish(bad);
  rig->step(t + 2);

  const LocalizationStageCounters& c = rig->stage->counters();
  EXPECT_EQ(c.scans_malformed, 2U);
  EXPECT_EQ(c.odometry_non_finite, 1U);
  EXPECT_EQ(c.odometry_out_of_order, 1U);
  EXPECT_EQ(c.tiles_outside_area, 1U);
  EXPECT_EQ(c.tiles_stale, 1U);
  EXPECT_EQ(c.initial_pose_invalid, 1U);
  EXPECT_EQ(c.initial_poses, 1U) << "the bad guess did not re-initialise the filter";

  drive(*rig, d, half, d.truth.size(), scan);
  const LocalizationMsg& m = rig->latest();
  const Pose2& tl = d.truth.back().pose;
  EXPECT_EQ(m.status, LocalizationStatus::kTracking);
  EXPECT_LT(std::hypot(m.pose.x - tl.x, m.pose.y - tl.y), 1.0);
}

TEST(LocalizationStage, ANewInitialPoseReinitialises) {
  Drive d;
  auto rig = test::StageRig::make(d.w);
  ASSERT_NE(rig, nullptr);
  std::vector<ScanPoint> scan;
  start_near_truth(*rig, d);
  const Pose2& t0 = d.truth[0].pose;
  drive(*rig, d, 1, d.truth.size() / 2, scan);
  ASSERT_EQ(rig->latest().status, LocalizationStatus::kTracking);
  // an operator says the robot is somewhere else: the stage starts over from there
  rig->initial_pose(Pose2{t0.x + 40.0, t0.y + 40.0, t0.yaw}, 2.0, 0.1, 2);
  rig->step(d.truth[d.truth.size() / 2].stamp);
  EXPECT_EQ(rig->stage->counters().initial_poses, 2U);
  EXPECT_NE(rig->latest().status, LocalizationStatus::kTracking);
}

// The planner's word on "planned_path": a route it could not start from the tracked pose (planned after the
// robot began to track) makes the standing robot's localizer match again and give the pose up; one planned
// from before tracking began, or a route that succeeded, changes nothing.
TEST(LocalizationStage, ARouteThePlannerCouldNotStartFromTheTrackedPoseUnsettlesIt) {
  for (const int word : {0, 1, 2}) {  // 0: a route; 1: start blocked, planned before tracking began; 2: start blocked
    Drive d;
    auto rig = test::StageRig::make(d.w);
    ASSERT_NE(rig, nullptr);
    LatestWriter<PlannedPathMsg> path_w = rig->role->channels().latest_writer(chan::kPlannedPath).value();
    std::vector<ScanPoint> scan;
    start_near_truth(*rig, d);
    const std::size_t half = d.truth.size() / 2;
    drive(*rig, d, 1, half, scan);
    ASSERT_EQ(rig->latest().status, LocalizationStatus::kTracking);
    auto msg = std::make_unique<PlannedPathMsg>();
    msg->seq = 1;
    msg->status = word == 0 ? RouteStatus::kOk : RouteStatus::kBadEnds;
    msg->plan_status = word == 0 ? std::uint8_t{0} : kPlanStatusStartBlocked;
    msg->stamp = word == 1 ? d.truth[1].stamp : rig->latest().stamp;
    path_w.publish(*msg);
    // 20 s standing where the drive stopped, scans at 3 Hz
    const test::LidarModel lidar;
    for (int i = 1; i <= 200; ++i) {
      const TimeNs t = d.truth[half - 1].stamp + from_seconds(i / 10.0);
      rig->push_odometry(d.odom[half - 1], t);
      if (i % 3 == 0) {
        test::ray_cast(d.w, d.truth[half - 1].pose, lidar, static_cast<std::uint64_t>(i), scan);
        rig->push_scan(scan, t, lidar.rings, lidar.columns);
      }
      rig->step(t);
    }
    const LocalizationStageCounters& c = rig->stage->counters();
    EXPECT_EQ(c.planner_start_blocked, word == 2 ? 1U : 0U) << "word " << word;
    if (word == 2) {
      EXPECT_GE(c.recoveries, 1U) << "it gave the pose up";
    } else {
      EXPECT_EQ(c.recoveries, 0U) << "word " << word;
      EXPECT_EQ(rig->latest().status, LocalizationStatus::kTracking) << "word " << word;
    }
  }
}

TEST(LocalizationStage, AnInvertedAreaIsAConfigError) {
  test::SyntheticWorld w = test::make_world(2, 2, 1);
  static const std::vector<ParamSection> schema = role_schema(test::kRigRole);
  Config cfg = Config::defaults(schema);
  ASSERT_TRUE(cfg.set("localization.area_x1_m=-600").ok());
  SimClock clock;
  auto r = RoleInstance::create(test::kRigRole, cfg, clock, "ugv1");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("localization.area_x1_m"), std::string::npos) << r.error().message;
}

}  // namespace
}  // namespace ag::loc
