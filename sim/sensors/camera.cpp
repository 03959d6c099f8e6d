// The simulated nadir camera: lens model, per-pixel ray table and the ray-cast renderer.
#include "airground/sim/camera.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>

namespace ag::sim {

namespace {

// splitmix64's finaliser: a counter-based hash, so any pixel's noise is known without a sequence.
inline std::uint64_t mix64(std::uint64_t z) noexcept {
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31);
}

// Zero-mean unit-variance noise from one hash: the sum of four 16-bit uniforms (Irwin-Hall), whose
// variance is exact and which costs no log or sqrt; its tails end at 3.5 sigma.
inline double unit_noise(std::uint64_t h) noexcept {
  const auto u = [h](int shift) { return static_cast<double>((h >> shift) & 0xFFFFu); };
  constexpr double kScale = 1.7320508075688772 / 65536.0;  // sqrt(3) / 2^16
  return (u(0) + u(16) + u(32) + u(48) + 2.0 - 2.0 * 65536.0) * kScale;
}

constexpr int kMaxBlurSamples = 63;

// The OpenCV distortion of normalized coordinates and its Jacobian.
struct Distorted {
  double x, y;
  double dxdx, dxdy, dydx, dydy;
};
Distorted distort(const CameraModel& m, double x, double y) noexcept {
  const double r2 = x * x + y * y;
  const double radial = 1.0 + r2 * (m.k1 + r2 * (m.k2 + r2 * m.k3));
  const double dradial = m.k1 + r2 * (2.0 * m.k2 + 3.0 * m.k3 * r2);  // d radial / d r2
  Distorted d{};
  d.x = x * radial + 2.0 * m.p1 * x * y + m.p2 * (r2 + 2.0 * x * x);
  d.y = y * radial + m.p1 * (r2 + 2.0 * y * y) + 2.0 * m.p2 * x * y;
  d.dxdx = radial + 2.0 * x * x * dradial + 2.0 * m.p1 * y + 6.0 * m.p2 * x;
  d.dxdy = 2.0 * x * y * dradial + 2.0 * m.p1 * x + 2.0 * m.p2 * y;
  d.dydx = 2.0 * x * y * dradial + 2.0 * m.p1 * x + 2.0 * m.p2 * y;
  d.dydy = radial + 2.0 * y * y * dradial + 6.0 * m.p1 * y + 2.0 * m.p2 * x;
  return d;
}

// Newton iteration from the distorted point; false where the lens folds over (no unique inverse).
bool undistort(const CameraModel& m, double xd, double yd, double& x, double& y) noexcept {
  x = xd;
  y = yd;
  for (int it = 0; it < 60; ++it) {
    const Distorted d = distort(m, x, y);
    const double ex = d.x - xd, ey = d.y - yd;
    const double det = d.dxdx * d.dydy - d.dxdy * d.dydx;
    if (!(det > 1e-9)) return false;
    x -= (d.dydy * ex - d.dxdy * ey) / det;
    y -= (-d.dydx * ex + d.dxdx * ey) / det;
    if (ex * ex + ey * ey < 1e-28) break;
  }
  const Distorted d = distort(m, x, y);
  const double det = d.dxdx * d.dydy - d.dxdy * d.dydx;
  return std::hypot(d.x - xd, d.y - yd) < 1e-10 && det > 1e-9 && std::isfinite(x) && std::isfinite(y);
}

// Deterministic lattice hash in [0, 1): one multiply-xorshift round is plenty for value noise.
inline float lattice(std::int64_t i, std::int64_t j, std::uint64_t salt) noexcept {
  std::uint64_t z = (static_cast<std::uint64_t>(i) * 0x9E3779B97F4A7C15ULL) ^ (static_cast<std::uint64_t>(j) * 0xC2B2AE3D27D4EB4FULL) ^ salt;
  z = (z ^ (z >> 29)) * 0xBF58476D1CE4E5B9ULL;
  return static_cast<float>(z >> 40) * 0x1.0p-24f;
}

// Smooth value noise in [0, 1) on a unit lattice.
inline float value_noise(double a, double b, std::uint64_t salt) noexcept {
  const double fa = std::floor(a), fb = std::floor(b);
  const auto ia = static_cast<std::int64_t>(fa), ib = static_cast<std::int64_t>(fb);
  auto ta = static_cast<float>(a - fa), tb = static_cast<float>(b - fb);
  ta = ta * ta * (3.0f - 2.0f * ta);
  tb = tb * tb * (3.0f - 2.0f * tb);
  const float n00 = lattice(ia, ib, salt), n10 = lattice(ia + 1, ib, salt);
  const float n01 = lattice(ia, ib + 1, salt), n11 = lattice(ia + 1, ib + 1, salt);
  const float lo = n00 + (n10 - n00) * ta, hi = n01 + (n11 - n01) * ta;
  return lo + (hi - lo) * tb;
}

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr float kGroundStep = 0.3f;    // [m] lower steps are shaded as ground
constexpr double kShadowBias = 0.05;   // [m] shadow rays leave the ground this high (no self-shadowing)
constexpr int kSunBlockShift = 2;      // sun ceiling per 4x4-cell block

// Octaves of the detail texture: spatial frequency [1/m] and amplitude of the brightness factor.
struct Octave {
  double frequency;
  float amplitude;
  std::uint64_t salt;
};
constexpr Octave kOctaves[] = {
    {1.0 / 0.03, 0.08f, 0x1234567ULL}, {1.0 / 0.06, 0.08f, 0x2345678ULL}, {1.0 / 0.12, 0.09f, 0x3456789ULL},
    {1.0 / 0.25, 0.10f, 0x456789AULL}, {1.0 / 0.50, 0.10f, 0x56789ABULL}, {1.0 / 1.00, 0.08f, 0x6789ABCULL},
};

// Brightness factor at surface coordinates (a, b) [m] seen with a pixel footprint [m]: octaves finer than
// four footprints fade out, gone at two (a pixel integrates them), so every view agrees on what it resolves.
inline float detail_factor(double a, double b, double footprint) noexcept {
  float f = 1.0f;
  for (const Octave& o : kOctaves) {
    const auto w = static_cast<float>(std::min(2.0 - 4.0 * footprint * o.frequency, 1.0));
    if (w <= 0.0f) continue;
    f += o.amplitude * w * (2.0f * value_noise(a * o.frequency, b * o.frequency, o.salt) - 1.0f);
  }
  return f;
}

// The sub-exposure samples of a shot, evenly spread over the exposure: the camera moved and yawed; the
// middle one (time 0) is the frame's pose and gives the class and depth.
struct SubExposures {
  int samples, mid;
  std::array<Eigen::Vector3d, kMaxBlurSamples> eyes;
  std::array<Eigen::Matrix3d, kMaxBlurSamples> rots;
  double ex_lo = kInf, ex_hi = -kInf, ey_lo = kInf, ey_hi = -kInf, ez_lo = kInf, ez_hi = -kInf;  // the eyes' box

  SubExposures(const CameraShot& shot, int blur_samples, const Eigen::Vector3d& eye, const Eigen::Matrix3d& map_from_camera) noexcept
      : samples(std::clamp(blur_samples, 1, kMaxBlurSamples) | 1), mid(samples / 2) {
    for (int i = 0; i < samples; ++i) {
      const double tau = ((i + 0.5) / samples - 0.5) * shot.exposure.exposure_s;
      const auto si = static_cast<std::size_t>(i);
      if (i == mid) {
        eyes[si] = eye;
        rots[si] = map_from_camera;
      } else {
        eyes[si] = eye + tau * shot.velocity;
        rots[si] = Eigen::AngleAxisd(shot.yaw_rate * tau, Eigen::Vector3d::UnitZ()).toRotationMatrix() * map_from_camera;
      }
    }
    for (int i = 0; i < samples; ++i) {
      const Eigen::Vector3d& e = eyes[static_cast<std::size_t>(i)];
      ex_lo = std::min(ex_lo, e.x()), ex_hi = std::max(ex_hi, e.x());
      ey_lo = std::min(ey_lo, e.y()), ey_hi = std::max(ey_hi, e.y());
      ez_lo = std::min(ez_lo, e.z()), ez_hi = std::max(ez_hi, e.z());
    }
  }
};

// Albedo x texture x light of a hit, in rendered units (a lit flat top at its albedo); sun_ceiling(col, row)
// is the renderer's height above which nothing can shade that cell.
template <class SunCeiling>
struct HitShading {
  const World& world;
  const HeightfieldRaycaster& rc;
  const CameraShading& shading;
  const Eigen::Vector3d& sun;
  SunCeiling sun_ceiling;
  double inv_res, zmax, sun_flat, pixel_angle;

  void operator()(const RayHit& hit, const Eigen::Vector3d& dw, double rad[3]) const noexcept {
    const GridGeometry& g = world.grid();
    // Steps lower than kGroundStep (terrain sampled into flat cells, curbs) are shaded as ground.
    const Eigen::Vector3d& p = hit.point;
    const float s_hit = rc.surface(hit.col, hit.row);
    bool wall = hit.vertical_face;
    if (wall) {
      const std::int32_t nc = hit.col + static_cast<std::int32_t>(hit.normal.x());
      const std::int32_t nr = hit.row - static_cast<std::int32_t>(hit.normal.y());
      wall = !g.contains(nc, nr) || s_hit - rc.surface(nc, nr) >= kGroundStep;
    }
    const Eigen::Vector3d normal = wall ? hit.normal : Eigen::Vector3d::UnitZ();

    // Albedo: bilinear between cell centres on the ground and tops, blending only cells of about the
    // same surface (a roof edge does not take the street's colour); the wall's own cell on sides.
    double alb[3] = {0, 0, 0};
    const cv::Vec3b& own = world.albedo.at<cv::Vec3b>(hit.row, hit.col);
    if (wall) {
      for (int k = 0; k < 3; ++k) alb[k] = own[k];
    } else {
      const double u = (p.x() - g.origin_x) * inv_res - 0.5, v = (g.origin_y - p.y()) * inv_res - 0.5;
      const double fu = std::floor(u), fv = std::floor(v);
      const double tu = u - fu, tv = v - fv;
      const auto i0 = static_cast<std::int32_t>(fu), j0 = static_cast<std::int32_t>(fv);
      double wsum = 0.0;
      for (int dj = 0; dj < 2; ++dj) {
        for (int di = 0; di < 2; ++di) {
          const std::int32_t i = std::clamp(i0 + di, 0, g.width - 1), j = std::clamp(j0 + dj, 0, g.height - 1);
          if (std::abs(rc.surface(i, j) - s_hit) > kGroundStep) continue;
          const double wgt = (di != 0 ? tu : 1.0 - tu) * (dj != 0 ? tv : 1.0 - tv);
          const cv::Vec3b& a = world.albedo.at<cv::Vec3b>(j, i);
          for (int k = 0; k < 3; ++k) alb[k] += wgt * a[k];
          wsum += wgt;
        }
      }
      if (wsum > 1e-9) {
        const double inv = 1.0 / wsum;
        for (double& a : alb) a *= inv;
      } else {
        for (int k = 0; k < 3; ++k) alb[k] = own[k];
      }
    }

    float factor = 1.0f;
    if (shading.detail_texture) {
      const double cos_view = std::max(0.2, std::abs(normal.dot(dw)));
      const double footprint = hit.range * pixel_angle / cos_view;
      if (!wall) {
        factor = detail_factor(p.x(), p.y(), footprint);
      } else if (normal.x() != 0.0) {
        factor = detail_factor(p.y(), p.z(), footprint);
      } else {
        factor = detail_factor(p.x(), p.z(), footprint);
      }
    }

    double light = shading.ambient;
    const double cos_sun = normal.dot(sun);
    if (cos_sun > 0.0) {
      bool lit = true;
      if (shading.shadows) {
        // From just off the surface (above the cell's top for ground), toward the sun; skipped where
        // the sun ceiling proves nothing can shade that height.
        const Eigen::Vector3d from = wall ? Eigen::Vector3d(p + 1e-3 * normal)
                                          : Eigen::Vector3d(p.x(), p.y(), static_cast<double>(s_hit) + kShadowBias);
        if (from.z() < zmax && (!shading.shadow_culling || from.z() <= static_cast<double>(sun_ceiling(hit.col, hit.row))))
          lit = !rc.cast(from, sun, (zmax - from.z()) / sun.z() + 1.0).hit;
      }
      if (lit) light += (1.0 - shading.ambient) * cos_sun;
    }
    const double gain_light = static_cast<double>(factor) * light / sun_flat;
    for (int k = 0; k < 3; ++k) rad[k] = alb[k] * gain_light;
  }
};

// The map-frame directions of a tile's rays (every sub-exposure sample's): whether all of them point down,
// and the range of their horizontal offset per metre of descent.
struct TileCone {
  double kx_lo = kInf, kx_hi = -kInf, ky_lo = kInf, ky_hi = -kInf;
  bool down = true;

  void extend(const Eigen::Vector3d& d) noexcept {
    if (!(d.z() < 0.0)) {
      down = false;
      return;
    }
    const double kx = d.x() / -d.z(), ky = d.y() / -d.z();
    kx_lo = std::min(kx_lo, kx), kx_hi = std::max(kx_hi, kx);
    ky_lo = std::min(ky_lo, ky), ky_hi = std::max(ky_hi, ky);
  }
};

// A height above which no ray of the tile meets anything (+inf: nothing known): the cells under the cone
// between the highest surface (or the eyes) and a height P are known from a block max query, and when
// they are all lower than P, no ray of the tile meets anything above P.
double tile_free_height(const TileCone& cone, const SubExposures& blur, const HeightfieldRaycaster& rc, const GridGeometry& g,
                        double inv_res, double zmax) noexcept {
  if (!cone.down || !(cone.kx_lo <= cone.kx_hi)) return kInf;
  constexpr double kMargin = 0.01;  // [m] above the highest surface found
  const double ztop = std::min(blur.ez_hi, zmax);
  // Cells under the tile's rays while they descend from ztop to height z (one cell of margin): a ray
  // point below zmax lies s = (its eye's height - its height) times its offset per metre away.
  const double s_lo = std::max(0.0, blur.ez_lo - zmax);
  const auto highest = [&](double z) noexcept {
    const double s_hi = blur.ez_hi - z;
    const double x_lo = blur.ex_lo + std::min(s_lo * cone.kx_lo, s_hi * cone.kx_lo);
    const double x_hi = blur.ex_hi + std::max(s_lo * cone.kx_hi, s_hi * cone.kx_hi);
    const double y_lo = blur.ey_lo + std::min(s_lo * cone.ky_lo, s_hi * cone.ky_lo);
    const double y_hi = blur.ey_hi + std::max(s_lo * cone.ky_hi, s_hi * cone.ky_hi);
    const double u_lo = (x_lo - g.origin_x) * inv_res, u_hi = (x_hi - g.origin_x) * inv_res;
    const double v_lo = (g.origin_y - y_hi) * inv_res, v_hi = (g.origin_y - y_lo) * inv_res;
    constexpr double kBig = 1e9;  // keeps the casts to int defined
    return static_cast<double>(rc.max_surface_in(
        static_cast<std::int32_t>(std::floor(std::clamp(u_lo, -kBig, kBig))) - 1,
        static_cast<std::int32_t>(std::floor(std::clamp(v_lo, -kBig, kBig))) - 1,
        static_cast<std::int32_t>(std::floor(std::clamp(u_hi, -kBig, kBig))) + 1,
        static_cast<std::int32_t>(std::floor(std::clamp(v_hi, -kBig, kBig))) + 1));
  };
  double proven = ztop;  // nothing is above zmax, and no ray point is above its eye
  double cand = highest(ztop) + kMargin;
  for (int it = 0; it < 6 && cand < proven; ++it) {
    const double m = highest(cand);
    if (m < cand) {  // free down to cand; try just above what that region holds
      proven = cand;
      cand = m + kMargin;
    } else {  // the region down to m + margin lies inside the one just searched: free down to there
      proven = std::min(proven, m + kMargin);
      break;
    }
  }
  return proven;
}

}  // namespace

CameraModel CameraModel::scaled(double factor) const {
  CameraModel m = *this;
  m.width = static_cast<int>(std::lround(width * factor));
  m.height = static_cast<int>(std::lround(height * factor));
  m.fx = fx * factor;
  m.fy = fy * factor;
  m.cx = (cx + 0.5) * factor - 0.5;  // pixel centres are integers: scale about the image corner
  m.cy = (cy + 0.5) * factor - 0.5;
  return m;
}

Status CameraModel::check() const {
  const auto bad = [](const std::string& what) { return Error::make(ErrorCode::kInvalidArgument, what); };
  if (width <= 0 || height <= 0) return bad("camera width and height must be positive");
  if (!(fx > 0.0) || !(fy > 0.0) || !std::isfinite(fx) || !std::isfinite(fy)) return bad("camera fx and fy must be positive");
  if (!(cx >= -0.5 && cx <= width - 0.5)) return bad("camera cx must lie inside the image [-0.5, width - 0.5]");
  if (!(cy >= -0.5 && cy <= height - 0.5)) return bad("camera cy must lie inside the image [-0.5, height - 0.5]");
  for (const double k : {k1, k2, p1, p2, k3})
    if (!std::isfinite(k)) return bad("camera distortion coefficients must be finite");
  return ok_status();
}

Eigen::Matrix3d CameraModel::body_from_camera() noexcept {
  Eigen::Matrix3d m;
  // camera x = body -y (right), camera y = body -x (image down = backward), camera z = body -z (down)
  m << 0, -1, 0,  //
      -1, 0, 0,   //
      0, 0, -1;
  return m;
}


Status CameraSensor::check() const {
  const auto bad = [](const std::string& what) { return Error::make(ErrorCode::kInvalidArgument, what); };
  const auto num = [](double v) { return std::to_string(v); };
  if (!(full_well_e > 0.0) || !(read_noise_e >= 0.0) || sensor_width_px <= 0 || !(full_scale_exposure_s > 0.0))
    return bad("camera_sensor: full_well_e, sensor_width_px and full_scale_exposure_s must be positive, read_noise_e >= 0");
  if (!(exposure_min_s > 0.0) || !(exposure_min_s <= exposure_max_s))
    return bad("camera_sensor.exposure_min_s = " + num(exposure_min_s) + " must be positive and <= exposure_max_s = " +
               num(exposure_max_s));
  if (!(exposure_s >= exposure_min_s && exposure_s <= exposure_max_s))
    return bad("camera_sensor.exposure_s = " + num(exposure_s) + " is out of range [exposure_min_s, exposure_max_s] = [" +
               num(exposure_min_s) + ", " + num(exposure_max_s) + "] s");
  if (!(gain_max >= 1.0) || !(gain >= 1.0 && gain <= gain_max))
    return bad("camera_sensor.gain = " + num(gain) + " is out of range [1, gain_max] = [1, " + num(gain_max) + "]");
  if (!(ae_target > 0.0 && ae_target < 1.0) || !(ae_speed > 0.0 && ae_speed <= 1.0) || !(ae_tolerance >= 0.0))
    return bad("camera_sensor: ae_target must lie in (0, 1), ae_speed in (0, 1], ae_tolerance >= 0");
  if (blur_max_samples < 1 || blur_max_samples > kMaxBlurSamples || blur_max_samples % 2 == 0)
    return bad("camera_sensor.blur_max_samples = " + std::to_string(blur_max_samples) + " must be odd, in [1, " +
               std::to_string(kMaxBlurSamples) + "]");
  if (!(corner_illumination > 0.0 && corner_illumination <= 1.0))
    return bad("camera_sensor.corner_illumination = " + num(corner_illumination) + " is out of range (0, 1]");
  return ok_status();
}

CameraAutoExposure::CameraAutoExposure(const CameraSensor& sensor) noexcept
    : sensor_(sensor), next_{sensor.exposure_s, sensor.gain} {}

void CameraAutoExposure::observe(const CameraFrame& frame) noexcept {
  if (!sensor_.auto_exposure || frame.rgb.empty()) return;
  std::uint64_t sum = 0;  // integer: the mean does not depend on summation order
  for (int r = 0; r < frame.rgb.rows; ++r) {
    const std::uint8_t* p = frame.rgb.ptr<std::uint8_t>(r);
    const int n = frame.rgb.cols * frame.rgb.channels();
    for (int i = 0; i < n; ++i) sum += p[i];
  }
  const double count = static_cast<double>(frame.rgb.total()) * frame.rgb.channels();
  last_mean_ = static_cast<double>(sum) / (255.0 * count);
  const CameraExposure used = frame.shot.exposure;
  const double ratio = sensor_.ae_target / std::max(last_mean_, 0.5 / 255.0);  // a black frame: as if half a level
  if (std::abs(std::log(ratio)) <= std::log1p(sensor_.ae_tolerance)) {
    next_ = used;
    return;
  }
  const double want = used.exposure_s * used.gain * std::pow(ratio, sensor_.ae_speed);  // [s] at gain 1
  // Exposure first (gain adds noise), up to its limit; then gain.
  next_.exposure_s = std::clamp(want, sensor_.exposure_min_s, sensor_.exposure_max_s);
  next_.gain = std::clamp(want / next_.exposure_s, 1.0, sensor_.gain_max);
}

CameraRenderer::CameraRenderer(const World& world, const CameraModel& model, const CameraShading& shading,
                               std::shared_ptr<const HeightfieldRaycaster> raycaster)
    : CameraRenderer(world, model, shading, CameraSensor{}, std::move(raycaster)) {}

CameraRenderer::CameraRenderer(const World& world, const CameraModel& model, const CameraShading& shading,
                               const CameraSensor& sensor, std::shared_ptr<const HeightfieldRaycaster> raycaster)
    : world_(world), model_(model), shading_(shading), sensor_(sensor), raycaster_(std::move(raycaster)) {
  if (auto st = model_.check(); !st) throw std::invalid_argument("CameraRenderer: " + st.error().message);
  if (auto st = sensor_.check(); !st) throw std::invalid_argument("CameraRenderer: " + st.error().message);
  const GridGeometry& g = world.grid();
  if (world.class_id.type() != CV_8UC1 || world.class_id.rows != g.height || world.class_id.cols != g.width ||
      world.albedo.type() != CV_8UC3 || world.albedo.rows != g.height || world.albedo.cols != g.width)
    throw std::invalid_argument("CameraRenderer: the world's class_id (CV_8UC1) and albedo (CV_8UC3) must match its grid");
  raycaster_ = raycaster_for(world, std::move(raycaster_), "CameraRenderer");
  const double az = shading_.sun_azimuth_deg * kPi / 180.0, el = shading_.sun_elevation_deg * kPi / 180.0;
  sun_ = Eigen::Vector3d(std::sin(az) * std::cos(el), std::cos(az) * std::cos(el), std::sin(el));

  if (shading_.shadows) build_sun_ceiling();

  const auto n = static_cast<std::size_t>(model_.width) * static_cast<std::size_t>(model_.height);
  rays_.assign(3 * n, 0.0f);
  for (int r = 0; r < model_.height; ++r) {
    for (int c = 0; c < model_.width; ++c) {
      double x = 0, y = 0;
      if (!undistort(model_, (c - model_.cx) / model_.fx, (r - model_.cy) / model_.fy, x, y)) continue;
      const double inv = 1.0 / std::sqrt(x * x + y * y + 1.0);
      float* p = rays_.data() + 3 * (static_cast<std::size_t>(r) * static_cast<std::size_t>(model_.width) +
                                     static_cast<std::size_t>(c));
      p[0] = static_cast<float>(x * inv);
      p[1] = static_cast<float>(y * inv);
      p[2] = static_cast<float>(inv);
    }
  }

  if (sensor_.vignetting) {
    // cos(theta)^k with k such that the corner farthest off the axis gets corner_illumination.
    float cos_corner = 1.0f;
    const std::array<std::pair<int, int>, 4> corners{{{0, 0}, {model_.width - 1, 0}, {0, model_.height - 1}, {model_.width - 1, model_.height - 1}}};
    for (const auto& [c, r] : corners) {
      const float z = pixel_ray(c, r).z();
      if (z > 0.0f) cos_corner = std::min(cos_corner, z);
    }
    const double k = cos_corner < 1.0f ? std::log(sensor_.corner_illumination) / std::log(static_cast<double>(cos_corner)) : 0.0;
    vignette_.assign(n, 1.0f);
    for (std::size_t i = 0; i < n; ++i)
      if (rays_[3 * i + 2] > 0.0f) vignette_[i] = static_cast<float>(std::pow(static_cast<double>(rays_[3 * i + 2]), k));
  }
}

float CameraRenderer::vignetting(int col, int row) const noexcept {
  if (vignette_.empty() || col < 0 || row < 0 || col >= model_.width || row >= model_.height) return 1.0f;
  return vignette_[static_cast<std::size_t>(row) * static_cast<std::size_t>(model_.width) + static_cast<std::size_t>(col)];
}

double CameraRenderer::blur_length_px(const Pose3& pose, const CameraShot& shot) const noexcept {
  const GridGeometry& g = world_.grid();
  const std::int32_t col = g.col(pose.x), row = g.row(pose.y);
  const double ground = g.contains(col, row) ? static_cast<double>(world_.terrain.at<float>(row, col)) : 0.0;
  const double h = std::max(pose.z - ground, 1.0);  // [m] above the ground at the nadir
  const double t = shot.exposure.exposure_s, f = std::max(model_.fx, model_.fy);
  const double r_corner = std::hypot(std::max(model_.cx, model_.width - 1 - model_.cx), std::max(model_.cy, model_.height - 1 - model_.cy));
  const double v_h = std::hypot(shot.velocity.x(), shot.velocity.y());
  return t * (v_h * f / h + std::abs(shot.velocity.z()) * r_corner / h + std::abs(shot.yaw_rate) * r_corner);
}

// U(B), an upper bound on the shadow height over block B, from the exact recursion along the sun's
// horizontal direction s (rise k per metre): G(x) = max(max_{0<=d<D} S(x + d s) - k d, G(x + D s) - k D).
// Over a block, the first term is bounded by the highest block in the bounding box of the region swept
// by B over [0, D), the second by U of the blocks under B + D s, which lie sunward of B (D = 2 blocks),
// so visiting blocks from the sun's side outward computes every U from finished ones.
void CameraRenderer::build_sun_ceiling() {
  const HeightfieldRaycaster& rc = *raycaster_;
  const GridGeometry& g = rc.grid();
  constexpr std::int32_t side = std::int32_t{1} << kSunBlockShift;
  const std::int32_t bw = (g.width + side - 1) >> kSunBlockShift, bh = (g.height + side - 1) >> kSunBlockShift;
  const auto nb = static_cast<std::size_t>(bw) * static_cast<std::size_t>(bh);
  const auto at = [bw](std::int32_t i, std::int32_t j) {
    return static_cast<std::size_t>(j) * static_cast<std::size_t>(bw) + static_cast<std::size_t>(i);
  };
  std::vector<float> block_max(nb, -std::numeric_limits<float>::infinity());
  for (std::int32_t r = 0; r < g.height; ++r)
    for (std::int32_t c = 0; c < g.width; ++c) {
      float& m = block_max[at(c >> kSunBlockShift, r >> kSunBlockShift)];
      m = std::max(m, rc.surface(c, r));
    }
  sun_blocks_w_ = bw;
  const double horizontal = std::hypot(sun_.x(), sun_.y());
  if (horizontal < 1e-9) {  // the sun overhead: only a point's own column could shade it
    sun_ceiling_ = std::move(block_max);
    return;
  }
  const double su = sun_.x() / horizontal, sv = -sun_.y() / horizontal;  // in (u east, v south) block units
  constexpr double kStep = 2.0;                                             // D [blocks]
  const double decay = sun_.z() / horizontal * kStep * side * g.resolution;
  std::vector<std::int32_t> order(nb);
  for (std::size_t k = 0; k < nb; ++k) order[k] = static_cast<std::int32_t>(k);
  const auto along = [&](std::int32_t k) { return (k % bw + 0.5) * su + (k / bw + 0.5) * sv; };
  std::sort(order.begin(), order.end(), [&](std::int32_t a, std::int32_t b) { return along(a) > along(b); });

  sun_ceiling_.assign(nb, -std::numeric_limits<float>::infinity());
  constexpr double kTouch = 1e-9;  // blocks that only touch a region count as inside it
  const auto span = [&](double lo, double hi, std::int32_t n, std::int32_t& first, std::int32_t& last) {
    first = std::max(static_cast<std::int32_t>(std::floor(lo - kTouch)), 0);
    last = std::min(static_cast<std::int32_t>(std::floor(hi + kTouch)), n - 1);
  };
  for (const std::int32_t k : order) {
    const std::int32_t bi = k % bw, bj = k / bw;
    float m = -std::numeric_limits<float>::infinity();
    std::int32_t i0 = 0, i1 = 0, j0 = 0, j1 = 0;
    span(bi + std::min(0.0, kStep * su), bi + 1 + std::max(0.0, kStep * su), bw, i0, i1);
    span(bj + std::min(0.0, kStep * sv), bj + 1 + std::max(0.0, kStep * sv), bh, j0, j1);
    for (std::int32_t j = j0; j <= j1; ++j)
      for (std::int32_t i = i0; i <= i1; ++i) m = std::max(m, block_max[at(i, j)]);
    span(bi + kStep * su, bi + 1 + kStep * su, bw, i0, i1);
    span(bj + kStep * sv, bj + 1 + kStep * sv, bh, j0, j1);
    for (std::int32_t j = j0; j <= j1; ++j) {
      for (std::int32_t i = i0; i <= i1; ++i) {
        const double lowered = static_cast<double>(sun_ceiling_[at(i, j)]) - decay;
        m = std::max(m, std::nextafter(static_cast<float>(lowered), std::numeric_limits<float>::infinity()));  // round up
      }
    }
    sun_ceiling_[static_cast<std::size_t>(k)] = m;
  }
}

Eigen::Vector3f CameraRenderer::pixel_ray(int col, int row) const noexcept {
  if (col < 0 || row < 0 || col >= model_.width || row >= model_.height) return Eigen::Vector3f::Zero();
  const float* p = rays_.data() + 3 * (static_cast<std::size_t>(row) * static_cast<std::size_t>(model_.width) +
                                       static_cast<std::size_t>(col));
  return {p[0], p[1], p[2]};
}

void CameraRenderer::prepare(const Pose3& body_pose_in_map, CameraFrame& out, std::int64_t stamp_ns) const {
  CameraShot shot;
  shot.exposure = {sensor_.exposure_s, sensor_.gain};
  prepare(body_pose_in_map, out, stamp_ns, shot);
}

void CameraRenderer::prepare(const Pose3& body_pose_in_map, CameraFrame& out, std::int64_t stamp_ns, const CameraShot& shot) const {
  out.rgb.create(model_.height, model_.width, CV_8UC3);
  out.cls.create(model_.height, model_.width, CV_8UC1);
  out.depth.create(model_.height, model_.width, CV_32FC1);
  out.pose = body_pose_in_map;
  out.stamp_ns = stamp_ns;
  out.shot = shot;
  out.blur_samples = 1;
  if (sensor_.motion_blur) {
    // About two samples per pixel of blur, odd so that the middle one is the frame's pose.
    const double len = blur_length_px(body_pose_in_map, shot);
    if (len >= 0.5) out.blur_samples = std::min(sensor_.blur_max_samples, 2 * static_cast<int>(std::ceil(len)) + 1);
  }
}

void CameraRenderer::render(const Pose3& body_pose_in_map, CameraFrame& out, std::int64_t stamp_ns) const {
  prepare(body_pose_in_map, out, stamp_ns);
  render_rows(body_pose_in_map, 0, model_.height, out);
}

void CameraRenderer::render(const Pose3& body_pose_in_map, CameraFrame& out, std::int64_t stamp_ns, const CameraShot& shot) const {
  prepare(body_pose_in_map, out, stamp_ns, shot);
  render_rows(body_pose_in_map, 0, model_.height, out);
}

void CameraRenderer::render_rows(const Pose3& pose, int row_begin, int row_end, CameraFrame& out) const noexcept {
  row_begin = std::max(row_begin, 0);
  row_end = std::min(row_end, std::min(model_.height, out.rgb.rows));
  if (out.rgb.cols != model_.width || out.cls.size() != out.rgb.size() || out.depth.size() != out.rgb.size()) return;

  const Eigen::Matrix3d map_from_camera = rotation_of(pose) * CameraModel::body_from_camera();
  const Eigen::Vector3d eye(pose.x, pose.y, pose.z);
  const HeightfieldRaycaster& rc = *raycaster_;
  const GridGeometry& g = world_.grid();
  const double inv_res = 1.0 / g.resolution;
  const double zmax = static_cast<double>(rc.max_surface());
  const double sun_flat = shading_.ambient + (1.0 - shading_.ambient) * sun_.z();  // a lit flat top renders at albedo
  const double pixel_angle = 1.0 / std::max(model_.fx, model_.fy);

  const CameraShot& shot = out.shot;
  const SubExposures blur(shot, out.blur_samples, eye, map_from_camera);
  const int samples = blur.samples, mid = blur.mid;
  const auto& eyes = blur.eyes;
  const auto& rots = blur.rots;

  // The sensor: exposure factor (rendered value 255 = full well), noise in DN at gain 1 (variance
  // a * signal + b), vignetting. The ideal camera skips it all and rounds the rendered value.
  const double exposure_factor = shot.exposure.exposure_s / sensor_.full_scale_exposure_s;
  const double gain = shot.exposure.gain;
  const double binned = std::pow(static_cast<double>(sensor_.sensor_width_px) / model_.width, 2.0);  // sensor pixels per pixel
  const double full_well = sensor_.full_well_e * binned;
  const double noise_a = 255.0 / full_well;
  const double noise_b = std::pow(255.0 / full_well, 2.0) * sensor_.read_noise_e * sensor_.read_noise_e * binned;
  const bool ideal = !sensor_.noise && vignette_.empty() && samples == 1 && exposure_factor * gain == 1.0;
  const std::uint64_t frame_key = mix64(shot.seed ^ mix64(shot.frame + 0x632BE59BD9B4E019ULL));
  const double inv_samples = 1.0 / samples;
  const HitShading shade{world_, rc, shading_, sun_,
                         [this](std::int32_t col, std::int32_t row) noexcept { return sun_ceiling(col, row); },
                         inv_res, zmax, sun_flat, pixel_angle};

  // Tiles of kTile x kTile pixels. All rays of a tile (every sub-exposure sample's) leave their eyes
  // downward inside a thin cone; each cast starts at the height the tile's rays are proven free above
  // (the same hits as a cast from the eye, most of the descent skipped).
  constexpr int kTile = 8;
  std::array<Eigen::Vector3d, kTile * kTile> dirs;
  for (int tr = row_begin; tr < row_end; tr += kTile) {
    const int tr1 = std::min(tr + kTile, row_end);
    for (int tc = 0; tc < model_.width; tc += kTile) {
      const int tc1 = std::min(tc + kTile, model_.width);
      const int tw = tc1 - tc;
      TileCone cone;
      for (int r = tr; r < tr1; ++r) {
        const float* ray = rays_.data() + 3 * (static_cast<std::size_t>(r) * static_cast<std::size_t>(model_.width) +
                                               static_cast<std::size_t>(tc));
        for (int c = 0; c < tw; ++c, ray += 3) {
          const Eigen::Vector3d dc(ray[0], ray[1], ray[2]);
          Eigen::Vector3d& d = dirs[static_cast<std::size_t>((r - tr) * kTile + c)];
          if (!(dc.z() > 0.0)) continue;  // no ray: sky, not cast
          d = map_from_camera * dc;
          cone.extend(d);
          for (int i = 0; i < samples; ++i)
            if (i != mid) cone.extend(rots[static_cast<std::size_t>(i)] * dc);
        }
      }
      const double proven = shading_.tile_start ? tile_free_height(cone, blur, rc, g, inv_res, zmax) : kInf;
      const auto cast = [&](const Eigen::Vector3d& from, const Eigen::Vector3d& dw) noexcept {
        if (proven < from.z()) {
          const double t_start = std::max(0.0, (proven - from.z()) / dw.z() - 1e-6);
          return rc.cast_from(from, dw, shading_.max_range_m, t_start, false);
        }
        return rc.cast(from, dw, shading_.max_range_m);
      };

      for (int r = tr; r < tr1; ++r) {
        auto* rgb = out.rgb.ptr<cv::Vec3b>(r);
        auto* cls = out.cls.ptr<std::uint8_t>(r);
        auto* depth = out.depth.ptr<float>(r);
        const float* ray = rays_.data() + 3 * (static_cast<std::size_t>(r) * static_cast<std::size_t>(model_.width) +
                                               static_cast<std::size_t>(tc));
        for (int c = tc; c < tc1; ++c, ray += 3) {
          const Eigen::Vector3d dc(ray[0], ray[1], ray[2]);
          const Eigen::Vector3d& dw = dirs[static_cast<std::size_t>((r - tr) * kTile + (c - tc))];
          RayHit hit;
          if (dc.z() > 0.0) hit = cast(eye, dw);
          double rad[3] = {0, 0, 0};  // sky: no light
          if (!hit.hit) {
            cls[c] = raw(ClassId::kUnknown);
            depth[c] = 0.0f;
          } else {
            depth[c] = static_cast<float>(hit.range * dc.z());
            cls[c] = world_.class_id.at<std::uint8_t>(hit.row, hit.col);
            shade(hit, dw, rad);
          }
          if (ideal) {
            rgb[c] = cv::Vec3b(cv::saturate_cast<std::uint8_t>(rad[0]), cv::saturate_cast<std::uint8_t>(rad[1]),
                               cv::saturate_cast<std::uint8_t>(rad[2]));
            continue;
          }
          if (samples > 1 && dc.z() > 0.0) {  // the other sub-exposure samples: light only
            for (int i = 0; i < samples; ++i) {
              if (i == mid) continue;
              const Eigen::Vector3d di = rots[static_cast<std::size_t>(i)] * dc;
              const RayHit hi = cast(eyes[static_cast<std::size_t>(i)], di);
              if (!hi.hit) continue;
              double ri[3];
              shade(hi, di, ri);
              for (int k = 0; k < 3; ++k) rad[k] += ri[k];
            }
            for (double& x : rad) x *= inv_samples;
          }
          const std::size_t pix = static_cast<std::size_t>(r) * static_cast<std::size_t>(model_.width) + static_cast<std::size_t>(c);
          const double vig = vignette_.empty() ? 1.0 : static_cast<double>(vignette_[pix]);
          std::uint8_t dn[3];
          for (int k = 0; k < 3; ++k) {
            double s = rad[k] * vig * exposure_factor;  // [DN at gain 1] = electrons * 255 / full well
            if (sensor_.noise)
              s += std::sqrt(std::max(s, 0.0) * noise_a + noise_b) * unit_noise(mix64(frame_key + (3 * pix + static_cast<std::size_t>(k)) * 0x9E3779B97F4A7C15ULL));
            s = std::clamp(s, 0.0, 255.0);  // the well holds no more (and no fewer than zero) electrons
            dn[k] = cv::saturate_cast<std::uint8_t>(s * gain);
          }
          rgb[c] = cv::Vec3b(dn[0], dn[1], dn[2]);
        }
      }
    }
  }
}

}  // namespace ag::sim
