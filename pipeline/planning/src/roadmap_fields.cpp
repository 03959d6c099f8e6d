// Roadmap fields (traversable, closed, clearance, free) and the line walk over them.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include "airground/planning/roadmap.hpp"

namespace ag::plan {

namespace {
constexpr float kFar = 1e9F;
}  // namespace

void Roadmap::recompute_closed(Rect out) noexcept {
  out = clamp(out);
  if (close_r_ == 0) {
    for (std::int32_t y = out.y0; y < out.y1; ++y)
      for (std::int32_t x = out.x0; x < out.x1; ++x) closed_[idx(x, y)] = trav_[idx(x, y)];
    return;
  }
  const Rect d = clamp(out.grown(close_r_));
  for (std::int32_t y = d.y0; y < d.y1; ++y)
    for (std::int32_t x = d.x0; x < d.x1; ++x) {
      std::uint8_t any = 0;
      for (std::int32_t yy = std::max(0, y - close_r_); yy <= std::min(h_ - 1, y + close_r_) && any == 0; ++yy)
        for (std::int32_t xx = std::max(0, x - close_r_); xx <= std::min(w_ - 1, x + close_r_); ++xx)
          if (trav_[idx(xx, yy)] != 0) {
            any = 1;
            break;
          }
      dil_[idx(x, y)] = any;
    }
  for (std::int32_t y = out.y0; y < out.y1; ++y)
    for (std::int32_t x = out.x0; x < out.x1; ++x) {
      const std::size_t k = idx(x, y);
      if (trav_[k] != 0) {
        closed_[k] = 1;
        continue;
      }
      std::uint8_t all = mark_[k] == 0 ? fillable_[cls_[k]] : 0;  // a blocked disc is never filled
      for (std::int32_t yy = y - close_r_; yy <= y + close_r_ && all != 0; ++yy)
        for (std::int32_t xx = x - close_r_; xx <= x + close_r_; ++xx)
          if (!inside(xx, yy) || dil_[idx(xx, yy)] == 0) {
            all = 0;
            break;
          }
      closed_[k] = in_fence(x, y) ? all : 0;  // a hole is never closed across the fence
    }
}

// Exact Euclidean distance to the nearest blocked cell centre (outside the extent is blocked), capped:
// column distances over the output rows, then Felzenszwalb-Huttenlocher lower envelopes along rows.
void Roadmap::recompute_clearance(Rect out) noexcept {
  out = clamp(out);
  if (out.x1 <= out.x0 || out.y1 <= out.y0) return;
  const std::int32_t m = cap_cells_ + 1;
  const std::int32_t ix0 = out.x0 - m, ix1 = out.x1 + m, iw = ix1 - ix0;
  const std::int32_t iy0 = out.y0 - m, iy1 = out.y1 + m;
  const std::int32_t far = m + 1;
  auto blocked = [&](std::int32_t x, std::int32_t y) { return !inside(x, y) || closed_[idx(x, y)] == 0; };
  // column pass: g[(y - out.y0) * iw + (x - ix0)] = vertical distance to a blocked cell, capped at far
  for (std::int32_t x = ix0; x < ix1; ++x) {
    std::int32_t last = iy0 - far;  // row of the last blocked cell seen going up
    for (std::int32_t y = iy0; y < out.y1; ++y) {
      if (blocked(x, y)) last = y;
      if (y >= out.y0) col_g_[static_cast<std::size_t>(y - out.y0) * static_cast<std::size_t>(iw) + static_cast<std::size_t>(x - ix0)] =
          static_cast<std::uint8_t>(std::min(far, y - last));
    }
    last = iy1 + far;
    for (std::int32_t y = iy1 - 1; y >= out.y0; --y) {
      if (blocked(x, y)) last = y;
      if (y < out.y1) {
        std::uint8_t& g = col_g_[static_cast<std::size_t>(y - out.y0) * static_cast<std::size_t>(iw) + static_cast<std::size_t>(x - ix0)];
        g = static_cast<std::uint8_t>(std::min<std::int32_t>(g, std::min(far, last - y)));
      }
    }
  }
  // row pass: every input column is a parabola (at `far` where no blocked cell is near)
  const auto cap = static_cast<float>(cap_cells_);
  for (std::int32_t y = out.y0; y < out.y1; ++y) {
    const std::uint8_t* g = &col_g_[static_cast<std::size_t>(y - out.y0) * static_cast<std::size_t>(iw)];
    dt::squared_distance_line(
        iw, [](std::int32_t) { return true; }, [&](std::int32_t q) { return static_cast<float>(g[q] * g[q]); }, out.x0 - ix0,
        out.x1 - ix0, envelope_, [&](std::int32_t q, float d2) {
          const std::size_t i = idx(q + ix0, y);
          const float d = closed_[i] == 0 ? 0.0F : std::min(cap, std::sqrt(d2));
          edt_[i] = d;
          free_[i] = (closed_[i] != 0 && d >= free_min_edt_ - 1e-4F) ? 1 : 0;
        });
  }
}

void Roadmap::recompute_fields(Rect changed) noexcept {
  const Rect q = clamp(changed.grown(2 * close_r_));
  recompute_closed(q);
  recompute_clearance(q.grown(cap_cells_ + 1));
}
bool Roadmap::walk(double x0, double y0, double x1, double y1, float* min_clear, std::uint32_t* costly) const noexcept {
  std::int32_t c = static_cast<std::int32_t>(std::floor(x0)), r = static_cast<std::int32_t>(std::floor(y0));
  const std::int32_t ce = static_cast<std::int32_t>(std::floor(x1)), re = static_cast<std::int32_t>(std::floor(y1));
  const double dx = x1 - x0, dy = y1 - y0;
  const std::int32_t sx = dx > 0 ? 1 : -1, sy = dy > 0 ? 1 : -1;
  const double adx = std::fabs(dx), ady = std::fabs(dy);
  constexpr double kInf = std::numeric_limits<double>::infinity();
  double tmx = adx > 0 ? (sx > 0 ? (c + 1 - x0) : (x0 - c)) / adx : kInf;
  double tmy = ady > 0 ? (sy > 0 ? (r + 1 - y0) : (y0 - r)) / ady : kInf;
  const double tdx = adx > 0 ? 1.0 / adx : kInf, tdy = ady > 0 ? 1.0 / ady : kInf;
  float mc = kFar;
  std::uint32_t nc = 0;
  auto check = [&](std::int32_t cc, std::int32_t rr) {
    if (!inside(cc, rr)) return false;
    const std::size_t i = idx(cc, rr);
    if (free_[i] == 0) return false;
    mc = std::min(mc, edt_[i]);
    nc += costly_cell(i) ? 1U : 0U;
    return true;
  };
  if (!check(c, r)) return false;
  std::int32_t guard = std::abs(ce - c) + std::abs(re - r) + 2;
  while ((c != ce || r != re) && guard-- > 0) {
    const bool can_x = c != ce, can_y = r != re;
    if (can_x && can_y && std::fabs(tmx - tmy) < 1e-9) {
      if (!check(c + sx, r) || !check(c, r + sy)) return false;
      c += sx;
      r += sy;
      tmx += tdx;
      tmy += tdy;
    } else if (can_x && (!can_y || tmx < tmy)) {
      c += sx;
      tmx += tdx;
    } else {
      r += sy;
      tmy += tdy;
    }
    if (!check(c, r)) return false;
  }
  if (min_clear != nullptr) *min_clear = mc;
  if (costly != nullptr) *costly = nc;
  return true;
}

bool Roadmap::line_free(Point2 a, Point2 b, double* min_clearance_m) const noexcept {
  const double res = p_.resolution_m;
  float mc = 0;
  const bool ok = walk((a.x - ox_) / res, (a.y - oy_) / res, (b.x - ox_) / res, (b.y - oy_) / res, &mc, nullptr);
  if (ok && min_clearance_m != nullptr) *min_clearance_m = (static_cast<double>(mc) - 0.5) * res;
  return ok;
}

}  // namespace ag::plan
