// Local waypoint tracker: RANSAC ground plane, obstacle grid by ray casting, local goal, back-up and
// cancel, reflex stop.
#include "airground/planning/local_tracker.hpp"

#include <algorithm>
#include <cmath>

#include "airground/messages/pose_math.hpp"

namespace ag::plan {

namespace {
constexpr std::uint8_t kUnknown = 0, kFree = 1, kObstacle = 2;
constexpr float kClearCap = 3.0F;
constexpr double kResumeMinM = 1.0;  // [m] a forward goal nearer than this does not end a back-up
constexpr std::size_t kFarSlots = 1U << 14;  // end cells outside the grid, per scan (power of two)
constexpr int kFarProbes = 16;
}  // namespace

const char* to_string(TrackState s) noexcept {
  switch (s) {
    case TrackState::kIdle: return "idle";
    case TrackState::kTracking: return "tracking";
    case TrackState::kBackingUp: return "backing up to the last waypoint";
    case TrackState::kFailed: return "blocked: path cancelled";
    case TrackState::kArrived: return "arrived";
  }
  return "?";
}

LocalTracker::LocalTracker(const LocalTrackerParams& p) : p_(p) {
  n_ = std::max(8, static_cast<int>(std::ceil(p.grid_size_m / p.cell_m)));
  grid_.assign(static_cast<std::size_t>(n_) * static_cast<std::size_t>(n_), kUnknown);
  clear_.assign(grid_.size(), 0.0F);
  inliers_.assign(4096, 0);
  end_stamp_.assign(grid_.size(), 0);
  hit_stamp_.assign(grid_.size(), 0);
  nog_stamp_.assign(grid_.size(), 0);
  memo_key_.assign(grid_.size(), 0);
  memo_at_.assign(grid_.size(), 0);
  const int nr = static_cast<int>(std::floor(p.no_ground_radius_m / p.cell_m));
  for (int dj = -nr; dj <= nr; ++dj)
    for (int di = -nr; di <= nr; ++di)
      if (di * di + dj * dj <= nr * nr) {
        near_di_.push_back(static_cast<std::int16_t>(di));
        near_dj_.push_back(static_cast<std::int16_t>(dj));
      }
  far_keys_.assign(kFarSlots, 0);
  far_stamp_.assign(kFarSlots, 0);
}

bool LocalTracker::first_free_ray(int ei, int ej) noexcept {
  if (ei >= 0 && ej >= 0 && ei < n_ && ej < n_) {
    std::uint32_t& s = end_stamp_[idx(ei, ej)];
    if (s == stamp_) return false;
    s = stamp_;
    return true;
  }
  const std::uint64_t key = (static_cast<std::uint64_t>(static_cast<std::uint32_t>(ei)) << 32) | static_cast<std::uint32_t>(ej);
  std::uint64_t h = key * 0x9E3779B97F4A7C15ULL;
  for (int probe = 0; probe < kFarProbes; ++probe, ++h) {
    const std::size_t slot = static_cast<std::size_t>(h >> 50) & (kFarSlots - 1);
    if (far_stamp_[slot] != stamp_) {
      far_stamp_[slot] = stamp_;
      far_keys_[slot] = key;
      return true;
    }
    if (far_keys_[slot] == key) return false;
  }
  return true;  // the set is crowded here: trace it again (same result, more work)
}

bool LocalTracker::cell_of(double x, double y, int& i, int& j) const noexcept {
  i = static_cast<int>(std::floor((x - cx_) / p_.cell_m + 0.5 * n_));
  j = static_cast<int>(std::floor((y - cy_) / p_.cell_m + 0.5 * n_));
  return i >= 0 && j >= 0 && i < n_ && j < n_;
}

std::uint8_t LocalTracker::cell_at(double x, double y) const noexcept {
  int i = 0, j = 0;
  return cell_of(x, y, i, j) ? grid_[idx(i, j)] : kUnknown;
}

double LocalTracker::clearance_at(double x, double y) const noexcept {
  int i = 0, j = 0;
  return cell_of(x, y, i, j) ? static_cast<double>(clear_[idx(i, j)]) : 0.0;
}

bool LocalTracker::fit_plane(std::span<const ScanReturn> pts) noexcept {
  // Candidates: a deterministic subsample of the returns within 15 m.
  std::size_t n = 0;
  const std::size_t stride = std::max<std::size_t>(1, pts.size() / inliers_.size());
  for (std::size_t k = 0; k < pts.size() && n < inliers_.size(); k += stride)
    if (pts[k].range > 0.5F && pts[k].range < 15.0F) inliers_[n++] = static_cast<std::int32_t>(k);
  if (n < 10) return false;
  auto rnd = [&]() {
    rng_ ^= rng_ << 13;
    rng_ ^= rng_ >> 7;
    rng_ ^= rng_ << 17;
    return rng_;
  };
  std::size_t best_count = 0;
  Plane best;
  const double cos_tilt = std::cos(p_.max_ground_tilt_rad);
  for (int it = 0; it < p_.ransac_iterations; ++it) {
    const ScanReturn& a = pts[static_cast<std::size_t>(inliers_[rnd() % n])];
    const ScanReturn& b = pts[static_cast<std::size_t>(inliers_[rnd() % n])];
    const ScanReturn& c = pts[static_cast<std::size_t>(inliers_[rnd() % n])];
    const double ux = b.x - a.x, uy = b.y - a.y, uz = b.z - a.z, vx = c.x - a.x, vy = c.y - a.y, vz = c.z - a.z;
    double nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
    const double len = std::sqrt(nx * nx + ny * ny + nz * nz);
    if (len < 1e-6) continue;
    nx /= len;
    ny /= len;
    nz /= len;
    if (nz < 0) {
      nx = -nx;
      ny = -ny;
      nz = -nz;
    }
    if (nz < cos_tilt) continue;
    const double ax = a.x, ay = a.y, az = a.z;
    const Plane pl{nx, ny, nz, -(nx * ax + ny * ay + nz * az)};
    std::size_t count = 0;
    for (std::size_t k = 0; k < n; ++k) {
      const ScanReturn& q = pts[static_cast<std::size_t>(inliers_[k])];
      if (std::fabs(pl.height(q.x, q.y, q.z)) < p_.ransac_threshold_m) ++count;
    }
    // Prefer the lowest plane among equals: the ground, not a table top.
    if (count > best_count || (count == best_count && count > 0 && pl.d > best.d)) {
      best_count = count;
      best = pl;
    }
  }
  if (best_count < 10) return false;
  // Least squares z = alpha x + beta y + gamma over the inliers.
  double sxx = 0, sxy = 0, sx = 0, syy = 0, sy = 0, sn = 0, sxz = 0, syz = 0, sz = 0;
  for (std::size_t k = 0; k < n; ++k) {
    const ScanReturn& q = pts[static_cast<std::size_t>(inliers_[k])];
    if (std::fabs(best.height(q.x, q.y, q.z)) >= p_.ransac_threshold_m) continue;
    const double x = q.x, y = q.y, z = q.z;
    sxx += x * x;
    sxy += x * y;
    sx += x;
    syy += y * y;
    sy += y;
    sn += 1;
    sxz += x * z;
    syz += y * z;
    sz += z;
  }
  // Solve [sxx sxy sx; sxy syy sy; sx sy sn] [al be ga] = [sxz syz sz] (Cramer's rule).
  const double det = sxx * (syy * sn - sy * sy) - sxy * (sxy * sn - sy * sx) + sx * (sxy * sy - syy * sx);
  if (std::fabs(det) > 1e-9) {
    const double al = (sxz * (syy * sn - sy * sy) - sxy * (syz * sn - sy * sz) + sx * (syz * sy - syy * sz)) / det;
    const double be = (sxx * (syz * sn - sz * sy) - sxz * (sxy * sn - sy * sx) + sx * (sxy * sz - syz * sx)) / det;
    const double ga = (sxx * (syy * sz - sy * syz) - sxy * (sxy * sz - syz * sx) + sxz * (sxy * sy - syy * sx)) / det;
    const double len = std::sqrt(al * al + be * be + 1.0);
    plane_ = Plane{-al / len, -be / len, 1.0 / len, -ga / len};
  } else {
    plane_ = best;
  }
  return true;
}

bool LocalTracker::update(std::span<const ScanReturn> pts, const Pose3& mount, const Pose2& robot, double speed_mps) noexcept {
  cx_ = robot.x;
  cy_ = robot.y;
  std::fill(grid_.begin(), grid_.end(), kUnknown);
  reflex_ = false;
  have_plane_ = fit_plane(pts);
  if (!have_plane_) {
    compute_clearance();
    return false;
  }
  const Eigen::Matrix3d rm = rotation_matrix(mount.roll, mount.pitch, mount.yaw);
  const double r[6] = {rm(0, 0), rm(0, 1), rm(0, 2), rm(1, 0), rm(1, 1), rm(1, 2)};
  const double cy = std::cos(robot.yaw), sy = std::sin(robot.yaw);
  int ri = 0, rj = 0;
  (void)cell_of(robot.x, robot.y, ri, rj);
  const double reach = p_.reflex_distance_m + std::max(0.0, speed_mps) * p_.reflex_time_s;
  auto to_map = [&](const ScanReturn& q, double& mx, double& my, double& bx, double& by) {
    const double qx = q.x, qy = q.y, qz = q.z;
    bx = r[0] * qx + r[1] * qy + r[2] * qz + mount.x;
    by = r[3] * qx + r[4] * qy + r[5] * qz + mount.y;
    mx = robot.x + cy * bx - sy * by;
    my = robot.y + sy * bx + cy * by;
  };
  // Free space first: a ray from the robot to every ground return (once per end cell).
  if (++stamp_ == 0) {  // wrapped: forget every old mark
    std::fill(nog_stamp_.begin(), nog_stamp_.end(), 0U);
    std::fill(end_stamp_.begin(), end_stamp_.end(), 0U);
    std::fill(hit_stamp_.begin(), hit_stamp_.end(), 0U);
    std::fill(far_stamp_.begin(), far_stamp_.end(), 0U);
    stamp_ = 1;
  }
  double r_min = 1e9;  // [m] the nearest ground return, horizontally from the robot
  for (const ScanReturn& q : pts) {
    if (!(q.range > 0.0F)) continue;
    const double h = plane_.height(q.x, q.y, q.z);
    if (std::fabs(h) >= p_.ground_band_m) continue;
    double mx = 0, my = 0, bx = 0, by = 0;
    to_map(q, mx, my, bx, by);
    int ei = 0, ej = 0;
    if (cell_of(mx, my, ei, ej)) hit_stamp_[idx(ei, ej)] = stamp_;
    r_min = std::min(r_min, std::hypot(bx, by));
    if (p_.trace_each_end_cell_once && !first_free_ray(ei, ej)) continue;
    int x = ri, y = rj;
    const int dx = std::abs(ei - ri), dy = -std::abs(ej - rj), sx = ri < ei ? 1 : -1, syy = rj < ej ? 1 : -1;
    int err = dx + dy;
    for (int guard = 0; guard < 4 * n_; ++guard) {
      if (x < 0 || y < 0 || x >= n_ || y >= n_) break;
      grid_[idx(x, y)] = kFree;
      if (x == ei && y == ej) break;
      const int e2 = 2 * err;
      if (e2 >= dy) {
        err += dy;
        x += sx;
      }
      if (e2 <= dx) {
        err += dx;
        y += syy;
      }
    }
  }
  if (p_.no_ground_range_m > 0) mark_no_ground(ri, rj, r_min);
  // Then obstacles, which win; and the reflex.
  for (const ScanReturn& q : pts) {
    if (!(q.range > 0.0F)) continue;
    const double h = plane_.height(q.x, q.y, q.z);
    if (h <= p_.obstacle_min_m || h >= p_.overhang_m) continue;
    double mx = 0, my = 0, bx = 0, by = 0;
    to_map(q, mx, my, bx, by);
    int i = 0, j = 0;
    if (cell_of(mx, my, i, j)) {
      grid_[idx(i, j)] = kObstacle;
      nog_stamp_[idx(i, j)] = 0;  // a return: the obstacle is exactly here
    }
    if (h > p_.reflex_height_m && bx > 0.0 && bx < reach && std::fabs(by) < p_.reflex_half_width_m) reflex_ = true;
  }
  compute_clearance();
  return true;
}

// Free cells (crossed by rays), and with no_ground_unseen unknown ones, with no ground return within
// no_ground_radius_m, in the ring where the ground returns lie that close together: no ground there
// (water, a drop); an obstacle.
void LocalTracker::mark_no_ground(int ri, int rj, double r_min_m) noexcept {
  ++updates_;
  if (updates_ == 0) {  // wrapped: forget the memory
    std::fill(memo_at_.begin(), memo_at_.end(), 0U);
    updates_ = 1;
  }
  const double r0 = (r_min_m + p_.no_ground_radius_m) / p_.cell_m, r1 = p_.no_ground_range_m / p_.cell_m;
  const int rc = static_cast<int>(std::ceil(std::max(r0, r1)));
  const std::size_t m = near_di_.size();
  const auto n = static_cast<std::int64_t>(n_);
  // map-frame cell of grid cell (i, j), and its slot in the memory
  auto key_of = [&](int i, int j, std::size_t& slot) {
    const auto gx = static_cast<std::int64_t>(std::floor(cx_ / p_.cell_m + (i + 0.5 - 0.5 * n_)));
    const auto gy = static_cast<std::int64_t>(std::floor(cy_ / p_.cell_m + (j + 0.5 - 0.5 * n_)));
    slot = static_cast<std::size_t>(((gy % n + n) % n) * n + ((gx % n + n) % n));
    return (static_cast<std::uint64_t>(static_cast<std::uint32_t>(gx)) << 32) | static_cast<std::uint32_t>(gy);
  };
  const auto memory = static_cast<std::uint32_t>(std::max(0, p_.no_ground_memory_updates));
  for (int dj = -rc; dj <= rc; ++dj)
    for (int di = -rc; di <= rc; ++di) {
      const int i = ri + di, j = rj + dj;
      if (i < 0 || j < 0 || i >= n_ || j >= n_ || grid_[idx(i, j)] == kObstacle) continue;
      const double d2 = static_cast<double>(di * di + dj * dj);
      if (d2 > std::max(r0, r1) * std::max(r0, r1)) continue;
      std::size_t slot = 0;
      const std::uint64_t key = key_of(i, j, slot);
      if (d2 < r0 * r0) {  // too near for this scan to tell: what it found before
        if (memory > 0 && memo_key_[slot] == key && memo_at_[slot] != 0 && updates_ - memo_at_[slot] <= memory) {
          grid_[idx(i, j)] = kObstacle;
          nog_stamp_[idx(i, j)] = stamp_;
        }
        continue;
      }
      // A cell no ray crossed is no-ground too: the LiDAR sees the ground all round within this ring, so
      // there it is water whose far shore is out of reach, a drop, or ground hidden behind an obstacle.
      const std::uint8_t v = grid_[idx(i, j)];
      if (!(v == kFree || (p_.no_ground_unseen && v == kUnknown)) || !(r1 > r0)) continue;
      bool ground = false;
      for (std::size_t k = 0; k < m && !ground; ++k) {
        const int x = i + near_di_[k], y = j + near_dj_[k];
        ground = x >= 0 && y >= 0 && x < n_ && y < n_ && hit_stamp_[idx(x, y)] == stamp_;
      }
      if (!ground) {
        grid_[idx(i, j)] = kObstacle;
        nog_stamp_[idx(i, j)] = stamp_;
        memo_key_[slot] = key;
        memo_at_[slot] = updates_;
      } else if (memo_key_[slot] == key) {
        memo_at_[slot] = 0;  // ground seen there now
      }
    }
}

// Chamfer (1, sqrt 2) distance to the nearest obstacle cell, capped; less half a cell: from the cell's
// centre to the obstacle cell's edge. A no-ground cell starts at -no_ground_radius_m: it was marked
// because no ground return lay within that radius, so the water's real edge may be that much nearer
// (a cell 0.4 m from the shore still had the track's returns within 0.5 m and stayed free).
void LocalTracker::compute_clearance() noexcept {
  const auto c = static_cast<float>(p_.cell_m), d = c * 1.41421356F;
  const float edge = p_.no_ground_edge_margin ? -static_cast<float>(p_.no_ground_radius_m) : 0.0F;
  for (std::size_t k = 0; k < grid_.size(); ++k)
    clear_[k] = grid_[k] != kObstacle ? kClearCap : (have_plane_ && nog_stamp_[k] == stamp_ ? edge : 0.0F);
  for (int j = 0; j < n_; ++j)
    for (int i = 0; i < n_; ++i) {
      float& v = clear_[idx(i, j)];
      if (i > 0) v = std::min(v, clear_[idx(i - 1, j)] + c);
      if (j > 0) v = std::min(v, clear_[idx(i, j - 1)] + c);
      if (i > 0 && j > 0) v = std::min(v, clear_[idx(i - 1, j - 1)] + d);
      if (i + 1 < n_ && j > 0) v = std::min(v, clear_[idx(i + 1, j - 1)] + d);
    }
  for (int j = n_ - 1; j >= 0; --j)
    for (int i = n_ - 1; i >= 0; --i) {
      float& v = clear_[idx(i, j)];
      if (i + 1 < n_) v = std::min(v, clear_[idx(i + 1, j)] + c);
      if (j + 1 < n_) v = std::min(v, clear_[idx(i, j + 1)] + c);
      if (i + 1 < n_ && j + 1 < n_) v = std::min(v, clear_[idx(i + 1, j + 1)] + d);
      if (i > 0 && j + 1 < n_) v = std::min(v, clear_[idx(i - 1, j + 1)] + d);
    }
  for (float& v : clear_) v = std::max(0.0F, v - 0.5F * c);
}

void LocalTracker::set_path(std::span<const Point2> path) noexcept {
  n_path_ = static_cast<std::uint32_t>(std::min(path.size(), path_.size()));
  std::copy(path.begin(), path.begin() + n_path_, path_.begin());
  wp_ = 0;
  have_prev_ = false;
  state_ = n_path_ >= 2 ? TrackState::kTracking : TrackState::kIdle;
}

bool LocalTracker::pick_goal(const Point2& target, double radius_m, LocalGoal& out) const noexcept {
  int ti = 0, tj = 0;
  (void)cell_of(target.x, target.y, ti, tj);
  const int rad = std::max(1, static_cast<int>(std::ceil(radius_m / p_.cell_m)));
  int ri = 0, rj = 0;
  (void)cell_of(cx_, cy_, ri, rj);
  // Enough clearance is enough: beyond min + 0.9 m a cell is not better, so the goal stays near the
  // target; among equals, the one nearest the previous goal (no flipping between the sides of an
  // obstacle), else nearest the target.
  const double enough = p_.min_clearance_m + 0.9;
  const Point2 ref = have_prev_ ? prev_goal_ : target;
  double best = -1, best_d = 1e30;
  int bi = -1, bj = -1;
  for (int dj = -rad; dj <= rad; ++dj)
    for (int di = -rad; di <= rad; ++di) {
      const int i = ti + di, j = tj + dj;
      if (i < 0 || j < 0 || i >= n_ || j >= n_ || di * di + dj * dj > rad * rad) continue;
      if (grid_[idx(i, j)] != kFree) continue;
      const double cl = static_cast<double>(clear_[idx(i, j)]);
      if (cl < p_.min_clearance_m) continue;
      const double score = std::min(cl, enough);
      const double gx = cx_ + (i + 0.5 - 0.5 * n_) * p_.cell_m, gy = cy_ + (j + 0.5 - 0.5 * n_) * p_.cell_m;
      const double dd = std::hypot(gx - ref.x, gy - ref.y);
      if (score < best - 1e-6 || (std::fabs(score - best) <= 1e-6 && dd >= best_d)) continue;
      // The way there keeps the clearance too (but for the first half metre: the robot is where it is).
      bool clear_line = true;
      const int steps = std::max(std::abs(i - ri), std::abs(j - rj));
      const int skip = static_cast<int>(0.5 / p_.cell_m);
      for (int s = 1; s <= steps && clear_line; ++s) {
        const int x = ri + static_cast<int>(std::lround(static_cast<double>((i - ri) * s) / steps));
        const int y = rj + static_cast<int>(std::lround(static_cast<double>((j - rj) * s) / steps));
        if (grid_[idx(x, y)] == kObstacle || (s > skip && static_cast<double>(clear_[idx(x, y)]) < p_.min_clearance_m - p_.cell_m)) clear_line = false;
      }
      if (!clear_line) continue;
      best = score;
      best_d = dd;
      bi = i;
      bj = j;
    }
  if (bi < 0) return false;
  out.valid = true;
  out.goal = Point2{cx_ + (bi + 0.5 - 0.5 * n_) * p_.cell_m, cy_ + (bj + 0.5 - 0.5 * n_) * p_.cell_m};
  out.clearance_m = static_cast<double>(clear_[idx(bi, bj)]);
  return true;
}

LocalGoal LocalTracker::local_goal(const Pose2& robot, TimeNs now) noexcept {
  LocalGoal out;
  out.reflex_stop = reflex_;
  if (state_ == TrackState::kIdle || state_ == TrackState::kFailed || state_ == TrackState::kArrived || n_path_ < 2) return out;
  // Advance the waypoint past segments the robot has gone beyond.
  while (wp_ + 1 < n_path_) {
    const Point2 a = path_[wp_], b = path_[wp_ + 1];
    const double dx = b.x - a.x, dy = b.y - a.y, l2 = dx * dx + dy * dy;
    const double t = l2 > 0 ? ((robot.x - a.x) * dx + (robot.y - a.y) * dy) / l2 : 1.0;
    if (t < 1.0 || wp_ + 2 >= n_path_) break;
    ++wp_;
  }
  const Point2 last = path_[n_path_ - 1];
  if (std::hypot(last.x - robot.x, last.y - robot.y) < 0.5) {
    state_ = TrackState::kArrived;
    return out;
  }
  // The point goal_distance ahead along the path from the robot's foot on the current segment.
  auto ahead = [&](double dist) {
    const Point2 a = path_[wp_], b = path_[wp_ + 1];
    const double dx = b.x - a.x, dy = b.y - a.y, l2 = dx * dx + dy * dy;
    const double t = l2 > 0 ? std::clamp(((robot.x - a.x) * dx + (robot.y - a.y) * dy) / l2, 0.0, 1.0) : 1.0;
    return walk_along(std::span<const Point2>(path_.data(), n_path_), wp_ + 1, Point2{a.x + t * dx, a.y + t * dy}, dist);
  };
  for (const double dist : {p_.goal_distance_m, 0.5 * p_.goal_distance_m, std::min(1.5, p_.goal_distance_m)})
    // Cells nearer the target than half the way there: a goal that makes progress.
    if (pick_goal(ahead(dist), std::min(p_.goal_search_m, 0.5 * dist), out)) {
      // Hysteresis: once backing up, a forward goal less than kResumeMinM ahead (the cell just in front
      // of the obstacle that stopped us) does not end the back-up; the robot would flip between the two
      // and never fail the route.
      if (state_ == TrackState::kBackingUp && std::hypot(out.goal.x - robot.x, out.goal.y - robot.y) < kResumeMinM) {
        out = LocalGoal{};
        out.reflex_stop = reflex_;
        continue;
      }
      state_ = TrackState::kTracking;
      prev_goal_ = out.goal;
      have_prev_ = true;
      return out;
    }
  // Forward is blocked: back up to the last waypoint; if that is blocked too, or takes too long, fail.
  if (state_ != TrackState::kBackingUp) {
    state_ = TrackState::kBackingUp;
    backup_since_ = now;
    have_prev_ = false;
  }
  const double back = std::hypot(path_[wp_].x - robot.x, path_[wp_].y - robot.y);
  if (now - backup_since_ <= from_seconds(p_.backup_timeout_s) && back > 0.3 && pick_goal(path_[wp_], std::min(p_.goal_search_m, 0.5 * back), out))
    return out;
  state_ = TrackState::kFailed;
  ++failures_;
  out = LocalGoal{};
  out.reflex_stop = reflex_;
  return out;
}

}  // namespace ag::plan
