// The polar scan render: which bin a point lands in, channel counts, the mount offset, the sparse bin
// list the filter walks, and range-bin sizes.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "airground/localization/polar_render.hpp"
#include "synthetic_world.hpp"

namespace ag::loc {
namespace {

ScanPoint at(double range, double angle_deg, ClassId cls, double z = 0.0) {
  ScanPoint p;
  const double a = angle_deg * kPi / 180.0;
  p.x = static_cast<float>(range * std::cos(a));
  p.y = static_cast<float>(range * std::sin(a));
  p.z = static_cast<float>(z);
  p.range = static_cast<float>(range);
  p.cls = raw(cls);
  return p;
}

TEST(ScanRenderPolar, PointsLandInTheirAngleAndRangeBins) {
  const LocalizationChannels ch = LocalizationChannels::per_class();
  ScanRenderPolar r(PolarRenderParams{}, ch);
  const int road = ch.scan_channel(raw(ClassId::kRoad)), building = ch.scan_channel(raw(ClassId::kBuilding));
  ASSERT_GE(road, 0);
  ASSERT_GE(building, 0);
  std::vector<ScanPoint> pts{
      at(5.5, 1.0, ClassId::kRoad),        // angle bin 0 (3.6 deg each), range bin 5 at 1 m
      at(5.6, 2.0, ClassId::kRoad),        // same bin
      at(5.7, 3.0, ClassId::kBuilding),    // same bin, other channel
      at(10.2, 90.0 + 1.0, ClassId::kRoad),   // 91 deg: angle bin 25, range bin 10
      at(3.5, -1.0, ClassId::kTree),       // 359 deg: angle bin 99, range bin 3
      at(0.5, 45.0, ClassId::kRoad),       // too close (min 1 m)
      at(30.0, 45.0, ClassId::kRoad),      // beyond 25 bins x 1 m
      at(5.0, 45.0, ClassId::kWater),      // water: no channel (weight 0)
      at(5.0, 45.0, ClassId::kUnknown),    // unknown label: not counted
      at(5.0, 45.0, ClassId::kRoad, 30.0), // above max height
  };
  r.render(pts, 1.0);
  EXPECT_EQ(r.count(0, 5, road), 2);
  EXPECT_EQ(r.count(0, 5, building), 1);
  EXPECT_EQ(r.count(25, 10, road), 1);
  EXPECT_EQ(r.count(99, 3, ch.scan_channel(raw(ClassId::kTree))), 1);
  EXPECT_EQ(r.points_counted(), 5U);
  EXPECT_EQ(r.used_range_bins(), 11);
  ASSERT_EQ(r.bins().size(), 3U);
  // the sparse list: bins in angle-major order, entries carry count x weight
  const auto& b0 = r.bins()[0];
  EXPECT_EQ(b0.angle, 0);
  EXPECT_EQ(b0.range, 5);
  ASSERT_EQ(b0.entries, 2U);
  EXPECT_FLOAT_EQ(b0.weight, 2 * ch.weight(road) + ch.weight(building));
  EXPECT_FLOAT_EQ(r.entries()[b0.first].value, 2 * ch.weight(road));
  EXPECT_NEAR(r.total_weight(), 3 * ch.weight(road) + ch.weight(building) + ch.weight(ch.scan_channel(raw(ClassId::kTree))), 1e-5);

  // Wider range bins: the 30 m point now counts (range bin 7 at 4 m).
  r.render(pts, 4.0);
  EXPECT_EQ(r.count(12, 7, road), 1);  // 45 deg: bin 12
  EXPECT_EQ(r.count(0, 1, road), 2);
  EXPECT_EQ(r.points_counted(), 6U);
}

TEST(ScanRenderPolar, MountOffsetAndCountCap) {
  const LocalizationChannels ch = LocalizationChannels::per_class();
  PolarRenderParams p;
  p.sensor_in_body = Pose2{1.0, 0.0, kPi / 2};  // 1 m forward, looking left
  p.max_count_per_bin = 3;
  ScanRenderPolar r(p, ch);
  const int road = ch.scan_channel(raw(ClassId::kRoad));
  std::vector<ScanPoint> pts;
  for (int i = 0; i < 10; ++i) pts.push_back(at(4.0, 0.0, ClassId::kRoad));  // sensor forward = body left
  r.render(pts, 1.0);
  // body point (1, 4): range 4.12 m, angle 75.96 deg -> bin 21
  EXPECT_EQ(r.count(21, 4, road), 3);
  EXPECT_EQ(r.points_counted(), 3U);
}

TEST(ScanRenderPolar, TwoClassChannelsCountGroupsOfLabels) {
  const LocalizationChannels ch = LocalizationChannels::two_class();
  ScanRenderPolar r(PolarRenderParams{}, ch);
  std::vector<ScanPoint> pts{at(5.5, 1.0, ClassId::kRoad), at(5.5, 1.0, ClassId::kGrass), at(5.5, 1.0, ClassId::kDirt),
                             at(5.5, 1.0, ClassId::kTree), at(5.5, 1.0, ClassId::kBuilding), at(5.5, 1.0, ClassId::kVehicle),
                             at(5.5, 1.0, ClassId::kWater)};
  r.render(pts, 1.0);  // fine bins: obstacles count into the faces
  EXPECT_EQ(r.count(0, 5, 0), 4);  // road, grass, dirt and water: flat
  EXPECT_EQ(r.count(0, 5, 1), 0);
  EXPECT_EQ(r.count(0, 5, 2), 3);
  r.render(pts, 2.0);  // coarse bins (converging): into the regions
  EXPECT_EQ(r.count(0, 2, 0), 4);
  EXPECT_EQ(r.count(0, 2, 1), 3);
  EXPECT_EQ(r.count(0, 2, 2), 0);
}

TEST(ScanRenderPolar, ARayCastScanFillsTheNearBinsAllAround) {
  const test::SyntheticWorld w = test::make_world(4, 4, 3);
  std::vector<ScanPoint> scan;
  test::LidarModel m;
  m.rings = 32;
  m.columns = 512;
  test::ray_cast(w, Pose2{w.road_x[1], w.road_y[1], 0.3}, m, 1, scan);
  ASSERT_GT(scan.size(), 5000U);
  const LocalizationChannels ch = LocalizationChannels::per_class();
  ScanRenderPolar r(PolarRenderParams{}, ch);
  r.render(scan, 1.0);
  // every angle bin sees the road within a few metres of a crossing
  const int road = ch.scan_channel(raw(ClassId::kRoad));
  for (int a = 0; a < r.angle_bins(); ++a) {
    int n = 0;
    for (int k = 1; k < 4; ++k) n += r.count(a, k, road);
    EXPECT_GT(n, 0) << "angle bin " << a;
  }
  // the bins' counts add up to the points counted
  std::uint64_t total = 0;
  for (int a = 0; a < r.angle_bins(); ++a)
    for (int k = 0; k < r.range_bins(); ++k)
      for (int c = 0; c < ch.count(); ++c) total += r.count(a, k, c);
  EXPECT_EQ(total, r.points_counted());
}

}  // namespace
}  // namespace ag::loc
