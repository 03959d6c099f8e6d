// StereoBM's block matching (PREFILTER_XSOBEL, SAD, texture and uniqueness checks, parabola sub-pixel)
// and cv::filterSpeckles, written row by row: per row band, vertical SAD sums per column and disparity
// (updated by one added and one removed image row), then a horizontal running sum over the block. The
// inner loops run over the disparities with GCC/Clang vector extensions (16 x uint16 with AVX2, 8 x
// uint16 on SSE2/NEON); num_disparities is a multiple of 16, so there is no remainder loop.
#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>

#include "stereo_internal.hpp"

namespace ag::mapping::detail {
namespace {

#if defined(__AVX2__)
constexpr int kLanes = 16;
#else
constexpr int kLanes = 8;
#endif
using U16 = std::uint16_t __attribute__((vector_size(kLanes * 2)));
using S16 = std::int16_t __attribute__((vector_size(kLanes * 2)));
using U8 = std::uint8_t __attribute__((vector_size(kLanes)));

template <typename V, typename T>
[[gnu::always_inline]] inline V load(const T* p) noexcept {
  V v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
template <typename V, typename T>
[[gnu::always_inline]] inline void store(T* p, const V& v) noexcept {
  std::memcpy(p, &v, sizeof v);
}

std::size_t sz(int v) noexcept { return static_cast<std::size_t>(v); }

}  // namespace

BlockMatcher::BlockMatcher(const StereoParams& params, int max_width, int max_height)
    : p_(params),
      max_width_(max_width),
      max_height_(max_height),
      ndisp_(params.num_disparities),
      max_disp_(params.min_disparity + params.num_disparities - 1),
      half_(params.block_size / 2),
      filtered_(static_cast<std::int16_t>((params.min_disparity - 1) * 16)) {
  const auto bad = [](const std::string& what) { throw std::invalid_argument("StereoParams: " + what); };
  if (p_.num_disparities <= 0 || p_.num_disparities % 16 != 0) bad("num_disparities must be a positive multiple of 16");
  if (p_.block_size < 5 || p_.block_size > 255 || p_.block_size % 2 == 0) bad("block_size must be odd in [5, 255]");
  if (p_.prefilter_cap < 1 || p_.prefilter_cap > 63) bad("prefilter_cap must be in [1, 63]");
  if (p_.block_size * p_.block_size * 2 * p_.prefilter_cap >= 65536) bad("block_size^2 * 2 * prefilter_cap must be < 65536");
  if (p_.min_disparity < 0 || p_.min_disparity > 1000) bad("min_disparity must be in [0, 1000]");
  if (p_.texture_threshold < 0 || p_.uniqueness_ratio < 0) bad("texture_threshold and uniqueness_ratio must be >= 0");
  if (p_.speckle_window < 0 || p_.speckle_range < 0 || p_.speckle_range > 2047) bad("speckle_window >= 0, speckle_range in [0, 2047]");
  if (max_width <= 0 || max_height <= 0) bad("rectified size must be positive");
  const std::size_t n = sz(max_width) * sz(max_height);
  pre_left_.assign(n, 0);
  pre_right_.assign(n, 0);
  colsad_.assign(sz(max_width) * sz(ndisp_), 0);
  sad_.assign(sz(ndisp_), 0);
  coltex_.assign(sz(max_width), 0);
  if (p_.lr_max_diff >= 0) {
    rcost_.assign(sz(max_width) + sz(kLanes), 0);
    rcol_.assign(sz(max_width) + sz(kLanes), 0);
  }
  labels_.assign(n, 0);
  stack_.assign(n, 0);
  small_.assign(n + 1, 0);
}

void BlockMatcher::compute(const std::uint8_t* left, const std::uint8_t* right, int width, int height,
                           std::int16_t* disp) {
  if (width > max_width_ || height > max_height_) throw std::logic_error("BlockMatcher: image larger than its buffers");
  prefilter(left, width, height, pre_left_.data());
  prefilter(right, width, height, pre_right_.data());
  match(width, height, disp);
  if (p_.speckle_window > 0) filter_speckles(disp, width, height);
}

// x-Sobel (1 2 1 vertical smoothing) clipped to [-cap, cap] and offset by cap, rows mirrored at the
// borders (BORDER_REFLECT_101), the first and last columns (and, for an odd height, the last row) set to
// cap, exactly as StereoBM's prefilterXSobel.
void BlockMatcher::prefilter(const std::uint8_t* src, int width, int height, std::uint8_t* dst) const {
  const int cap = p_.prefilter_cap;
  const auto cap8 = static_cast<std::uint8_t>(cap);
  for (int y = 0; y < height; ++y) {
    std::uint8_t* d = dst + sz(y) * sz(width);
    if ((height % 2 == 1 && y == height - 1) || width < 3) {
      std::memset(d, cap8, sz(width));
      continue;
    }
    const int ya = y > 0 ? y - 1 : (height > 1 ? 1 : 0);
    const int yc = y < height - 1 ? y + 1 : (height > 1 ? height - 2 : 0);
    const std::uint8_t* a = src + sz(ya) * sz(width);
    const std::uint8_t* b = src + sz(y) * sz(width);
    const std::uint8_t* c = src + sz(yc) * sz(width);
    d[0] = cap8;
    d[width - 1] = cap8;
    for (int x = 1; x < width - 1; ++x) {
      const int v = (a[x + 1] - a[x - 1]) + 2 * (b[x + 1] - b[x - 1]) + (c[x + 1] - c[x - 1]);
      d[x] = static_cast<std::uint8_t>(std::clamp(v, -cap, cap) + cap);
    }
  }
}

void BlockMatcher::match(int width, int height, std::int16_t* disp) {
  const int nd = ndisp_, maxd = max_disp_, half = half_, bs = p_.block_size;
  const int cap = p_.prefilter_cap;
  std::fill(disp, disp + sz(width) * sz(height), filtered_);
  lr_rejected_ = 0;
  // StereoBM's valid window (getValidDisparityROI): full blocks in both images for every disparity.
  const int x_lo = maxd + half, x_hi = width - half;
  const int y_lo = half, y_hi = height - half;
  if (x_hi <= x_lo || y_hi <= y_lo) return;
  const int c0 = maxd;                 // left-image column of colsad column 0
  const int ncols = x_hi + half - c0;  // colsad columns
  const int nchunks = nd / kLanes;
  std::uint16_t* const cs = colsad_.data();
  std::int32_t* const tex = coltex_.data();
  std::uint16_t* const sad = sad_.data();
  const std::uint8_t* const L = pre_left_.data();
  const std::uint8_t* const R = pre_right_.data();
  const bool lr = p_.lr_max_diff >= 0;
  std::uint16_t* const rcost = rcost_.data();
  std::uint16_t* const rcol = rcol_.data();
  std::memset(cs, 0, sz(ncols) * sz(nd) * sizeof(std::uint16_t));
  std::fill(tex, tex + ncols, 0);

  // colsad[j][k] += |L(y, c0 + j) - R(y, c0 + j - maxd + k)| for row `ya`, minus the same for row `ys`
  // (if ys >= 0). Disparity index k stands for disparity maxd - k (StereoBM's order).
  const auto update = [&](int ya, int ys) {
    const std::uint8_t* la = L + sz(ya) * sz(width) + sz(c0);
    const std::uint8_t* ra = R + sz(ya) * sz(width);
    if (ys < 0) {
      for (int j = 0; j < ncols; ++j) {
        const U8 lv = U8{} + la[j];
        std::uint16_t* col = cs + sz(j) * sz(nd);
        const std::uint8_t* rr = ra + j;
        for (int k = 0; k < nd; k += kLanes) {
          const U8 rv = load<U8>(rr + k);
          const U8 dv = lv > rv ? lv - rv : rv - lv;
          store(col + k, load<U16>(col + k) + __builtin_convertvector(dv, U16));
        }
        tex[j] += std::abs(la[j] - cap);
      }
      return;
    }
    const std::uint8_t* ls = L + sz(ys) * sz(width) + sz(c0);
    const std::uint8_t* rs = R + sz(ys) * sz(width);
    for (int j = 0; j < ncols; ++j) {
      const U8 lv = U8{} + la[j];
      const U8 lw = U8{} + ls[j];
      std::uint16_t* col = cs + sz(j) * sz(nd);
      const std::uint8_t* rr = ra + j;
      const std::uint8_t* rq = rs + j;
      for (int k = 0; k < nd; k += kLanes) {
        const U8 rv = load<U8>(rr + k);
        const U8 dv = lv > rv ? lv - rv : rv - lv;
        const U8 qv = load<U8>(rq + k);
        const U8 dw = lw > qv ? lw - qv : qv - lw;
        store(col + k, load<U16>(col + k) + __builtin_convertvector(dv, U16) - __builtin_convertvector(dw, U16));
      }
      tex[j] += std::abs(la[j] - cap) - std::abs(ls[j] - cap);
    }
  };

  for (int y = 0; y < bs; ++y) update(y, -1);
  for (int y = y_lo; y < y_hi; ++y) {
    if (y > y_lo) update(y + half, y - half - 1);
    std::int16_t* drow = disp + sz(y) * sz(width);
    if (lr) {
      std::fill(rcost, rcost + width, std::numeric_limits<std::uint16_t>::max());
      std::fill(rcol, rcol + width, std::uint16_t{0});
    }
    // Block sums at the first valid column.
    std::memset(sad, 0, sz(nd) * sizeof(std::uint16_t));
    int tsum = 0;
    for (int j = 0; j < bs; ++j) {
      const std::uint16_t* col = cs + sz(j) * sz(nd);
      for (int k = 0; k < nd; k += kLanes) store(sad + k, load<U16>(sad + k) + load<U16>(col + k));
      tsum += tex[j];
    }
    for (int i = 0, x = x_lo; x < x_hi; ++i, ++x) {
      if (i > 0) {
        const std::uint16_t* cin = cs + sz(i + bs - 1) * sz(nd);
        const std::uint16_t* cout = cs + sz(i - 1) * sz(nd);
        for (int k = 0; k < nd; k += kLanes)
          store(sad + k, load<U16>(sad + k) + load<U16>(cin + k) - load<U16>(cout + k));
        tsum += tex[i + bs - 1] - tex[i - 1];
      }
      if (tsum < p_.texture_threshold) continue;
      if (lr) {
        // The right image's winner take all, from the same SAD vector: lane k is right column
        // x - maxd + k at disparity maxd - k; keep the least SAD per right column and where it came from.
        std::uint16_t* rc = rcost + (x - maxd);
        std::uint16_t* rx = rcol + (x - maxd);
        const U16 xv = U16{} + static_cast<std::uint16_t>(x);
        for (int k = 0; k < nd; k += kLanes) {
          const U16 s = load<U16>(sad + k);
          const U16 c = load<U16>(rc + k);
          const auto lt = s < c;
          store(rc + k, lt ? s : c);
          store(rx + k, lt ? xv : load<U16>(rx + k));
        }
      }
      // Winner take all: the smallest SAD, the first index (largest disparity) among equals.
      U16 mv = load<U16>(sad);
      U16 mi = U16{};
      for (int c = 1; c < nchunks; ++c) {
        const U16 v = load<U16>(sad + c * kLanes);
        const auto lt = v < mv;
        mv = lt ? v : mv;
        mi = lt ? U16{} + static_cast<std::uint16_t>(c) : mi;
      }
      int minsad = std::numeric_limits<int>::max();
      for (int l = 0; l < kLanes; ++l) minsad = std::min(minsad, static_cast<int>(mv[l]));
      int best = std::numeric_limits<int>::max();
      for (int l = 0; l < kLanes; ++l)
        if (mv[l] == minsad) best = std::min(best, static_cast<int>(mi[l]) * kLanes + l);
      if (p_.uniqueness_ratio > 0) {
        // Any SAD beyond best +- 1 within the ratio of the best rejects the pixel.
        const int thresh = minsad + minsad * p_.uniqueness_ratio / 100;
        const U16 tv = U16{} + static_cast<std::uint16_t>(std::min(thresh, 65535));
        S16 cnt = S16{};  // comparisons give -1 per true lane
        for (int k = 0; k < nd; k += kLanes) cnt -= load<U16>(sad + k) <= tv;
        int n = 0;
        for (int l = 0; l < kLanes; ++l) n += cnt[l];
        for (int k = std::max(best - 1, 0); k <= std::min(best + 1, nd - 1); ++k)
          if (sad[k] <= thresh) --n;
        if (n > 0) continue;
      }
      const int p = best + 1 < nd ? sad[best + 1] : sad[nd - 2];
      const int m = best > 0 ? sad[best - 1] : sad[1];
      const int dd = p + m - 2 * static_cast<int>(sad[best]) + std::abs(p - m);
      drow[x] = static_cast<std::int16_t>(((maxd - best) * 256 + (dd != 0 ? (p - m) * 256 / dd : 0) + 15) >> 4);
    }
    if (lr) {
      // SGBM's disp12MaxDiff test at the two integer disparities around the sub-pixel one.
      const int maxdiff = p_.lr_max_diff;
      const auto disagrees = [&](int xr, int d) {
        if (xr < 0 || xr >= width || rcol[xr] == 0) return false;
        return std::abs(static_cast<int>(rcol[xr]) - xr - d) > maxdiff;
      };
      for (int x = x_lo; x < x_hi; ++x) {
        const int d16 = drow[x];
        if (d16 == filtered_) continue;
        const int d_lo = d16 >> 4, d_hi = (d16 + 15) >> 4;
        if (disagrees(x - d_lo, d_lo) && disagrees(x - d_hi, d_hi)) {
          drow[x] = filtered_;
          ++lr_rejected_;
        }
      }
    }
  }
}

// cv::filterSpeckles: 4-connected regions of valid disparities whose neighbours differ by at most
// speckle_range * 16 are found by flood fill; regions of at most speckle_window pixels are invalidated.
void BlockMatcher::filter_speckles(std::int16_t* img, int width, int height) {
  const int invalid = filtered_;
  const int max_diff = p_.speckle_range * 16;
  const int max_size = p_.speckle_window;
  const std::size_t n = sz(width) * sz(height);
  std::uint32_t* labels = labels_.data();
  std::uint32_t* stack = stack_.data();
  std::fill(labels, labels + n, 0u);
  std::uint32_t current = 0;
  const auto w = static_cast<std::uint32_t>(width);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const std::size_t idx = sz(y) * sz(width) + sz(x);
      if (img[idx] == invalid) continue;
      if (labels[idx] != 0) {
        if (small_[labels[idx]] != 0) img[idx] = static_cast<std::int16_t>(invalid);
        continue;
      }
      ++current;
      labels[idx] = current;
      std::size_t top = 0;
      stack[top++] = static_cast<std::uint32_t>(idx);
      int count = 0;
      while (top > 0) {
        const std::uint32_t q = stack[--top];
        ++count;
        const std::uint32_t qy = q / w, qx = q - qy * w;
        const int dq = img[q];
        const auto visit = [&](std::uint32_t r) {
          if (labels[r] == 0 && img[r] != invalid && std::abs(dq - img[r]) <= max_diff) {
            labels[r] = current;
            stack[top++] = r;
          }
        };
        if (qy + 1 < static_cast<std::uint32_t>(height)) visit(q + w);
        if (qy > 0) visit(q - w);
        if (qx + 1 < w) visit(q + 1);
        if (qx > 0) visit(q - 1);
      }
      const bool is_small = count <= max_size;
      small_[current] = is_small ? 1 : 0;
      if (is_small) img[idx] = static_cast<std::int16_t>(invalid);
    }
  }
}

}  // namespace ag::mapping::detail
