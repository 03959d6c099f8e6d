// Vehicle detection from labelled LiDAR points and the per-object EKF.
#include "airground/mission/targets.hpp"

#include <algorithm>
#include <cmath>

namespace ag::mission {

namespace {
// Points are collected this far beyond max_range_m so an object within it is seen whole.
constexpr double kEdgeMarginM = 6.0;
}  // namespace

VehicleDetector::VehicleDetector(const DetectorParams& p) : p_(p) {
  n_ = static_cast<std::int32_t>(std::ceil(2.0 * (p.max_range_m + kEdgeMarginM) / p.cell_m)) + 2;
  const std::size_t cells = static_cast<std::size_t>(n_) * static_cast<std::size_t>(n_);
  count_.assign(cells, 0);
  sx_.assign(cells, 0.0f);
  sy_.assign(cells, 0.0f);
  label_.assign(cells, -1);
  queue_.assign(cells, 0);
  touched_.assign(cells, 0);
  out_.assign(p.max_detections, Detection{});
}

std::span<const Detection> VehicleDetector::detect(std::span<const ScanReturn> points, const Pose3& m, const Pose2& robot,
                                                   const std::array<double, 9>& cov) noexcept {
  for (std::size_t k = 0; k < n_touched_; ++k) {
    const auto i = static_cast<std::size_t>(touched_[k]);
    count_[i] = 0;
    sx_[i] = sy_[i] = 0.0f;
    label_[i] = -1;
  }
  n_touched_ = 0;
  n_out_ = 0;
  // sensor -> body (R = Rz(yaw) Ry(pitch) Rx(roll)), body -> map (planar)
  const double cr = std::cos(m.roll), sr = std::sin(m.roll), cp = std::cos(m.pitch), sp = std::sin(m.pitch), cy = std::cos(m.yaw),
               sy = std::sin(m.yaw);
  const double r00 = cy * cp, r01 = cy * sp * sr - sy * cr, r02 = cy * sp * cr + sy * sr;
  const double r10 = sy * cp, r11 = sy * sp * sr + cy * cr, r12 = sy * sp * cr - cy * sr;
  const double ch = std::cos(robot.yaw), sh = std::sin(robot.yaw);
  const double half = 0.5 * n_ * p_.cell_m;
  for (const ScanReturn& q : points) {
    const double qr = static_cast<double>(q.range), qx = static_cast<double>(q.x), qy = static_cast<double>(q.y), qz = static_cast<double>(q.z);
    if (q.cls != p_.cls || !(qr >= p_.min_range_m && qr <= p_.max_range_m + kEdgeMarginM)) continue;
    const double bx = m.x + r00 * qx + r01 * qy + r02 * qz, by = m.y + r10 * qx + r11 * qy + r12 * qz;
    const double dx = ch * bx - sh * by, dy = sh * bx + ch * by;  // body offset in the map frame
    const double fc = std::floor((dx + half) / p_.cell_m), fr = std::floor((dy + half) / p_.cell_m);
    if (!(fc >= 0 && fr >= 0 && fc < n_ && fr < n_)) continue;
    const std::size_t i = static_cast<std::size_t>(fr) * static_cast<std::size_t>(n_) + static_cast<std::size_t>(fc);
    if (count_[i] == 0) touched_[n_touched_++] = static_cast<std::int32_t>(i);
    if (count_[i] < 0xFFFF) ++count_[i];
    sx_[i] += static_cast<float>(dx);
    sy_[i] += static_cast<float>(dy);
  }
  const double pxx = std::max(0.0, cov[0]), pxy = cov[1], pyy = std::max(0.0, cov[4]);
  for (std::size_t k = 0; k < n_touched_; ++k) {
    const auto seed = static_cast<std::size_t>(touched_[k]);
    if (label_[seed] != -1) continue;
    std::size_t qn = 0;
    queue_[qn++] = static_cast<std::int32_t>(seed);
    label_[seed] = 0;
    double sx = 0, sy2 = 0;
    std::uint32_t pts = 0;
    std::int32_t c0 = n_, c1 = -1, rw0 = n_, rw1 = -1;
    for (std::size_t h = 0; h < qn; ++h) {
      const std::int32_t i = queue_[h];
      const std::int32_t c = i % n_, r = i / n_;
      const auto ui = static_cast<std::size_t>(i);
      pts += count_[ui];
      sx += static_cast<double>(sx_[ui]);
      sy2 += static_cast<double>(sy_[ui]);
      c0 = std::min(c0, c);
      c1 = std::max(c1, c);
      rw0 = std::min(rw0, r);
      rw1 = std::max(rw1, r);
      for (std::int32_t dr = -1; dr <= 1; ++dr)
        for (std::int32_t dc = -1; dc <= 1; ++dc) {
          const std::int32_t nc = c + dc, nr = r + dr;
          if (nc < 0 || nr < 0 || nc >= n_ || nr >= n_) continue;
          const std::size_t j = static_cast<std::size_t>(nr) * static_cast<std::size_t>(n_) + static_cast<std::size_t>(nc);
          if (count_[j] == 0 || label_[j] != -1) continue;
          label_[j] = 0;
          queue_[qn++] = static_cast<std::int32_t>(j);
        }
    }
    if (pts < static_cast<std::uint32_t>(p_.min_points) || n_out_ >= out_.size()) continue;
    const double mx = sx / pts, my = sy2 / pts;
    // objects beyond max_range_m are left out: their far side may lie past the collection range
    if (std::hypot(mx, my) > p_.max_range_m) continue;
    Detection& d = out_[n_out_++];
    d.x = robot.x + mx;
    d.y = robot.y + my;
    d.points = pts;
    d.range_m = std::hypot(mx, my);
    const double s = p_.sigma0_m + p_.sigma_per_m * d.range_m;
    // the centroid of the visible side is off the object's centre by up to half its extent
    const double ex = 0.25 * (c1 - c0 + 1) * p_.cell_m, ey = 0.25 * (rw1 - rw0 + 1) * p_.cell_m;
    d.cxx = s * s + ex * ex + pxx;
    d.cyy = s * s + ey * ey + pyy;
    d.cxy = pxy;
  }
  return {out_.data(), n_out_};
}

ObjectTracker::ObjectTracker(const TrackerParams& p) : p_(p) { objs_.assign(p.max_objects, TrackedObject{}); }

int ObjectTracker::update(const Detection& d, TimeNs now) noexcept {
  if (!std::isfinite(d.x) || !std::isfinite(d.y)) {
    ++dropped_;
    return -1;
  }
  int best = -1;
  double best_m2 = p_.gate_chi2;
  for (std::size_t i = 0; i < n_; ++i) {
    TrackedObject& o = objs_[i];
    const double q = p_.process_noise_m2_per_s * std::max(0.0, to_seconds(now - o.last));
    const double sxx = o.cxx + q + d.cxx, sxy = o.cxy + d.cxy, syy = o.cyy + q + d.cyy;
    const double det = sxx * syy - sxy * sxy;
    if (!(det > 0)) continue;
    const double vx = d.x - o.x, vy = d.y - o.y;
    if (std::hypot(vx, vy) > p_.gate_max_m) continue;
    const double m2 = (syy * vx * vx - 2 * sxy * vx * vy + sxx * vy * vy) / det;
    if (m2 < best_m2) {
      best_m2 = m2;
      best = static_cast<int>(i);
    }
  }
  if (best < 0) {
    if (n_ == objs_.size()) {
      ++dropped_;
      return -1;
    }
    TrackedObject& o = objs_[n_];
    o = TrackedObject{next_id_++, d.x, d.y, d.cxx, d.cxy, d.cyy, 1, now};
    return static_cast<int>(n_++);
  }
  // Kalman update with H = I: K = P S^-1, x += K v, P = (I - K) P
  TrackedObject& o = objs_[static_cast<std::size_t>(best)];
  const double q = p_.process_noise_m2_per_s * std::max(0.0, to_seconds(now - o.last));
  const double pxx = o.cxx + q, pxy = o.cxy, pyy = o.cyy + q;
  const double sxx = pxx + d.cxx, sxy = pxy + d.cxy, syy = pyy + d.cyy;
  const double det = sxx * syy - sxy * sxy;
  const double ixx = syy / det, ixy = -sxy / det, iyy = sxx / det;
  const double kxx = pxx * ixx + pxy * ixy, kxy = pxx * ixy + pxy * iyy;
  const double kyx = pxy * ixx + pyy * ixy, kyy = pxy * ixy + pyy * iyy;
  const double vx = d.x - o.x, vy = d.y - o.y;
  o.x += kxx * vx + kxy * vy;
  o.y += kyx * vx + kyy * vy;
  const double nxx = (1 - kxx) * pxx - kxy * pxy, nxy = (1 - kxx) * pxy - kxy * pyy;
  const double nyy = -kyx * pxy + (1 - kyy) * pyy;
  o.cxx = nxx;
  o.cxy = nxy;
  o.cyy = nyy;
  if (o.detections < 0xFFFF) ++o.detections;
  o.last = now;
  return best;
}

ObjectRecord ObjectTracker::record(std::size_t i, std::uint8_t cls) const noexcept {
  const TrackedObject& o = objs_[i];
  return ObjectRecord{cls, o.detections, o.id, static_cast<float>(o.x), static_cast<float>(o.y), static_cast<float>(o.cxx),
                      static_cast<float>(o.cxy), static_cast<float>(o.cyy)};
}

}  // namespace ag::mission
