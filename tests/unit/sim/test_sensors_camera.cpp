// CameraRenderer: what each pixel sees (class, depth, colour) checked against rays computed independently.
#include <gtest/gtest.h>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "airground/sim/camera.hpp"
#include "test_sensors_world.hpp"

namespace ag::sim {
namespace {

using testing::class_rgb;
using testing::fill_cells;
using testing::fill_rect;
using testing::flat_world;

// The pose rotation, written out from its definition R = Rz(yaw) Ry(pitch) Rx(roll).
Eigen::Matrix3d map_from_body(const Pose3& p) {
  const double cr = std::cos(p.roll), sr = std::sin(p.roll), cp = std::cos(p.pitch), sp = std::sin(p.pitch);
  const double cy = std::cos(p.yaw), sy = std::sin(p.yaw);
  Eigen::Matrix3d rx, ry, rz;
  rx << 1, 0, 0, 0, cr, -sr, 0, sr, cr;
  ry << cp, 0, sp, 0, 1, 0, -sp, 0, cp;
  rz << cy, -sy, 0, sy, cy, 0, 0, 0, 1;
  return rz * ry * rx;
}

// The mount from its description: image right = body right (-y), image down = body backward (-x),
// optical axis = body down (-z). Columns are the camera axes in body coordinates.
Eigen::Matrix3d body_from_camera_spec() {
  Eigen::Matrix3d m;
  m.col(0) = Eigen::Vector3d(0, -1, 0);
  m.col(1) = Eigen::Vector3d(-1, 0, 0);
  m.col(2) = Eigen::Vector3d(0, 0, -1);
  return m;
}

cv::Matx33d camera_matrix(const CameraModel& m) { return {m.fx, 0, m.cx, 0, m.fy, m.cy, 0, 0, 1}; }
std::vector<double> dist_coeffs(const CameraModel& m) { return {m.k1, m.k2, m.p1, m.p2, m.k3}; }

// Normalized undistorted coordinates of a pixel, by OpenCV.
Eigen::Vector2d undistort_cv(const CameraModel& m, double u, double v) {
  std::vector<cv::Point2d> in{{u, v}}, out;
  cv::undistortPoints(in, out, camera_matrix(m), dist_coeffs(m), cv::noArray(), cv::noArray(),
                      cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 200, 1e-14));
  return {out[0].x, out[0].y};
}

// Pixel of a map point, by OpenCV's projection.
cv::Point2d project_cv(const CameraModel& m, const Pose3& pose, const Eigen::Vector3d& p_map) {
  const Eigen::Matrix3d map_from_cam = map_from_body(pose) * body_from_camera_spec();
  const Eigen::Vector3d pc = map_from_cam.transpose() * (p_map - Eigen::Vector3d(pose.x, pose.y, pose.z));
  std::vector<cv::Point3d> obj{{pc.x(), pc.y(), pc.z()}};
  std::vector<cv::Point2d> img;
  cv::projectPoints(obj, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), camera_matrix(m), dist_coeffs(m), img);
  return img[0];
}

CameraModel half_model() { return CameraModel{}.scaled(0.5); }

// A flat patchwork: every 2 m block gets a class from a hash, so a ray landing in the wrong place usually
// reads the wrong class.
World patchwork() {
  World w = flat_world(400, 400, 0.25, -50.0, 50.0, ClassId::kGrass);
  const ClassId kinds[] = {ClassId::kRoad, ClassId::kDirt, ClassId::kGrass, ClassId::kWater, ClassId::kVehicle};
  for (std::int32_t br = 0; br < 50; ++br) {
    for (std::int32_t bc = 0; bc < 50; ++bc) {
      const std::uint32_t h = (static_cast<std::uint32_t>(br) * 73856093u) ^ (static_cast<std::uint32_t>(bc) * 19349663u);
      const ClassId k = kinds[(h >> 4) % 5];
      fill_cells(w, bc * 8, br * 8, bc * 8 + 8, br * 8 + 8, k, 0.0f, class_rgb(k));
    }
  }
  return w;
}

TEST(Camera, PixelsSeeTheClassWhereTheirRayMeetsTheGround) {
  const World w = patchwork();
  const CameraModel m = half_model();
  const CameraRenderer cam(w, m);
  const Pose3 poses[] = {
      {0, 0, 40, 0, 0, 0},          {3.3, -2.1, 45, 0, 0, 0.7},      {-5, 4, 50, 0.05, -0.04, 0.7},
      {1, 1, 60, -0.06, 0.03, -2.0}, {0.4, -0.7, 40, 0.0, 0.08, 1.3},
  };
  CameraFrame f;
  int checked = 0;
  for (const Pose3& pose : poses) {
    cam.render(pose, f);
    const Eigen::Matrix3d map_from_cam = map_from_body(pose) * body_from_camera_spec();
    const Eigen::Vector3d eye(pose.x, pose.y, pose.z);
    // The centre pixel, the corners and a grid in between.
    std::vector<cv::Point> pixels{{m.width / 2, m.height / 2}, {0, 0}, {m.width - 1, 0}, {0, m.height - 1},
                                  {m.width - 1, m.height - 1}};
    for (int v = 10; v < m.height; v += 37)
      for (int u = 7; u < m.width; u += 41) pixels.emplace_back(u, v);
    for (const cv::Point& px : pixels) {
      const Eigen::Vector2d xy = undistort_cv(m, px.x, px.y);
      const Eigen::Vector3d dir = map_from_cam * Eigen::Vector3d(xy.x(), xy.y(), 1.0);
      const double t = -pose.z / dir.z();  // ground plane z = 0
      const Eigen::Vector3d g = eye + t * dir;
      SCOPED_TRACE("pose yaw " + std::to_string(pose.yaw) + " pixel " + std::to_string(px.x) + "," + std::to_string(px.y));
      if (std::max(std::abs(g.x()), std::abs(g.y())) > 49.99) {  // beyond the world: nothing seen
        ASSERT_EQ(f.cls.at<std::uint8_t>(px), raw(ClassId::kUnknown));
        ASSERT_EQ(f.depth.at<float>(px), 0.0f);
        continue;
      }
      const double bx = std::fmod(g.x() + 1000.0, 2.0), by = std::fmod(g.y() + 1000.0, 2.0);
      if (std::min({bx, 2.0 - bx, by, 2.0 - by}) < 0.02) continue;  // too close to a patch edge to judge
      ASSERT_EQ(f.cls.at<std::uint8_t>(px), raw(w.class_at_xy(g.x(), g.y())));
      ASSERT_NEAR(f.depth.at<float>(px), (g - eye).dot(map_from_cam.col(2)), 1e-3);
      ++checked;
    }
  }
  EXPECT_GT(checked, 500);
}

TEST(Camera, ImageTopIsBodyForwardAndImageRightIsBodyRight) {
  World w = flat_world(200, 200, 0.25, -25.0, 25.0, ClassId::kGrass);
  fill_rect(w, 10, -2, 14, 2, ClassId::kBuilding, 5.0f, class_rgb(ClassId::kBuilding));  // east
  fill_rect(w, -2, 10, 2, 14, ClassId::kWater, 0.0f, class_rgb(ClassId::kWater));        // north
  const CameraModel m = half_model();
  const CameraRenderer cam(w, m);
  CameraFrame f;
  const auto centroid = [&](ClassId k) {
    cv::Mat mask = f.cls == raw(k);
    const cv::Moments mo = cv::moments(mask, true);
    EXPECT_GT(mo.m00, 100.0);
    return cv::Point2d(mo.m10 / mo.m00, mo.m01 / mo.m00);
  };
  cam.render({0, 0, 40, 0, 0, 0}, f);  // facing east: the building ahead, the water on the left
  cv::Point2d b = centroid(ClassId::kBuilding), wa = centroid(ClassId::kWater);
  EXPECT_LT(b.y, m.cy - 100);
  EXPECT_NEAR(b.x, m.cx, 5);
  EXPECT_LT(wa.x, m.cx - 100);
  EXPECT_NEAR(wa.y, m.cy, 5);
  cam.render({0, 0, 40, 0, 0, kPi / 2}, f);  // facing north: the water ahead, the building on the right
  b = centroid(ClassId::kBuilding);
  wa = centroid(ClassId::kWater);
  EXPECT_LT(wa.y, m.cy - 100);
  EXPECT_GT(b.x, m.cx + 100);
  EXPECT_NEAR(b.y, m.cy, 5);
}

// Sloping terrain with buildings, trees and cars of many heights.
World town() {
  World w = flat_world(320, 320, 0.25, -40.0, 40.0, ClassId::kRoad);
  const GridGeometry& g = w.grid();
  for (std::int32_t r = 0; r < g.height; ++r)
    for (std::int32_t c = 0; c < g.width; ++c) w.terrain.at<float>(r, c) = static_cast<float>(0.05 * g.x_of(c) - 0.02 * g.y_of(r));
  std::mt19937 rng(5);
  const auto uni = [&](int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(rng); };
  for (int i = 0; i < 30; ++i) {
    const int c = uni(0, 300), r = uni(0, 300);
    fill_cells(w, c, r, c + uni(8, 40), r + uni(8, 40), ClassId::kBuilding, static_cast<float>(uni(4, 25)), {150, 140, 130});
  }
  for (int i = 0; i < 60; ++i) {
    const int c = uni(0, 310), r = uni(0, 310);
    fill_cells(w, c, r, c + uni(3, 8), r + uni(3, 8), ClassId::kTree, static_cast<float>(uni(3, 12)), {30, 110, 40});
    const int cc = uni(0, 310), rr = uni(0, 310);
    fill_cells(w, cc, rr, cc + 7, rr + 17, ClassId::kVehicle, 1.5f, {220, 40, 40});
  }
  return w;
}

TEST(Camera, DepthBackProjectsOntoTheSurfaceOfTheClassSeen) {
  const World w = town();
  const GridGeometry& g = w.grid();
  const CameraModel m = half_model();
  const CameraRenderer cam(w, m);
  const Pose3 pose{2, -3, 50, 0.04, -0.03, 0.7};
  CameraFrame f;
  cam.render(pose, f);
  const Eigen::Matrix3d map_from_cam = map_from_body(pose) * body_from_camera_spec();
  const Eigen::Vector3d eye(pose.x, pose.y, pose.z);
  int tops = 0, walls = 0;
  for (int v = 0; v < m.height; v += 5) {
    for (int u = 0; u < m.width; u += 7) {
      const float z = f.depth.at<float>(v, u);
      if (z <= 0.0f) continue;
      const Eigen::Vector2d xy = undistort_cv(m, u, v);
      const Eigen::Vector3d p = eye + map_from_cam * (static_cast<double>(z) * Eigen::Vector3d(xy.x(), xy.y(), 1.0));
      const std::uint8_t cls = f.cls.at<std::uint8_t>(v, u);
      const std::int32_t c = g.col(p.x()), r = g.row(p.y());
      SCOPED_TRACE("pixel " + std::to_string(u) + "," + std::to_string(v));
      if (g.contains(c, r) && std::abs(p.z() - static_cast<double>(w.surface_at(c, r))) < 2e-3) {
        EXPECT_EQ(cls, raw(w.class_at(c, r)));
        ++tops;
        continue;
      }
      // Otherwise a wall: on a cell edge, below the top of a column beside it that has the class seen.
      const double cu = g.col_f(p.x()), rv = g.row_f(p.y());
      const bool on_col_edge = std::abs(cu - std::round(cu)) < 1e-2, on_row_edge = std::abs(rv - std::round(rv)) < 1e-2;
      ASSERT_TRUE(on_col_edge || on_row_edge) << "neither on a top nor on a cell edge: " << p.transpose();
      bool found = false;
      const auto wall_of = [&](std::int32_t cc, std::int32_t rr) {
        found = found || (g.contains(cc, rr) && p.z() <= static_cast<double>(w.surface_at(cc, rr)) + 2e-3 &&
                          cls == raw(w.class_at(cc, rr)));
      };
      for (int k = -1; k <= 0; ++k) {
        if (on_col_edge) wall_of(static_cast<std::int32_t>(std::lround(cu)) + k, r);
        if (on_row_edge) wall_of(c, static_cast<std::int32_t>(std::lround(rv)) + k);
      }
      EXPECT_TRUE(found) << "no wall of class " << int{cls} << " at " << p.transpose();
      ++walls;
    }
  }
  EXPECT_GT(tops, 4000);
  EXPECT_GT(walls, 500);  // 50 m up, buildings up to 25 m tall are seen from the side toward the edges
  EXPECT_GT(tops, 2 * walls);
}

TEST(Camera, RoofAtNadirIsBuildingAtAltitudeMinusRoofHeight) {
  World w = flat_world(200, 200, 0.25, -25.0, 25.0, ClassId::kGrass);
  w.terrain.setTo(5.0);
  fill_rect(w, -10, -10, 10, 10, ClassId::kBuilding, 15.0f, {150, 150, 150});
  const CameraModel m = half_model();
  const CameraRenderer cam(w, m);
  CameraFrame f;
  cam.render({0.3, -0.2, 5.0 + 45.0, 0, 0, 0.4}, f);
  const cv::Rect centre(m.width / 2 - 60, m.height / 2 - 60, 120, 120);
  for (int v = centre.y; v < centre.y + centre.height; ++v) {
    for (int u = centre.x; u < centre.x + centre.width; ++u) {
      ASSERT_EQ(f.cls.at<std::uint8_t>(v, u), raw(ClassId::kBuilding));
      ASSERT_NEAR(f.depth.at<float>(v, u), 30.0f, 1e-4f);
    }
  }
  // A lit flat top renders at its albedo, up to the detail texture.
  const cv::Scalar mean = cv::mean(f.rgb(centre));
  EXPECT_NEAR(mean[0], 150.0, 6.0);
}

TEST(Camera, WallsAreDarkerThanRoofsAndShadowsFallAwayFromTheSun) {
  World w = flat_world(240, 240, 0.25, -30.0, 30.0, ClassId::kRoad);
  w.albedo.setTo(cv::Scalar(160, 160, 160));
  fill_rect(w, -5, -5, 5, 5, ClassId::kBuilding, 20.0f, {160, 160, 160});
  const CameraModel m = half_model();
  CameraShading sh;
  sh.detail_texture = false;  // exact intensities
  sh.shadows = true;
  const CameraRenderer cam(w, m, sh);
  CameraFrame f;

  // Seen from the south-west, looking forward and down: the south and west walls and the roof.
  const Pose3 oblique{-15, -15, 30, 0, -0.9, kPi / 4};
  cam.render(oblique, f);
  const Eigen::Matrix3d map_from_cam = map_from_body(oblique) * body_from_camera_spec();
  double roof = 0, wall = 0;
  int nroof = 0, nwall = 0;
  for (int v = 0; v < m.height; v += 2) {
    for (int u = 0; u < m.width; u += 2) {
      if (f.cls.at<std::uint8_t>(v, u) != raw(ClassId::kBuilding)) continue;
      const Eigen::Vector2d xy = undistort_cv(m, u, v);
      const Eigen::Vector3d p = Eigen::Vector3d(oblique.x, oblique.y, oblique.z) +
                                map_from_cam * (static_cast<double>(f.depth.at<float>(v, u)) * Eigen::Vector3d(xy.x(), xy.y(), 1.0));
      const double level = f.rgb.at<cv::Vec3b>(v, u)[1];
      if (p.z() > 19.99) {
        roof += level, ++nroof;
      } else if (p.z() < 19.5) {
        wall += level, ++nwall;
      }
    }
  }
  ASSERT_GT(nroof, 100);
  ASSERT_GT(nwall, 100);
  EXPECT_NEAR(roof / nroof, 160.0, 1.0);
  EXPECT_LT(wall / nwall, roof / nroof - 20.0);

  // Nadir from north of the building: the sun stands in the south-south-east, so the ground just
  // north-north-west of the building is in its shadow while ground further north is lit.
  const Pose3 above{0, 12, 60, 0, 0, 0};
  const Eigen::Vector3d shadowed(-1.5, 7.6, 0.0), lit(-1.5, 20.0, 0.0);
  const auto level_at = [&](const CameraFrame& fr, const Eigen::Vector3d& p) {
    const cv::Point2d px = project_cv(m, above, p);
    const cv::Point ip(static_cast<int>(std::lround(px.x)), static_cast<int>(std::lround(px.y)));
    EXPECT_EQ(fr.cls.at<std::uint8_t>(ip), raw(ClassId::kRoad));
    return static_cast<double>(fr.rgb.at<cv::Vec3b>(ip)[0]);
  };
  cam.render(above, f);
  const double ratio = level_at(f, shadowed) / level_at(f, lit);
  EXPECT_NEAR(ratio, sh.ambient / (sh.ambient + (1 - sh.ambient) * std::sin(sh.sun_elevation_deg * kPi / 180)), 0.02);
  sh.shadows = false;
  const CameraRenderer no_shadows(w, m, sh);
  no_shadows.render(above, f);
  EXPECT_NEAR(level_at(f, shadowed) / level_at(f, lit), 1.0, 0.01);
}

TEST(Camera, ShadowCullingChangesNothing) {
  World w = town();
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> jitter(-0.03f, 0.03f);
  for (std::int32_t r = 0; r < w.grid().height; ++r)
    for (std::int32_t c = 0; c < w.grid().width; ++c) w.terrain.at<float>(r, c) += jitter(rng);
  const CameraModel m = half_model();
  for (const double azimuth : {150.0, 20.0, 270.0}) {
    CameraShading culled;
    culled.shadows = true;
    culled.sun_azimuth_deg = azimuth;
    culled.sun_elevation_deg = azimuth == 20.0 ? 25.0 : 50.0;
    CameraShading exact = culled;
    exact.shadow_culling = false;
    const CameraRenderer fast(w, m, culled), slow(w, m, exact);
    for (const Pose3& pose : {Pose3{0, 0, 45, 0, 0, 0.3}, Pose3{-12, 9, 30, 0.1, -0.5, 2.0}}) {
      CameraFrame a, b;
      fast.render(pose, a);
      slow.render(pose, b);
      EXPECT_EQ(cv::norm(a.rgb, b.rgb, cv::NORM_INF), 0.0) << "sun azimuth " << azimuth;
    }
  }
}

// Casts that start where a tile's block max query proves them free see exactly what casts from the eye
// see: nadir and strongly tilted views, an eye below the roofs, views off the world's edge, shadows on.
TEST(Camera, TileStartChangesNothing) {
  World w = town();
  std::mt19937 rng(4);
  std::uniform_real_distribution<float> jitter(-0.2f, 0.2f);
  for (std::int32_t r = 0; r < w.grid().height; ++r)
    for (std::int32_t c = 0; c < w.grid().width; ++c) w.terrain.at<float>(r, c) += jitter(rng);
  CameraModel m = half_model();
  m.k1 = -0.2;  // strong barrel distortion: tiles are not pinhole cones
  m.k2 = 0.05;
  for (const bool shadows : {false, true}) {
    CameraShading tiled;
    tiled.shadows = shadows;
    CameraShading exact = tiled;
    exact.tile_start = false;
    const CameraRenderer fast(w, m, tiled), slow(w, m, exact);
    for (const Pose3& pose : {Pose3{0, 0, 45, 0, 0, 0.3}, Pose3{-12, 9, 30, 0.1, -0.5, 2.0}, Pose3{5, -5, 12, 0.3, 0.2, -1.0},
                              Pose3{30, 20, 60, -0.2, 0.4, 0.9}, Pose3{-3, 4, 8, 0.0, 1.2, 0.5}}) {
      CameraFrame a, b;
      fast.render(pose, a);
      slow.render(pose, b);
      EXPECT_EQ(cv::norm(a.rgb, b.rgb, cv::NORM_INF), 0.0) << "shadows " << shadows << " z " << pose.z;
      EXPECT_EQ(cv::norm(a.cls, b.cls, cv::NORM_INF), 0.0) << "shadows " << shadows << " z " << pose.z;
      EXPECT_EQ(cv::norm(a.depth, b.depth, cv::NORM_INF), 0.0) << "shadows " << shadows << " z " << pose.z;
    }
  }
}

TEST(Camera, DetailTextureIsFixedToTheWorld) {
  World w = flat_world(240, 240, 0.25, -30.0, 30.0, ClassId::kGrass);
  w.albedo.setTo(cv::Scalar(128, 128, 128));
  CameraModel m = half_model();
  m.k1 = m.k2 = 0.0;  // a pure pinhole, so that moving forward shifts the image by whole rows
  const CameraRenderer cam(w, m);
  const double z = 40.0;
  const int shift = 10;
  const double dx = shift * z / m.fy;
  CameraFrame a, b;
  cam.render({0, 0, z, 0, 0, 0}, a);
  cam.render({dx, 0, z, 0, 0, 0}, b);  // forward: the ground moves down the image
  cv::Mat ga, gb;
  cv::extractChannel(a.rgb, ga, 1);
  cv::extractChannel(b.rgb, gb, 1);
  const cv::Rect ra(40, 40, m.width - 80, m.height - 80 - shift), rb = ra + cv::Point(0, shift);
  cv::Scalar mean, sd;
  cv::meanStdDev(ga(ra), mean, sd);
  EXPECT_GT(sd[0], 3.0) << "no texture to match";
  EXPECT_LT(cv::norm(ga(ra), gb(rb), cv::NORM_L1) / ra.area(), 1.0) << "texture moved with the camera";
  EXPECT_GT(cv::norm(ga(ra), gb(ra), cv::NORM_L1) / ra.area(), sd[0] / 2) << "texture is not structured";

  CameraShading flat;
  flat.detail_texture = false;
  const CameraRenderer plain(w, m, flat);
  plain.render({0, 0, z, 0, 0, 0}, a);
  cv::meanStdDev(a.rgb, mean, sd);
  EXPECT_LT(sd[0], 0.5);
}

TEST(Camera, OutsideTheWorldIsBlackUnknownAndDepthZero) {
  const World w = flat_world(200, 200, 0.25, -25.0, 25.0, ClassId::kDirt);
  const CameraModel m = half_model();
  const CameraRenderer cam(w, m);
  CameraFrame f;
  cam.render({20, 0, 40, 0, 0, 0}, f);  // 5 m from the east edge, facing it: the top of the image is beyond
  EXPECT_EQ(f.cls.at<std::uint8_t>(5, m.width / 2), raw(ClassId::kUnknown));
  EXPECT_EQ(f.depth.at<float>(5, m.width / 2), 0.0f);
  EXPECT_EQ(f.rgb.at<cv::Vec3b>(5, m.width / 2), cv::Vec3b(0, 0, 0));
  EXPECT_EQ(f.cls.at<std::uint8_t>(m.height - 5, m.width / 2), raw(ClassId::kDirt));
  EXPECT_GT(f.depth.at<float>(m.height - 5, m.width / 2), 39.0f);
}

TEST(Camera, RowsRenderedInPiecesEqualTheWholeFrame) {
  const World w = town();
  const CameraModel m = half_model();
  const CameraRenderer cam(w, m);
  const Pose3 pose{1, 2, 45, 0.02, 0.01, -0.3};
  CameraFrame whole, parts;
  cam.render(pose, whole, 123);
  EXPECT_EQ(whole.stamp_ns, 123);
  cam.prepare(pose, parts);
  cam.render_rows(pose, 0, 150, parts);
  cam.render_rows(pose, 150, 151, parts);
  cam.render_rows(pose, 151, m.height, parts);
  EXPECT_EQ(cv::norm(whole.rgb, parts.rgb, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(whole.cls, parts.cls, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(whole.depth, parts.depth, cv::NORM_INF), 0.0);
  const auto* data = whole.rgb.data;
  cam.render(pose, whole);
  EXPECT_EQ(whole.rgb.data, data) << "a second render reallocated the frame";
}

TEST(Camera, RayTableMatchesOpenCvUndistortion) {
  const World w = flat_world(40, 40, 0.25, 0.0, 10.0);
  CameraModel m;  // full size, default lens
  m.p1 = 0.001;
  m.p2 = -0.0007;
  m.k3 = -0.002;
  const CameraRenderer cam(w, m);
  for (int v = 0; v < m.height; v += 53) {
    for (int u = 0; u < m.width; u += 47) {
      const Eigen::Vector2d xy = undistort_cv(m, u, v);
      const Eigen::Vector3d expect = Eigen::Vector3d(xy.x(), xy.y(), 1.0).normalized();
      EXPECT_LT((cam.pixel_ray(u, v).cast<double>() - expect).norm(), 1e-6) << u << "," << v;
    }
  }
  EXPECT_EQ(cam.pixel_ray(-1, 0), Eigen::Vector3f::Zero());
}

TEST(Camera, ModelScalingAndYaml) {
  const CameraModel half = CameraModel{}.scaled(0.5);
  EXPECT_EQ(half.width, 640);
  EXPECT_EQ(half.height, 400);
  EXPECT_DOUBLE_EQ(half.fx, 483.5);
  EXPECT_DOUBLE_EQ(half.cx, 319.5);
  EXPECT_DOUBLE_EQ(half.cy, 199.5);
  EXPECT_DOUBLE_EQ(half.k1, CameraModel{}.k1);

  const char* yaml = R"(camera:
  width: 640
  height: 400
  fx: 480.0
  fy: 481.0
  cx: 320.5
  cy: 199.0
  k1: -0.04
  k2: 0.008
camera_shading:
  shadows: true
  sun_elevation_deg: 35
)";
  auto m = CameraModel::load_string(yaml, "test.yaml");
  ASSERT_TRUE(m.ok()) << m.error().message;
  EXPECT_EQ(m->width, 640);
  EXPECT_DOUBLE_EQ(m->fy, 481.0);
  EXPECT_DOUBLE_EQ(m->k1, -0.04);
  EXPECT_DOUBLE_EQ(m->p1, 0.0);
  auto sh = CameraShading::load_string(yaml, "test.yaml");
  ASSERT_TRUE(sh.ok()) << sh.error().message;
  EXPECT_TRUE(sh->shadows);
  EXPECT_DOUBLE_EQ(sh->sun_elevation_deg, 35.0);
  EXPECT_TRUE(sh->detail_texture);

  const auto error_of = [](const char* text) {
    auto r = CameraModel::load_string(text, "bad.yaml");
    EXPECT_FALSE(r.ok());
    return r.ok() ? std::string() : r.error().message;
  };
  EXPECT_NE(error_of("camera:\n  fov: 90\n").find("camera.fov"), std::string::npos);
  EXPECT_NE(error_of("camera:\n  fx: -3\n").find("camera.fx"), std::string::npos);
  EXPECT_NE(error_of("camera:\n  fx: wide\n").find("camera.fx"), std::string::npos);
  EXPECT_NE(error_of("camera:\n  width: 640\n  cx: 900\n").find("cx"), std::string::npos);
  EXPECT_NE(error_of("camera: [1, 2\n").find("bad.yaml"), std::string::npos);

  auto file = CameraModel::load_file(std::string(AG_SOURCE_DIR) + "/config/sensors/camera.yaml");
  ASSERT_TRUE(file.ok()) << file.error().message;
  EXPECT_EQ(file->width, CameraModel{}.width);
  EXPECT_DOUBLE_EQ(file->fx, CameraModel{}.fx);
  EXPECT_TRUE(CameraShading::load_file(std::string(AG_SOURCE_DIR) + "/config/sensors/camera.yaml").ok());
}

TEST(Camera, RejectsBadModelsAndMismatchedWorlds) {
  const World w = flat_world(40, 40, 0.25, 0.0, 10.0);
  CameraModel m;
  m.fx = 0;
  EXPECT_THROW(CameraRenderer(w, m), std::invalid_argument);
  World bad = w;
  bad.albedo = cv::Mat(10, 10, CV_8UC3);
  EXPECT_THROW(CameraRenderer(bad, CameraModel{}), std::invalid_argument);
  const World other = flat_world(50, 40, 0.25, 0.0, 10.0);
  auto rc = std::make_shared<const HeightfieldRaycaster>(other);
  EXPECT_THROW(CameraRenderer(w, CameraModel{}, CameraShading{}, rc), std::invalid_argument);
}

}  // namespace
}  // namespace ag::sim
