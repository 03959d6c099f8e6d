// Target mapping: vehicles found in labelled LiDAR points and fused per object by the EKF.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "airground/mission/targets.hpp"

namespace ag::mission {
namespace {

struct Car {
  double cx, cy, yaw;
};

// Returns of the robot's sensor (mounted 0.8 m up, 0.2 m ahead, level) on the cars' sides (all four; the
// points a real scan sees of the near sides are a subset) and on the ground around the robot.
std::vector<ScanReturn> scan(const Pose2& robot, const std::vector<Car>& cars, std::mt19937& rng) {
  std::vector<ScanReturn> out;
  std::normal_distribution<double> n(0.0, 0.02);
  const double ch = std::cos(robot.yaw), sh = std::sin(robot.yaw);
  auto add = [&](double mx, double my, double mz, std::uint8_t cls) {
    const double dx = mx - robot.x, dy = my - robot.y;
    const double bx = ch * dx + sh * dy, by = -sh * dx + ch * dy;
    ScanReturn r;
    r.x = static_cast<float>(bx - 0.2 + n(rng));
    r.y = static_cast<float>(by + n(rng));
    r.z = static_cast<float>(mz - 0.8);
    r.range = std::sqrt(r.x * r.x + r.y * r.y + r.z * r.z);
    r.cls = cls;
    out.push_back(r);
  };
  for (const Car& c : cars) {
    const double cc = std::cos(c.yaw), sc = std::sin(c.yaw);
    for (double u = -2.25; u <= 2.25; u += 0.1)
      for (double z = 0.2; z <= 1.4; z += 0.3)
        for (double side : {-1.0, 1.0}) add(c.cx + cc * u - sc * side, c.cy + sc * u + cc * side, z, 5);
    for (double v = -1.0; v <= 1.0; v += 0.1)
      for (double z = 0.2; z <= 1.4; z += 0.3)
        for (double end : {-2.25, 2.25}) add(c.cx + cc * end - sc * v, c.cy + sc * end + cc * v, z, 5);
  }
  for (double a = 0; a < 6.28; a += 0.05) add(robot.x + 5 * std::cos(a), robot.y + 5 * std::sin(a), 0.0, 0);
  // a few vehicle-labelled stray returns (mislabels): too few to be a detection
  add(robot.x + 8, robot.y - 8, 0.5, 5);
  add(robot.x + 8.1, robot.y - 8, 0.5, 5);
  return out;
}

const Pose3 kMount{0.2, 0, 0.8, 0, 0, 0};
const std::array<double, 9> kCov{0.09, 0, 0, 0, 0.09, 0, 0, 0, 0.01};

TEST(Targets, TwoParkedCarsAreTwoDetectionsAtTheirCentres) {
  std::mt19937 rng(1);
  const Pose2 robot{10, 5, 0.5};
  const std::vector<Car> cars = {{25, 12, 0.3}, {22, 22, 1.2}};
  const auto pts = scan(robot, cars, rng);
  VehicleDetector det(DetectorParams{});
  const auto d = det.detect(pts, kMount, robot, kCov);
  ASSERT_EQ(d.size(), 2U);
  for (const Car& c : cars) {
    double best = 1e9;
    for (const Detection& x : d) best = std::min(best, std::hypot(x.x - c.cx, x.y - c.cy));
    EXPECT_LT(best, 0.3);
  }
  for (const Detection& x : d) {
    EXPECT_GT(x.cxx, kCov[0]) << "the robot's own uncertainty is part of the detection's";
    EXPECT_GT(x.points, 100U);
  }
  // far away (beyond max_range_m): nothing
  const Pose2 far{-60, -60, 0};
  EXPECT_TRUE(det.detect(scan(far, cars, rng), kMount, far, kCov).empty());
  // only the two mislabelled returns near the robot: below min_points, no detection
  EXPECT_TRUE(det.detect(scan(robot, {}, rng), kMount, robot, kCov).empty());
}

TEST(Targets, TheEkfFusesDetectionsAndItsCovarianceShrinks) {
  std::mt19937 rng(2);
  std::normal_distribution<double> pose_noise(0.0, 0.3);
  const std::vector<Car> cars = {{25, 12, 0.3}, {60, 12, 0.0}};
  VehicleDetector det(DetectorParams{});
  ObjectTracker trk(TrackerParams{});
  double first_var = 0;
  for (int k = 0; k < 30; ++k) {
    const Pose2 truth{5.0 + k * 1.5, 5, 0.0};
    const Pose2 believed{truth.x + pose_noise(rng), truth.y + pose_noise(rng), truth.yaw};  // the localizer's error
    const auto pts = scan(truth, cars, rng);
    for (const Detection& d : det.detect(pts, kMount, believed, kCov)) {
      const int i = trk.update(d, from_seconds(k * 0.5));
      ASSERT_GE(i, 0);
      if (k == 0 && first_var == 0) first_var = trk.objects()[static_cast<std::size_t>(i)].cxx;
    }
  }
  ASSERT_EQ(trk.objects().size(), 2U) << "one object per car, every detection associated";
  for (std::size_t i = 0; i < 2; ++i) {
    const TrackedObject& o = trk.objects()[i];
    const Car& c = std::hypot(o.x - cars[0].cx, o.y - cars[0].cy) < 5 ? cars[0] : cars[1];
    EXPECT_LT(std::hypot(o.x - c.cx, o.y - c.cy), 0.35) << "fused estimate of car at " << c.cx << ": " << o.x << ", " << o.y << " after " << o.detections;
    EXPECT_GT(o.detections, 5U);
    EXPECT_TRUE(trk.confirmed(i));
    EXPECT_LT(o.cxx, first_var / 4) << "the covariance shrank";
    EXPECT_GT(o.cxx * o.cyy - o.cxy * o.cxy, 0) << "stays positive definite";
    // the shared record carries the estimate
    std::array<std::uint8_t, 64> buf{};
    ObjectRecord back;
    ASSERT_EQ(decode(std::span<const std::uint8_t>(buf.data(), encode(trk.record(i), buf)), back), DecodeError::kOk);
    EXPECT_EQ(back.object_id, o.id);
    EXPECT_NEAR(back.x, o.x, 1e-4);
  }
}

TEST(Targets, GatingKeepsNearbyCarsApartAndCapacityIsCounted) {
  TrackerParams p;
  p.max_objects = 2;
  ObjectTracker trk(p);
  Detection a{10, 10, 0.1, 0, 0.1, 100, 10};
  Detection b{14, 10, 0.1, 0, 0.1, 100, 10};  // 4 m away: inside gate_max_m but far outside the Mahalanobis gate
  Detection c{40, 10, 0.1, 0, 0.1, 100, 10};
  EXPECT_EQ(trk.update(a, 0), 0);
  EXPECT_EQ(trk.update(b, 0), 1);
  EXPECT_EQ(trk.update(a, from_seconds(1)), 0);
  EXPECT_EQ(trk.update(c, 0), -1);
  EXPECT_EQ(trk.dropped(), 1U);
  Detection nan{std::nan(""), 0, 1, 0, 1, 10, 1};
  EXPECT_EQ(trk.update(nan, 0), -1);
  EXPECT_EQ(trk.dropped(), 2U);
}

}  // namespace
}  // namespace ag::mission
