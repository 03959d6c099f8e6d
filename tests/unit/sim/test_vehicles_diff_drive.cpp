// Tests of the differential-drive robot: kinematics, limits, collisions with blocked cells, curbs, config.
#include <gtest/gtest.h>

#include <opencv2/core.hpp>

#include <cmath>

#include "airground/sim/diff_drive.hpp"

namespace ag::sim {
namespace {

// A flat road world of 100 x 100 m at 0.25 m/cell, origin at the south-west corner (0, 0).
World flat_world() {
  World w;
  w.header.grid.resolution = 0.25;
  w.header.grid.width = 400;
  w.header.grid.height = 400;
  w.header.grid.origin_x = 0.0;
  w.header.grid.origin_y = 100.0;
  w.class_id = cv::Mat(400, 400, CV_8UC1, cv::Scalar(raw(ClassId::kRoad)));
  w.height = cv::Mat(400, 400, CV_32FC1, cv::Scalar(0.0));
  w.terrain = cv::Mat(400, 400, CV_32FC1, cv::Scalar(0.0));
  w.albedo = cv::Mat(400, 400, CV_8UC3, cv::Scalar(128, 128, 128));
  return w;
}

// Fills the map-frame rectangle [x0, x1) x [y0, y1) with a class and an object height.
void fill(World& w, double x0, double y0, double x1, double y1, ClassId c, float h) {
  const GridGeometry& g = w.grid();
  for (int r = g.row(y1 - 1e-9); r <= g.row(y0 + 1e-9); ++r)
    for (int col = g.col(x0); col <= g.col(x1 - 1e-9); ++col) {
      w.class_id.at<std::uint8_t>(r, col) = raw(c);
      w.height.at<float>(r, col) = h;
    }
}

constexpr double kDt = 0.01;

void run(DiffDriveRobot& robot, const World& w, double seconds) {
  for (int i = 0; i < static_cast<int>(std::lround(seconds / kDt)); ++i) robot.step(kDt, w);
}

TEST(DiffDrive, DrivesStraightAtTheCommandedSpeed) {
  const World w = flat_world();
  DiffDriveConfig c;
  c.command_timeout_s = 0;
  DiffDriveRobot robot(c, Pose2{10, 50, 0});
  robot.command_twist(1.0, 0.0);
  run(robot, w, 5.0);
  // 0.5 s of acceleration at 2 m/s^2 (0.25 m) then 4.5 s at 1 m/s.
  EXPECT_NEAR(robot.pose().x, 10.0 + 0.25 + 4.5, 0.02);
  EXPECT_NEAR(robot.pose().y, 50.0, 1e-12);
  EXPECT_NEAR(robot.linear_speed(), 1.0, 1e-12);
  EXPECT_NEAR(robot.wheel_left_rad_s(), 1.0 / c.wheel_radius_m, 1e-9);
  EXPECT_NEAR(robot.wheel_right_rad_s(), 1.0 / c.wheel_radius_m, 1e-9);
  EXPECT_NEAR(robot.distance_travelled(), 4.75, 0.02);
  EXPECT_EQ(robot.collisions(), 0u);
}

TEST(DiffDrive, TurnsOnAnArcAndInPlace) {
  const World w = flat_world();
  DiffDriveConfig c;
  c.command_timeout_s = 0;
  c.max_linear_accel_mps2 = 1000;  // start at speed so the arc is exact
  c.max_angular_accel_radps2 = 1000;
  DiffDriveRobot robot(c, Pose2{50, 50, 0});
  // Wheels at v -+ w*W/2 give radius v/omega = 2 m: a half circle ends 4 m to the left.
  robot.command_twist(1.0, 0.5);
  run(robot, w, kPi / 0.5);
  EXPECT_NEAR(robot.pose().x, 50.0, 0.01);  // 628 steps of 10 ms: 6.28 s, not quite pi / 0.5
  EXPECT_NEAR(robot.pose().y, 54.0, 0.01);
  EXPECT_NEAR(std::abs(robot.pose().yaw), kPi, 0.01);
  EXPECT_NEAR(std::hypot(robot.pose().x - 50.0, robot.pose().y - 52.0), 2.0, 1e-9);  // on the circle
  // Turning in place: the centre does not move.
  DiffDriveRobot spin(c, Pose2{50, 50, 0});
  spin.command_wheels(-5.0, 5.0);
  run(spin, w, 1.0);
  EXPECT_NEAR(spin.pose().x, 50.0, 1e-12);
  EXPECT_NEAR(spin.pose().y, 50.0, 1e-12);
  EXPECT_NEAR(spin.yaw_rate(), 2 * 5.0 * c.wheel_radius_m / c.track_width_m, 1e-9);
  EXPECT_NEAR(spin.pose().yaw, wrap_angle(spin.yaw_rate() * 1.0), 1e-6);
}

TEST(DiffDrive, SpeedAndAccelerationLimitsHold) {
  const World w = flat_world();
  DiffDriveConfig c;
  c.command_timeout_s = 0;
  DiffDriveRobot robot(c, Pose2{5, 50, 0});
  robot.command_wheels(100.0, 100.0);  // far above the limit
  double last_v = 0, last_om = 0;
  for (int i = 0; i < 300; ++i) {
    robot.step(kDt, w);
    EXPECT_LE(std::abs(robot.wheel_left_rad_s()), c.max_wheel_speed_rad_s + 1e-9);
    EXPECT_LE(std::abs(robot.wheel_right_rad_s()), c.max_wheel_speed_rad_s + 1e-9);
    EXPECT_LE(std::abs(robot.linear_speed() - last_v), c.max_linear_accel_mps2 * kDt + 1e-9);
    last_v = robot.linear_speed();
  }
  EXPECT_NEAR(robot.linear_speed(), 2.0, 1e-9);  // Jackal top speed
  // Full reverse on one wheel: angular acceleration is limited, wheels stay within their limit.
  robot.command_wheels(-100.0, 100.0);
  for (int i = 0; i < 300; ++i) {
    robot.step(kDt, w);
    EXPECT_LE(std::abs(robot.yaw_rate() - last_om), c.max_angular_accel_radps2 * kDt + 1e-9);
    EXPECT_LE(std::abs(robot.wheel_left_rad_s()), c.max_wheel_speed_rad_s + 1e-9);
    EXPECT_LE(std::abs(robot.wheel_right_rad_s()), c.max_wheel_speed_rad_s + 1e-9);
    last_om = robot.yaw_rate();
  }
}

TEST(DiffDrive, StopsWhenCommandsTimeOut) {
  const World w = flat_world();
  DiffDriveRobot robot(DiffDriveConfig{}, Pose2{10, 50, 0});
  robot.command_twist(1.0, 0.0);
  run(robot, w, 0.4);
  EXPECT_GT(robot.linear_speed(), 0.7);
  run(robot, w, 1.0);  // timeout 0.5 s, then braking at 2 m/s^2
  EXPECT_EQ(robot.linear_speed(), 0.0);
}

TEST(DiffDrive, BuildingStopsTheRobotAndCountsOnce) {
  World w = flat_world();
  fill(w, 20.0, 0.0, 30.0, 100.0, ClassId::kBuilding, 10.0f);
  DiffDriveConfig c;
  c.command_timeout_s = 0;
  DiffDriveRobot robot(c, Pose2{10, 50, 0});
  robot.command_twist(1.5, 0.0);
  run(robot, w, 20.0);  // keeps pushing into the wall
  // The footprint (0.3 m) stops short of the wall at x = 20.
  EXPECT_LT(robot.pose().x, 20.0 - c.footprint_radius_m);
  EXPECT_GT(robot.pose().x, 20.0 - c.footprint_radius_m - 0.05);
  EXPECT_EQ(robot.collisions(), 1u);
  EXPECT_GT(robot.collision_steps(), 100u);
  EXPECT_TRUE(robot.in_collision());
  EXPECT_EQ(robot.wheel_left_rad_s(), 0.0);
  // Backing off frees it; driving in again is a second collision.
  robot.command_twist(-1.0, 0.0);
  run(robot, w, 1.0);
  EXPECT_FALSE(robot.in_collision());
  robot.command_twist(1.0, 0.0);
  run(robot, w, 3.0);
  EXPECT_EQ(robot.collisions(), 2u);
}

TEST(DiffDrive, EveryBlockingClassStopsAndOthersDoNot) {
  for (const ClassId cls : {ClassId::kTree, ClassId::kVehicle, ClassId::kWater}) {
    World w = flat_world();
    fill(w, 20.0, 49.0, 20.5, 51.0, cls, 0.0f);
    DiffDriveConfig c;
    c.command_timeout_s = 0;
    DiffDriveRobot robot(c, Pose2{15, 50, 0});
    robot.command_twist(1.0, 0.0);
    run(robot, w, 10.0);
    EXPECT_EQ(robot.collisions(), 1u) << int(raw(cls));
    EXPECT_LT(robot.pose().x, 20.0);
  }
  for (const ClassId cls : {ClassId::kGrass, ClassId::kDirt, ClassId::kUnknown}) {
    World w = flat_world();
    fill(w, 20.0, 49.0, 20.5, 51.0, cls, 0.0f);
    DiffDriveConfig c;
    c.command_timeout_s = 0;
    DiffDriveRobot robot(c, Pose2{15, 50, 0});
    robot.command_twist(1.0, 0.0);
    run(robot, w, 10.0);
    EXPECT_EQ(robot.collisions(), 0u) << int(raw(cls));
    EXPECT_GT(robot.pose().x, 24.0);
  }
  // A class can be made passable.
  World w = flat_world();
  fill(w, 20.0, 49.0, 20.5, 51.0, ClassId::kWater, 0.0f);
  DiffDriveConfig c;
  c.command_timeout_s = 0;
  c.block_water = false;
  DiffDriveRobot robot(c, Pose2{15, 50, 0});
  robot.command_twist(1.0, 0.0);
  run(robot, w, 10.0);
  EXPECT_EQ(robot.collisions(), 0u);
}

TEST(DiffDrive, CrossesACurbButNotAStep) {
  World w = flat_world();
  fill(w, 20.0, 0.0, 100.0, 100.0, ClassId::kRoad, 0.15f);  // a 15 cm curb up onto a raised pavement
  DiffDriveConfig c;
  c.command_timeout_s = 0;
  DiffDriveRobot robot(c, Pose2{15, 50, 0});
  robot.command_twist(1.0, 0.0);
  run(robot, w, 10.0);
  EXPECT_EQ(robot.collisions(), 0u);
  EXPECT_GT(robot.pose().x, 24.0);
  EXPECT_NEAR(robot.pose3().z, 0.15, 1e-6);  // on top of it

  World wall = flat_world();
  fill(wall, 20.0, 0.0, 100.0, 100.0, ClassId::kRoad, 0.4f);  // 40 cm: too high
  DiffDriveRobot blocked(c, Pose2{15, 50, 0});
  blocked.command_twist(1.0, 0.0);
  run(blocked, wall, 10.0);
  EXPECT_EQ(blocked.collisions(), 1u);
  EXPECT_LT(blocked.pose().x, 20.0);
  // Coming down a 40 cm drop is not blocked.
  DiffDriveRobot down(c, Pose2{25, 50, kPi});
  down.command_twist(1.0, 0.0);
  run(down, wall, 10.0);
  EXPECT_EQ(down.collisions(), 0u);
  EXPECT_LT(down.pose().x, 20.0);
}

TEST(DiffDrive, PlacedAgainstATreeItCanOnlyLeave) {
  World w = flat_world();
  fill(w, 50.0, 49.0, 51.0, 51.0, ClassId::kTree, 8.0f);
  DiffDriveConfig c;
  c.command_timeout_s = 0;
  DiffDriveRobot into(c, Pose2{49.9, 50, 0});  // footprint already over the trunk
  EXPECT_FALSE(into.footprint_free(w, 49.9, 50, 0.0));
  into.command_twist(0.5, 0.0);
  run(into, w, 2.0);
  EXPECT_EQ(into.collisions(), 1u);
  // It may move within the cells it already covers, never into the next one (x + 0.3 < 50.25).
  EXPECT_LE(into.pose().x, 49.95 + 1e-9);
  DiffDriveRobot away(c, Pose2{49.9, 50, kPi});
  away.command_twist(0.5, 0.0);
  run(away, w, 2.0);
  EXPECT_EQ(away.collisions(), 0u);
  EXPECT_LT(away.pose().x, 49.0);
  EXPECT_TRUE(away.footprint_free(w, away.pose().x, away.pose().y, 0.0));
}

TEST(DiffDrive, WorldEdgeIsAWallAndSlopeTiltsTheBody) {
  World w = flat_world();
  DiffDriveConfig c;
  c.command_timeout_s = 0;
  DiffDriveRobot robot(c, Pose2{98, 50, 0});
  robot.command_twist(1.0, 0.0);
  run(robot, w, 5.0);
  EXPECT_EQ(robot.collisions(), 1u);
  EXPECT_LT(robot.pose().x, 100.0 - c.footprint_radius_m);
  // A 10% slope up to the east: nose up is negative pitch (REP-103).
  for (int col = 0; col < 400; ++col)
    for (int r = 0; r < 400; ++r) w.terrain.at<float>(r, col) = static_cast<float>(0.1 * (col + 0.5) * 0.25);
  DiffDriveRobot climber(c, Pose2{50, 50, 0});
  climber.command_twist(0.5, 0.0);
  run(climber, w, 2.0);
  EXPECT_NEAR(climber.pose3().pitch, -std::atan(0.1), 0.02);
  EXPECT_NEAR(climber.pose3().roll, 0.0, 1e-9);
  EXPECT_NEAR(climber.pose3().z, 0.1 * climber.pose().x, 0.03);
}

TEST(DiffDriveConfigYaml, LoadsAndValidatesEveryKey) {
  auto ok = load_diff_drive_config("footprint_radius_m: 0.35\nblock_water: false\n", "drive.yaml");
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  EXPECT_DOUBLE_EQ(ok->footprint_radius_m, 0.35);
  EXPECT_FALSE(ok->block_water);
  EXPECT_DOUBLE_EQ(ok->track_width_m, 0.37);
  auto unknown = load_diff_drive_config("footprint: 0.3\n", "drive.yaml");
  ASSERT_FALSE(unknown.ok());
  EXPECT_NE(unknown.error().message.find("diff_drive.footprint"), std::string::npos);
  auto range = load_diff_drive_config("max_linear_accel_mps2: 0\n", "drive.yaml");
  ASSERT_FALSE(range.ok());
  EXPECT_NE(range.error().message.find("[0.01, 100] m/s^2"), std::string::npos) << range.error().message;
  auto type = load_diff_drive_config("block_tree: 3\n", "drive.yaml");
  EXPECT_FALSE(type.ok());
}

}  // namespace
}  // namespace ag::sim
