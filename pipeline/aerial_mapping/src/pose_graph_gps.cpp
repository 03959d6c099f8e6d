// The pose graph's GPS side: fixes interpolated to frames, the gate against the estimate, and the
// closed-form alignment that places a segment once its fixes are spread far enough.
#include <algorithm>
#include <cmath>
#include <complex>
#include <limits>
#include <vector>

#include "pose_graph_internal.hpp"

namespace ag::mapping {
namespace {

// After this many consecutive gate rejections fixes are accepted again (until one passes the gate): if
// the estimate itself went wrong, the graph must not lock GPS out for ever.
constexpr int kMaxConsecutiveGated = 25;

}  // namespace

using detail::yaw_quaternion;

bool PoseGraph::Impl::add_gps(TimeNs stamp, const Eigen::Vector3d& enu, double sigma_h) {
  ++st.gps_fixes;
  if (have_fix_stamp && stamp <= last_fix_stamp) {
    ++st.gps_rejected_order;
    return false;
  }
  have_fix_stamp = true;
  last_fix_stamp = stamp;
  if (!enu.allFinite()) return true;
  const double sig = std::max(std::isfinite(sigma_h) ? sigma_h : 0.0, prm.gps_sigma_m);
  if (beyond_gate(stamp, enu, sig)) {
    if (consecutive_gated < kMaxConsecutiveGated) {
      ++st.gps_rejected_gate;
      ++consecutive_gated;
      return true;
    }
  } else {
    consecutive_gated = 0;
  }
  fixes.push_back(Fix{stamp, enu, sig, false});
  // Frames between the previous fix and this one (and at this one) get their factors now.
  const TimeNs prev_t = fixes.size() >= 2 ? fixes[fixes.size() - 2].stamp : std::numeric_limits<TimeNs>::min();
  std::size_t i = nodes.size();
  while (i > 0 && nodes[i - 1].stamp > prev_t) --i;
  for (; i < nodes.size() && nodes[i].stamp <= stamp; ++i) attach_to_node(i);
  return true;
}

// Position estimate at time t from the nodes around it; false if there is none close enough.
bool PoseGraph::Impl::predict(TimeNs t, Eigen::Vector3d& p, std::size_t& seg) const {
  if (nodes.empty()) return false;
  const auto it = std::upper_bound(nodes.begin(), nodes.end(), t, [](TimeNs v, const Node& n) { return v < n.stamp; });
  const auto k = static_cast<std::size_t>(it - nodes.begin());  // first node after t
  const double lim = std::max(prm.gps_max_interpolation_s, 0.5);
  if (k == 0) {
    if (to_seconds(nodes[0].stamp - t) > lim) return false;
    p = pos(nodes[0]);
    seg = nodes[0].seg;
    return true;
  }
  const Node& a = nodes[k - 1];
  if (k < nodes.size() && nodes[k].seg == a.seg) {
    const Node& b = nodes[k];
    const double w = to_seconds(t - a.stamp) / to_seconds(b.stamp - a.stamp);
    p = (1.0 - w) * pos(a) + w * pos(b);
    seg = a.seg;
    return true;
  }
  if (k < nodes.size() && to_seconds(nodes[k].stamp - t) < to_seconds(t - a.stamp)) {
    p = pos(nodes[k]);
    seg = nodes[k].seg;
    return to_seconds(nodes[k].stamp - t) <= lim;
  }
  const double dt = to_seconds(t - a.stamp);
  if (dt > lim) return false;
  p = pos(a);
  seg = a.seg;
  if (k - 1 > segments[a.seg].first) {  // extrapolate at the velocity of the last two nodes
    const Node& z = nodes[k - 2];
    const double dtv = to_seconds(a.stamp - z.stamp);
    if (dtv > 0) p += (pos(a) - pos(z)) * (dt / dtv);
  }
  return true;
}

double PoseGraph::Impl::gate_distance(const Eigen::Vector3d& d) const {
  const double vf = prm.gps_vertical_factor > 0 ? prm.gps_vertical_factor : 1.0;
  return std::hypot(d.head<2>().norm(), d.z() / vf);
}

double PoseGraph::Impl::gate_limit(double sigma_h) const { return std::max(prm.gps_gate_sigmas * sigma_h, prm.gps_gate_floor_m); }

bool PoseGraph::Impl::beyond_gate(TimeNs t, const Eigen::Vector3d& enu, double sigma_h) const {
  if (prm.gps_gate_sigmas <= 0) return false;
  Eigen::Vector3d p;
  std::size_t seg = 0;
  if (!predict(t, p, seg) || !segments[seg].initialised) return false;
  return gate_distance(enu - p) > gate_limit(sigma_h);
}

// Gives node i its GPS factor if two consecutive fixes close enough in time bracket it (or one hits it).
void PoseGraph::Impl::attach_to_node(std::size_t i) {
  Node& n = nodes[i];
  if (n.has_gps || fixes.empty()) return;
  const auto it = std::lower_bound(fixes.begin(), fixes.end(), n.stamp, [](const Fix& f, TimeNs v) { return f.stamp < v; });
  const auto b = static_cast<std::size_t>(it - fixes.begin());  // first fix at or after the frame
  if (b == fixes.size()) return;
  std::size_t ia = b, ib = b;
  if (fixes[b].stamp != n.stamp) {
    if (b == 0) return;
    ia = b - 1;
    if (to_seconds(fixes[ib].stamp - fixes[ia].stamp) > prm.gps_max_interpolation_s) return;
  }
  const Fix& fa = fixes[ia];
  const Fix& fb = fixes[ib];
  if (fa.removed || fb.removed) return;
  double w = 0, gap = 0;
  if (ia != ib) {
    w = to_seconds(n.stamp - fa.stamp) / to_seconds(fb.stamp - fa.stamp);
    gap = std::min(to_seconds(n.stamp - fa.stamp), to_seconds(fb.stamp - n.stamp));
  }
  n.has_gps = true;
  n.gps = (1.0 - w) * fa.enu + w * fb.enu;
  n.gps_sigma_h = std::max({fa.sigma_h, fb.sigma_h, prm.gps_sigma_m}) + prm.gps_sigma_per_gap_s * gap;
  n.fix_a = ia;
  n.fix_b = ib;
  ++st.gps_factors;

  Segment& s = segments[n.seg];
  if (s.fixes == 0) {
    s.first_fix = fa.enu;
    // The segment's first fix: an uninitialised segment is moved onto the GPS.
    if (!s.aligned) {
      const Eigen::Vector3d d = n.gps - pos(n);
      for (std::size_t k = s.first; k <= s.last; ++k) set_state(nodes[k], pos(nodes[k]) + d, rot(nodes[k]));
    }
  }
  for (const std::size_t f : {ia, ib}) {
    if (s.newest_fix != std::numeric_limits<std::size_t>::max() && f <= s.newest_fix) continue;
    s.newest_fix = f;
    ++s.fixes;
    s.spread = std::max(s.spread, (fixes[f].enu - s.first_fix).norm());
  }
  if (!s.aligned && s.fixes >= static_cast<std::size_t>(std::max(prm.min_gps_fixes, 2)) && s.spread >= prm.min_gps_baseline_m)
    align(n.seg);
}

void PoseGraph::Impl::drop_factor(Node& n) {
  if (!n.has_gps) return;
  n.has_gps = false;
  --st.gps_factors;
}

// Closed-form yaw/scale/translation of segment `si`'s odometry onto its GPS factors; drops the worst
// fix while it lies beyond the gate. On success resets every node of the segment and marks it pending.
void PoseGraph::Impl::align(std::size_t si) {
  Segment& s = segments[si];
  for (;;) {
    std::vector<std::size_t> idx;
    for (std::size_t k = s.first; k <= s.last; ++k)
      if (nodes[k].has_gps) idx.push_back(k);
    if (idx.size() < 2) return;
    Eigen::Vector3d co = Eigen::Vector3d::Zero(), cg = Eigen::Vector3d::Zero();
    for (const std::size_t k : idx) {
      co += nodes[k].odo_p;
      cg += nodes[k].gps;
    }
    co /= static_cast<double>(idx.size());
    cg /= static_cast<double>(idx.size());
    std::complex<double> num{0, 0};
    double den = 0;
    for (const std::size_t k : idx) {
      const Eigen::Vector3d o = nodes[k].odo_p - co, g = nodes[k].gps - cg;
      const std::complex<double> oc{o.x(), o.y()}, gc{g.x(), g.y()};
      num += std::conj(oc) * gc;
      den += std::norm(oc);
    }
    if (!(den > 1e-12)) return;  // no horizontal odometry motion: wait for more
    const std::complex<double> a = num / den;
    const double scale = std::abs(a);
    if (!(scale > 1e-9) || !std::isfinite(scale)) return;
    const double yaw = std::arg(a);
    const Eigen::Quaterniond rz = yaw_quaternion(yaw);
    const Eigen::Vector3d t = cg - scale * (rz * co);
    // Trim: the worst factor beyond the gate takes its fix (all factors interpolated from it) away.
    std::size_t worst = idx.front();
    double worst_ratio = 0;
    for (const std::size_t k : idx) {
      const double r = gate_distance(nodes[k].gps - (scale * (rz * nodes[k].odo_p) + t)) / gate_limit(nodes[k].gps_sigma_h);
      if (r > worst_ratio) {
        worst_ratio = r;
        worst = k;
      }
    }
    if (worst_ratio > 1.0 && prm.gps_gate_sigmas > 0) {
      const Node& w = nodes[worst];
      const double wa = w.fix_a == w.fix_b ? 1.0 : to_seconds(fixes[w.fix_b].stamp - w.stamp) / to_seconds(fixes[w.fix_b].stamp - fixes[w.fix_a].stamp);
      const std::size_t bad = wa >= 0.5 ? w.fix_a : w.fix_b;
      fixes[bad].removed = true;
      ++st.gps_rejected_gate;
      for (std::size_t k = s.first; k <= s.last; ++k)
        if (nodes[k].has_gps && (nodes[k].fix_a == bad || nodes[k].fix_b == bad)) drop_factor(nodes[k]);
      recount(s);
      if (s.fixes < static_cast<std::size_t>(std::max(prm.min_gps_fixes, 2)) || s.spread < prm.min_gps_baseline_m) return;
      continue;
    }
    for (Knot& k : s.knots) k.log_scale = std::log(scale);
    for (std::size_t k = s.first; k <= s.last; ++k) set_state(nodes[k], scale * (rz * nodes[k].odo_p) + t, rz * nodes[k].odo_q);
    s.aligned = true;
    s.pending = true;
    return;
  }
}

void PoseGraph::Impl::recount(Segment& s) const {
  s.fixes = 0;
  s.spread = 0;
  s.newest_fix = std::numeric_limits<std::size_t>::max();
  bool first = true;
  for (std::size_t k = s.first; k <= s.last; ++k) {
    const Node& n = nodes[k];
    if (!n.has_gps) continue;
    for (const std::size_t f : {n.fix_a, n.fix_b}) {
      if (s.newest_fix != std::numeric_limits<std::size_t>::max() && f <= s.newest_fix) continue;
      if (first) s.first_fix = fixes[f].enu;
      first = false;
      s.newest_fix = f;
      ++s.fixes;
      s.spread = std::max(s.spread, (fixes[f].enu - s.first_fix).norm());
    }
  }
}

}  // namespace ag::mapping
