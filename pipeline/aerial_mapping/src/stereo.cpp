// DenseStereo: rectify (stereo_rectify.cpp), block-match (stereo_block_match.cpp), mask the black
// borders, project the disparities to coloured, classified map points.
#include "airground/aerial_mapping/stereo.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "stereo_internal.hpp"

namespace ag::mapping {
namespace {

std::size_t sz(int v) noexcept { return static_cast<std::size_t>(v); }

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

// OpenCV's fixed-point RGB -> grey (0.299 R + 0.587 G + 0.114 B).
void to_grey(const std::uint8_t* rgb, std::size_t n, std::uint8_t* grey) {
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint32_t r = rgb[3 * i], g = rgb[3 * i + 1], b = rgb[3 * i + 2];
    grey[i] = static_cast<std::uint8_t>((r * 4899u + g * 9617u + b * 1868u + (1u << 13)) >> 14);
  }
}

int checked_camera_size(const PinholeCamera& c) {
  if (c.width < 2 || c.height < 2 || !(c.fx > 0.0) || !(c.fy > 0.0))
    throw std::invalid_argument("DenseStereo: camera needs a size of at least 2x2 px and positive focal lengths");
  return c.width;
}

constexpr std::int16_t kNoDisparity = std::numeric_limits<std::int16_t>::max();
#if defined(__AVX2__)
constexpr int kMinLanes = 16;
#else
constexpr int kMinLanes = 8;  // one SSE2/NEON register (a wider vector would change the ABI of the helpers)
#endif
using S16 = std::int16_t __attribute__((vector_size(2 * kMinLanes)));

[[gnu::always_inline]] inline S16 load16(const std::int16_t* p) noexcept {
  S16 v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
[[gnu::always_inline]] inline void store16(std::int16_t* p, const S16& v) noexcept { std::memcpy(p, &v, sizeof v); }
[[gnu::always_inline]] inline S16 vmin(const S16& a, const S16& b) noexcept { return a < b ? a : b; }

// dst = minimum of the positive values of src over the (2r+1)^2 window around each pixel (clipped at
// the image border), kNoDisparity where there is none; tmp: width * height, pad: width + 2 * r +
// kMinLanes. dst may be src.
void window_min(const std::int16_t* src, int width, int height, int r, std::int16_t* tmp, std::int16_t* dst,
                std::int16_t* pad) {
  const std::size_t w = sz(width), rr = sz(r);
  std::fill(pad, pad + w + 2 * rr + kMinLanes, kNoDisparity);
  const S16 zero = S16{}, none = S16{} + kNoDisparity;
  for (int y = 0; y < height; ++y) {
    const std::int16_t* in = src + sz(y) * w;
    std::size_t x = 0;
    for (; x + kMinLanes <= w; x += kMinLanes) {
      const S16 v = load16(in + x);
      store16(pad + rr + x, v > zero ? v : none);
    }
    for (; x < w; ++x) pad[rr + x] = in[x] > 0 ? in[x] : kNoDisparity;
    std::int16_t* out = tmp + sz(y) * w;
    for (x = 0; x < w; x += kMinLanes) {  // the last vector may spill into pad's tail
      S16 acc = load16(pad + x);
      for (std::size_t k = 1; k <= 2 * rr; ++k) acc = vmin(acc, load16(pad + x + k));
      if (x + kMinLanes <= w) {
        store16(out + x, acc);
      } else {
        for (std::size_t l = 0; x + l < w; ++l) out[x + l] = acc[l];
      }
    }
  }
  for (int y = 0; y < height; ++y) {
    std::int16_t* out = dst + sz(y) * w;
    const int y0 = std::max(0, y - r), y1 = std::min(height - 1, y + r);
    std::size_t x = 0;
    for (; x + kMinLanes <= w; x += kMinLanes) {
      S16 acc = load16(tmp + sz(y0) * w + x);
      for (int yy = y0 + 1; yy <= y1; ++yy) acc = vmin(acc, load16(tmp + sz(yy) * w + x));
      store16(out + x, acc);
    }
    for (; x < w; ++x) {
      std::int16_t acc = tmp[sz(y0) * w + x];
      for (int yy = y0 + 1; yy <= y1; ++yy) acc = std::min(acc, tmp[sz(yy) * w + x]);
      out[x] = acc;
    }
  }
}

}  // namespace

struct DenseStereo::Impl {
  Impl(const PinholeCamera& c, const StereoParams& p)
      : camera(c),
        params(p),
        max_r2((checked_camera_size(c), detail::max_undistorted_r2(c))),
        // Any in-plane rotation of the undistorted image (+10% for tilt) plus the matcher's margins.
        content(static_cast<int>(std::ceil(2.2 * c.fx * std::sqrt(max_r2)))),
        max_width(content + p.min_disparity + p.num_disparities + 2 * (p.block_size / 2) + 2),
        max_height(content + 2 * (p.block_size / 2) + 2),
        matcher(p, max_width, max_height) {
    if (p.border_dilate_px < 0 || !(p.min_depth_m >= 0.0) || !(p.max_depth_m > p.min_depth_m) || !(p.min_baseline_m >= 0.0))
      throw std::invalid_argument("StereoParams: border_dilate_px >= 0, 0 <= min_depth_m < max_depth_m, min_baseline_m >= 0");
    if (p.edge_margin_px < 0 || p.edge_margin_px > 64 || p.edge_jump_px < 0 || p.edge_jump_px > 1000)
      throw std::invalid_argument("StereoParams: edge_margin_px in [0, 64], edge_jump_px in [0, 1000]");
    const std::size_t src = sz(c.width) * sz(c.height), cap = sz(max_width) * sz(max_height);
    grey_ref.assign(src, 0);
    grey_other.assign(src, 0);
    for (auto* v : {&rect_ref, &rect_other, &invalid_ref, &invalid_other, &valid_ref, &valid_other, &tmp}) v->reserve(cap);
    map_ref.reserve(2 * cap);
    map_other.reserve(2 * cap);
    raw.reserve(cap);
    disp.reserve(cap);
    if (p.edge_margin_px > 0) {
      wa.reserve(cap);
      wb.reserve(cap);
      wt.reserve(cap);
      pad16.assign(sz(max_width) + 2 * sz(p.edge_margin_px) + sz(kMinLanes), 0);
    }
    pad.assign(sz(max_width) + 2 * sz(std::max(p.border_dilate_px, 0)) + 64, 0);
    scratch.assign(2 * sz(max_width + detail::kRectifyLanes), 0.0f);
  }

  PinholeCamera camera;
  StereoParams params;
  double max_r2;
  int content, max_width, max_height;
  detail::BlockMatcher matcher;
  RectifiedGeometry geometry;
  StereoStats stats;
  std::vector<std::uint8_t> grey_ref, grey_other;
  std::vector<std::uint8_t> rect_ref, rect_other, invalid_ref, invalid_other, valid_ref, valid_other, tmp;
  std::vector<float> map_ref, map_other;
  std::vector<std::int16_t> raw, disp;
  std::vector<std::int16_t> wa, wb, wt, pad16;  // edge guard: window minima and scratch
  std::vector<std::uint8_t> pad;
  std::vector<float> scratch;

  // The steps of compute() on the pair's rectified geometry.
  void rectify(const StereoImage& prev, const StereoImage& cur);
  std::uint64_t match_inside_borders();  // valid disparities
  std::uint64_t drop_edge_fattening();   // disparities dropped
  void project(const StereoImage& cur, std::vector<MapPoint>& out) const;
};

DenseStereo::DenseStereo(const PinholeCamera& camera, const StereoParams& params)
    : impl_(std::make_unique<Impl>(camera, params)) {}
DenseStereo::~DenseStereo() = default;

// 1. Grey, rectified images of the pair, and where their content is valid (black borders dilated).
void DenseStereo::Impl::rectify(const StereoImage& prev, const StereoImage& cur) {
  const RectifiedGeometry& g = geometry;
  const int w = g.width, h = g.height;
  const std::size_t n = sz(w) * sz(h);
  const std::size_t src = sz(camera.width) * sz(camera.height);
  to_grey(cur.rgb, src, grey_ref.data());
  to_grey(prev.rgb, src, grey_other.data());
  for (auto* v : {&rect_ref, &rect_other, &invalid_ref, &invalid_other, &valid_ref, &valid_other, &tmp}) v->resize(n);
  map_ref.resize(2 * n);
  map_other.resize(2 * n);
  raw.resize(n);
  disp.resize(n);
  detail::build_rectified(camera, g, g.rect_from_reference, max_r2, grey_ref.data(), map_ref.data(),
                          map_ref.data() + n, rect_ref.data(), invalid_ref.data(), scratch.data());
  detail::build_rectified(camera, g, g.rect_from_other, max_r2, grey_other.data(), map_other.data(),
                          map_other.data() + n, rect_other.data(), invalid_other.data(), scratch.data());
  detail::dilate_invalid(invalid_ref.data(), w, h, params.border_dilate_px, valid_ref.data(), tmp.data(), pad.data());
  detail::dilate_invalid(invalid_other.data(), w, h, params.border_dilate_px, valid_other.data(), tmp.data(), pad.data());
}

// 2. Match, then drop disparities on or near the black border of either image (the other image is checked
// at the matched column).
std::uint64_t DenseStereo::Impl::match_inside_borders() {
  const int w = geometry.width, h = geometry.height;
  matcher.compute(rect_ref.data(), rect_other.data(), w, h, raw.data());
  const std::int16_t filtered = matcher.filtered_value();
  std::uint64_t valid = 0;
  for (int y = 0; y < h; ++y) {
    const std::size_t row = sz(y) * sz(w);
    for (int x = 0; x < w; ++x) {
      const std::size_t i = row + sz(x);
      const std::int16_t d = raw[i];
      bool ok = d != filtered && d > 0 && valid_ref[i] != 0;
      if (ok) {
        const int xo = x - (d + 8) / 16;
        ok = xo >= 0 && valid_other[row + sz(xo)] != 0;
      }
      disp[i] = ok ? d : std::int16_t{-1};
      valid += ok ? 1u : 0u;
    }
  }
  return valid;
}

// 2b. Foreground fattening: near a depth edge the block straddles both surfaces and the one with more
// texture wins, so the foreground's disparity spreads up to half a block over the background (in the
// reference image where the background is visible in both views, in the other image's columns where the
// background beside the foreground is occluded in the other view and the spread pixels border the
// unmatched occlusion). Drop every disparity more than edge_jump_px above the smallest one within
// edge_margin_px, in both images' columns.
std::uint64_t DenseStereo::Impl::drop_edge_fattening() {
  const int w = geometry.width, h = geometry.height;
  const std::size_t n = sz(w) * sz(h);
  const int r = params.edge_margin_px, jump = 16 * params.edge_jump_px;
  wa.resize(n);
  wb.resize(n);
  wt.resize(n);
  // wb: window minimum in the reference's columns; wa: the same in the other image's columns.
  window_min(disp.data(), w, h, r, wt.data(), wb.data(), pad16.data());
  std::fill(wa.begin(), wa.end(), kNoDisparity);
  for (int y = 0; y < h; ++y) {
    const std::size_t row = sz(y) * sz(w);
    for (int x = 0; x < w; ++x) {
      const std::int16_t d = disp[row + sz(x)];
      if (d <= 0) continue;
      std::int16_t& o = wa[row + sz(x - (d + 8) / 16)];  // the border mask keeps the column >= 0
      o = std::min(o, d);
    }
  }
  window_min(wa.data(), w, h, r, wt.data(), wa.data(), pad16.data());
  std::uint64_t dropped = 0;
  for (int y = 0; y < h; ++y) {
    const std::size_t row = sz(y) * sz(w);
    for (int x = 0; x < w; ++x) {
      std::int16_t& d = disp[row + sz(x)];
      if (d <= 0) continue;
      if (d - wb[row + sz(x)] > jump || d - wa[row + sz(x - (d + 8) / 16)] > jump) {
        d = -1;
        ++dropped;
      }
    }
  }
  return dropped;
}

// 3. The disparities as coloured, classified map points.
void DenseStereo::Impl::project(const StereoImage& cur, std::vector<MapPoint>& out) const {
  const StereoParams& p = params;
  const RectifiedGeometry& g = geometry;
  const int w = g.width, h = g.height;
  const std::size_t n = sz(w) * sz(h);
  const Eigen::Matrix3d map_r = g.map_from_rect.linear();
  const Eigen::Vector3d map_t = g.map_from_rect.translation();
  const Eigen::Matrix3d cam_from_rect = g.rect_from_reference.transpose();
  const double fb16 = g.f * g.baseline_m * 16.0;
  const int cw = camera.width, ch = camera.height;
  const std::size_t sw = sz(cw);
  for (int y = 0; y < h; ++y) {
    const std::size_t row = sz(y) * sz(w);
    const double yn = (y - g.cy) / g.f;
    for (int x = 0; x < w; ++x) {
      const std::size_t i = row + sz(x);
      const std::int16_t d = disp[i];
      if (d <= 0) continue;
      const double z = fb16 / d;
      if (z < p.min_depth_m || z > p.max_depth_m) continue;
      const Eigen::Vector3d xr((x - g.cx) / g.f * z, yn * z, z);
      const Eigen::Vector3d xm = map_r * xr + map_t;
      const Eigen::Vector3d xc = cam_from_rect * xr;
      const float sx = map_ref[i], sy = map_ref[n + i];
      const int x0 = std::min(static_cast<int>(sx), cw - 2), y0 = std::min(static_cast<int>(sy), ch - 2);
      const float ax = sx - static_cast<float>(x0), ay = sy - static_cast<float>(y0);
      const std::uint8_t* q = cur.rgb + 3 * (sz(y0) * sw + sz(x0));
      const std::size_t down = 3 * sw;
      std::uint8_t rgb[3];
      for (std::size_t c = 0; c < 3; ++c) {
        const float top = static_cast<float>(q[c]) + ax * static_cast<float>(q[c + 3] - q[c]);
        const float bot = static_cast<float>(q[down + c]) + ax * static_cast<float>(q[down + c + 3] - q[down + c]);
        rgb[c] = static_cast<std::uint8_t>(top + ay * (bot - top) + 0.5f);
      }
      const int nx = static_cast<int>(sx + 0.5f), ny = static_cast<int>(sy + 0.5f);
      MapPoint pt{};
      pt.x = static_cast<float>(xm.x());
      pt.y = static_cast<float>(xm.y());
      pt.z = static_cast<float>(xm.z());
      pt.r = rgb[0];
      pt.g = rgb[1];
      pt.b = rgb[2];
      pt.cls = cur.cls[sz(ny) * sw + sz(nx)];
      pt.cos_axis = static_cast<float>(xc.z() / xc.norm());
      out.push_back(pt);
    }
  }
}

Result<std::size_t> DenseStereo::compute(const StereoImage& prev, const StereoImage& cur, std::vector<MapPoint>& out,
                                         StereoTiming* timing) {
  Impl& m = *impl_;
  const StereoParams& p = m.params;
  out.clear();
  ++m.stats.pairs;  // every pair offered, refused ones included
  m.stats.valid_disparities = 0;
  m.stats.lr_rejected = 0;
  m.stats.edge_rejected = 0;
  if (prev.rgb == nullptr || cur.rgb == nullptr || cur.cls == nullptr) {
    ++m.stats.refused;
    return Error::make(ErrorCode::kInvalidArgument, "stereo pair: missing image data");
  }
  const auto t0 = std::chrono::steady_clock::now();
  const double baseline = (prev.map_from_camera.translation() - cur.map_from_camera.translation()).norm();
  if (!(baseline >= p.min_baseline_m)) {
    ++m.stats.refused;
    return Error::make(ErrorCode::kInvalidArgument, "stereo pair refused: baseline " + std::to_string(baseline) +
                                                        " m is below min_baseline_m " + std::to_string(p.min_baseline_m));
  }
  auto plan = detail::plan_rectification(m.camera, p, m.max_width, m.max_height, cur.map_from_camera, prev.map_from_camera);
  if (!plan.ok()) {
    ++m.stats.refused;
    return plan.error();
  }
  m.geometry = plan.value();

  m.rectify(prev, cur);
  const auto t1 = std::chrono::steady_clock::now();
  std::uint64_t valid = m.match_inside_borders();
  m.stats.lr_rejected = m.matcher.lr_rejected();
  m.stats.edge_rejected = 0;
  const auto t_edge = std::chrono::steady_clock::now();
  if (p.edge_margin_px > 0) {
    const std::uint64_t dropped = m.drop_edge_fattening();
    valid -= dropped;
    m.stats.edge_rejected = dropped;
  }
  m.stats.valid_disparities = valid;
  const auto t2 = std::chrono::steady_clock::now();

  m.project(cur, out);
  if (timing != nullptr) {
    timing->rectify_ms = std::chrono::duration<double, std::milli>(t1 - t0).count();
    timing->match_ms = std::chrono::duration<double, std::milli>(t2 - t1).count();
    timing->edge_ms = std::chrono::duration<double, std::milli>(t2 - t_edge).count();
    timing->project_ms = ms_since(t2);
  }
  return out.size();
}

const std::vector<std::uint8_t>& DenseStereo::rectified_reference() const noexcept { return impl_->rect_ref; }
const std::vector<std::uint8_t>& DenseStereo::rectified_other() const noexcept { return impl_->rect_other; }
const std::vector<std::int16_t>& DenseStereo::disparity() const noexcept { return impl_->disp; }
const std::vector<std::int16_t>& DenseStereo::raw_disparity() const noexcept { return impl_->raw; }
const std::vector<std::uint8_t>& DenseStereo::valid_mask() const noexcept { return impl_->valid_ref; }
const std::vector<float>& DenseStereo::map_reference() const noexcept { return impl_->map_ref; }
const std::vector<float>& DenseStereo::map_other() const noexcept { return impl_->map_other; }
const RectifiedGeometry& DenseStereo::rectified() const noexcept { return impl_->geometry; }
const StereoStats& DenseStereo::stats() const noexcept { return impl_->stats; }
const PinholeCamera& DenseStereo::camera() const noexcept { return impl_->camera; }
const StereoParams& DenseStereo::params() const noexcept { return impl_->params; }

}  // namespace ag::mapping
