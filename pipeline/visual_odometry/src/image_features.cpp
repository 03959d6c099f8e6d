// Pyramids, corners and Lucas-Kanade flow for the VO front end.
#include "airground/visual_odometry/image_features.hpp"

#include <algorithm>
#include <cmath>

namespace ag::vo {

namespace {

constexpr std::size_t uz(int v) noexcept { return static_cast<std::size_t>(v); }
constexpr float fl(int v) noexcept { return static_cast<float>(v); }

void gradients(const GreyImage& im, GreyImage& gx, GreyImage& gy) {
  gx.resize(im.width, im.height);
  gy.resize(im.width, im.height);
  const int w = im.width, h = im.height;
  for (int y = 0; y < h; ++y) {
    const float* r = im.px.data() + uz(y) * uz(w);
    const float* up = im.px.data() + uz(std::max(y - 1, 0)) * uz(w);
    const float* dn = im.px.data() + uz(std::min(y + 1, h - 1)) * uz(w);
    float* ox = gx.px.data() + uz(y) * uz(w);
    float* oy = gy.px.data() + uz(y) * uz(w);
    ox[0] = r[1] - r[0];
    ox[w - 1] = r[w - 1] - r[w - 2];
    for (int x = 1; x < w - 1; ++x) ox[x] = 0.5F * (r[x + 1] - r[x - 1]);
    const float s = (y == 0 || y == h - 1) ? 1.0F : 0.5F;
    for (int x = 0; x < w; ++x) oy[x] = s * (dn[x] - up[x]);
  }
}

}  // namespace

void GreyImage::resize(int w, int h) {
  width = w;
  height = h;
  px.resize(uz(w) * uz(h));
}

float GreyImage::sample(float x, float y) const noexcept {
  const int x0 = std::min(static_cast<int>(x), width - 2), y0 = std::min(static_cast<int>(y), height - 2);
  const float ax = x - fl(x0), ay = y - fl(y0);
  const float* r0 = px.data() + uz(y0) * uz(width) + uz(x0);
  const float* r1 = r0 + width;
  return (1 - ay) * ((1 - ax) * r0[0] + ax * r0[1]) + ay * ((1 - ax) * r1[0] + ax * r1[1]);
}

void ImagePyramid::build_from_rgb(const std::uint8_t* rgb, int width, int height) {
  level[0].resize(width, height);
  const std::size_t n = uz(width) * uz(height);
  float* o = level[0].px.data();
  for (std::size_t i = 0; i < n; ++i)
    o[i] = 0.299F * static_cast<float>(rgb[3 * i]) + 0.587F * static_cast<float>(rgb[3 * i + 1]) + 0.114F * static_cast<float>(rgb[3 * i + 2]);
  build_levels();
}

void ImagePyramid::build_from_grey(const std::uint8_t* grey, int width, int height) {
  level[0].resize(width, height);
  const std::size_t n = uz(width) * uz(height);
  for (std::size_t i = 0; i < n; ++i) level[0].px[i] = static_cast<float>(grey[i]);
  build_levels();
}

void ImagePyramid::build_levels() {
  for (std::size_t l = 1; l < uz(kPyramidLevels); ++l) {
    const GreyImage& a = level[l - 1];
    GreyImage& b = level[l];
    b.resize(a.width / 2, a.height / 2);
    for (int y = 0; y < b.height; ++y) {
      const float* r0 = a.px.data() + uz(2 * y) * uz(a.width);
      const float* r1 = r0 + a.width;
      float* o = b.px.data() + uz(y) * uz(b.width);
      for (int x = 0; x < b.width; ++x) o[x] = 0.25F * (r0[2 * x] + r0[2 * x + 1] + r1[2 * x] + r1[2 * x + 1]);
    }
  }
  for (std::size_t l = 0; l < uz(kPyramidLevels); ++l) gradients(level[l], grad_x[l], grad_y[l]);
}

void CornerDetector::detect(const ImagePyramid& pyr, std::span<const Pixel> existing, std::vector<Pixel>& out,
                            std::size_t max_new) {
  out.clear();
  const GreyImage& gx = pyr.grad_x[0];
  const GreyImage& gy = pyr.grad_y[0];
  const int w = gx.width, h = gx.height;
  const std::size_t W = uz(w + 1);
  const std::size_t n = W * uz(h + 1);
  ixx_.resize(n);
  ixy_.resize(n);
  iyy_.resize(n);
  std::fill(ixx_.begin(), ixx_.begin() + static_cast<std::ptrdiff_t>(W), 0.0);
  std::fill(ixy_.begin(), ixy_.begin() + static_cast<std::ptrdiff_t>(W), 0.0);
  std::fill(iyy_.begin(), iyy_.begin() + static_cast<std::ptrdiff_t>(W), 0.0);
  for (int y = 0; y < h; ++y) {
    double sxx = 0, sxy = 0, syy = 0;
    const std::size_t row = uz(y + 1) * W, prev = uz(y) * W;
    ixx_[row] = ixy_[row] = iyy_[row] = 0.0;
    const float* ax = gx.px.data() + uz(y) * uz(w);
    const float* ay = gy.px.data() + uz(y) * uz(w);
    for (std::size_t x = 0; x < uz(w); ++x) {
      const double dx = static_cast<double>(ax[x]), dy = static_cast<double>(ay[x]);
      sxx += dx * dx;
      sxy += dx * dy;
      syy += dy * dy;
      ixx_[row + x + 1] = ixx_[prev + x + 1] + sxx;
      ixy_[row + x + 1] = ixy_[prev + x + 1] + sxy;
      iyy_[row + x + 1] = iyy_[prev + x + 1] + syy;
    }
  }
  const int gc = p_.grid_cols, gr = p_.grid_rows;
  occupied_.assign(uz(gc) * uz(gr), 0);
  const float cw = fl(w) / fl(gc), ch = fl(h) / fl(gr);
  for (const Pixel& e : existing) {
    const int cx = std::clamp(static_cast<int>(e.u / cw), 0, gc - 1), cy = std::clamp(static_cast<int>(e.v / ch), 0, gr - 1);
    occupied_[uz(cy) * uz(gc) + uz(cx)] = 1;
  }
  const int k = p_.window_half;
  const double area = static_cast<double>((2 * k + 1) * (2 * k + 1));
  const std::size_t side = uz(2 * k + 1);
  auto box = [&](const std::vector<double>& I, int x, int y) {
    const std::size_t a = uz(y - k) * W + uz(x - k), b = uz(y + k + 1) * W + uz(x - k);
    return I[b + side] - I[b] - I[a + side] + I[a];
  };
  const float min_d2 = p_.min_distance_px * p_.min_distance_px;
  const int margin_lo = std::max(p_.border_px, k), margin_hi = std::max(p_.border_px, k + 1);
  for (int cy = 0; cy < gr && out.size() < max_new; ++cy) {
    for (int cx = 0; cx < gc && out.size() < max_new; ++cx) {
      if (occupied_[uz(cy) * uz(gc) + uz(cx)]) continue;
      const int x0 = std::max(static_cast<int>(fl(cx) * cw), margin_lo), x1 = std::min(static_cast<int>(fl(cx + 1) * cw), w - margin_hi);
      const int y0 = std::max(static_cast<int>(fl(cy) * ch), margin_lo), y1 = std::min(static_cast<int>(fl(cy + 1) * ch), h - margin_hi);
      double best = static_cast<double>(p_.min_score);
      int bx = -1, by = -1;
      for (int y = y0; y < y1; ++y)
        for (int x = x0; x < x1; ++x) {
          const double a = box(ixx_, x, y) / area, b = box(ixy_, x, y) / area, c = box(iyy_, x, y) / area;
          const double score = 0.5 * (a + c - std::sqrt((a - c) * (a - c) + 4 * b * b));
          if (score > best) {
            best = score;
            bx = x;
            by = y;
          }
        }
      if (bx < 0) continue;
      bool near = false;
      for (const Pixel& e : existing) {
        const float du = e.u - fl(bx), dv = e.v - fl(by);
        if (du * du + dv * dv < min_d2) {
          near = true;
          break;
        }
      }
      if (!near) out.push_back(Pixel{fl(bx), fl(by)});
    }
  }
}

void OpticalFlow::track(const ImagePyramid& prev, const ImagePyramid& next, std::span<const Pixel> prev_pts,
                        std::span<Pixel> next_pts, std::span<std::uint8_t> ok) const noexcept {
  for (std::size_t i = 0; i < prev_pts.size(); ++i) ok[i] = track_one(prev, next, prev_pts[i], next_pts[i]) ? 1 : 0;
}

bool OpticalFlow::track_one(const ImagePyramid& prev, const ImagePyramid& next, Pixel p, Pixel& q) const noexcept {
  constexpr int kMaxWin = 31;
  const int k = std::min(p_.window_half, kMaxWin / 2), side = 2 * k + 1;
  const std::size_t nw = uz(side * side);
  float tmpl[kMaxWin * kMaxWin], tx[kMaxWin * kMaxWin], ty[kMaxWin * kMaxWin], jv[kMaxWin * kMaxWin];
  float gu = q.u - p.u, gv = q.v - p.v;  // the caller's guess of the motion at level 0
  double resid = 0;
  for (int l = kPyramidLevels - 1; l >= 0; --l) {
    const std::size_t lu = uz(l);
    const float s = 1.0F / fl(1 << l);
    const GreyImage& I = prev.level[lu];
    const GreyImage& J = next.level[lu];
    const float pu = p.u * s, pv = p.v * s;
    const float lo = fl(k) + 1.0F;
    if (pu < lo || pv < lo || pu > fl(I.width - 2 - k) || pv > fl(I.height - 2 - k)) {
      if (l == 0) return false;
      continue;  // too close to the edge at this level: refine on the finer ones
    }
    double gxx = 0, gxy = 0, gyy = 0, mean_t = 0;
    std::size_t i = 0;
    for (int dy = -k; dy <= k; ++dy)
      for (int dx = -k; dx <= k; ++dx, ++i) {
        const float x = pu + fl(dx), y = pv + fl(dy);
        tmpl[i] = I.sample(x, y);
        tx[i] = prev.grad_x[lu].sample(x, y);
        ty[i] = prev.grad_y[lu].sample(x, y);
        const double a = static_cast<double>(tx[i]), b = static_cast<double>(ty[i]);
        gxx += a * a;
        gxy += a * b;
        gyy += b * b;
        mean_t += static_cast<double>(tmpl[i]);
      }
    const double dn = static_cast<double>(nw);
    mean_t /= dn;
    const double det = gxx * gyy - gxy * gxy;
    const double min_eig = 0.5 * (gxx + gyy - std::sqrt((gxx - gyy) * (gxx - gyy) + 4 * gxy * gxy)) / dn;
    if (det <= 1e-9 || min_eig < static_cast<double>(p_.min_eigen)) return false;
    float du = gu * s, dv = gv * s;
    for (int it = 0; it < p_.max_iterations; ++it) {
      const float qu = pu + du, qv = pv + dv;
      if (qu < lo || qv < lo || qu > fl(J.width - 2 - k) || qv > fl(J.height - 2 - k)) return false;
      double mean_j = 0;
      i = 0;
      for (int dy = -k; dy <= k; ++dy)
        for (int dx = -k; dx <= k; ++dx, ++i) {
          jv[i] = J.sample(qu + fl(dx), qv + fl(dy));
          mean_j += static_cast<double>(jv[i]);
        }
      mean_j /= dn;
      const double off = mean_j - mean_t;
      double bx = 0, by = 0, r = 0;
      for (std::size_t m = 0; m < nw; ++m) {
        const double e = static_cast<double>(tmpl[m]) - (static_cast<double>(jv[m]) - off);
        bx += e * static_cast<double>(tx[m]);
        by += e * static_cast<double>(ty[m]);
        r += std::fabs(e);
      }
      resid = r / dn;
      const double ddu = (gyy * bx - gxy * by) / det, ddv = (gxx * by - gxy * bx) / det;
      du += static_cast<float>(ddu);
      dv += static_cast<float>(ddv);
      if (ddu * ddu + ddv * ddv < static_cast<double>(p_.epsilon_px * p_.epsilon_px)) break;
    }
    gu = du / s;
    gv = dv / s;
  }
  q.u = p.u + gu;
  q.v = p.v + gv;
  return resid <= static_cast<double>(p_.max_residual);
}

}  // namespace ag::vo
