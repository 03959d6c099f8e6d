// DenseStereo on simulator frames: rectification against cv::stereoRectify/initUndistortRectifyMap and
// against the epipolar geometry itself, the block matcher against cv::StereoBM, the points against the
// world's true surface and classes, and the refusals.
#include <gtest/gtest.h>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <new>
#include <stdexcept>
#include <cmath>
#include <cstdio>
#include <memory>
#include <random>
#include <vector>

#include "airground/aerial_mapping/stereo.hpp"
#include "airground/messages/camera.hpp"
#include "airground/messages/classes.hpp"
#include "airground/messages/pose_math.hpp"
#include "airground/sim/camera.hpp"
#include "airground/sim/generator.hpp"

// Counts global operator new (not under sanitizers, which bring their own) to check that compute()
// does not allocate once warm.
#if !defined(__SANITIZE_ADDRESS__) && !defined(__SANITIZE_THREAD__)
#define AG_STEREO_COUNT_ALLOCS 1
namespace {
std::atomic<std::uint64_t> g_allocations{0};
}  // namespace
void* operator new(std::size_t n) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(n == 0 ? 1 : n)) return p;
  throw std::bad_alloc();
}
// Not inlined: GCC would otherwise see free() on a pointer from operator new (-Wmismatched-new-delete).
[[gnu::noinline]] void operator delete(void* p) noexcept { std::free(p); }
[[gnu::noinline]] void operator delete(void* p, std::size_t) noexcept { std::free(p); }
#endif

namespace {

using ag::Pose3;
using ag::mapping::DenseStereo;
using ag::mapping::MapPoint;
using ag::mapping::RectifiedGeometry;
using ag::mapping::StereoImage;
using ag::mapping::StereoParams;

Eigen::Isometry3d camera_pose(const Pose3& body) {
  Eigen::Isometry3d t = ag::to_isometry(body);
  t.linear() = t.linear() * ag::nadir_body_from_camera();
  return t;
}

// A body pose `ahead` metres along the body x axis of `p`, with a slightly different attitude.
Pose3 moved(const Pose3& p, double ahead, double side, double droll, double dpitch, double dyaw) {
  const Eigen::Isometry3d t = ag::to_isometry(p);
  const Eigen::Vector3d c = t * Eigen::Vector3d(ahead, side, 0.0);
  return Pose3{c.x(), c.y(), c.z(), p.roll + droll, p.pitch + dpitch, p.yaw + dyaw};
}

struct Frame {
  ag::sim::CameraFrame f;
  Eigen::Isometry3d map_from_camera;
  [[nodiscard]] StereoImage image() const { return {f.rgb.ptr<std::uint8_t>(), f.cls.ptr<std::uint8_t>(), map_from_camera}; }
};

struct Scene {
  const ag::sim::World& world = ag::sim::default_world();
  ag::sim::CameraModel model = ag::sim::CameraModel{}.scaled(0.5);
  ag::PinholeCamera camera = model.pinhole();
  ag::sim::CameraRenderer renderer{world, model};
  Pose3 cur_body;   // 40 m over the most built-up spot of the world, flying north-east-ish
  Pose3 prev_body;  // 2 m behind it along body x
  Frame cur, prev;

  Scene() {
    // The candidate centre (10 m grid, inside the world) with the most building cells under the footprint.
    const auto& g = world.grid();
    double best_x = 0, best_y = 0;
    int best = -1;
    for (double x = -150; x <= 150; x += 10) {
      for (double y = -150; y <= 150; y += 10) {
        int n = 0;
        for (double dx = -15; dx <= 15; dx += 1)
          for (double dy = -15; dy <= 15; dy += 1)
            n += world.class_at_xy(x + dx, y + dy) == ag::ClassId::kBuilding ? 1 : 0;
        if (n > best) {
          best = n;
          best_x = x;
          best_y = y;
        }
      }
    }
    const double ground = static_cast<double>(world.terrain.at<float>(g.row(best_y), g.col(best_x)));
    cur_body = Pose3{best_x, best_y, ground + 40.0, 0.02, -0.015, 0.6};
    prev_body = moved(cur_body, -2.0, 0.05, -0.012, 0.02, -0.01);
    render(cur_body, cur);
    render(prev_body, prev);
  }
  void render(const Pose3& body, Frame& out) const {
    renderer.render(body, out.f);
    out.map_from_camera = camera_pose(body);
  }
};

Scene& scene() {
  static Scene s;
  return s;
}

StereoParams test_params() { return StereoParams{}; }

// Bilinear sample of a planar (x plane, y plane) map at a rectified position; false if a corner has no source.
bool sample_map(const std::vector<float>& map, int width, int height, double x, double y, Eigen::Vector2d& out) {
  const std::size_t n = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
  if (x0 < 0 || y0 < 0 || x0 + 1 >= width || y0 + 1 >= height) return false;
  const double ax = x - x0, ay = y - y0;
  Eigen::Vector2d acc(0, 0);
  for (int dy = 0; dy < 2; ++dy) {
    for (int dx = 0; dx < 2; ++dx) {
      const std::size_t i = static_cast<std::size_t>(y0 + dy) * static_cast<std::size_t>(width) + static_cast<std::size_t>(x0 + dx);
      if (map[i] < 0.0f) return false;
      const double wgt = (dx == 1 ? ax : 1.0 - ax) * (dy == 1 ? ay : 1.0 - ay);
      acc += wgt * Eigen::Vector2d(static_cast<double>(map[i]), static_cast<double>(map[n + i]));
    }
  }
  out = acc;
  return true;
}

// Coverage: rectified reference pixels whose true surface point (render depth) is inside the other
// image, and how many of them gave a point.
struct Coverage {
  std::size_t overlap{0}, covered{0};
  [[nodiscard]] double share() const { return static_cast<double>(covered) / static_cast<double>(std::max<std::size_t>(overlap, 1)); }
};
Coverage overlap_coverage(const DenseStereo& stereo, const Frame& cur, const Frame& prev) {
  const RectifiedGeometry& g = stereo.rectified();
  const ag::PinholeCamera& cam = stereo.camera();
  const StereoParams& p = stereo.params();
  const auto& map = stereo.map_reference();
  const auto& disp = stereo.disparity();
  const Eigen::Isometry3d prev_from_cur = prev.map_from_camera.inverse() * cur.map_from_camera;
  Coverage c;
  for (int y = 0; y < g.height; ++y) {
    for (int x = 0; x < g.width; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * static_cast<std::size_t>(g.width) + static_cast<std::size_t>(x);
      const double su = static_cast<double>(map[i]), sv = static_cast<double>(map[static_cast<std::size_t>(g.width * g.height) + i]);
      if (su < 0) continue;
      const double z = static_cast<double>(cur.f.depth.at<float>(static_cast<int>(sv + 0.5), static_cast<int>(su + 0.5)));
      if (z <= 0) continue;
      const Eigen::Vector2d nrm = cam.undistort_pixel(su, sv);
      const Eigen::Vector3d xp = prev_from_cur * Eigen::Vector3d(nrm.x() * z, nrm.y() * z, z);
      if (xp.z() <= 0) continue;
      const Eigen::Vector2d q = cam.distort_to_pixel(xp.x() / xp.z(), xp.y() / xp.z());
      if (q.x() < 0 || q.y() < 0 || q.x() > cam.width - 1 || q.y() > cam.height - 1) continue;
      ++c.overlap;
      if (disp[i] > 0) {
        const double zd = g.f * g.baseline_m * 16.0 / disp[i];
        c.covered += zd >= p.min_depth_m && zd <= p.max_depth_m ? 1u : 0u;
      }
    }
  }
  return c;
}

TEST(StereoSim, CameraMountMatchesTheSimulator) {
  EXPECT_TRUE(ag::sim::CameraModel::body_from_camera().isApprox(ag::nadir_body_from_camera(), 1e-12));
  EXPECT_EQ(scene().camera.width, 640);
  EXPECT_EQ(scene().camera.height, 400);
}

// 1a. Rotations and remap tables equal OpenCV's. OpenCV rectifies a baseline along the image y axis
// vertically, ours always horizontally; so OpenCV gets the same cameras turned by 90 degrees about their
// optical axis (x' = y, y' = -x: the images transposed and mirrored, which the radial-only lens model
// does not notice), where the baseline is along x', and its maps are turned back.
TEST(StereoSim, RectificationMatchesOpenCvStereoRectify) {
  Scene& s = scene();
  ASSERT_EQ(s.model.p1, 0.0);
  ASSERT_EQ(s.model.p2, 0.0);
  DenseStereo stereo(s.camera, test_params());
  std::vector<MapPoint> pts;
  auto r = stereo.compute(s.prev.image(), s.cur.image(), pts);
  ASSERT_TRUE(r.ok()) << r.error().message;
  const RectifiedGeometry& g = stereo.rectified();
  std::printf("rectified %dx%d f=%.1f c=(%.1f, %.1f) baseline %.3f m\n", g.width, g.height, g.f, g.cx, g.cy, g.baseline_m);
  EXPECT_GT(g.width, 400);
  EXPECT_GT(g.height, 600);

  const Eigen::Matrix3d r_ref = s.cur.map_from_camera.linear(), r_oth = s.prev.map_from_camera.linear();
  const Eigen::Vector3d c_ref = s.cur.map_from_camera.translation(), c_oth = s.prev.map_from_camera.translation();
  const Eigen::Matrix3d rel_r = r_oth.transpose() * r_ref;        // X_prev = R X_cur + T
  const Eigen::Vector3d rel_t = r_oth.transpose() * (c_ref - c_oth);
  Eigen::Matrix3d q;
  q << 0, 1, 0, -1, 0, 0, 0, 0, 1;  // turned camera from camera
  const Eigen::Matrix3d rq = q * rel_r * q.transpose();
  const Eigen::Vector3d tq = q * rel_t;
  const double f = s.camera.fx, cx = s.camera.cx, cy = s.camera.cy;
  const cv::Matx33d k_turned(f, 0, cy, 0, f, cx, 0, 0, 1);  // u' = v, v' = 2 cx - u
  const cv::Mat dist = (cv::Mat_<double>(1, 5) << s.camera.k1, s.camera.k2, s.camera.p1, s.camera.p2, s.camera.k3);
  cv::Matx33d cv_r(rq(0, 0), rq(0, 1), rq(0, 2), rq(1, 0), rq(1, 1), rq(1, 2), rq(2, 0), rq(2, 1), rq(2, 2));
  cv::Vec3d cv_t(tq.x(), tq.y(), tq.z());
  cv::Mat r1, r2, p1, p2, q4;
  cv::stereoRectify(k_turned, dist, k_turned, dist, cv::Size(s.camera.height, s.camera.width), cv_r, cv_t, r1, r2, p1, p2,
                    q4, cv::CALIB_ZERO_DISPARITY, -1);
  ASSERT_GT(std::abs(p2.at<double>(0, 3)), std::abs(p2.at<double>(1, 3))) << "OpenCV should rectify the turned pair horizontally";
  Eigen::Matrix3d e_r1, e_r2;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      e_r1(i, j) = r1.at<double>(i, j);
      e_r2(i, j) = r2.at<double>(i, j);
    }
  const double rot_err_ref = (g.rect_from_reference - e_r1 * q).cwiseAbs().maxCoeff();
  const double rot_err_oth = (g.rect_from_other - e_r2 * q).cwiseAbs().maxCoeff();
  std::printf("rotation vs stereoRectify: max |diff| ref %.2e other %.2e\n", rot_err_ref, rot_err_oth);
  EXPECT_LT(rot_err_ref, 1e-9);
  EXPECT_LT(rot_err_oth, 1e-9);

  const cv::Matx33d p_ours(g.f, 0, g.cx, 0, g.f, g.cy, 0, 0, 1);
  for (int which = 0; which < 2; ++which) {
    cv::Mat mx, my;
    cv::initUndistortRectifyMap(k_turned, dist, which == 0 ? r1 : r2, p_ours, cv::Size(g.width, g.height), CV_32FC1, mx, my);
    const std::vector<float>& ours = which == 0 ? stereo.map_reference() : stereo.map_other();
    double max_err = 0;
    std::size_t compared = 0, missing = 0;
    for (int y = 0; y < g.height; ++y) {
      for (int x = 0; x < g.width; ++x) {
        const double u = 2.0 * cx - static_cast<double>(my.at<float>(y, x)), v = static_cast<double>(mx.at<float>(y, x));
        const std::size_t i = static_cast<std::size_t>(y) * static_cast<std::size_t>(g.width) + static_cast<std::size_t>(x);
        const std::size_t n = static_cast<std::size_t>(g.width) * static_cast<std::size_t>(g.height);
        const bool cv_inside = u >= 0.1 && v >= 0.1 && u <= s.camera.width - 1.1 && v <= s.camera.height - 1.1;
        if (ours[i] < 0.0f) {
          missing += cv_inside ? 1u : 0u;
          continue;
        }
        ++compared;
        max_err = std::max({max_err, std::abs(static_cast<double>(ours[i]) - u), std::abs(static_cast<double>(ours[n + i]) - v)});
      }
    }
    std::printf("%s map vs initUndistortRectifyMap: %zu px compared, max error %.2e px, %zu inside for OpenCV but not ours\n",
                which == 0 ? "reference" : "other", compared, max_err, missing);
    EXPECT_GT(compared, static_cast<std::size_t>(g.width * g.height) / 2);
    EXPECT_LT(max_err, 0.05);
    EXPECT_EQ(missing, 0u);
  }
}

// 1b. The epipolar property itself: a 3D point seen by both cameras lands on the same rectified row of
// both images, at disparity f * B / z, and our remap tables send those rectified positions to where the
// point is in each distorted original.
TEST(StereoSim, RectifiedCorrespondencesShareRowsAndDisparity) {
  Scene& s = scene();
  DenseStereo stereo(s.camera, test_params());
  std::vector<MapPoint> pts;
  ASSERT_TRUE(stereo.compute(s.prev.image(), s.cur.image(), pts).ok());
  const RectifiedGeometry& g = stereo.rectified();
  const ag::PinholeCamera& cam = s.camera;
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> du(0, cam.width - 1), dv(0, cam.height - 1);
  double max_row = 0, max_disp = 0, max_map = 0;
  int n = 0;
  for (int trial = 0; trial < 20000 && n < 2000; ++trial) {
    const int u = du(rng), v = dv(rng);
    const double z = static_cast<double>(s.cur.f.depth.at<float>(v, u));
    if (z <= 0) continue;
    const Eigen::Vector2d nrm = cam.undistort_pixel(u, v);
    const Eigen::Vector3d x_cur(nrm.x() * z, nrm.y() * z, z);
    const Eigen::Vector3d x_map = s.cur.map_from_camera * x_cur;
    const Eigen::Vector3d x_prev = s.prev.map_from_camera.inverse() * x_map;
    if (x_prev.z() <= 0) continue;
    const Eigen::Vector2d pix_prev = cam.distort_to_pixel(x_prev.x() / x_prev.z(), x_prev.y() / x_prev.z());
    if (pix_prev.x() < 1 || pix_prev.y() < 1 || pix_prev.x() > cam.width - 2 || pix_prev.y() > cam.height - 2) continue;
    const Eigen::Vector3d ra = g.rect_from_reference * x_cur, rb = g.rect_from_other * x_prev;
    const Eigen::Vector2d a(g.f * ra.x() / ra.z() + g.cx, g.f * ra.y() / ra.z() + g.cy);
    const Eigen::Vector2d b(g.f * rb.x() / rb.z() + g.cx, g.f * rb.y() / rb.z() + g.cy);
    max_row = std::max(max_row, std::abs(a.y() - b.y()));
    max_disp = std::max(max_disp, std::abs((a.x() - b.x()) - g.f * g.baseline_m / ra.z()));
    EXPECT_GT(a.x() - b.x(), 0.0) << "disparity must be positive";
    Eigen::Vector2d ma, mb;
    if (sample_map(stereo.map_reference(), g.width, g.height, a.x(), a.y(), ma) &&
        sample_map(stereo.map_other(), g.width, g.height, b.x(), b.y(), mb)) {
      max_map = std::max({max_map, (ma - Eigen::Vector2d(u, v)).norm(), (mb - pix_prev).norm()});
      ++n;
    }
  }
  std::printf("%d correspondences: max row difference %.2e px, max |disparity - fB/z| %.2e px, max map error %.3f px\n", n,
              max_row, max_disp, max_map);
  EXPECT_GT(n, 1000);
  EXPECT_LT(max_row, 0.05);
  EXPECT_LT(max_disp, 0.05);
  // Bilinear interpolation of a smooth map between pixel centres: well under the 0.05 px budget.
  EXPECT_LT(max_map, 0.05);
}

// 2. Our block matcher against cv::StereoBM on our rectified pair with the same parameters.
TEST(StereoSim, BlockMatcherMatchesOpenCvStereoBM) {
  Scene& s = scene();
  StereoParams p = test_params();
  p.lr_max_diff = -1;    // StereoBM has no left-right check
  p.edge_margin_px = 0;  // nor an edge guard
  DenseStereo stereo(s.camera, p);
  std::vector<MapPoint> pts;
  ag::mapping::StereoTiming t;
  ASSERT_TRUE(stereo.compute(s.prev.image(), s.cur.image(), pts, &t).ok());
  std::printf("timing: rectify %.1f ms, match %.1f ms, project %.1f ms, %zu points\n", t.rectify_ms, t.match_ms, t.project_ms,
              pts.size());
  const RectifiedGeometry& g = stereo.rectified();
  const cv::Mat left(g.height, g.width, CV_8UC1, const_cast<std::uint8_t*>(stereo.rectified_reference().data()));
  const cv::Mat right(g.height, g.width, CV_8UC1, const_cast<std::uint8_t*>(stereo.rectified_other().data()));
  auto bm = cv::StereoBM::create(p.num_disparities, p.block_size);
  bm->setMinDisparity(p.min_disparity);
  bm->setPreFilterType(cv::StereoBM::PREFILTER_XSOBEL);
  bm->setPreFilterCap(p.prefilter_cap);
  bm->setTextureThreshold(p.texture_threshold);
  bm->setUniquenessRatio(p.uniqueness_ratio);
  bm->setSpeckleWindowSize(p.speckle_window);
  bm->setSpeckleRange(16 * p.speckle_range);  // StereoBM's speckle range is in 1/16 px
  cv::Mat cv_disp;
  bm->compute(left, right, cv_disp);
  ASSERT_EQ(cv_disp.type(), CV_16SC1);
  const std::int16_t filtered = static_cast<std::int16_t>((p.min_disparity - 1) * 16);

  // Raw output (before our border mask) against StereoBM's.
  const auto& raw = stereo.raw_disparity();
  std::size_t ours_valid = 0, cv_valid = 0, both = 0, agree = 0, identical = 0;
  for (int y = 0; y < g.height; ++y) {
    for (int x = 0; x < g.width; ++x) {
      const std::int16_t a = raw[static_cast<std::size_t>(y) * static_cast<std::size_t>(g.width) + static_cast<std::size_t>(x)];
      const std::int16_t b = cv_disp.at<std::int16_t>(y, x);
      const bool va = a != filtered, vb = b != filtered;
      ours_valid += va ? 1u : 0u;
      cv_valid += vb ? 1u : 0u;
      identical += a == b ? 1u : 0u;
      if (va && vb) {
        ++both;
        agree += std::abs(a - b) <= 16 ? 1u : 0u;
      }
    }
  }
  std::printf("raw: ours %zu valid, OpenCV %zu valid, %zu both, %.4f%% of those within 1 px, %.4f%% of all pixels identical\n",
              ours_valid, cv_valid, both, 100.0 * static_cast<double>(agree) / static_cast<double>(std::max<std::size_t>(both, 1)),
              100.0 * static_cast<double>(identical) / static_cast<double>(g.width * g.height));
  EXPECT_GT(ours_valid, static_cast<std::size_t>(g.width * g.height) / 3);
  EXPECT_GE(static_cast<double>(agree), 0.95 * static_cast<double>(both));
  EXPECT_LE(std::abs(static_cast<double>(ours_valid) - static_cast<double>(cv_valid)), 0.10 * static_cast<double>(cv_valid));

  // Masked output: OpenCV's disparities under the same border masks.
  const auto& disp = stereo.disparity();
  const auto& mask = stereo.valid_mask();
  // The other image's border mask, from its remap table, dilated by OpenCV.
  cv::Mat invalid_other(g.height, g.width, CV_8UC1);
  for (int y = 0; y < g.height; ++y)
    for (int x = 0; x < g.width; ++x)
      invalid_other.at<std::uint8_t>(y, x) =
          stereo.map_other()[static_cast<std::size_t>(y) * static_cast<std::size_t>(g.width) + static_cast<std::size_t>(x)] < 0.0f ? 1 : 0;
  cv::dilate(invalid_other, invalid_other, cv::Mat::ones(2 * p.border_dilate_px + 1, 2 * p.border_dilate_px + 1, CV_8UC1),
             cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, cv::Scalar(0));
  // Our reference mask is the same dilation of the reference's border.
  cv::Mat invalid_ref(g.height, g.width, CV_8UC1);
  for (int y = 0; y < g.height; ++y)
    for (int x = 0; x < g.width; ++x)
      invalid_ref.at<std::uint8_t>(y, x) =
          stereo.map_reference()[static_cast<std::size_t>(y) * static_cast<std::size_t>(g.width) + static_cast<std::size_t>(x)] < 0.0f ? 1 : 0;
  cv::dilate(invalid_ref, invalid_ref, cv::Mat::ones(2 * p.border_dilate_px + 1, 2 * p.border_dilate_px + 1, CV_8UC1),
             cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, cv::Scalar(0));
  std::size_t mask_diff = 0;
  for (int y = 0; y < g.height; ++y)
    for (int x = 0; x < g.width; ++x)
      mask_diff += (mask[static_cast<std::size_t>(y) * static_cast<std::size_t>(g.width) + static_cast<std::size_t>(x)] != 0) ==
                           (invalid_ref.at<std::uint8_t>(y, x) != 0)
                       ? 1u
                       : 0u;
  EXPECT_EQ(mask_diff, 0u) << "valid_mask() differs from cv::dilate of the reference's border";
  std::size_t m_ours = 0, m_cv = 0, m_both = 0, m_agree = 0;
  for (int y = 0; y < g.height; ++y) {
    for (int x = 0; x < g.width; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * static_cast<std::size_t>(g.width) + static_cast<std::size_t>(x);
      const std::int16_t b = cv_disp.at<std::int16_t>(y, x);
      const bool va = disp[i] >= 0;
      bool vb = b != filtered && b > 0 && mask[i] != 0;
      // The other image's border is checked at the matched column.
      if (vb) {
        const int xo = x - (b + 8) / 16;
        vb = xo >= 0 && invalid_other.at<std::uint8_t>(y, xo) == 0;
      }
      m_ours += va ? 1u : 0u;
      m_cv += vb ? 1u : 0u;
      if (va && vb) {
        ++m_both;
        m_agree += std::abs(disp[i] - b) <= 16 ? 1u : 0u;
      }
    }
  }
  std::printf("masked: ours %zu valid, OpenCV %zu, %zu both, %.3f%% within 1 px\n", m_ours, m_cv, m_both,
              100.0 * static_cast<double>(m_agree) / static_cast<double>(std::max<std::size_t>(m_both, 1)));
  EXPECT_GE(static_cast<double>(m_agree), 0.95 * static_cast<double>(m_both));
  EXPECT_LE(std::abs(static_cast<double>(m_ours) - static_cast<double>(m_cv)), 0.10 * static_cast<double>(m_cv));
  EXPECT_EQ(stereo.stats().valid_disparities, m_ours);
}

// 3. The points against the world: heights on open ground, coverage of the overlap, classes.
TEST(StereoSim, PointsMatchTheWorld) {
  Scene& s = scene();
  const StereoParams p = test_params();
  DenseStereo stereo(s.camera, p);
  std::vector<MapPoint> pts;
  auto r = stereo.compute(s.prev.image(), s.cur.image(), pts);
  ASSERT_TRUE(r.ok()) << r.error().message;
  ASSERT_EQ(r.value(), pts.size());
  const ag::sim::World& w = s.world;
  const auto& grid = w.grid();

  // Heights: points over open ground (no object within 0.5 m) against the terrain.
  std::vector<double> ground_err, all_err;
  std::size_t cls_ok = 0, cls_n = 0;
  for (const MapPoint& pt : pts) {
    const int c = grid.col(static_cast<double>(pt.x)), rr = grid.row(static_cast<double>(pt.y));
    if (!grid.contains(c - 2, rr - 2) || !grid.contains(c + 2, rr + 2)) continue;
    bool open = true;
    for (int dr = -2; dr <= 2 && open; ++dr)
      for (int dc = -2; dc <= 2 && open; ++dc) open = w.height.at<float>(rr + dr, c + dc) == 0.0f;
    const double err = static_cast<double>(pt.z - w.surface_at(c, rr));
    all_err.push_back(std::abs(err));
    if (open) ground_err.push_back(std::abs(err));
    EXPECT_GT(pt.cos_axis, 0.75f);
    EXPECT_LE(pt.cos_axis, 1.0f);
    if (pt.cls != ag::raw(ag::ClassId::kUnknown)) {
      ++cls_n;
      cls_ok += pt.cls == ag::raw(w.class_at(c, rr)) ? 1u : 0u;
    }
  }
  const auto median = [](std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
    return v[v.size() / 2];
  };
  ASSERT_GT(ground_err.size(), 10000u);
  const double med_ground = median(ground_err), med_all = median(all_err);
  std::printf("%zu points, %zu on open ground: median |z error| ground %.3f m, all %.3f m; class agreement %.2f%%\n", pts.size(),
              ground_err.size(), med_ground, med_all, 100.0 * static_cast<double>(cls_ok) / static_cast<double>(cls_n));
  EXPECT_LE(med_ground, 0.3);
  EXPECT_GE(static_cast<double>(cls_ok), 0.95 * static_cast<double>(cls_n));

  const Coverage cov = overlap_coverage(stereo, s.cur, s.prev);
  std::printf("overlap %zu rectified px, %zu with a point (%.1f%%)\n", cov.overlap, cov.covered, 100.0 * cov.share());
  EXPECT_GE(cov.share(), 0.60);
}

// 4. Refusals, and no reallocation between pairs.
TEST(StereoSim, RefusesShortBaselinesAndNonOverlappingPairs) {
  Scene& s = scene();
  DenseStereo stereo(s.camera, test_params());
  std::vector<MapPoint> pts;

  Frame near;
  s.render(moved(s.cur_body, -0.3, 0.0, 0.0, 0.0, 0.0), near);
  auto r = stereo.compute(near.image(), s.cur.image(), pts);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("baseline"), std::string::npos) << r.error().message;
  EXPECT_EQ(stereo.stats().refused, 1u);
  EXPECT_TRUE(pts.empty());

  Frame far;
  s.render(moved(s.cur_body, -60.0, 0.0, 0.0, 0.0, 0.0), far);
  r = stereo.compute(far.image(), s.cur.image(), pts);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("overlap"), std::string::npos) << r.error().message;
  EXPECT_EQ(stereo.stats().refused, 2u);

  // A camera turned to look along the baseline cannot be rectified.
  Frame turned = s.prev;
  turned.map_from_camera.linear() = s.prev.map_from_camera.linear() *
                                    Eigen::AngleAxisd(1.5, Eigen::Vector3d::UnitX()).toRotationMatrix();
  r = stereo.compute(turned.image(), s.cur.image(), pts);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(stereo.stats().refused, 3u);

  // Good pairs go through and reuse the buffers.
  ASSERT_TRUE(stereo.compute(s.prev.image(), s.cur.image(), pts).ok());
  const auto* disp_data = stereo.disparity().data();
  const auto* map_data = stereo.map_reference().data();
  const auto* rect_data = stereo.rectified_reference().data();
  Frame other;
  s.render(moved(s.cur_body, 2.0, -0.1, 0.01, 0.0, 0.02), other);
  ASSERT_TRUE(stereo.compute(s.cur.image(), other.image(), pts).ok());
  EXPECT_FALSE(pts.empty());
  EXPECT_EQ(stereo.disparity().data(), disp_data);
  EXPECT_EQ(stereo.map_reference().data(), map_data);
  EXPECT_EQ(stereo.rectified_reference().data(), rect_data);
  EXPECT_EQ(stereo.stats().pairs, 5u);
  EXPECT_EQ(stereo.stats().refused, 3u);
}

// Sideways and diagonal baselines (crabbing in wind, turns) rectify too, within the buffers, with 112
// and with 256 disparities: the wider range only widens StereoBM's dead band on the left (by exactly
// 144 columns, so no window was clamped) and finds the same points.
TEST(StereoSim, AnyBaselineDirectionInTheImage) {
  Scene& s = scene();
  StereoParams wide = test_params();
  wide.num_disparities = 256;
  DenseStereo stereo(s.camera, test_params()), stereo_wide(s.camera, wide);
  std::vector<MapPoint> pts;
  const double dirs[][2] = {{0.0, 2.0}, {0.0, -2.0}, {1.5, 1.5}, {-1.4, 1.4}, {2.0, 0.0}};
  for (const auto& d : dirs) {
    Frame other;
    s.render(moved(s.cur_body, d[0], d[1], 0.01, -0.01, 0.02), other);
    int width[2] = {0, 0};
    std::size_t points[2] = {0, 0};
    for (int k = 0; k < 2; ++k) {
      DenseStereo& st = k == 0 ? stereo : stereo_wide;
      auto r = st.compute(other.image(), s.cur.image(), pts);
      ASSERT_TRUE(r.ok()) << r.error().message;
      const RectifiedGeometry& g = st.rectified();
      std::printf("baseline (%.1f, %.1f) m in body axes, %d disparities: rectified %dx%d, %zu points\n", d[0], d[1],
                  st.params().num_disparities, g.width, g.height, pts.size());
      EXPECT_GT(pts.size(), 100000u);
      width[k] = g.width;
      points[k] = pts.size();
      // The other camera sits at +x of the reference's rectified frame.
      const Eigen::Vector3d c_other = g.map_from_rect.inverse() * other.map_from_camera.translation();
      EXPECT_NEAR(c_other.x(), g.baseline_m, 1e-9);
      EXPECT_NEAR(c_other.y(), 0.0, 1e-9);
      EXPECT_NEAR(c_other.z(), 0.0, 1e-9);
    }
    EXPECT_EQ(width[1] - width[0], 256 - 112);
    EXPECT_GE(static_cast<double>(points[1]), 0.95 * static_cast<double>(points[0]));
    EXPECT_LE(static_cast<double>(points[1]), 1.02 * static_cast<double>(points[0]));
  }
}

// A keyframe pair over (x, y) (default: Scene's built-up spot) at another altitude and baseline, with
// the same small attitude changes as Scene's pair.
struct PairAt {
  Frame cur, prev;
  PairAt(double altitude_m, double baseline_m) : PairAt(altitude_m, baseline_m, scene().cur_body.x, scene().cur_body.y) {}
  PairAt(double altitude_m, double baseline_m, double x, double y) {
    Scene& s = scene();
    const auto& g = s.world.grid();
    const double ground = static_cast<double>(s.world.terrain.at<float>(g.row(y), g.col(x)));
    const Pose3 c{x, y, ground + altitude_m, s.cur_body.roll, s.cur_body.pitch, s.cur_body.yaw};
    s.render(c, cur);
    s.render(moved(c, -baseline_m, 0.025 * baseline_m, -0.012, 0.02, -0.01), prev);
  }
};

// The 10 m grid point with the most cells of buildings 28 m or taller within 15 m (the world's tallest
// are 30 m).
Eigen::Vector2d find_tall_spot() {
  const ag::sim::World& w = scene().world;
  const auto& g = w.grid();
  Eigen::Vector2d best(0, 0);
  int most = -1;
  for (double x = -150; x <= 150; x += 10) {
    for (double y = -150; y <= 150; y += 10) {
      int n = 0;
      for (double dx = -15; dx <= 15; dx += 0.5)
        for (double dy = -15; dy <= 15; dy += 0.5) {
          const int c = g.col(x + dx), r = g.row(y + dy);
          n += g.contains(c, r) && w.class_at(c, r) == ag::ClassId::kBuilding && w.height.at<float>(r, c) >= 28.0f ? 1 : 0;
        }
      if (n > most) {
        most = n;
        best = {x, y};
      }
    }
  }
  return best;
}

Eigen::Vector2d tall_spot() {
  static const Eigen::Vector2d spot = find_tall_spot();
  return spot;
}

// Projected points against the world surface of their cell: the share more than 1 m off, and the
// height RMSE of points in open-ground cells within 0.5 m of an object taller than 2 m (beside
// buildings and trees, where foreground fattening and occlusions put roof heights on the ground).
struct SurfaceErrors {
  std::size_t points{0}, off_1m{0}, beside{0};
  double beside_rmse{0};
  [[nodiscard]] double off_share() const { return static_cast<double>(off_1m) / static_cast<double>(std::max<std::size_t>(points, 1)); }
};
SurfaceErrors surface_errors(const std::vector<MapPoint>& pts) {
  const ag::sim::World& w = scene().world;
  const auto& grid = w.grid();
  SurfaceErrors e;
  double beside_sq = 0;
  for (const MapPoint& pt : pts) {
    const int c = grid.col(static_cast<double>(pt.x)), r = grid.row(static_cast<double>(pt.y));
    if (!grid.contains(c - 2, r - 2) || !grid.contains(c + 2, r + 2)) continue;
    const double err = static_cast<double>(pt.z - w.surface_at(c, r));
    ++e.points;
    e.off_1m += std::abs(err) > 1.0 ? 1u : 0u;
    if (w.height.at<float>(r, c) != 0.0f) continue;
    bool tall = false;
    for (int dr = -2; dr <= 2 && !tall; ++dr)
      for (int dc = -2; dc <= 2 && !tall; ++dc) tall = w.height.at<float>(r + dr, c + dc) > 2.0f;
    if (tall) {
      ++e.beside;
      beside_sq += err * err;
    }
  }
  e.beside_rmse = std::sqrt(beside_sq / static_cast<double>(std::max<std::size_t>(e.beside, 1)));
  return e;
}

// A synthetic pair without the simulator: textured ground at 40 m depth and a textured box whose top is
// at 25 m, seen by two distortion-free nadir cameras 4 m apart along their x axis (the rectified images
// are the originals). Ground beside the box's left side is hidden from the other camera: an occlusion
// 29 px wide (ground disparity 48.4 px, box top 77.4 px).
struct BoxScene {
  static constexpr double kBaseline = 4.0, kGround = 40.0, kTop = 25.0;
  static constexpr double kX0 = -4.0, kX1 = 4.0, kY0 = -5.0, kY1 = 3.0;
  ag::PinholeCamera camera;  // 640x400, f 483.5, no distortion
  std::vector<std::uint8_t> rgb_ref, rgb_other, cls;
  Eigen::Isometry3d ref{Eigen::Isometry3d::Identity()}, other{Eigen::Isometry3d::Identity()};

  // Bilinear value noise on a 0.1 m lattice, in [0, 1).
  static double noise(double a, double b, std::uint32_t seed) {
    const auto lattice = [seed](std::int64_t i, std::int64_t j) {
      std::uint64_t h = static_cast<std::uint64_t>(i) * 0x9E3779B97F4A7C15ull ^
                        static_cast<std::uint64_t>(j) * 0xC2B2AE3D27D4EB4Full ^ seed;
      h ^= h >> 31;
      h *= 0xBF58476D1CE4E5B9ull;
      h ^= h >> 29;
      return static_cast<double>(h >> 40) / static_cast<double>(1ull << 24);
    };
    const double fa = std::floor(a / 0.1), fb = std::floor(b / 0.1);
    const double ta = a / 0.1 - fa, tb = b / 0.1 - fb;
    const auto i = static_cast<std::int64_t>(fa), j = static_cast<std::int64_t>(fb);
    const double top = lattice(i, j) + ta * (lattice(i + 1, j) - lattice(i, j));
    const double bot = lattice(i, j + 1) + ta * (lattice(i + 1, j + 1) - lattice(i, j + 1));
    return top + tb * (bot - top);
  }
  // Depth along the ray centre + t * dir (dir.z() = 1) where it enters the box, or a negative value.
  static double box_entry(const Eigen::Vector3d& c, const Eigen::Vector3d& dir) {
    double t0 = 0.0, t1 = kGround;
    const double lo[3] = {kX0, kY0, kTop}, hi[3] = {kX1, kY1, kGround};
    for (int k = 0; k < 3; ++k) {
      if (std::abs(dir[k]) < 1e-12) {
        if (c[k] < lo[k] || c[k] > hi[k]) return -1.0;
        continue;
      }
      double a = (lo[k] - c[k]) / dir[k], b = (hi[k] - c[k]) / dir[k];
      if (a > b) std::swap(a, b);
      t0 = std::max(t0, a);
      t1 = std::min(t1, b);
    }
    return t0 < t1 - 1e-9 ? t0 : -1.0;
  }
  // True if the segment from `c` to the ground point g passes through the box.
  static bool blocked(const Eigen::Vector3d& c, const Eigen::Vector3d& g) {
    const Eigen::Vector3d dir = (g - c) / (g.z() - c.z());
    const double t = box_entry(c, dir);
    return t >= 0.0 && t < kGround - 1e-6;
  }
  void render(const Eigen::Vector3d& c, std::vector<std::uint8_t>& rgb) const {
    rgb.assign(static_cast<std::size_t>(3 * camera.width * camera.height), 0);
    for (int v = 0; v < camera.height; ++v) {
      for (int u = 0; u < camera.width; ++u) {
        const Eigen::Vector3d dir((u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, 1.0);
        const double t = box_entry(c, dir);
        double val;
        if (t < 0.0) {
          const Eigen::Vector3d g = c + kGround * dir;
          val = noise(g.x(), g.y(), 1);
        } else {
          const Eigen::Vector3d q = c + t * dir;
          val = std::abs(t - kTop) < 1e-9 ? noise(q.x(), q.y(), 2) : noise(q.x() + q.y(), q.z(), 3);
        }
        const auto g8 = static_cast<std::uint8_t>(30.0 + 200.0 * val);
        const std::size_t i = 3 * (static_cast<std::size_t>(v) * static_cast<std::size_t>(camera.width) + static_cast<std::size_t>(u));
        rgb[i] = rgb[i + 1] = rgb[i + 2] = g8;
      }
    }
  }
  BoxScene() {
    other.translation() = Eigen::Vector3d(kBaseline, 0.0, 0.0);
    render(ref.translation(), rgb_ref);
    render(other.translation(), rgb_other);
    cls.assign(static_cast<std::size_t>(camera.width * camera.height), 0);
  }
  [[nodiscard]] StereoImage ref_image() const { return {rgb_ref.data(), cls.data(), ref}; }
  [[nodiscard]] StereoImage other_image() const { return {rgb_other.data(), cls.data(), other}; }

  // Per rectified reference pixel: 0 no source, 1 ground seen by both, 2 ground occluded in the other
  // view (but inside its image), 3 box top seen by both, 4 other (walls, outside the other image).
  [[nodiscard]] std::vector<std::uint8_t> truth(const DenseStereo& stereo) const {
    const RectifiedGeometry& g = stereo.rectified();
    const std::size_t n = static_cast<std::size_t>(g.width) * static_cast<std::size_t>(g.height);
    std::vector<std::uint8_t> out(n, 0);
    const auto& map = stereo.map_reference();
    for (std::size_t i = 0; i < n; ++i) {
      if (map[i] < 0.0f) continue;
      const Eigen::Vector3d dir((static_cast<double>(map[i]) - camera.cx) / camera.fx,
                                (static_cast<double>(map[n + i]) - camera.cy) / camera.fy, 1.0);
      const double t = box_entry(ref.translation(), dir);
      const Eigen::Vector3d p = ref.translation() + (t < 0.0 ? kGround : t) * dir;
      const Eigen::Vector3d po = p - other.translation();
      const double uo = camera.fx * po.x() / po.z() + camera.cx;
      const bool in_other = uo >= 8.0 && uo <= camera.width - 9.0;
      if (!in_other) {
        out[i] = 4;
      } else if (t < 0.0) {
        out[i] = blocked(other.translation(), p) ? 2 : 1;
      } else {
        out[i] = std::abs(t - kTop) < 1e-9 ? 3 : 4;
      }
    }
    return out;
  }
};

TEST(StereoSim, LeftRightCheckInvalidatesSyntheticOcclusion) {
  const BoxScene box;
  struct Counts {
    std::size_t n[5] = {}, valid[5] = {}, right[5] = {};
  };
  const auto run = [&](const StereoParams& p, Counts& c) {
    DenseStereo stereo(box.camera, p);
    std::vector<MapPoint> pts;
    auto r = stereo.compute(box.other_image(), box.ref_image(), pts);
    ASSERT_TRUE(r.ok()) << r.error().message;
    const RectifiedGeometry& g = stereo.rectified();
    ASSERT_NEAR(g.baseline_m, BoxScene::kBaseline, 1e-12);
    const std::vector<std::uint8_t> truth = box.truth(stereo);
    const auto& disp = stereo.disparity();
    const double d_ground = g.f * BoxScene::kBaseline / BoxScene::kGround, d_top = g.f * BoxScene::kBaseline / BoxScene::kTop;
    for (std::size_t i = 0; i < truth.size(); ++i) {
      const int t = truth[i];
      ++c.n[t];
      if (disp[i] < 0) continue;
      ++c.valid[t];
      const double d = disp[i] / 16.0;
      c.right[t] += std::abs(d - (t == 3 ? d_top : d_ground)) <= 1.0 ? 1u : 0u;
    }
  };
  // The check on its own: no uniqueness test, speckle filter or edge guard, so that every textured
  // pixel of the occlusion gets some (wrong) winner.
  StereoParams bare;
  bare.uniqueness_ratio = 0;
  bare.speckle_window = 0;
  bare.edge_margin_px = 0;
  bare.lr_max_diff = -1;
  Counts off, on, dflt;
  run(bare, off);
  bare.lr_max_diff = 1;
  run(bare, on);
  run(StereoParams{}, dflt);
  const auto share = [](std::size_t a, std::size_t b) {
    return static_cast<double>(a) / static_cast<double>(std::max<std::size_t>(b, 1));
  };
  for (const auto& [name, c] : {std::pair<const char*, const Counts&>{"lr off", off}, {"lr on", on}, {"defaults", dflt}})
    std::printf("%-8s: occluded %zu px, %.1f%% valid; ground seen by both %.1f%% valid, %.1f%% within 1 px; "
                "box top %.1f%% valid, %.1f%% within 1 px\n",
                name, c.n[2], 100.0 * share(c.valid[2], c.n[2]), 100.0 * share(c.valid[1], c.n[1]), 100.0 * share(c.right[1], c.valid[1]),
                100.0 * share(c.valid[3], c.n[3]), 100.0 * share(c.right[3], c.valid[3]));
  ASSERT_GT(off.n[2], 3000u);  // ~29 px x ~160 rows
  // Without the check nearly every occluded pixel gets a disparity (measured 100%); with it nearly none
  // (3.8%), while the pixels both cameras see keep theirs (ground 95.9% vs 96.2% valid, box top 98.4%
  // vs 100%) and get more of them right.
  EXPECT_GE(share(off.valid[2], off.n[2]), 0.90);
  EXPECT_LE(share(on.valid[2], on.n[2]), 0.10);
  EXPECT_GE(share(on.valid[1], on.n[1]), 0.97 * share(off.valid[1], off.n[1]));
  EXPECT_GE(share(on.valid[3], on.n[3]), 0.95 * share(off.valid[3], off.n[3]));
  EXPECT_GE(share(on.right[1], on.valid[1]), 0.99);
  EXPECT_GE(share(on.right[3], on.valid[3]), 0.99);
  // With the defaults (uniqueness, speckle filter, edge guard) the occlusion is gone (0.3%); the edge
  // guard costs the box top its outer block_size / 2 (90.4% valid).
  EXPECT_LE(share(dflt.valid[2], dflt.n[2]), 0.02);
  EXPECT_GE(share(dflt.valid[1], dflt.n[1]), 0.90);
  EXPECT_GE(share(dflt.valid[3], dflt.n[3]), 0.85);
}

// The check only drops disparities: with it, the block matcher's output is the StereoBM output (lr off)
// minus some pixels, the rest bit-identical (the speckle filter runs after the check, and removing
// pixels only shrinks its regions).
TEST(StereoSim, LeftRightCheckOnlyDropsDisparities) {
  Scene& s = scene();
  StereoParams p = test_params();
  p.edge_margin_px = 0;
  p.lr_max_diff = -1;
  DenseStereo off(s.camera, p);
  p.lr_max_diff = 1;
  DenseStereo on(s.camera, p);
  std::vector<MapPoint> pts;
  ASSERT_TRUE(off.compute(s.prev.image(), s.cur.image(), pts).ok());
  ASSERT_TRUE(on.compute(s.prev.image(), s.cur.image(), pts).ok());
  EXPECT_EQ(off.stats().lr_rejected, 0u);
  EXPECT_GT(on.stats().lr_rejected, 0u);
  const std::int16_t filtered = static_cast<std::int16_t>((p.min_disparity - 1) * 16);
  const auto& a = off.raw_disparity();
  const auto& b = on.raw_disparity();
  ASSERT_EQ(a.size(), b.size());
  std::size_t valid_off = 0, valid_on = 0, changed = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    valid_off += a[i] != filtered ? 1u : 0u;
    valid_on += b[i] != filtered ? 1u : 0u;
    changed += b[i] != filtered && b[i] != a[i] ? 1u : 0u;
  }
  std::printf("raw valid: lr off %zu, lr on %zu (%llu dropped by the check before the speckle filter)\n", valid_off, valid_on,
              static_cast<unsigned long long>(on.stats().lr_rejected));
  EXPECT_EQ(changed, 0u);
  EXPECT_LT(valid_on, valid_off);
  EXPECT_GE(static_cast<double>(valid_on), 0.97 * static_cast<double>(valid_off));
}

// Beside buildings and trees: the share of points more than 1 m off the world's surface and the height
// RMSE of points on open ground within 0.5 m of a tall object, for StereoBM alone, with the left-right
// check, and with the check and the edge guard (the defaults), on ASOOM's pair (2 m at 40 m, 112
// disparities), a long-baseline pair (8 m at 50 m, 256 disparities) and a long-baseline pair over the
// world's 30 m towers. The points given up are mostly the wrong ones: the good points (within 1 m) stay.
TEST(StereoSim, FewerOutliersBesideBuildings) {
  struct Case {
    const char* name;
    double altitude_m, baseline_m;
    int num_disparities;
    bool towers;                                 // over the 30 m towers instead of Scene's spot
    double max_lr_ratio, max_full_ratio;         // bounds on the share off by > 1 m: lr / off, defaults / off
    double max_full_rmse_ratio;                  // bound on the beside-objects RMSE: defaults / off
    double min_lr_points, min_full_points;       // bounds on the point count: lr / off, defaults / off
  };
  // Measured (off -> lr -> defaults):
  //   2 m:    2.49% -> 2.28% -> 1.35% off by > 1 m, beside RMSE 5.97 -> 5.58 -> 3.18 m, points 224311 -> 223710 -> 218976
  //   8 m:    2.12% -> 1.82% -> 0.51%,                           5.58 -> 5.50 -> 1.78 m,         182429 -> 181562 -> 175309
  //   towers: 7.64% -> 3.57% -> 1.85%,                         14.26 -> 10.53 -> 5.24 m,         98724 -> 93854 -> 88246
  const Case cases[] = {{"2 m at 40 m, 112 disparities", 40.0, 2.0, 112, false, 0.95, 0.65, 0.65, 0.98, 0.95},
                        {"8 m at 50 m, 256 disparities", 50.0, 8.0, 256, false, 0.92, 0.35, 0.40, 0.98, 0.93},
                        {"towers, 10 m at 50 m, 256 disparities", 50.0, 10.0, 256, true, 0.60, 0.35, 0.50, 0.93, 0.86}};
  const Eigen::Vector2d tall = tall_spot();
  for (const Case& c : cases) {
    const PairAt pair = c.towers ? PairAt(c.altitude_m, c.baseline_m, tall.x(), tall.y()) : PairAt(c.altitude_m, c.baseline_m);
    SurfaceErrors e[3];
    for (int k = 0; k < 3; ++k) {
      StereoParams p = test_params();
      p.num_disparities = c.num_disparities;
      p.lr_max_diff = k == 0 ? -1 : 1;
      p.edge_margin_px = k == 2 ? StereoParams{}.edge_margin_px : 0;
      DenseStereo stereo(scene().camera, p);
      std::vector<MapPoint> pts;
      auto r = stereo.compute(pair.prev.image(), pair.cur.image(), pts);
      ASSERT_TRUE(r.ok()) << r.error().message;
      e[k] = surface_errors(pts);
      static const char* const names[3] = {"StereoBM", "+ lr check", "+ edge guard"};
      std::printf("%s, %-12s: %6zu points (%zu within 1 m), %.3f%% off by > 1 m, beside objects %zu points, height RMSE %.2f m\n",
                  c.name, names[k], e[k].points, e[k].points - e[k].off_1m, 100.0 * e[k].off_share(), e[k].beside, e[k].beside_rmse);
    }
    const auto good = [](const SurfaceErrors& x) { return static_cast<double>(x.points - x.off_1m); };
    EXPECT_LE(e[1].off_share(), c.max_lr_ratio * e[0].off_share()) << c.name;
    EXPECT_LE(e[2].off_share(), c.max_full_ratio * e[0].off_share()) << c.name;
    EXPECT_LE(e[1].beside_rmse, e[0].beside_rmse) << c.name;
    EXPECT_LE(e[2].beside_rmse, c.max_full_rmse_ratio * e[0].beside_rmse) << c.name;
    EXPECT_GE(static_cast<double>(e[1].points), c.min_lr_points * static_cast<double>(e[0].points)) << c.name;
    EXPECT_GE(static_cast<double>(e[2].points), c.min_full_points * static_cast<double>(e[0].points)) << c.name;
    EXPECT_GE(good(e[1]), 0.98 * good(e[0])) << c.name;
    EXPECT_GE(good(e[2]), 0.93 * good(e[0])) << c.name;
  }
}

// Longer baselines with wider disparity ranges (the mapper pairs keyframes 6-10 m apart at 50 m: ground
// at 60-100 px, 30 m roofs up to ~240 px): rectified window, heights on the ground and on roofs, coverage.
TEST(StereoSim, WideDisparityRangesOnLongBaselines) {
  struct Case {
    double baseline_m;
    int num_disparities;
  };
  const Case cases[] = {{6.0, 160}, {8.0, 256}, {10.0, 256}};
  const ag::sim::World& w = scene().world;
  const auto& grid = w.grid();
  const Eigen::Vector2d spot = tall_spot();
  for (const Case& c : cases) {
    PairAt pair(50.0, c.baseline_m, spot.x(), spot.y());
    StereoParams p = test_params();
    p.num_disparities = c.num_disparities;
    DenseStereo stereo(scene().camera, p);
    std::vector<MapPoint> pts;
    auto r = stereo.compute(pair.prev.image(), pair.cur.image(), pts);
    ASSERT_TRUE(r.ok()) << r.error().message;
    const RectifiedGeometry& g = stereo.rectified();
    std::vector<double> ground, roof, tall;
    for (const MapPoint& pt : pts) {
      const int cc = grid.col(static_cast<double>(pt.x)), rr = grid.row(static_cast<double>(pt.y));
      if (!grid.contains(cc - 2, rr - 2) || !grid.contains(cc + 2, rr + 2)) continue;
      float hmin = 1e9f, hmax = 0.0f;
      for (int dr = -2; dr <= 2; ++dr)
        for (int dc = -2; dc <= 2; ++dc) {
          hmin = std::min(hmin, w.height.at<float>(rr + dr, cc + dc));
          hmax = std::max(hmax, w.height.at<float>(rr + dr, cc + dc));
        }
      const double err = std::abs(static_cast<double>(pt.z - w.surface_at(cc, rr)));
      if (hmax == 0.0f) ground.push_back(err);
      if (hmin >= 10.0f && hmax - hmin < 0.5f && w.class_at(cc, rr) == ag::ClassId::kBuilding) {
        roof.push_back(err);
        if (hmin >= 28.0f) tall.push_back(err);
      }
    }
    const auto median = [](std::vector<double> v) {
      std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
      return v[v.size() / 2];
    };
    int max_disp = 0;
    for (std::int16_t d : stereo.disparity()) max_disp = std::max<int>(max_disp, d);
    const Coverage cov = overlap_coverage(stereo, pair.cur, pair.prev);
    std::printf("%.0f m baseline, %d disparities: rectified %dx%d, %zu points, largest disparity %.1f px; median |z error| "
                "open ground %.3f m (%zu), roofs >= 10 m %.3f m (%zu), roofs >= 28 m %.3f m (%zu); overlap %zu px, %.1f%% with a point\n",
                c.baseline_m, c.num_disparities, g.width, g.height, pts.size(), max_disp / 16.0, median(ground), ground.size(),
                roof.empty() ? 0.0 : median(roof), roof.size(), tall.empty() ? 0.0 : median(tall), tall.size(), cov.overlap,
                100.0 * cov.share());
    ASSERT_GT(ground.size(), 10000u);
    ASSERT_GT(roof.size(), 10000u);
    ASSERT_GT(tall.size(), 3000u);
    EXPECT_LE(median(ground), 0.3);
    EXPECT_LE(median(roof), 0.3);
    EXPECT_LE(median(tall), 0.3);
    // The 30 m roofs 20 m under the camera: f * baseline / 20 m (145 px at 6 m, 242 px at 10 m).
    EXPECT_GE(max_disp / 16.0, 0.95 * g.f * c.baseline_m / 20.0);
    EXPECT_GE(cov.share(), 0.60);
  }
}

TEST(StereoSim, RefusesBadEdgeGuardParameters) {
  const ag::PinholeCamera cam;
  StereoParams p;
  p.edge_margin_px = -1;
  EXPECT_THROW(DenseStereo(cam, p), std::invalid_argument);
  p.edge_margin_px = 65;
  EXPECT_THROW(DenseStereo(cam, p), std::invalid_argument);
  p.edge_margin_px = 4;
  p.edge_jump_px = -1;
  EXPECT_THROW(DenseStereo(cam, p), std::invalid_argument);
  p.edge_jump_px = 1;
  p.lr_max_diff = -5;  // any negative value turns the check off
  EXPECT_NO_THROW(DenseStereo(cam, p));
}

#ifdef AG_STEREO_COUNT_ALLOCS
// With the defaults (left-right check and edge guard on) and with 256 disparities.
TEST(StereoSim, ComputeDoesNotAllocateOnceWarm) {
  Scene& s = scene();
  for (const int nd : {112, 256}) {
    StereoParams p = test_params();
    p.num_disparities = nd;
    ASSERT_GE(p.lr_max_diff, 0);
    ASSERT_GT(p.edge_margin_px, 0);
    const std::uint64_t at_start = g_allocations.load();
    DenseStereo stereo(s.camera, p);
    ASSERT_GT(g_allocations.load(), at_start) << "the counter must see the constructor's buffers";
    std::vector<MapPoint> pts;
    pts.reserve(static_cast<std::size_t>(4 * s.camera.width * s.camera.height));
    ASSERT_TRUE(stereo.compute(s.prev.image(), s.cur.image(), pts).ok());
    Frame next;
    s.render(moved(s.cur_body, 2.1, 0.2, -0.01, 0.015, 0.03), next);
    ag::mapping::StereoTiming t;
    const std::uint64_t before = g_allocations.load();
    auto r = stereo.compute(s.cur.image(), next.image(), pts, &t);
    const std::uint64_t after = g_allocations.load();
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_GT(r.value(), 100000u);
    EXPECT_GT(stereo.stats().lr_rejected + stereo.stats().edge_rejected, 0u);
    EXPECT_EQ(after - before, 0u) << "allocations in a warm compute() with " << nd << " disparities";
    // A wider window than the first pair's (sideways baseline) must not allocate either.
    Frame side;
    s.render(moved(s.cur_body, 0.0, 2.0, 0.01, -0.01, 0.02), side);
    const std::uint64_t before2 = g_allocations.load();
    ASSERT_TRUE(stereo.compute(side.image(), s.cur.image(), pts).ok());
    EXPECT_EQ(g_allocations.load() - before2, 0u) << "allocations for a wider window with " << nd << " disparities";
  }
}
#endif

}  // namespace
