// Scan labelling: channels of the two labellings, ground truth passing through, and the geometric
// obstacle / ground split against the ground truth of ray-cast scans.
#include <gtest/gtest.h>

#include <cstdio>
#include <vector>

#include "airground/localization/scan_labeller.hpp"
#include "synthetic_world.hpp"

namespace ag::loc {
namespace {

bool is_obstacle_class(std::uint8_t c) {
  return c == raw(ClassId::kTree) || c == raw(ClassId::kBuilding) || c == raw(ClassId::kVehicle);
}

TEST(LocalizationChannels, PerClassAndTwoClass) {
  const LocalizationChannels pc = LocalizationChannels::per_class();
  EXPECT_EQ(pc.count(), 6);  // water has weight 0
  EXPECT_EQ(pc.scan_channel(raw(ClassId::kWater)), -1);
  EXPECT_EQ(pc.scan_channel(255), -1);
  const int road = pc.scan_channel(raw(ClassId::kRoad));
  EXPECT_EQ(pc.map_sources(raw(ClassId::kRoad)), 1U << road);
  EXPECT_FLOAT_EQ(pc.weight(road), 2.0F);  // config/classes.yaml
  EXPECT_EQ(pc.name(road), "road");
  EXPECT_EQ(pc.map_sources(255), 0U);

  const LocalizationChannels tc = LocalizationChannels::two_class();
  EXPECT_EQ(tc.count(), 3);  // ground, obstacle, obstacle faces (obstacle points while tracking)
  EXPECT_EQ(tc.fine_scan_channel(raw(kObstacleLabel)), 2);
  EXPECT_EQ(tc.fine_scan_channel(raw(kGroundLabel)), 0);
  EXPECT_EQ(tc.map_sources(raw(ClassId::kTree)), 6U);
  EXPECT_EQ(LocalizationChannels::two_class(1.0, 1.5, false).count(), 2);
  EXPECT_EQ(tc.scan_channel(raw(kGroundLabel)), 0);
  EXPECT_EQ(tc.scan_channel(raw(kObstacleLabel)), 1);
  EXPECT_EQ(tc.map_sources(raw(ClassId::kGrass)), 1U);
  EXPECT_EQ(tc.map_sources(raw(ClassId::kVehicle)), 6U);
  EXPECT_EQ(tc.map_sources(raw(ClassId::kWater)), 1U);  // flat: what a LiDAR gets back from water is ground
}

TEST(GroundTruthLabeller, ClassesPassThroughAndUnknownIdsBecome255) {
  GroundTruthLabeller l;
  std::vector<ScanPoint> pts(4);
  pts[0].cls = 0;
  pts[1].cls = 6;
  pts[2].cls = 7;  // not in the table
  pts[3].cls = 255;
  l.label(pts, 1, 4);
  EXPECT_EQ(pts[0].cls, 0);
  EXPECT_EQ(pts[1].cls, 6);
  EXPECT_EQ(pts[2].cls, 255);
  EXPECT_EQ(pts[3].cls, 255);
}

TEST(GeometricLabeller, FlatGroundIsGroundAndAWallIsObstacle) {
  // 16 rings from +10 deg down to -20 deg in 2 deg steps over flat ground 0.7 m below the sensor, and a
  // wall 8 m away in columns 0..9 (upward rings see nothing elsewhere).
  std::vector<ScanPoint> pts;
  const int rings = 16, cols = 64;
  for (int c = 0; c < cols; ++c)
    for (int ring = 0; ring < rings; ++ring) {
      const double alt = (10.0 - ring * 2.0) * kPi / 180.0, az = 2.0 * kPi * c / cols;
      double t = alt < -1e-9 ? 0.7 / -std::tan(alt) : 1e9;  // horizontal distance to the ground
      double z = -0.7;
      if (c < 10 && t > 8.0) {
        t = 8.0;
        z = std::tan(alt) * 8.0;
      }
      if (t > 100.0) continue;
      ScanPoint p;
      p.x = static_cast<float>(t * std::cos(az));
      p.y = static_cast<float>(t * std::sin(az));
      p.z = static_cast<float>(z);
      p.range = static_cast<float>(std::hypot(t, z));
      p.ring = static_cast<std::uint16_t>(ring);
      p.col = static_cast<std::uint16_t>(c);
      pts.push_back(p);
    }
  GeometricLabeller l(GeometricLabelParams{}, 64, 64);
  l.label(pts, rings, cols);
  int wall = 0, wall_obstacle = 0, ground = 0, ground_ok = 0;
  for (const ScanPoint& p : pts) {
    const bool on_wall = std::hypot(p.x, p.y) > 7.99F && std::hypot(p.x, p.y) < 8.01F && p.z > -0.65F;
    if (on_wall) {
      ++wall;
      wall_obstacle += p.cls == raw(kObstacleLabel) ? 1 : 0;
    } else if (p.col >= 12 && p.col <= 60) {
      ++ground;
      ground_ok += p.cls == raw(kGroundLabel) ? 1 : 0;
    }
  }
  EXPECT_EQ(wall, 80);
  EXPECT_GE(wall_obstacle, wall - 10) << "all but the foot of the wall";
  EXPECT_EQ(ground_ok, ground);
}

TEST(GeometricLabeller, AgreesWithTheGroundTruthOfRayCastScans) {
  const test::SyntheticWorld w = test::make_world(6, 6, 17);
  test::LidarModel m;
  m.rings = 64;
  m.columns = 1024;
  GeometricLabeller l(GeometricLabelParams{}, 64, 1024);
  std::vector<ScanPoint> scan;
  std::uint64_t n = 0, agree = 0, obst = 0, obst_found = 0;
  for (std::size_t i = 0; i < 4; ++i) {
    const Pose2 pose{w.road_x[i % w.road_x.size()] + 1.0, w.road_y[(i + 1) % w.road_y.size()] + 10.0, 0.4 * static_cast<double>(i)};
    test::ray_cast(w, pose, m, i, scan);
    std::vector<std::uint8_t> truth;
    for (const ScanPoint& p : scan) truth.push_back(p.cls);
    l.label(scan, m.rings, m.columns);
    for (std::size_t k = 0; k < scan.size(); ++k) {
      const bool want = is_obstacle_class(truth[k]);
      const bool got = scan[k].cls == raw(kObstacleLabel);
      ASSERT_TRUE(got || scan[k].cls == raw(kGroundLabel));
      ++n;
      agree += want == got ? 1 : 0;
      obst += want ? 1 : 0;
      obst_found += want && got ? 1 : 0;
    }
  }
  const double accuracy = static_cast<double>(agree) / static_cast<double>(n);
  const double recall = static_cast<double>(obst_found) / static_cast<double>(obst);
  std::printf("geometric labelling vs ground truth: %llu points, accuracy %.3f, obstacle recall %.3f\n",
              static_cast<unsigned long long>(n), accuracy, recall);
  EXPECT_GT(obst, n / 20) << "the scans must see obstacles";
  EXPECT_GT(accuracy, 0.95);
  EXPECT_GT(recall, 0.9);
}

TEST(GeometricLabeller, ScansLargerThanItsBuffersAreLeftUnknown) {
  GeometricLabeller l(GeometricLabelParams{}, 8, 8);
  std::vector<ScanPoint> pts(3);
  for (auto& p : pts) {
    p.range = 5.0F;
    p.cls = 0;
  }
  l.label(pts, 16, 8);
  for (const auto& p : pts) EXPECT_EQ(p.cls, 255);
}

}  // namespace
}  // namespace ag::loc
