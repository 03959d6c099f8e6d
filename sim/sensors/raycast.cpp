// Ray / 2.5D heightfield intersection: Amanatides-Woo cell traversal that skips max-pyramid blocks.
#include "airground/sim/raycast.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>
#include <stdexcept>
#include <string>
#include <type_traits>

namespace ag::sim {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr int kLevelShifts[] = {2, 3, 4, 5, 6};  // blocks of 4, 8, 16, 32 and 64 cells
constexpr int kNearSteps = 12;  // cells a `near` cast steps one by one before it tests blocks again

// floor() of a grid coordinate already known to lie near [lo, hi], as a clamped index.
std::int32_t floor_clamped(double x, std::int32_t lo, std::int32_t hi) noexcept {
  const double f = std::floor(std::clamp(x, static_cast<double>(lo), static_cast<double>(hi)));
  return static_cast<std::int32_t>(f);
}

}  // namespace

Eigen::Matrix3d rotation_of(const Pose3& pose) noexcept {
  return (Eigen::AngleAxisd(pose.yaw, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(pose.pitch, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(pose.roll, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

HeightfieldRaycaster::HeightfieldRaycaster(const World& world, RaycastOptions options) : grid_(world.grid()) {
  const auto w = grid_.width, h = grid_.height;
  if (w <= 0 || h <= 0 || !(grid_.resolution > 0.0) || !std::isfinite(grid_.resolution))
    throw std::invalid_argument("HeightfieldRaycaster: the world grid is empty or its resolution is not positive");
  const auto check = [&](const cv::Mat& m, const char* name) {
    if (m.type() != CV_32FC1 || m.rows != h || m.cols != w)
      throw std::invalid_argument(std::string("HeightfieldRaycaster: layer '") + name + "' must be CV_32FC1 of " +
                                  std::to_string(w) + "x" + std::to_string(h) + " cells");
  };
  check(world.height, "height");
  check(world.terrain, "terrain");

  const auto uw = static_cast<std::size_t>(w);
  surface_.resize(uw * static_cast<std::size_t>(h));
  max_surface_ = -std::numeric_limits<float>::infinity();
  min_surface_ = std::numeric_limits<float>::infinity();
  for (std::int32_t r = 0; r < h; ++r) {
    const float* hr = world.height.ptr<float>(r);
    const float* tr = world.terrain.ptr<float>(r);
    float* sr = surface_.data() + static_cast<std::size_t>(r) * uw;
    for (std::int32_t c = 0; c < w; ++c) {
      const float s = tr[c] + hr[c];  // the same float sum as World::surface_at
      if (!std::isfinite(s))
        throw std::invalid_argument("HeightfieldRaycaster: non-finite surface at cell (" + std::to_string(c) + ", " +
                                    std::to_string(r) + ")");
      sr[c] = s;
      max_surface_ = std::max(max_surface_, s);
      min_surface_ = std::min(min_surface_, s);
    }
  }

  if (!options.hierarchical) return;
  static_assert(std::size(kLevelShifts) == kMaxLevels);
  const auto build_levels = [&](const std::vector<float>& src, std::vector<Level>& out) {
    for (const int shift : kLevelShifts) {
      Level lv;
      lv.shift = shift;
      const std::int32_t side = std::int32_t{1} << shift;
      lv.width = (w + side - 1) >> shift;
      lv.height = (h + side - 1) >> shift;
      lv.max.assign(static_cast<std::size_t>(lv.width) * static_cast<std::size_t>(lv.height),
                    -std::numeric_limits<float>::infinity());
      for (std::int32_t r = 0; r < h; ++r) {
        const float* sr = src.data() + static_cast<std::size_t>(r) * uw;
        float* mr = lv.max.data() + static_cast<std::size_t>(r >> shift) * static_cast<std::size_t>(lv.width);
        for (std::int32_t c = 0; c < w; ++c) {
          float& m = mr[c >> shift];
          m = std::max(m, sr[c]);
        }
      }
      out.push_back(std::move(lv));
    }
  };
  build_levels(surface_, levels_);
  if (!options.fan_bounds) return;

  // 3x3 max, separably: rows first, then columns.
  std::vector<float> rowmax(surface_.size());
  for (std::int32_t r = 0; r < h; ++r) {
    const float* sr = surface_.data() + static_cast<std::size_t>(r) * uw;
    float* dr = rowmax.data() + static_cast<std::size_t>(r) * uw;
    for (std::int32_t c = 0; c < w; ++c) {
      float m = sr[c];
      if (c > 0) m = std::max(m, sr[c - 1]);
      if (c + 1 < w) m = std::max(m, sr[c + 1]);
      dr[c] = m;
    }
  }
  dilated_.resize(surface_.size());
  for (std::int32_t r = 0; r < h; ++r) {
    const float* a = rowmax.data() + static_cast<std::size_t>(std::max(r - 1, 0)) * uw;
    const float* b = rowmax.data() + static_cast<std::size_t>(r) * uw;
    const float* c = rowmax.data() + static_cast<std::size_t>(std::min(r + 1, h - 1)) * uw;
    float* d = dilated_.data() + static_cast<std::size_t>(r) * uw;
    for (std::size_t i = 0; i < uw; ++i) d[i] = std::max(a[i], std::max(b[i], c[i]));
  }
  build_levels(dilated_, dlevels_);
}

RayHit HeightfieldRaycaster::cast(const Eigen::Vector3d& origin, const Eigen::Vector3d& unit_dir,
                                  double max_range) const noexcept {
  return cast_impl(origin, unit_dir, max_range, 0.0, false);
}

RayHit HeightfieldRaycaster::cast_from(const Eigen::Vector3d& origin, const Eigen::Vector3d& unit_dir, double max_range,
                                       double t_start, bool near) const noexcept {
  return cast_impl(origin, unit_dir, max_range, t_start, near);
}

RayHit HeightfieldRaycaster::cast_impl(const Eigen::Vector3d& origin, const Eigen::Vector3d& unit_dir,
                                       double max_range, double t_start, bool near) const noexcept {
  RayHit out;
  const std::int32_t w = grid_.width, h = grid_.height;
  const double inv_res = 1.0 / grid_.resolution;
  // Grid coordinates: u along columns (east), v along rows (south), z up; all linear in t [m].
  const double u0 = (origin.x() - grid_.origin_x) * inv_res;
  const double v0 = (grid_.origin_y - origin.y()) * inv_res;
  const double z0 = origin.z();
  const double du = unit_dir.x() * inv_res;
  const double dv = -unit_dir.y() * inv_res;
  const double dz = unit_dir.z();
  if (!(max_range > 0.0) || !std::isfinite(u0 + v0 + z0 + du + dv + dz)) return out;
  const double wd = static_cast<double>(w), hd = static_cast<double>(h);
  // A zero component never reaches a boundary: its exit parameter is +inf (boundaries lie strictly ahead).
  const double idu = du != 0.0 ? 1.0 / du : kInf;
  const double idv = dv != 0.0 ? 1.0 / dv : kInf;

  // Clip to the world's box: the grid rectangle and, above, the highest column top.
  double t0 = 0.0, t1 = max_range;
  int axis = 0;  // how the current cell was entered: 0 from above or at the origin, 1 across u, 2 across v
  if (du != 0.0) {
    const double ta = ((du > 0.0 ? 0.0 : wd) - u0) * idu, tb = ((du > 0.0 ? wd : 0.0) - u0) * idu;
    if (ta > t0) {
      t0 = ta;
      axis = 1;
    }
    t1 = std::min(t1, tb);
  } else if (!(u0 >= 0.0 && u0 < wd)) {
    return out;
  }
  if (dv != 0.0) {
    const double ta = ((dv > 0.0 ? 0.0 : hd) - v0) * idv, tb = ((dv > 0.0 ? hd : 0.0) - v0) * idv;
    if (ta > t0) {
      t0 = ta;
      axis = 2;
    }
    t1 = std::min(t1, tb);
  } else if (!(v0 >= 0.0 && v0 < hd)) {
    return out;
  }
  const double zmax = static_cast<double>(max_surface_);
  if (dz > 0.0) {
    if (z0 > zmax) return out;
    t1 = std::min(t1, (zmax - z0) / dz);
  } else if (dz < 0.0) {
    if (z0 > zmax) {
      const double tz = (zmax - z0) / dz;
      if (tz > t0) {
        t0 = tz;
        axis = 0;
      }
    }
  } else if (z0 > zmax) {
    return out;
  }
  if (t_start > t0) {  // the caller vouches for [t0, t_start): start mid-air, as if entered from above
    t0 = t_start;
    axis = 0;
  }
  if (!(t0 <= t1)) return out;

  Ray ray{origin, unit_dir, u0, v0, z0, du, dv, dz, idu, idv, t0, t1, axis};
  bool stopped = false;
  // One traversal per sign of the horizontal direction: the stepping has no direction branches.
  const auto run = [&](auto pos_u, auto pos_v) noexcept {
    constexpr bool kU = decltype(pos_u)::value, kV = decltype(pos_v)::value;
    if (levels_.empty()) return traverse<kU, kV, 0>(ray, 0, stopped);
    if (near) {  // a few cells to go: plain cell stepping beats testing blocks on the way down...
      RayHit hit = traverse<kU, kV, 0>(ray, kNearSteps, stopped);
      if (!stopped) return hit;  // ...unless the ray only grazed something and flies on: blocks again
    }
    return traverse<kU, kV, kMaxLevels>(ray, 0, stopped);
  };
  using T = std::true_type;
  using F = std::false_type;
  if (du >= 0.0) return dv >= 0.0 ? run(T{}, T{}) : run(T{}, F{});
  return dv >= 0.0 ? run(F{}, T{}) : run(F{}, F{});
}

template <bool kPosU, bool kPosV, int kLevels>
RayHit HeightfieldRaycaster::traverse(Ray& ray, int max_steps, bool& stopped) const noexcept {
  RayHit out;
  const std::int32_t w = grid_.width, h = grid_.height;
  const double u0 = ray.u0, v0 = ray.v0, z0 = ray.z0, du = ray.du, dv = ray.dv, dz = ray.dz, t1 = ray.t1;
  const double idu = ray.idu, idv = ray.idv;
  int axis = ray.axis;
  std::int32_t ci = ray.ci >= 0 ? ray.ci : axis == 1 ? (kPosU ? 0 : w - 1) : floor_clamped(u0 + ray.t0 * du, 0, w - 1);
  std::int32_t cj = ray.cj >= 0 ? ray.cj : axis == 2 ? (kPosV ? 0 : h - 1) : floor_clamped(v0 + ray.t0 * dv, 0, h - 1);
  stopped = false;
  constexpr std::int32_t su = kPosU ? 1 : -1, sv = kPosV ? 1 : -1;

  const auto make_hit = [&](double th, int ax) noexcept {
    out.hit = true;
    out.range = th;
    out.point = ray.origin + th * ray.dir;
    out.col = ci;
    out.row = cj;
    out.vertical_face = ax != 0;
    if (ax == 1) out.normal = Eigen::Vector3d(kPosU ? -1.0 : 1.0, 0.0, 0.0);
    if (ax == 2) out.normal = Eigen::Vector3d(0.0, kPosV ? 1.0 : -1.0, 0.0);  // +v is south
    return out;
  };

  // Blocks the ray was found to dip into; re-tested only once it has left them.
  std::int32_t dip_bx[kMaxLevels], dip_by[kMaxLevels];
  std::fill(std::begin(dip_bx), std::end(dip_bx), -1);
  std::fill(std::begin(dip_by), std::end(dip_by), -1);
  double t = ray.t0;

  for (;;) {
    bool skipped = false;
    for (int l = kLevels - 1; l >= 0; --l) {  // unrolled: the block sizes are constants
      const Level& lv = levels_[static_cast<std::size_t>(l)];
      const int shift = kLevelShifts[l];
      const std::int32_t bx = ci >> shift, by = cj >> shift;
      if (bx == dip_bx[l] && by == dip_by[l]) continue;
      const std::int32_t side = std::int32_t{1} << shift;
      const std::int32_t bu = bx << shift, bv = by << shift;
      const double tu = (static_cast<double>(kPosU ? bu + side : bu) - u0) * idu;
      const double tv = (static_cast<double>(kPosV ? bv + side : bv) - v0) * idv;
      const double te = std::max(t, std::min(tu, tv));  // never -0 at a start on a boundary
      const double zlow = z0 + std::min(t * dz, std::min(te, t1) * dz);  // lowest point inside the block
      if (zlow > static_cast<double>(lv.max[static_cast<std::size_t>(by) * static_cast<std::size_t>(lv.width) +
                                            static_cast<std::size_t>(bx)])) {
        if (te >= t1) return out;
        // Leave the block across the face reached first; the index along the other axis is clamped into
        // the block and kept monotone. Selected without branches: which face comes first is a coin toss.
        const bool across_u = tu <= tv;
        std::int32_t ni = floor_clamped(u0 + te * du, bu, bu + side - 1);
        std::int32_t nj = floor_clamped(v0 + te * dv, bv, bv + side - 1);
        ni = kPosU ? std::max(ni, ci) : std::min(ni, ci);
        nj = kPosV ? std::max(nj, cj) : std::min(nj, cj);
        ci = across_u ? (kPosU ? bu + side : bu - 1) : ni;
        cj = across_u ? nj : (kPosV ? bv + side : bv - 1);
        axis = across_u ? 1 : 2;
        t = te;
        skipped = true;
        break;
      }
      dip_bx[l] = bx;
      dip_by[l] = by;
    }
    if (skipped) {
      if (ci < 0 || cj < 0 || ci >= w || cj >= h) return out;
      continue;
    }

    if (kLevels == 0 && max_steps > 0 && --max_steps == 0) {  // the cell (ci, cj) entered at t is still to test
      stopped = true;
      ray.t0 = t;
      ray.axis = axis;
      ray.ci = ci;
      ray.cj = cj;
      return out;
    }
    const double s = static_cast<double>(surface_[static_cast<std::size_t>(cj) * static_cast<std::size_t>(w) +
                                                  static_cast<std::size_t>(ci)]);
    if (z0 + t * dz <= s) return make_hit(t, axis);  // entered through a side (a wall), or started inside
    const double tu = (static_cast<double>(kPosU ? ci + 1 : ci) - u0) * idu;
    const double tv = (static_cast<double>(kPosV ? cj + 1 : cj) - v0) * idv;
    const double te = std::max(t, std::min(tu, tv));  // never -0 at a start on a boundary
    if (dz < 0.0) {
      const double tl = std::min(te, t1);
      if (z0 + tl * dz <= s) return make_hit(std::clamp((s - z0) / dz, t, tl), 0);  // through the top
    }
    if (te >= t1) return out;
    const bool across_u = tu <= tv;
    ci += across_u ? su : 0;
    cj += across_u ? 0 : sv;
    axis = across_u ? 1 : 2;
    t = te;
    if (ci < 0 || cj < 0 || ci >= w || cj >= h) return out;
  }
}

bool HeightfieldRaycaster::fan_free_bounds(const Eigen::Vector3d& origin, double cu, double cv, double s_stop,
                                           FanBeam* beams, int n, double& walked) const noexcept {
  walked = 0.0;
  for (int i = 0; i < n; ++i) beams[i].bound = 0.0, beams[i].blocked = false;
  if (dilated_.empty() || n <= 0) return false;
  const double inv_res = 1.0 / grid_.resolution;
  const double u0 = (origin.x() - grid_.origin_x) * inv_res;
  const double v0 = (grid_.origin_y - origin.y()) * inv_res;
  const double z0 = origin.z();
  if (!std::isfinite(u0 + v0 + z0 + cu + cv + s_stop)) return false;
  // Outside the grid the centre line's cells do not exist, while a beam beside it may be inside.
  if (!(u0 >= 0.0 && v0 >= 0.0 && u0 < static_cast<double>(grid_.width) && v0 < static_cast<double>(grid_.height)))
    return false;
  if (cu >= 0.0) {
    if (cv >= 0.0) fan_walk<true, true>(u0, v0, z0, cu, cv, s_stop, beams, n, walked);
    else fan_walk<true, false>(u0, v0, z0, cu, cv, s_stop, beams, n, walked);
  } else {
    if (cv >= 0.0) fan_walk<false, true>(u0, v0, z0, cu, cv, s_stop, beams, n, walked);
    else fan_walk<false, false>(u0, v0, z0, cu, cv, s_stop, beams, n, walked);
  }
  return true;
}

// The centre line's cells are visited as in traverse(), against the dilated surface: a beam whose line
// stays within one cell of the centre line meets, at horizontal distance s, a cell no higher than the
// dilated value of the centre cell at s. The beams share the origin, so at any s >= 0 a steeper beam is
// higher: the beams still unbounded are always the steepest ones, and the lowest of them decides.
template <bool kPosU, bool kPosV>
void HeightfieldRaycaster::fan_walk(double u0, double v0, double z0, double cu, double cv, double s_stop,
                                    FanBeam* beams, int n, double& walked) const noexcept {
  constexpr double kEps = 1e-6;  // [m] height margin: rounding can only make a bound shorter
  const std::int32_t w = grid_.width, h = grid_.height;
  const double icu = cu != 0.0 ? 1.0 / cu : kInf;
  const double icv = cv != 0.0 ? 1.0 / cv : kInf;
  const double zmax = static_cast<double>(max_surface_);
  constexpr std::int32_t su = kPosU ? 1 : -1, sv = kPosV ? 1 : -1;
  std::int32_t ci = floor_clamped(u0, 0, w - 1), cj = floor_clamped(v0, 0, h - 1);
  for (int i = 0; i < n; ++i) beams[i].bound = kInf;
  int next = 0;
  double s = 0.0;
  // Beams left unbounded when the walk ends early were checked up to s.
  const auto stop_at = [&](double s_end) noexcept {
    walked = s_end;
    for (int i = next; i < n; ++i) beams[i].bound = s_end;
  };
  const auto zlow = [&](double m, double a, double b) noexcept { return z0 + std::min(m * a, m * b); };

  std::int32_t dip_bx[kMaxLevels], dip_by[kMaxLevels];
  std::fill(std::begin(dip_bx), std::end(dip_bx), -1);
  std::fill(std::begin(dip_by), std::end(dip_by), -1);
  for (;;) {
    if (next == n) {
      walked = s;
      return;
    }
    const double m = beams[next].slope;
    if (m >= 0.0 && z0 + m * s > zmax + kEps) {  // every beam left rises above the highest surface from here
      walked = s;
      return;
    }
    if (s >= s_stop) return stop_at(s);
    bool skipped = false;
    for (int l = kMaxLevels - 1; l >= 0; --l) {
      const Level& lv = dlevels_[static_cast<std::size_t>(l)];
      const int shift = kLevelShifts[l];
      const std::int32_t bx = ci >> shift, by = cj >> shift;
      if (bx == dip_bx[l] && by == dip_by[l]) continue;
      const std::int32_t side = std::int32_t{1} << shift;
      const std::int32_t bu = bx << shift, bv = by << shift;
      const double tu = (static_cast<double>(kPosU ? bu + side : bu) - u0) * icu;
      const double tv = (static_cast<double>(kPosV ? bv + side : bv) - v0) * icv;
      const double te = std::max(s, std::min(tu, tv));
      if (zlow(m, s, std::min(te, s_stop)) >
          static_cast<double>(lv.max[static_cast<std::size_t>(by) * static_cast<std::size_t>(lv.width) +
                                     static_cast<std::size_t>(bx)]) + kEps) {
        if (te >= s_stop) return stop_at(s_stop);
        const bool across_u = tu <= tv;
        std::int32_t ni = floor_clamped(u0 + te * cu, bu, bu + side - 1);
        std::int32_t nj = floor_clamped(v0 + te * cv, bv, bv + side - 1);
        ni = kPosU ? std::max(ni, ci) : std::min(ni, ci);
        nj = kPosV ? std::max(nj, cj) : std::min(nj, cj);
        ci = across_u ? (kPosU ? bu + side : bu - 1) : ni;
        cj = across_u ? nj : (kPosV ? bv + side : bv - 1);
        s = te;
        skipped = true;
        break;
      }
      dip_bx[l] = bx;
      dip_by[l] = by;
    }
    if (skipped) {
      if (ci < 0 || cj < 0 || ci >= w || cj >= h) return stop_at(s);
      continue;
    }

    const double top = static_cast<double>(dilated_[static_cast<std::size_t>(cj) * static_cast<std::size_t>(w) +
                                                    static_cast<std::size_t>(ci)]) + kEps;
    const double tu = (static_cast<double>(kPosU ? ci + 1 : ci) - u0) * icu;
    const double tv = (static_cast<double>(kPosV ? cj + 1 : cj) - v0) * icv;
    const double te = std::max(s, std::min(tu, tv));
    const double so = std::min(te, s_stop);
    const int before = next;
    while (next < n && zlow(beams[next].slope, s, so) <= top) {
      beams[next].bound = s;
      beams[next++].blocked = true;
    }
    if (next == n) continue;
    if (next != before) {  // a higher beam decides now: blocks the last one dipped into may be skipped
      std::fill(std::begin(dip_bx), std::end(dip_bx), -1);
      std::fill(std::begin(dip_by), std::end(dip_by), -1);
    }
    if (te >= s_stop) return stop_at(s_stop);
    const bool across_u = tu <= tv;
    ci += across_u ? su : 0;
    cj += across_u ? 0 : sv;
    s = te;
    if (ci < 0 || cj < 0 || ci >= w || cj >= h) return stop_at(s);
  }
}

float HeightfieldRaycaster::max_surface_in(std::int32_t c0, std::int32_t r0, std::int32_t c1, std::int32_t r1) const noexcept {
  c0 = std::max(c0, 0);
  r0 = std::max(r0, 0);
  c1 = std::min(c1, grid_.width - 1);
  r1 = std::min(r1, grid_.height - 1);
  float m = -std::numeric_limits<float>::infinity();
  if (c0 > c1 || r0 > r1) return m;
  constexpr std::int64_t kReads = 64;
  if (levels_.empty() || static_cast<std::int64_t>(c1 - c0 + 1) * (r1 - r0 + 1) <= kReads) {
    for (std::int32_t r = r0; r <= r1; ++r)
      for (std::int32_t c = c0; c <= c1; ++c) m = std::max(m, surface(c, r));
    return m;
  }
  std::size_t l = 0;
  while (l + 1 < levels_.size()) {
    const int sh = levels_[l].shift;
    if (static_cast<std::int64_t>((c1 >> sh) - (c0 >> sh) + 1) * ((r1 >> sh) - (r0 >> sh) + 1) <= kReads) break;
    ++l;
  }
  const Level& lv = levels_[l];
  for (std::int32_t by = r0 >> lv.shift; by <= r1 >> lv.shift; ++by) {
    const float* row = lv.max.data() + static_cast<std::size_t>(by) * static_cast<std::size_t>(lv.width);
    for (std::int32_t bx = c0 >> lv.shift; bx <= c1 >> lv.shift; ++bx) m = std::max(m, row[bx]);
  }
  return m;
}

std::shared_ptr<const HeightfieldRaycaster> raycaster_for(const World& world,
                                                          std::shared_ptr<const HeightfieldRaycaster> shared,
                                                          const char* who) {
  if (!shared) return std::make_shared<const HeightfieldRaycaster>(world);
  const GridGeometry& g = world.grid();
  const GridGeometry& r = shared->grid();
  if (r.width != g.width || r.height != g.height || r.resolution != g.resolution || r.origin_x != g.origin_x ||
      r.origin_y != g.origin_y)
    throw std::invalid_argument(std::string(who) + ": the shared raycaster was built for another world");
  return shared;
}

}  // namespace ag::sim
