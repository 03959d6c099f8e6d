// A synthetic semantic world for the localization tests and benchmark: a seeded class map (an irregular
// road grid with buildings, trees, parked vehicles, dirt, grass and a pond) with obstacle heights, a
// height-field ray caster that makes organised labelled LiDAR scans of it, robot routes along its roads
// and noisy odometry. No simulator headers: the filter tests run in the aarch64 cross build too.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include "airground/messages/classes.hpp"
#include "airground/messages/geometry.hpp"
#include "airground/localization/class_distance_fields.hpp"
#include "airground/localization/fused_pose.hpp"
#include "airground/localization/scan.hpp"
#include "airground/platform/time.hpp"

namespace ag::loc::test {

// The aarch64 build runs its unit tests under qemu-user (some 40 times slower): the scenario tests use a
// sparser LiDAR and shorter routes there, and check the same properties.
#if defined(__aarch64__)
inline constexpr bool kSlowTarget = true;
#else
inline constexpr bool kSlowTarget = false;
#endif

struct TestRng {
  std::uint64_t s;
  explicit TestRng(std::uint64_t seed) : s(seed * 0x9E3779B97F4A7C15ULL + 0x1234567ULL) {}
  std::uint64_t next() {
    std::uint64_t z = (s += 0x9E3779B97F4A7C15ULL);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
  }
  double uniform() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }
  double uniform(double a, double b) { return a + (b - a) * uniform(); }
  double normal() {
    double u = uniform();
    while (u <= 0.0) u = uniform();
    return std::sqrt(-2.0 * std::log(u)) * std::cos(2.0 * kPi * uniform());
  }
};

// Cells of `resolution` metres, row 0 at the south edge, cell (0, 0) at the map-frame origin (so the
// map's tiles are the ortho-map's tiles 0..tiles-1).
struct SyntheticWorld {
  double resolution{0.5};
  int tile_cells{64};
  int width{0}, height{0};
  std::vector<std::uint8_t> cls;
  std::vector<float> top;           // [m] obstacle top above the ground, 0 for ground classes
  std::vector<double> road_x, road_y;  // [m] centre lines of the north-south and east-west roads
  float max_top{0};                 // [m] the tallest obstacle

  [[nodiscard]] bool inside(int c, int r) const { return c >= 0 && r >= 0 && c < width && r < height; }
  [[nodiscard]] std::size_t index(int c, int r) const {
    return static_cast<std::size_t>(r) * static_cast<std::size_t>(width) + static_cast<std::size_t>(c);
  }
  [[nodiscard]] std::uint8_t class_at(double x, double y) const {
    const int c = static_cast<int>(std::floor(x / resolution)), r = static_cast<int>(std::floor(y / resolution));
    return inside(c, r) ? cls[index(c, r)] : std::uint8_t{255};
  }
  void fill_rect(double x0, double y0, double x1, double y1, ClassId id, float h, bool only_on_grass = false) {
    const int c0 = std::max(0, static_cast<int>(std::floor(x0 / resolution)));
    const int c1 = std::min(width, static_cast<int>(std::ceil(x1 / resolution)));
    const int r0 = std::max(0, static_cast<int>(std::floor(y0 / resolution)));
    const int r1 = std::min(height, static_cast<int>(std::ceil(y1 / resolution)));
    for (int r = r0; r < r1; ++r)
      for (int c = c0; c < c1; ++c) {
        const std::size_t i = index(c, r);
        if (only_on_grass && cls[i] != raw(ClassId::kGrass)) continue;
        cls[i] = raw(id);
        top[i] = h;
        max_top = std::max(max_top, h);
      }
  }
  void fill_disc(double cx, double cy, double radius, ClassId id, float h, bool only_on_grass) {
    const int c0 = std::max(0, static_cast<int>(std::floor((cx - radius) / resolution)));
    const int c1 = std::min(width, static_cast<int>(std::ceil((cx + radius) / resolution)));
    const int r0 = std::max(0, static_cast<int>(std::floor((cy - radius) / resolution)));
    const int r1 = std::min(height, static_cast<int>(std::ceil((cy + radius) / resolution)));
    for (int r = r0; r < r1; ++r)
      for (int c = c0; c < c1; ++c) {
        const double x = (c + 0.5) * resolution - cx, y = (r + 0.5) * resolution - cy;
        if (x * x + y * y > radius * radius) continue;
        const std::size_t i = index(c, r);
        if (only_on_grass && cls[i] != raw(ClassId::kGrass)) continue;
        cls[i] = raw(id);
        top[i] = h;
        max_top = std::max(max_top, h);
      }
  }
  // One tile's class ids in ortho-map order (row 0 = south).
  [[nodiscard]] std::vector<std::uint8_t> tile(int tx, int ty) const {
    std::vector<std::uint8_t> t(static_cast<std::size_t>(tile_cells * tile_cells), 255);
    for (int r = 0; r < tile_cells; ++r)
      for (int c = 0; c < tile_cells; ++c) {
        const int gc = tx * tile_cells + c, gr = ty * tile_cells + r;
        if (inside(gc, gr)) t[static_cast<std::size_t>(r * tile_cells + c)] = cls[index(gc, gr)];
      }
    return t;
  }
  [[nodiscard]] int tiles_x() const { return (width + tile_cells - 1) / tile_cells; }
  [[nodiscard]] int tiles_y() const { return (height + tile_cells - 1) / tile_cells; }
  [[nodiscard]] TileExtent extent() const { return TileExtent{0, 0, tiles_x(), tiles_y()}; }
};

inline SyntheticWorld make_world(int tiles_x, int tiles_y, std::uint64_t seed) {
  SyntheticWorld w;
  w.width = tiles_x * w.tile_cells;
  w.height = tiles_y * w.tile_cells;
  const std::size_t n = static_cast<std::size_t>(w.width) * static_cast<std::size_t>(w.height);
  w.cls.assign(n, raw(ClassId::kGrass));
  w.top.assign(n, 0.0F);
  TestRng rng(seed);
  const double sx = w.width * w.resolution, sy = w.height * w.resolution;
  for (double x = rng.uniform(15, 30); x < sx - 15; x += rng.uniform(45, 80)) w.road_x.push_back(x);
  for (double y = rng.uniform(15, 30); y < sy - 15; y += rng.uniform(45, 80)) w.road_y.push_back(y);
  std::vector<double> half_x, half_y;
  for (double x : w.road_x) {
    const double hw = rng.uniform(3.0, 4.5);
    half_x.push_back(hw);
    w.fill_rect(x - hw, 0, x + hw, sy, ClassId::kRoad, 0.0F);
  }
  for (double y : w.road_y) {
    const double hw = rng.uniform(3.0, 4.5);
    half_y.push_back(hw);
    w.fill_rect(0, y - hw, sx, y + hw, ClassId::kRoad, 0.0F);
  }
  // Blocks between the roads: dirt yards, buildings set back from the roads, trees, a pond.
  std::vector<double> xs{0.0}, ys{0.0};
  for (std::size_t i = 0; i < w.road_x.size(); ++i) {
    xs.push_back(w.road_x[i] - half_x[i]);
    xs.push_back(w.road_x[i] + half_x[i]);
  }
  xs.push_back(sx);
  for (std::size_t i = 0; i < w.road_y.size(); ++i) {
    ys.push_back(w.road_y[i] - half_y[i]);
    ys.push_back(w.road_y[i] + half_y[i]);
  }
  ys.push_back(sy);
  bool pond = false;
  for (std::size_t bi = 0; bi + 1 < xs.size(); bi += 2)
    for (std::size_t bj = 0; bj + 1 < ys.size(); bj += 2) {
      const double x0 = xs[bi] + 2.0, x1 = xs[bi + 1] - 2.0, y0 = ys[bj] + 2.0, y1 = ys[bj + 1] - 2.0;
      if (x1 - x0 < 10 || y1 - y0 < 10) continue;
      if (rng.uniform() < 0.35) {
        const double dx = rng.uniform(x0, x1 - 6), dy = rng.uniform(y0, y1 - 6);
        w.fill_rect(dx, dy, dx + rng.uniform(6, 15), dy + rng.uniform(6, 15), ClassId::kDirt, 0.0F);
      }
      if (!pond && rng.uniform() < 0.2 && x1 - x0 > 30 && y1 - y0 > 30) {
        pond = true;
        w.fill_disc(0.5 * (x0 + x1), 0.5 * (y0 + y1), 7.0, ClassId::kWater, 0.0F, false);
      }
      const int buildings = 1 + static_cast<int>(rng.uniform() * 4.0);
      for (int b = 0; b < buildings; ++b) {
        const double bw = rng.uniform(7, 22), bh = rng.uniform(7, 22);
        if (x1 - x0 < bw + 4 || y1 - y0 < bh + 4) continue;
        const double bx = rng.uniform(x0 + 2, x1 - 2 - bw), by = rng.uniform(y0 + 2, y1 - 2 - bh);
        w.fill_rect(bx, by, bx + bw, by + bh, ClassId::kBuilding, static_cast<float>(rng.uniform(4, 14)));
      }
      const int trees = static_cast<int>((x1 - x0) * (y1 - y0) / 350.0);
      for (int t = 0; t < trees; ++t)
        w.fill_disc(rng.uniform(x0, x1), rng.uniform(y0, y1), rng.uniform(1.5, 3.5), ClassId::kTree,
                    static_cast<float>(rng.uniform(4, 9)), true);
    }
  // Parked vehicles along the road edges.
  for (std::size_t i = 0; i < w.road_x.size(); ++i)
    for (double y = rng.uniform(5, 40); y < sy - 5; y += rng.uniform(25, 70)) {
      const double x = w.road_x[i] + (rng.uniform() < 0.5 ? -1.0 : 1.0) * (half_x[i] - 1.2);
      w.fill_rect(x - 1.0, y - 2.25, x + 1.0, y + 2.25, ClassId::kVehicle, 1.6F);
    }
  for (std::size_t i = 0; i < w.road_y.size(); ++i)
    for (double x = rng.uniform(5, 40); x < sx - 5; x += rng.uniform(25, 70)) {
      const double y = w.road_y[i] + (rng.uniform() < 0.5 ? -1.0 : 1.0) * (half_y[i] - 1.2);
      w.fill_rect(x - 2.25, y - 1.0, x + 2.25, y + 1.0, ClassId::kVehicle, 1.6F);
    }
  // Keep the crossings clear of vehicles (routes turn there).
  for (double x : w.road_x)
    for (double y : w.road_y) w.fill_rect(x - 5, y - 5, x + 5, y + 5, ClassId::kRoad, 0.0F);
  return w;
}

// Loads every tile of the world into the fields (version 1) and recomputes them.
inline void load_world(const SyntheticWorld& w, ClassDistanceFields& f, std::uint64_t version = 1) {
  for (int ty = 0; ty < w.tiles_y(); ++ty)
    for (int tx = 0; tx < w.tiles_x(); ++tx) {
      const std::vector<std::uint8_t> t = w.tile(tx, ty);
      f.set_tile(tx, ty, version, t);
    }
  f.recompute_all();
}

struct LidarModel {
  int rings{kSlowTarget ? 16 : 32};
  int columns{kSlowTarget ? 256 : 512};
  double top_deg{16.6}, bottom_deg{-16.6};  // OS-1: 33.2 deg vertical field of view
  double sensor_height_m{0.7};
  double max_range_m{100.0};
  double range_sigma_m{0.02};
};

// An organised scan of the world from the robot pose `body` (sensor on the body origin at sensor_height):
// ring 0 is the top beam, columns sweep CCW from forward; labels are the ground-truth classes; no return
// from water, the sky or beyond the map.
inline void ray_cast(const SyntheticWorld& w, const Pose2& body, const LidarModel& m, std::uint64_t seed,
                     std::vector<ScanPoint>& out) {
  out.clear();
  TestRng rng(seed);
  const double res = w.resolution;
  for (int col = 0; col < m.columns; ++col) {
    const double az = 2.0 * kPi * col / m.columns;
    const double dx = std::cos(body.yaw + az), dy = std::sin(body.yaw + az);
    for (int ring = 0; ring < m.rings; ++ring) {
      const double alt = (m.top_deg + (m.bottom_deg - m.top_deg) * ring / std::max(1, m.rings - 1)) * kPi / 180.0;
      const double slope = std::tan(alt), t_max = m.max_range_m * std::cos(alt);
      // DDA over the cells along the horizontal ray; t is the horizontal distance
      int c = static_cast<int>(std::floor(body.x / res)), r = static_cast<int>(std::floor(body.y / res));
      const int step_c = dx > 0 ? 1 : -1, step_r = dy > 0 ? 1 : -1;
      const double inv_dx = std::fabs(dx) > 1e-12 ? 1.0 / std::fabs(dx) : 1e30;
      const double inv_dy = std::fabs(dy) > 1e-12 ? 1.0 / std::fabs(dy) : 1e30;
      double t_next_c = ((dx > 0 ? (c + 1) * res : c * res) - body.x) * (dx > 0 ? inv_dx : -inv_dx);
      double t_next_r = ((dy > 0 ? (r + 1) * res : r * res) - body.y) * (dy > 0 ? inv_dy : -inv_dy);
      if (dx == 0.0) t_next_c = 1e30;
      if (dy == 0.0) t_next_r = 1e30;
      double t_in = 0.0, hit_t = -1.0;
      std::uint8_t hit_cls = 255;
      const double t_sky = slope > 0.0 ? (static_cast<double>(w.max_top) - m.sensor_height_m) / slope : 1e30;  // above everything
      while (t_in < t_max && t_in <= t_sky && w.inside(c, r)) {
        const double t_out = std::min({t_next_c, t_next_r, t_max});
        const std::size_t i = w.index(c, r);
        const double h = w.top[i];
        const double z_in = m.sensor_height_m + slope * t_in, z_out = m.sensor_height_m + slope * t_out;
        if (h > 0.0 && t_in > 0.0 && z_in <= h) {
          hit_t = t_in;  // a wall
          hit_cls = w.cls[i];
          break;
        }
        if (h > 0.0 && z_out <= h) {
          hit_t = t_in > 0.0 ? (h - m.sensor_height_m) / slope : t_in;  // coming down onto the top
          hit_cls = w.cls[i];
          break;
        }
        if (h <= 0.0 && z_out <= 0.0) {
          hit_t = -m.sensor_height_m / slope;  // the ground
          hit_cls = w.cls[i];
          break;
        }
        t_in = t_out;
        if (t_next_c < t_next_r) {
          c += step_c;
          t_next_c += res * inv_dx;
        } else {
          r += step_r;
          t_next_r += res * inv_dy;
        }
      }
      if (hit_t < 0.0 || hit_cls == raw(ClassId::kWater) || hit_t > t_max) continue;
      const double range = hit_t / std::cos(alt) + m.range_sigma_m * rng.normal();
      if (range < 0.3) continue;
      const double th = range * std::cos(alt);
      ScanPoint p;
      p.x = static_cast<float>(th * std::cos(az));
      p.y = static_cast<float>(th * std::sin(az));
      p.z = static_cast<float>(range * std::sin(alt));
      p.range = static_cast<float>(range);
      p.cls = hit_cls;
      p.ring = static_cast<std::uint16_t>(ring);
      p.col = static_cast<std::uint16_t>(col);
      out.push_back(p);
    }
  }
}

struct TruthSample {
  TimeNs stamp{0};
  Pose2 pose;
};

// A route through road crossings (indices into road_x, road_y; consecutive crossings share a road),
// driven at `speed`, turning in place at `turn_rate` at each crossing, sampled at `rate_hz`.
inline std::vector<TruthSample> drive_route(const SyntheticWorld& w, std::span<const std::pair<int, int>> crossings,
                                            double speed = 2.0, double turn_rate = 0.8, double rate_hz = 10.0,
                                            TimeNs t0 = 0) {
  std::vector<TruthSample> out;
  const double dt = 1.0 / rate_hz;
  auto at = [&](std::pair<int, int> k) {
    return Pose2{w.road_x[static_cast<std::size_t>(k.first)], w.road_y[static_cast<std::size_t>(k.second)], 0.0};
  };
  Pose2 p = at(crossings[0]);
  {
    const Pose2 q = at(crossings[1]);
    p.yaw = std::atan2(q.y - p.y, q.x - p.x);
  }
  TimeNs t = t0;
  out.push_back({t, p});
  for (std::size_t k = 1; k < crossings.size(); ++k) {
    const Pose2 q = at(crossings[k]);
    const double heading = std::atan2(q.y - p.y, q.x - p.x);
    while (std::fabs(wrap_angle(heading - p.yaw)) > 1e-9) {
      const double d = wrap_angle(heading - p.yaw);
      p.yaw = wrap_angle(p.yaw + std::clamp(d, -turn_rate * dt, turn_rate * dt));
      t += from_seconds(dt);
      out.push_back({t, p});
    }
    for (;;) {
      const double rem = std::hypot(q.x - p.x, q.y - p.y);
      if (rem < 1e-9) break;
      const double step = std::min(rem, speed * dt);
      p.x += step * std::cos(heading);
      p.y += step * std::sin(heading);
      t += from_seconds(dt);
      out.push_back({t, p});
    }
  }
  return out;
}

// Appends `seconds` of standing at the last pose.
inline void stand(std::vector<TruthSample>& path, double seconds, double rate_hz = 10.0) {
  if (path.empty()) return;
  const TruthSample last = path[path.size() - 1];
  const auto n = static_cast<int>(seconds * rate_hz);
  for (int i = 1; i <= n; ++i) path.push_back({last.stamp + from_seconds(i / rate_hz), last.pose});
}

struct OdometryNoise {
  double sigma_xy_m{0.01};       // per step while moving (the paper's simulation: truth plus noise)
  double sigma_yaw_rad{0.002};   // per step while moving
  double scale_error{0.01};      // relative distance error
  double yaw_drift_at_rest_rad_per_s{0.0};
};

// The odometry's cumulative pose (odometry frame = the first truth pose) for every truth sample.
inline std::vector<Pose2> odometry(std::span<const TruthSample> truth, const OdometryNoise& n, std::uint64_t seed) {
  TestRng rng(seed);
  std::vector<Pose2> out;
  Pose2 o{};
  out.push_back(o);
  for (std::size_t k = 1; k < truth.size(); ++k) {
    Pose2 d = between(truth[k - 1].pose, truth[k].pose);
    const bool moving = std::hypot(d.x, d.y) > 1e-6 || std::fabs(d.yaw) > 1e-6;
    if (moving) {
      d.x = d.x * (1.0 + n.scale_error) + n.sigma_xy_m * rng.normal();
      d.y = d.y * (1.0 + n.scale_error) + n.sigma_xy_m * rng.normal();
      d.yaw += n.sigma_yaw_rad * rng.normal();
    } else {
      d.yaw += n.yaw_drift_at_rest_rad_per_s * to_seconds(truth[k].stamp - truth[k - 1].stamp);
    }
    o = compose(o, d);
    out.push_back(o);
  }
  return out;
}

}  // namespace ag::loc::test
