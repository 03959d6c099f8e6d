// The tracker and drive stages together (RoleInstance, real channels): a box the aerial map missed on
// the route stops the robot before it; a return right ahead stops the wheels in the same drive step (no
// ramp); a wall across the route and behind it cancels the route and stops.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>

#include "airground/messages/channels.hpp"
#include "airground/planning/stages.hpp"
#include "airground/platform/role_instance.hpp"
#include "synthetic_scan.hpp"

namespace ag::plan {
namespace {

inline constexpr StageSpec kStages[] = {
    {"tracker", &TrackerStage::make, 10.0, 20'000, 35, -1, TrackerStage::kParams, "local tracker"},
    {"drive", &DriveStage::make, 20.0, 2'000, 45, -1, DriveStage::kParams, "drive control"},
};
inline constexpr RoleDescription kRole{"ugv", "tracker + drive rig", kStages, {}};
// The aarch64 build runs its tests under qemu-user: a sparser scan there (same properties).
#if defined(__aarch64__)
inline constexpr int kAzimuthStepDeg = 3;
#else
inline constexpr int kAzimuthStepDeg = 1;
#endif

struct Rig {
  SimClock clock{0};
  std::unique_ptr<RoleInstance> role;
  TrackerStage* tracker{nullptr};
  DriveStage* drive{nullptr};
  RingWriter<LidarScanMsg, kLidarRing> scan_w;
  LatestWriter<LocalizationMsg> loc_w;
  LatestWriter<PlannedPathMsg> path_w;
  std::unique_ptr<LidarScanMsg> scan = std::make_unique<LidarScanMsg>();
  Pose2 pose{};

  Rig() {
    static const std::vector<ParamSection> schema = role_schema(kRole);
    Config cfg = Config::defaults(schema);
    EXPECT_TRUE(cfg.set("tracker.backup_timeout_s=3").ok());
    auto r = RoleInstance::create(kRole, cfg, clock, "ugv1");
    EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().message);
    role = std::move(r).value();
    tracker = dynamic_cast<TrackerStage*>(role->stages()[0].stage.get());
    drive = dynamic_cast<DriveStage*>(role->stages()[1].stage.get());
    scan_w = role->channels().ring_writer(chan::kLidarScan).value();
    loc_w = role->channels().latest_writer(chan::kLocalization).value();
    path_w = role->channels().latest_writer(chan::kPlannedPath).value();
    auto p = std::make_unique<PlannedPathMsg>();
    p->seq = 1;
    p->status = RouteStatus::kOk;
    p->count = 2;
    p->points[0] = RoutePoint{0, 0};
    p->points[1] = RoutePoint{40, 0};
    path_w.publish(*p);
  }
  // 50 ms: a scan of `boxes` (world frame, the robot facing east) every other tick, tracker, drive, move.
  void tick(int k, const std::vector<test::Box>& world_boxes) {
    clock.set(clock.now() + 50 * kNsPerMs);
    LocalizationMsg m;
    m.stamp = clock.now();
    m.status = LocalizationStatus::kTracking;
    m.pose = pose;
    loc_w.publish(m);
    if (k % 2 == 0) {
      std::vector<test::Box> body;  // the boxes relative to the robot (it keeps heading close to east)
      for (const auto& b : world_boxes) body.push_back({b.x0 - pose.x, b.x1 - pose.x, b.y0 - pose.y, b.y1 - pose.y, b.h});
      const auto pts = test::scan(body, 0.6, 0.0, 0.0, kAzimuthStepDeg);
      scan->stamp = clock.now();
      scan->sensor_in_body = Pose3{0, 0, 0.6, 0, 0, -pose.yaw};  // the scan is cast level along east
      scan->count = static_cast<std::uint32_t>(pts.size());
      std::copy(pts.begin(), pts.end(), scan->points.begin());
      EXPECT_EQ(scan_w.push(*scan), 0U);
      tracker->step(clock.now());
    }
    drive->step(clock.now());
    const WheelCommandMsg& c = drive->published();
    const double v = 0.5 * (c.left_mps + c.right_mps), wz = (c.right_mps - c.left_mps) / 0.55, dt = 0.05;
    pose.x += v * dt * std::cos(pose.yaw + 0.5 * wz * dt);
    pose.y += v * dt * std::sin(pose.yaw + 0.5 * wz * dt);
    pose.yaw = wrap_angle(pose.yaw + wz * dt);
  }
};

TEST(TrackerDrive, ABoxTheMapMissedOnTheRouteStopsTheRobotBeforeIt) {
  Rig rig;
  const std::vector<test::Box> boxes{{10, 11, -0.8, 0.8, 1.0}};
  double closest = 1e9;
  for (int k = 0; k < 300; ++k) {  // 15 s: up to the box at 1.2 m/s, backing up for 3 s, then standing
    rig.tick(k, boxes);
    const double dx = std::max({10.0 - rig.pose.x, 0.0, rig.pose.x - 11.0}), dy = std::max({-0.8 - rig.pose.y, 0.0, rig.pose.y - 0.8});
    closest = std::min(closest, std::hypot(dx, dy));
  }
  EXPECT_GT(closest, 0.3) << "[m] closest approach to the box";
  EXPECT_GT(rig.pose.x, 7.0) << "it drove up to it";
  EXPECT_NEAR(rig.drive->published().v_mps, 0.0, 1e-9) << "and stands: the blocked route was cancelled";
  EXPECT_EQ(rig.tracker->published().state, static_cast<std::uint8_t>(TrackState::kFailed));
}

// Two scans queued, then steps with none (a driver on its own thread, as on the robot): the tracker takes
// the newest and then waits. It used to pop without front(), so the ring's reader overtook the writer:
// a stale scan came out, then size() wrapped and the step never returned (seen in the HIL run).
TEST(TrackerDrive, QueuedScansThenNoneTheNewestIsTakenAndTheStepReturns) {
  Rig rig;
  LocalizationMsg m;
  m.status = LocalizationStatus::kTracking;
  rig.loc_w.publish(m);
  const auto pts = test::scan({}, 0.6, 0.0, 0.0, kAzimuthStepDeg);
  for (TimeNs stamp : {TimeNs{100}, TimeNs{200}}) {
    rig.scan->stamp = stamp;
    rig.scan->sensor_in_body = Pose3{0, 0, 0.6, 0, 0, 0};
    rig.scan->count = static_cast<std::uint32_t>(pts.size());
    std::copy(pts.begin(), pts.end(), rig.scan->points.begin());
    ASSERT_EQ(rig.scan_w.push(*rig.scan), 0U);
  }
  for (int k = 1; k <= 5; ++k) {
    rig.clock.set(k * 100 * kNsPerMs);
    rig.tracker->step(rig.clock.now());
    EXPECT_EQ(rig.tracker->published().stamp, 200) << "step " << k << ": the newest scan, and nothing after it";
  }
  rig.scan->stamp = 300;
  ASSERT_EQ(rig.scan_w.push(*rig.scan), 0U);
  rig.tracker->step(rig.clock.now() + 100 * kNsPerMs);
  EXPECT_EQ(rig.tracker->published().stamp, 300);
}

TEST(TrackerDrive, AReturnRightAheadStopsTheWheelsAtOnce) {
  Rig rig;
  for (int k = 0; k < 60; ++k) rig.tick(k, {});
  ASSERT_GT(rig.drive->published().v_mps, 0.5);
  const double x = rig.pose.x;
  // Something steps in front of the robot.
  rig.tick(60, {{x + 0.5, x + 0.8, -0.2, 0.2, 0.8}});
  EXPECT_EQ(rig.drive->published().left_mps, 0.0) << "zero in the drive step after the scan";
  EXPECT_EQ(rig.drive->published().right_mps, 0.0);
  EXPECT_TRUE(rig.tracker->published().reflex_stop);
  EXPECT_EQ(rig.drive->reflex_stops(), 1U);
}

// The robot stopped facing a box at an angle (a parked car at the end of a row), the route clear beside it:
// the reflex holds it still for reflex_turn_after_s, then it turns on the spot toward the tracker's goal,
// never creeping forward into the box, and drives on. The drive stage used to halt both wheels for as
// long as the reflex held, so the robot stood there for ever (seen in a 5-robot study mission).
TEST(TrackerDrive, StoppedFacingABoxItTurnsAwayOnTheSpotAndDrivesOn) {
  Rig rig;
  rig.pose = Pose2{5.0, 0.0, 0.9};
  const std::vector<test::Box> box{{5.25, 5.65, 0.4, 0.75, 1.0}};
  double first_turn = -1, yaw_at_turn = 0;
  bool forward_while_reflex = false;
  for (int k = 0; k < 200; ++k) {  // 10 s
    const Pose2 before = rig.pose;
    rig.tick(k, box);
    const WheelCommandMsg& c = rig.drive->published();
    if (rig.tracker->published().reflex_stop && c.left_mps + c.right_mps > 1e-9) forward_while_reflex = true;
    if (first_turn < 0 && std::fabs(rig.pose.yaw - before.yaw) > 1e-6) {
      first_turn = (k + 1) * 0.05;
      yaw_at_turn = before.yaw;
    }
  }
  ASSERT_GE(first_turn, 0.0) << "it never turned: standing facing the box";
  EXPECT_GE(first_turn, 1.0 - 0.11) << "a standstill first";
  EXPECT_NEAR(yaw_at_turn, 0.9, 1e-6);
  EXPECT_FALSE(forward_while_reflex) << "never forward while the reflex holds";
  EXPECT_GT(rig.pose.x, 9.0) << "then on along the route";
}

TEST(TrackerDrive, AWallAcrossTheRouteAndBehindCancelsItAndStops) {
  Rig rig;
  const std::vector<test::Box> walls{{6, 6.5, -12, 12, 1.5}, {-1.5, -1.2, -12, 12, 1.5}};
  for (int k = 0; k < 400; ++k) rig.tick(k, walls);
  EXPECT_EQ(rig.tracker->published().state, static_cast<std::uint8_t>(TrackState::kFailed));
  EXPECT_GE(rig.tracker->published().failures, 1U);
  EXPECT_NEAR(rig.drive->published().v_mps, 0.0, 1e-9);
  EXPECT_LT(rig.pose.x, 6.0 - 0.3) << "stopped before the wall";
}

}  // namespace
}  // namespace ag::plan
