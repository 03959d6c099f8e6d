// The ortho-map's cells and tiles: elevation, class and colour rules, versions, and rebuilding only the
// tiles a corrected keyframe touched.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <vector>

#include "airground/aerial_mapping/ortho_map.hpp"
#include "airground/messages/classes.hpp"

namespace ag::mapping {
namespace {

Eigen::Isometry3d nadir_at(double x, double y, double z) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.translation() = Eigen::Vector3d(x, y, z);
  // camera z (optical axis) down, x east, y south
  t.linear() << 1, 0, 0, 0, -1, 0, 0, 0, -1;
  return t;
}

// A square of points on the plane z = h, 16 per 0.5 m cell, centred on (cx, cy), half-size r metres.
std::vector<MapPoint> square(double cx, double cy, double r, double h, std::uint8_t cls, float cos_axis = 0.99F) {
  std::vector<MapPoint> pts;
  for (double y = cy - r + 0.0625; y < cy + r; y += 0.125)
    for (double x = cx - r + 0.0625; x < cx + r; x += 0.125)
      pts.push_back(MapPoint{static_cast<float>(x), static_cast<float>(y), static_cast<float>(h), 100, 110, 120, cls, cos_axis});
  return pts;
}

TEST(OrthoMap, CellTakesTheMeanElevationAndTheClassOfTheMostCentralView) {
  OrthoMap map;
  map.add_keyframe(0, nadir_at(0, 0, 40), square(0, 0, 4, 1.0, 0, 0.90F));
  map.add_keyframe(1, nadir_at(0, 0, 40), square(0, 0, 4, 1.4, 2, 0.99F));  // more central: its class wins
  map.add_keyframe(2, nadir_at(0, 0, 40), square(0, 0, 4, 1.2, 1, 0.95F));
  const Cell* c = map.cell_at(0.25, 0.25);
  ASSERT_NE(c, nullptr);
  EXPECT_NEAR(c->elevation(), 1.2, 1e-4);
  EXPECT_EQ(c->count, 48u);
  EXPECT_EQ(c->cls, 2);
  EXPECT_EQ(map.cell_at(50, 50), nullptr);
}

TEST(OrthoMap, UnknownNeverOverwritesAClass) {
  OrthoMap map;
  map.add_keyframe(0, nadir_at(0, 0, 40), square(0, 0, 2, 0.0, 4, 0.5F));
  map.add_keyframe(1, nadir_at(0, 0, 40), square(0, 0, 2, 0.0, 255, 1.0F));  // better view, but unknown
  const Cell* c = map.cell_at(0.1, 0.1);
  ASSERT_NE(c, nullptr);
  EXPECT_EQ(c->cls, 4);
  // ... while a known class from a better view does replace it.
  map.add_keyframe(2, nadir_at(0, 0, 40), square(0, 0, 2, 0.0, 0, 1.0F));
  EXPECT_EQ(map.cell_at(0.1, 0.1)->cls, 0);
}

TEST(OrthoMap, WrongMatchesInACellDoNotDragItsElevation) {
  OrthoMap map;
  auto pts = square(0, 0, 1, 2.0, 0);
  // A quarter of the points of every cell 20 m too high (a wrong stereo match).
  for (std::size_t i = 0; i < pts.size(); i += 4) pts[i].z = 22.0F;
  map.add_keyframe(0, nadir_at(0, 0, 40), pts);
  const Cell* c = map.cell_at(0.25, 0.25);
  ASSERT_NE(c, nullptr);
  EXPECT_NEAR(c->elevation(), 2.0, 1e-3);
}

// A road cell beside a wall: most of its points in this keyframe are roof points projected a little
// too far (labelled building, 10 m up), the most central labelled point is road.
std::vector<MapPoint> road_cell_with_roof_spill() {
  std::vector<MapPoint> pts;
  for (int i = 0; i < 20; ++i) {
    const float x = 0.05F + 0.02F * static_cast<float>(i), y = 0.25F;
    const bool roof = i % 5 < 3;  // 60 %
    pts.push_back(MapPoint{x, y, roof ? 10.0F : 0.0F, 90, 90, 90, static_cast<std::uint8_t>(roof ? 4 : 0), roof ? 0.97F : 0.99F});
  }
  return pts;
}

TEST(OrthoMap, CellHeightComesFromThePointsOfItsOwnKind) {
  OrthoMap map;
  map.add_keyframe(0, nadir_at(0, 0, 40), road_cell_with_roof_spill());
  const Cell* c = map.cell_at(0.25, 0.25);
  ASSERT_NE(c, nullptr);
  EXPECT_EQ(c->cls, 0);
  EXPECT_NEAR(c->elevation(), 0.0, 1e-4);
  // ASOOM's rule (every point counts) takes the roof's height for the road.
  OrthoMapParams p;
  p.class_consistent_elevation = false;
  OrthoMap plain(p);
  plain.add_keyframe(0, nadir_at(0, 0, 40), road_cell_with_roof_spill());
  EXPECT_NEAR(plain.cell_at(0.25, 0.25)->elevation(), 10.0, 1e-4);
}

TEST(OrthoMap, ClassNeedsMinPointsBeforeItIsSet) {
  OrthoMapParams p;
  p.min_points = 40;
  OrthoMap map(p);
  map.add_keyframe(0, nadir_at(0, 0, 40), square(0, 0, 1, 0.0, 2));  // 16 points per cell
  EXPECT_EQ(map.cell_at(0.1, 0.1)->cls, 255);
  map.add_keyframe(1, nadir_at(0, 0, 40), square(0, 0, 1, 0.0, 2));
  map.add_keyframe(2, nadir_at(0, 0, 40), square(0, 0, 1, 0.0, 2));  // 48 now
  EXPECT_EQ(map.cell_at(0.1, 0.1)->cls, 2);
}

// One keyframe over a 6 m square of grass at z = 1 beside a 4 m tree crown at z = 9: block matching
// spread the crown's height over a 1 m strip of grass-labelled pixels beside it, and gave the crown's
// rim the ground's height. The ground check drops both kinds of wrong point; without it they win their cells.
std::vector<MapPoint> grass_beside_a_crown() {
  auto pts = square(0, 0, 3, 1.0, raw(ClassId::kGrass));
  for (MapPoint& m : pts)
    if (m.x > 2.0F) m.z = 9.0F;  // grass pixels with the crown's disparity (x in 2..3)
  auto crown = square(5, 0, 2, 9.0, raw(ClassId::kTree));
  for (MapPoint& m : crown)
    if (m.x < 3.5F) m.z = 1.0F;  // the crown's rim with the ground's disparity (x in 3..3.5)
  pts.insert(pts.end(), crown.begin(), crown.end());
  return pts;
}

TEST(OrthoMap, GroundCheckDropsFlatPointsAboveTheGroundAndRaisedPointsOnIt) {
  OrthoMap map;
  map.add_keyframe(0, nadir_at(0, 0, 40), grass_beside_a_crown());
  const Cell* spill = map.cell_at(2.25, 0.25);  // grass cell that got the crown's height
  const Cell* rim = map.cell_at(3.25, 0.25);    // crown cell that got the ground's height
  const Cell* crown = map.cell_at(5.25, 0.25);
  const Cell* grass = map.cell_at(0.25, 0.25);
  EXPECT_TRUE(spill == nullptr || spill->count == 0) << "the spilled points are all dropped";
  EXPECT_TRUE(rim == nullptr || rim->count == 0);
  ASSERT_NE(crown, nullptr);
  EXPECT_NEAR(crown->elevation(), 9.0, 1e-4);
  EXPECT_EQ(crown->cls, raw(ClassId::kTree));
  ASSERT_NE(grass, nullptr);
  EXPECT_NEAR(grass->elevation(), 1.0, 1e-4);
  // Without the check the wrong heights stand.
  OrthoMapParams p;
  p.ground_check_m = 0;
  OrthoMap plain(p);
  plain.add_keyframe(0, nadir_at(0, 0, 40), grass_beside_a_crown());
  EXPECT_NEAR(plain.cell_at(2.25, 0.25)->elevation(), 9.0, 1e-4);
  EXPECT_NEAR(plain.cell_at(3.25, 0.25)->elevation(), 1.0, 1e-4);
}

TEST(OrthoMap, ABuildingAtGroundHeightIsPavedGroundEvenFarFromAnyFlatPoint) {
  // A 24 m paved square that ErfNet calls building (a flat grey square looks like a roof from 40 m), in
  // grass, beside a 6 m roof that is one. The square's middle is 10 m from the nearest flat point,
  // beyond the 3.5 m window: the keyframe's ground (the median of its flat points) decides there.
  auto pts = square(0, 0, 20, 0.0, raw(ClassId::kGrass));
  std::erase_if(pts, [](const MapPoint& m) { return (std::fabs(m.x) < 12 && std::fabs(m.y) < 12) || (m.x > 14 && m.x < 19 && std::fabs(m.y) < 3); });
  for (const MapPoint& m : square(0, 0, 12, 0.0, raw(ClassId::kBuilding))) pts.push_back(m);
  auto roof = square(16.5, 0, 2.5, 6.0, raw(ClassId::kBuilding));
  pts.insert(pts.end(), roof.begin(), roof.end());
  OrthoMap map;
  map.add_keyframe(0, nadir_at(0, 0, 40), pts);
  for (const auto& [x, y] : {std::pair{0.25, 0.25}, std::pair{10.25, -10.25}, std::pair{-11.75, 5.25}}) {
    const Cell* c = map.cell_at(x, y);
    ASSERT_NE(c, nullptr) << x << ", " << y;
    EXPECT_EQ(c->cls, raw(ClassId::kRoad)) << "paved, at " << x << ", " << y;
    EXPECT_NEAR(c->elevation(), 0.0, 1e-4);
  }
  const Cell* r = map.cell_at(16.25, 0.25);
  ASSERT_NE(r, nullptr);
  EXPECT_EQ(r->cls, raw(ClassId::kBuilding)) << "a roof above the ground stays a building";
  EXPECT_NEAR(r->elevation(), 6.0, 1e-4);
}

TEST(OrthoMap, GroundCheckFollowsASlope) {
  // Grass on a 20 % slope: 1 m rise per 5 m, 0.7 m across the 3.5 m window. Nothing is dropped.
  auto pts = square(0, 0, 4, 0.0, raw(ClassId::kGrass));
  for (MapPoint& m : pts) m.z = 0.2F * m.x;
  OrthoMap map;
  map.add_keyframe(0, nadir_at(0, 0, 40), pts);
  std::uint64_t n = 0;
  for (double x = -3.75; x < 4; x += 0.5)
    for (double y = -3.75; y < 4; y += 0.5) {
      const Cell* c = map.cell_at(x, y);
      ASSERT_NE(c, nullptr);
      n += c->count;
      EXPECT_NEAR(c->elevation(), 0.2 * x, 0.05);
    }
  EXPECT_EQ(n, pts.size());
}

TEST(OrthoMap, ElevationNeedsMinElevationPoints) {
  OrthoMapParams p;
  p.min_elevation_points = 40;
  OrthoMap map(p);
  map.add_keyframe(0, nadir_at(0, 0, 40), square(0, 0, 1, 2.0, 2));  // 16 points per cell
  const Cell* c = map.cell_at(0.1, 0.1);
  ASSERT_NE(c, nullptr);
  EXPECT_EQ(c->cls, 2) << "class and colour are still shown";
  EXPECT_TRUE(std::isnan(c->reported_elevation(40)));
  MapRaster r = map.raster();
  std::size_t finite = 0;
  for (float e : r.elevation) finite += std::isfinite(e) ? 1U : 0U;
  EXPECT_EQ(finite, 0U);
  map.add_keyframe(1, nadir_at(0, 0, 40), square(0, 0, 1, 2.0, 2));
  map.add_keyframe(2, nadir_at(0, 0, 40), square(0, 0, 1, 2.0, 2));  // 48 now
  EXPECT_NEAR(map.cell_at(0.1, 0.1)->reported_elevation(40), 2.0, 1e-4);
  r = map.raster();
  finite = 0;
  for (float e : r.elevation) finite += std::isfinite(e) ? 1U : 0U;
  EXPECT_EQ(finite, 16U);  // the 2 m square: 4 x 4 cells
}

// Keyframes along a line across four tiles (32 m each); then one keyframe's pose is corrected.
TEST(OrthoMap, CorrectionRebuildsOnlyTheTilesTheMovedKeyframeTouched) {
  OrthoMap map;
  std::vector<std::pair<std::uint32_t, Eigen::Isometry3d>> poses;
  for (std::uint32_t k = 0; k < 12; ++k) {
    const double x = 4.0 + 10.0 * k;
    const Eigen::Isometry3d pose = nadir_at(x, 10, 40);
    map.add_keyframe(k, pose, square(x, 10, 3, 0.1 * k, static_cast<std::uint8_t>(k % 3)));
    poses.emplace_back(k, pose);
  }
  std::map<std::uint64_t, std::uint64_t> versions;
  map.for_each_tile([&](const Tile& t) { versions[t.key.packed()] = t.version; });
  ASSERT_EQ(versions.size(), 4u);

  // Unchanged poses: nothing is rebuilt.
  EXPECT_EQ(map.correct(poses), 0u);
  // Keyframe 7 (x = 74 m, in tile 2) moves 1.5 m east.
  poses[7].second.translation().x() += 1.5;
  const std::size_t rebuilt = map.correct(poses);
  EXPECT_EQ(rebuilt, 1u);
  std::size_t changed = 0;
  map.for_each_tile([&](const Tile& t) {
    if (t.version != versions[t.key.packed()]) {
      ++changed;
      EXPECT_EQ(t.key.tx, 2);
    }
  });
  EXPECT_EQ(changed, 1u);

  // The rebuilt map equals one built from scratch with the corrected poses.
  OrthoMap fresh;
  for (std::uint32_t k = 0; k < 12; ++k) {
    const double x = 4.0 + 10.0 * k;
    // points were given in the map frame at the old pose: they move with the keyframe
    auto pts = square(x, 10, 3, 0.1 * k, static_cast<std::uint8_t>(k % 3));
    if (k == 7)
      for (auto& q : pts) q.x += 1.5F;
    fresh.add_keyframe(k, poses[k].second, pts);
  }
  for (double x = 0.25; x < 125; x += 0.5)
    for (double y = 6.25; y < 14; y += 0.5) {
      const Cell* a = map.cell_at(x, y);
      const Cell* b = fresh.cell_at(x, y);
      ASSERT_EQ(a == nullptr, b == nullptr);
      if (a == nullptr) continue;
      EXPECT_EQ(a->count, b->count) << x << "," << y;
      EXPECT_NEAR(a->elevation(), b->elevation(), 1e-4) << x << "," << y;
      EXPECT_EQ(a->cls, b->cls) << x << "," << y;
    }
}

// Stereo depth is baseline x focal / disparity: when the graph finds the pair 2 % further apart than it
// was matched at (its scale corrected by GPS), every point lies 2 % further from the camera.
TEST(OrthoMap, DepthFollowsTheCorrectedStereoBaseline) {
  for (const bool rescale : {true, false}) {
    OrthoMapParams p;
    p.rescale_depth = rescale;
    OrthoMap map(p);
    const Eigen::Isometry3d partner = nadir_at(0, 0, 40), cur = nadir_at(7.2, 0, 40);
    map.add_keyframe(0, partner, {}, OrthoMap::kNoPartner, 0.0);  // the partner: no points of its own
    map.add_keyframe(1, cur, square(7.2, 0, 4, 0.0, 0), 0, 7.2);   // ground at z = 0, 40 m below
    ASSERT_NEAR(map.cell_at(7.25, 0.25)->elevation(), 0.0, 1e-4);
    // Only the partner moves (back 0.144 m): baseline 7.344 m, 2 % longer; points 40.8 m below the camera.
    std::vector<std::pair<std::uint32_t, Eigen::Isometry3d>> poses{{0, nadir_at(-0.144, 0, 40)}, {1, cur}};
    const std::size_t rebuilt = map.correct(poses);
    const Cell* c = map.cell_at(7.25, 0.25);
    ASSERT_NE(c, nullptr);
    if (rescale) {
      EXPECT_GE(rebuilt, 1u) << "0.8 m of depth change is past rebuild_translation_m";
      EXPECT_NEAR(c->elevation(), -0.8, 1e-3);
      EXPECT_NEAR(map.cell_at(10.25, -2.75)->elevation(), -0.8, 1e-3) << "off nadir too";
    } else {
      EXPECT_EQ(rebuilt, 0u);
      EXPECT_NEAR(c->elevation(), 0.0, 1e-4);
    }
    // A partner the corrections do not name (it left the graph's window): the depth stays as it is.
    const double before = c->elevation();
    std::vector<std::pair<std::uint32_t, Eigen::Isometry3d>> only_cur{{1, cur}};
    map.correct(only_cur);
    EXPECT_NEAR(map.cell_at(7.25, 0.25)->elevation(), before, 1e-4);
  }
}

TEST(OrthoMap, KeyframesLeavingTheWindowStayInTheMapAndMemoryIsBounded) {
  OrthoMapParams p;
  p.window_keyframes = 4;
  OrthoMap map(p);
  for (std::uint32_t k = 0; k < 10; ++k) map.add_keyframe(k, nadir_at(10.0 * k, 0, 40), square(10.0 * k, 0, 3, 1.0, 0));
  EXPECT_EQ(map.window_size(), 4u);
  EXPECT_EQ(map.stats().keyframes_frozen, 6u);
  EXPECT_EQ(map.keyframe_pose(2), nullptr);       // frozen: no longer correctable
  ASSERT_NE(map.keyframe_pose(8), nullptr);
  ASSERT_NE(map.cell_at(0.25, 0.25), nullptr);    // ... but its cells are still mapped
  EXPECT_EQ(map.cell_at(0.25, 0.25)->cls, 0);
  EXPECT_NEAR(map.cell_at(0.25, 0.25)->elevation(), 1.0, 1e-5);
}

TEST(OrthoMap, RasterIsNorthUp) {
  OrthoMap map;
  map.add_keyframe(0, nadir_at(0, 0, 40), square(0, 5, 1, 3.0, 4));   // north: building
  map.add_keyframe(1, nadir_at(0, 0, 40), square(0, -5, 1, 0.0, 0));  // south: road
  const MapRaster r = map.raster();
  ASSERT_GT(r.grid.height, 10);
  // First and last classified rows.
  int first = -1, last = -1;
  for (int row = 0; row < r.grid.height; ++row)
    for (int col = 0; col < r.grid.width; ++col) {
      const std::uint8_t c = r.cls[static_cast<std::size_t>(row) * static_cast<std::size_t>(r.grid.width) + static_cast<std::size_t>(col)];
      if (c == 255) continue;
      if (first < 0) first = c;
      last = c;
    }
  EXPECT_EQ(first, 4);  // row 0 is the north edge
  EXPECT_EQ(last, 0);
}

}  // namespace
}  // namespace ag::mapping
