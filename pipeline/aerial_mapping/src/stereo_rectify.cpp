// Rectification of a keyframe pair for its real relative pose: cv::stereoRectify's rotations (always to
// a horizontal baseline), a rectified window fitted to the overlap, remap tables like
// cv::initUndistortRectifyMap, bilinear grey remap and the dilated invalid border.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <numbers>
#include <string>

#include "stereo_internal.hpp"

namespace ag::mapping::detail {
namespace {

std::size_t sz(int v) noexcept { return static_cast<std::size_t>(v); }

using F32 = float __attribute__((vector_size(kRectifyLanes * 4)));
using I32 = std::int32_t __attribute__((vector_size(kRectifyLanes * 4)));
constexpr int kF = kRectifyLanes;
using U8B = std::uint8_t __attribute__((vector_size(kRectifyLanes * 4)));

[[gnu::always_inline]] inline U8B load8(const std::uint8_t* p) noexcept {
  U8B v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
[[gnu::always_inline]] inline void store8(std::uint8_t* p, const U8B& v) noexcept { std::memcpy(p, &v, sizeof v); }

template <typename V>
[[gnu::always_inline]] inline void store(float* p, const V& v) noexcept {
  std::memcpy(p, &v, sizeof v);
}

Eigen::Matrix3d rodrigues(const Eigen::Vector3d& v) {
  const double a = v.norm();
  if (a < 1e-300) return Eigen::Matrix3d::Identity();
  return Eigen::AngleAxisd(a, v / a).toRotationMatrix();
}

Eigen::Vector3d rodrigues_vector(const Eigen::Matrix3d& r) {
  const Eigen::AngleAxisd aa(r);
  return aa.axis() * aa.angle();
}

struct Box {
  double x0{1e300}, x1{-1e300}, y0{1e300}, y1{-1e300};
};

// The rectified-pixel bounding box (relative to the principal point, focal length f) of a camera's
// image border; false if some border ray is more than ~84 degrees off the rectified optical axis.
bool border_box(const PinholeCamera& cam, const Eigen::Matrix3d& rect_from_camera, double f, Box& box) {
  constexpr int kSteps = 64;
  const double w1 = cam.width - 1, h1 = cam.height - 1;
  for (int side = 0; side < 4; ++side) {
    for (int i = 0; i <= kSteps; ++i) {
      const double t = static_cast<double>(i) / kSteps;
      const double u = side == 0 ? t * w1 : side == 1 ? w1 : side == 2 ? (1.0 - t) * w1 : 0.0;
      const double v = side == 0 ? 0.0 : side == 1 ? t * h1 : side == 2 ? h1 : (1.0 - t) * h1;
      const Eigen::Vector2d n = cam.undistort_pixel(u, v);
      const Eigen::Vector3d x = rect_from_camera * Eigen::Vector3d(n.x(), n.y(), 1.0);
      if (x.z() < 0.1 * x.norm()) return false;
      const double px = f * x.x() / x.z(), py = f * x.y() / x.z();
      box.x0 = std::min(box.x0, px);
      box.x1 = std::max(box.x1, px);
      box.y0 = std::min(box.y0, py);
      box.y1 = std::max(box.y1, py);
    }
  }
  return true;
}

Error no_overlap(const std::string& why) { return Error::make(ErrorCode::kInvalidArgument, "stereo pair does not overlap: " + why); }

}  // namespace

RectifyRotations rectify_rotations(const Eigen::Matrix3d& r, const Eigen::Vector3d& t_in) {
  // Half of the relative rotation for each camera (cv::stereoRectify's r_r). Then a quarter turn about
  // the optical axis, k * 90 degrees, that brings the baseline nearest to -x (the other camera then sits
  // at +x in the reference's rectified frame), and cv::stereoRectify's smallest rotation from there.
  const Eigen::Matrix3d r_r = rodrigues(-0.5 * rodrigues_vector(r));
  const Eigen::Vector3d t0 = r_r * t_in;
  Eigen::Matrix3d pre = Eigen::Matrix3d::Identity();
  double best = t0.x();
  for (int k = 1; k < 4; ++k) {
    const Eigen::Matrix3d q = Eigen::AngleAxisd(k * std::numbers::pi / 2.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    const double x = (q * t0).x();
    if (x < best - 1e-12) {
      best = x;
      pre = q;
    }
  }
  const Eigen::Vector3d t = pre * t0;
  const Eigen::Vector3d target(-1.0, 0.0, 0.0);
  Eigen::Vector3d ww = t.cross(target);
  const double nw = ww.norm();
  if (nw > 0.0) ww *= std::acos(std::clamp(std::abs(t.x()) / t.norm(), -1.0, 1.0)) / nw;
  const Eigen::Matrix3d w_r = rodrigues(ww) * pre;
  return {w_r * r_r.transpose(), w_r * r_r};
}

double max_undistorted_r2(const PinholeCamera& cam) {
  double r2 = 0.0;
  constexpr int kSteps = 64;
  for (int i = 0; i <= kSteps; ++i) {
    const double t = static_cast<double>(i) / kSteps;
    const double us[4] = {t * (cam.width - 1), static_cast<double>(cam.width - 1), t * (cam.width - 1), 0.0};
    const double vs[4] = {0.0, t * (cam.height - 1), static_cast<double>(cam.height - 1), t * (cam.height - 1)};
    for (int s = 0; s < 4; ++s) r2 = std::max(r2, cam.undistort_pixel(us[s], vs[s]).squaredNorm());
  }
  return r2;
}

Result<RectifiedGeometry> plan_rectification(const PinholeCamera& camera, const StereoParams& params,
                                             int max_width, int max_height,
                                             const Eigen::Isometry3d& map_from_reference,
                                             const Eigen::Isometry3d& map_from_other) {
  RectifiedGeometry g;
  const Eigen::Vector3d c_ref = map_from_reference.translation(), c_oth = map_from_other.translation();
  g.baseline_m = (c_oth - c_ref).norm();
  const Eigen::Matrix3d r_ref = map_from_reference.linear(), r_oth = map_from_other.linear();
  // X_other = R X_ref + T
  const Eigen::Matrix3d r = r_oth.transpose() * r_ref;
  const Eigen::Vector3d t = r_oth.transpose() * (c_ref - c_oth);
  const RectifyRotations rot = rectify_rotations(r, t);
  g.rect_from_reference = rot.rect_from_reference;
  g.rect_from_other = rot.rect_from_other;
  g.f = camera.fx;
  g.map_from_rect.linear() = r_ref * g.rect_from_reference.transpose();
  g.map_from_rect.translation() = c_ref;

  const int half = params.block_size / 2;
  const int min_d = params.min_disparity, max_d = params.min_disparity + params.num_disparities - 1;
  // Depths the disparity range can measure at all.
  const double z_near = g.f * g.baseline_m / max_d;
  if (z_near > params.max_depth_m)
    return no_overlap("baseline " + std::to_string(g.baseline_m) + " m: the nearest depth the disparity range reaches (" +
                      std::to_string(z_near) + " m) is beyond max_depth_m");
  if (min_d > 0 && g.f * g.baseline_m / min_d < params.min_depth_m)
    return no_overlap("every depth the disparity range reaches is below min_depth_m");

  Box a, b;
  if (!border_box(camera, g.rect_from_reference, g.f, a) || !border_box(camera, g.rect_from_other, g.f, b))
    return no_overlap("a camera looks more than 84 degrees away from the rectified axis (baseline along the view?)");
  const double y0 = std::max(a.y0, b.y0), y1 = std::min(a.y1, b.y1);
  // Reference columns x match other columns x - d; only disparities that give a depth in
  // [min_depth_m, max_depth_m] matter (with a long baseline the far limit cuts the smallest ones).
  const double d_lo = std::max(static_cast<double>(min_d), g.f * g.baseline_m / params.max_depth_m);
  const double d_hi = params.min_depth_m > 0.0 ? std::min(static_cast<double>(max_d), g.f * g.baseline_m / params.min_depth_m)
                                               : static_cast<double>(max_d);
  const double left = std::max(a.x0, b.x0 + d_lo), right = std::min(a.x1, b.x1 + d_hi);
  if (y1 - y0 < params.block_size || right - left < params.block_size)
    return no_overlap("the rectified images share no block (rows " + std::to_string(y0) + ".." + std::to_string(y1) +
                      ", columns " + std::to_string(left) + ".." + std::to_string(right) + ")");
  // StereoBM computes nothing in its first max_d + half columns: put them left of the first column a
  // disparity in range can match.
  g.cx = static_cast<double>(max_d + half) - left;
  g.width = static_cast<int>(std::ceil(right - left)) + 1 + max_d + 2 * half;
  g.cy = static_cast<double>(half) - y0;
  g.height = static_cast<int>(std::ceil(y1 - y0)) + 1 + 2 * half;
  if (g.width > max_width) g.width = max_width;
  if (g.height > max_height) {
    g.cy -= 0.5 * (g.height - max_height);
    g.height = max_height;
  }
  return g;
}

void build_rectified(const PinholeCamera& cam, const RectifiedGeometry& g, const Eigen::Matrix3d& rect_from_camera,
                     double max_r2, const std::uint8_t* grey, float* map_x, float* map_y, std::uint8_t* rect,
                     std::uint8_t* invalid, float* scratch) {
  // Pass 1 per row, kF rays at a time in float (|error| ~1e-4 px): the source position, -1 without one.
  const Eigen::Matrix3d cam_from_rect = rect_from_camera.transpose();
  const Eigen::Vector3d step = cam_from_rect.col(0) / g.f;
  const auto fl = [](double v) { return static_cast<float>(v); };
  const float sx = fl(step.x()), sy = fl(step.y()), sz_ = fl(step.z());
  const float k1 = fl(cam.k1), k2 = fl(cam.k2), k3 = fl(cam.k3), p1 = fl(cam.p1), p2 = fl(cam.p2);
  const float fx = fl(cam.fx), fy = fl(cam.fy), cx = fl(cam.cx), cy = fl(cam.cy);
  const float w1 = fl(cam.width - 1), h1 = fl(cam.height - 1), r2max = fl(max_r2);
  F32 lane{};
  for (int l = 0; l < kF; ++l) lane[l] = static_cast<float>(l);
  const F32 minus_one = F32{} - 1.0f;
  float* row_x = scratch;
  float* row_y = scratch + sz(g.width + kF);
  const std::size_t sw = sz(cam.width);
  for (int v = 0; v < g.height; ++v) {
    const Eigen::Vector3d base = cam_from_rect * Eigen::Vector3d(-g.cx / g.f, (v - g.cy) / g.f, 1.0);
    const float bx = fl(base.x()), by = fl(base.y()), bz = fl(base.z());
    for (int u0 = 0; u0 < g.width; u0 += kF) {
      const F32 u = lane + static_cast<float>(u0);
      const F32 x = bx + u * sx, y = by + u * sy, z = bz + u * sz_;
      I32 ok = z > 1e-6f;
      const F32 iz = 1.0f / z;
      const F32 xn = x * iz, yn = y * iz;
      const F32 r2 = xn * xn + yn * yn;
      ok &= r2 <= r2max;
      const F32 radial = 1.0f + r2 * (k1 + r2 * (k2 + r2 * k3));
      const F32 xd = xn * radial + 2.0f * p1 * xn * yn + p2 * (r2 + 2.0f * xn * xn);
      const F32 yd = yn * radial + p1 * (r2 + 2.0f * yn * yn) + 2.0f * p2 * xn * yn;
      const F32 su = fx * xd + cx, sv = fy * yd + cy;
      ok &= (su >= 0.0f) & (su <= w1) & (sv >= 0.0f) & (sv <= h1);
      store(row_x + u0, ok ? su : minus_one);
      store(row_y + u0, ok ? sv : minus_one);
    }
    const std::size_t row = sz(v) * sz(g.width);
    std::memcpy(map_x + row, row_x, sz(g.width) * sizeof(float));
    std::memcpy(map_y + row, row_y, sz(g.width) * sizeof(float));
    // Pass 2: bilinear grey.
    for (int u = 0; u < g.width; ++u) {
      const float px = row_x[u], py = row_y[u];
      const std::size_t i = row + sz(u);
      if (px < 0.0f) {
        rect[i] = 0;
        invalid[i] = 1;
        continue;
      }
      invalid[i] = 0;
      const int x0 = std::min(static_cast<int>(px), cam.width - 2), y0 = std::min(static_cast<int>(py), cam.height - 2);
      const float ax = px - static_cast<float>(x0), ay = py - static_cast<float>(y0);
      const std::uint8_t* q = grey + sz(y0) * sw + sz(x0);
      const float top = static_cast<float>(q[0]) + ax * static_cast<float>(q[1] - q[0]);
      const float bot = static_cast<float>(q[sw]) + ax * static_cast<float>(q[sw + 1] - q[sw]);
      rect[i] = static_cast<std::uint8_t>(top + ay * (bot - top) + 0.5f);
    }
  }
}

void dilate_invalid(const std::uint8_t* invalid, int width, int height, int radius, std::uint8_t* valid,
                    std::uint8_t* tmp, std::uint8_t* pad) {
  const std::size_t n = sz(width) * sz(height);
  if (radius <= 0) {
    for (std::size_t i = 0; i < n; ++i) valid[i] = invalid[i] != 0 ? 0 : 1;
    return;
  }
  // Rows: tmp = OR of invalid over [x - radius, x + radius], through a zero-padded copy of the row.
  const std::size_t r = sz(radius), w = sz(width);
  std::memset(pad, 0, w + 2 * r + sizeof(U8B));
  for (int y = 0; y < height; ++y) {
    std::memcpy(pad + r, invalid + sz(y) * w, w);
    std::uint8_t* out = tmp + sz(y) * w;
    std::size_t x = 0;
    for (; x + sizeof(U8B) <= w; x += sizeof(U8B)) {
      U8B acc = load8(pad + x);
      for (std::size_t k = 1; k <= 2 * r; ++k) acc |= load8(pad + x + k);
      store8(out + x, acc);
    }
    for (; x < w; ++x) {
      std::uint8_t acc = 0;
      for (std::size_t k = 0; k <= 2 * r; ++k) acc = static_cast<std::uint8_t>(acc | pad[x + k]);
      out[x] = acc;
    }
  }
  // Columns: OR of tmp over rows [y - radius, y + radius], then valid = !that.
  for (int y = 0; y < height; ++y) {
    const int y0 = std::max(0, y - radius), y1 = std::min(height - 1, y + radius);
    std::uint8_t* out = valid + sz(y) * w;
    std::size_t x = 0;
    for (; x + sizeof(U8B) <= w; x += sizeof(U8B)) {
      U8B acc = load8(tmp + sz(y0) * w + x);
      for (int yy = y0 + 1; yy <= y1; ++yy) acc |= load8(tmp + sz(yy) * w + x);
      store8(out + x, (acc == 0) & 1);
    }
    for (; x < w; ++x) {
      std::uint8_t acc = 0;
      for (int yy = y0; yy <= y1; ++yy) acc = static_cast<std::uint8_t>(acc | tmp[sz(yy) * w + x]);
      out[x] = acc == 0 ? 1 : 0;
    }
  }
}

}  // namespace ag::mapping::detail
