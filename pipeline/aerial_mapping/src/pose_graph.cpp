// The ASOOM pose graph on Ceres (see pose_graph.hpp).
//
// State: one node per frame (position and an Eigen-order quaternion, body to map) and, per odometry
// segment, a piecewise-constant log-scale (metres per odometry unit = exp(log_scale) > 0, so a negative
// scale cannot occur): a new knot once a frame step lies scale_knot_s after the start of the newest knot
// (one knot per segment if scale_knot_s = 0, as ASOOM). Each between-factor multiplies its translation by
// the knot of its step; consecutive knots are tied by a random-walk prior, sigma
// scale_drift_per_sqrt_s x sqrt(time between their starts), which is the model of a monocular VO's scale.
//
// Life of a segment:
//  - uninitialised: its nodes are the odometry chained from an anchor pose with the segment's scale
//    guess (segment 0: scale 1, anchored at the origin or the newest fix; later segments: the previous
//    segment's scale, anchored at the last pose of the previous segment extrapolated at constant
//    velocity over the gap, with the previous body yaw). Its first GPS factor shifts it onto the GPS.
//    It is not part of the solves: the priors that hold an uninitialised segment in ASOOM would hold it
//    exactly there.
//  - aligned: once its GPS factors span min_gps_fixes fixes spread >= min_gps_baseline_m, a closed-form
//    4-DoF similarity (yaw, scale, translation; the odometry is gravity-aligned) maps its odometry onto
//    the fixes (the worst fix is dropped while it is beyond the gate), every node of the segment is reset
//    from it, and the next update() solves at once, over all of the segment's nodes.
//  - initialised: after that solve (scale finite and positive). From then on a fix that lands on the
//    segment is gated against the current estimate.
//
// Solves rebuild a small ceres::Problem over the newest window_frames nodes (of aligned segments) plus
// the one constant node before them that a between-factor ties to the window; factors among constant
// nodes are not added at all, but what their between-factors say about the scale of their knot (a
// quadratic in the scale once the poses are constant) is kept per knot as one residual, faded over
// window_frames. Knots whose steps all left the window are constant; the newest of them stays in the
// problem through its random-walk prior to the first free knot, so the scale survives a hover or a GPS
// gap that fills the window. A young segment is re-solved each time it has grown by a third (until the
// regular solve_every_frames cadence takes over). Levenberg-Marquardt, sparse normal Cholesky on Eigen
// (no SuiteSparse: the static binary has no METIS), one thread, warm-started from the stored states.
//
// What the scale knots buy, measured against the simulator's VO (log-scale random walk 0.002/sqrt(s),
// 0.5 m GPS at 5 Hz, 3-minute surveys, tests/unit/aerial_mapping/test_pose_graph_sim.cpp): current scale
// error rms 0.0086 -> 0.0064, the scale of past frames 0.0080 -> 0.0043, and the mean relative error of
// distances between frames 2 s apart (what biases stereo depth) 0.0028 -> 0.0011. The current scale is
// a filter's estimate: a Kalman filter given everything but the scale gets 0.0052 from that GPS.
#include "airground/aerial_mapping/pose_graph.hpp"

#include <ceres/ceres.h>
#include <ceres/manifold.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <complex>
#include <ctime>
#include <limits>
#include <utility>

#include "airground/core/pose_math.hpp"

namespace ag::mapping {
namespace {

// After this many consecutive gate rejections fixes are accepted again (until one passes the gate): if
// the estimate itself went wrong, the graph must not lock GPS out for ever.
constexpr int kMaxConsecutiveGated = 25;
// [s] the anchor of a new segment is extrapolated at constant velocity over at most this long a gap.
constexpr double kMaxExtrapolationS = 5.0;
// [-] weak prior on an aligned segment's log-scale, centred on its current value: only keeps the solve
// well posed when the window holds no GPS; the GPS factors outweigh it by orders of magnitude.
constexpr double kScaleMemorySigma = 0.5;

double thread_cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}

Eigen::Quaterniond yaw_quaternion(double yaw) { return Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ())); }

double yaw_of(const Eigen::Quaterniond& q) {
  const Eigen::Matrix3d r = q.toRotationMatrix();
  return std::atan2(r(1, 0), r(0, 0));
}

// Relative odometry between consecutive frames i -> j: translation in i's body frame (odometry units)
// times the segment scale, and rotation; whitened by the between sigmas.
struct BetweenCost {
  Eigen::Vector3d t_ij;
  Eigen::Quaterniond q_ij;
  double inv_sigma_t;
  double inv_sigma_r;

  template <typename T>
  bool operator()(const T* pi, const T* qi, const T* pj, const T* qj, const T* log_scale, T* res) const {
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> p_i(pi), p_j(pj);
    const Eigen::Map<const Eigen::Quaternion<T>> q_i(qi), q_j(qj);
    const Eigen::Quaternion<T> qi_inv = q_i.conjugate();
    const Eigen::Matrix<T, 3, 1> dp = qi_inv * (p_j - p_i);
    const T s = ceres::exp(log_scale[0]);
    Eigen::Map<Eigen::Matrix<T, 3, 1>> rt(res);
    rt = (dp - s * t_ij.cast<T>()) * T(inv_sigma_t);
    Eigen::Quaternion<T> dq = q_ij.conjugate().cast<T>() * (qi_inv * q_j);
    const T sign = dq.w() < T(0) ? T(-1) : T(1);
    Eigen::Map<Eigen::Matrix<T, 3, 1>> rr(res + 3);
    rr = dq.vec() * (T(2) * sign * T(inv_sigma_r));
    return true;
  }
};

// Roll and pitch from the gravity-aligned odometry: the map's up axis seen from the body.
struct GravityCost {
  Eigen::Vector3d up_in_body;
  double inv_sigma;

  template <typename T>
  bool operator()(const T* q, T* res) const {
    const Eigen::Map<const Eigen::Quaternion<T>> q_i(q);
    const Eigen::Matrix<T, 3, 1> up = q_i.conjugate() * Eigen::Matrix<T, 3, 1>(T(0), T(0), T(1));
    Eigen::Map<Eigen::Matrix<T, 3, 1>> r(res);
    r = (up - up_in_body.cast<T>()) * T(inv_sigma);
    return true;
  }
};

// Position-only GPS factor (the fix interpolated to the frame time), per-axis whitening.
struct GpsCost {
  Eigen::Vector3d pos;
  Eigen::Vector3d inv_sigma;

  template <typename T>
  bool operator()(const T* p, T* res) const {
    for (int k = 0; k < 3; ++k) res[k] = (p[k] - T(pos[k])) * T(inv_sigma[k]);
    return true;
  }
};

// The scale information of the between-factors among constant nodes: sqrt(B) (exp(log_s) - A/B).
struct ScaleInfoCost {
  double mean;
  double sqrt_info;
  template <typename T>
  bool operator()(const T* log_scale, T* res) const {
    res[0] = (ceres::exp(log_scale[0]) - T(mean)) * T(sqrt_info);
    return true;
  }
};

// Random walk between consecutive log-scale knots.
struct RandomWalkCost {
  double inv_sigma;
  template <typename T>
  bool operator()(const T* a, const T* b, T* res) const {
    res[0] = (b[0] - a[0]) * T(inv_sigma);
    return true;
  }
};

struct ScalarPriorCost {
  double mean;
  double inv_sigma;
  template <typename T>
  bool operator()(const T* x, T* res) const {
    res[0] = (x[0] - T(mean)) * T(inv_sigma);
    return true;
  }
};

}  // namespace

struct PoseGraph::Impl {
  struct Node {
    TimeNs stamp{0};
    std::uint32_t segment{0};      // the caller's segment value
    std::size_t seg{0};            // index into segments
    Eigen::Vector3d odo_p{Eigen::Vector3d::Zero()};
    Eigen::Quaterniond odo_q{Eigen::Quaterniond::Identity()};
    std::size_t knot{0};           // its segment's scale knot of the step from the previous node (0 for the first)
    double p[3]{0, 0, 0};          // state: position in the map frame [m]
    double q[4]{0, 0, 0, 1};       // state: body-to-map rotation, Eigen order (x, y, z, w)
    bool has_gps{false};
    Eigen::Vector3d gps{Eigen::Vector3d::Zero()};
    double gps_sigma_h{1.0};
    std::size_t fix_a{0}, fix_b{0};  // the fixes it was interpolated from (equal for an exact hit)
  };
  struct Knot {
    TimeNs start{0};                 // [ns] time of the first step on it
    double log_scale{0};
    // The between-factors on this knot that left the window (both nodes constant) depend on its scale
    // alone: sum |a - s b|^2 / sigma^2 = B (s - A/B)^2 + const, kept as A and B (faded over window_frames).
    double info_a{0}, info_b{0};
  };
  struct Segment {
    std::uint32_t id{0};
    std::size_t first{0}, last{0};   // node indices
    std::vector<Knot> knots;         // never empty once the segment has a node; newest = current scale
    bool aligned{false};
    bool initialised{false};
    bool pending{false};             // aligned, waiting for its first solve
    std::size_t fixes{0};            // distinct fixes in its GPS factors
    std::size_t newest_fix{std::numeric_limits<std::size_t>::max()};
    Eigen::Vector3d first_fix{Eigen::Vector3d::Zero()};
    double spread{0};                // [m] largest distance of a fix from the first one
    std::size_t info_until{0};       // pairs (k-1, k) with k < info_until are in their knot's A and B
  };
  struct Fix {
    TimeNs stamp{0};
    Eigen::Vector3d enu{Eigen::Vector3d::Zero()};
    double sigma_h{0};
    bool removed{false};             // dropped by the alignment's outlier trimming
  };

  PoseGraphParams prm;
  PoseGraphStats st;
  std::vector<Node> nodes;
  std::vector<Segment> segments;
  std::vector<Fix> fixes;            // accepted fixes, in time order
  bool have_fix_stamp{false};
  TimeNs last_fix_stamp{0};          // newest fix received in order (accepted or gated)
  int consecutive_gated{0};
  int frames_since_solve{0};
  ceres::EigenQuaternionManifold quat_manifold;
  std::unique_ptr<ceres::LossFunction> gps_loss;

  explicit Impl(const PoseGraphParams& p) : prm(p) {
    if (prm.gps_robust_sigmas > 0) gps_loss = std::make_unique<ceres::CauchyLoss>(prm.gps_robust_sigmas);
  }

  // ---- node state helpers ----
  static Eigen::Vector3d pos(const Node& n) { return {n.p[0], n.p[1], n.p[2]}; }
  static Eigen::Quaterniond rot(const Node& n) { return Eigen::Quaterniond(n.q[3], n.q[0], n.q[1], n.q[2]); }
  static void set_state(Node& n, const Eigen::Vector3d& p, const Eigen::Quaterniond& q) {
    const Eigen::Quaterniond u = q.normalized();
    n.p[0] = p.x();
    n.p[1] = p.y();
    n.p[2] = p.z();
    n.q[0] = u.x();
    n.q[1] = u.y();
    n.q[2] = u.z();
    n.q[3] = u.w();
  }
  // Node j predicted from node i of the same segment by the odometry and the scale of j's knot.
  void chain(const Node& from, Node& to) const {
    const double s = std::exp(segments[from.seg].knots[to.knot].log_scale);
    const Eigen::Quaterniond qf = rot(from);
    const Eigen::Vector3d dp = from.odo_q.conjugate() * (to.odo_p - from.odo_p);
    const Eigen::Quaterniond dq = from.odo_q.conjugate() * to.odo_q;
    set_state(to, pos(from) + qf * (s * dp), qf * dq);
  }

  [[nodiscard]] const Segment* find_segment(std::uint32_t id) const noexcept {
    for (auto it = segments.rbegin(); it != segments.rend(); ++it)
      if (it->id == id) return &*it;
    return nullptr;
  }

  // ---- frames ----
  NodeId add_frame(TimeNs stamp, std::uint32_t segment, const Pose3& odo) {
    if (!nodes.empty() && stamp <= nodes.back().stamp) {
      ++st.frames_rejected;
      return kNoNode;
    }
    Node n;
    n.stamp = stamp;
    n.segment = segment;
    const Eigen::Isometry3d t = to_isometry(odo);
    n.odo_p = t.translation();
    n.odo_q = Eigen::Quaterniond(t.linear()).normalized();
    const std::size_t idx = nodes.size();
    const bool new_segment = segments.empty() || nodes.back().segment != segment;
    if (new_segment) {
      start_segment(n, idx);
    } else {
      n.seg = segments.size() - 1;
      Segment& s = segments[n.seg];
      n.knot = s.knots.size() - 1;
      // A new knot once the step (its midpoint) lies scale_knot_s after the newest knot's start; a long
      // gap makes one knot, not many (the random-walk prior then spans the gap).
      const TimeNs mid = nodes.back().stamp + (stamp - nodes.back().stamp) / 2;
      if (prm.scale_knot_s > 0 && to_seconds(mid - s.knots.back().start) >= prm.scale_knot_s) {
        s.knots.push_back(Knot{mid, s.knots.back().log_scale, 0.0, 0.0});
        n.knot = s.knots.size() - 1;
        ++st.scale_knots;
      }
      chain(nodes.back(), n);
    }
    segments[n.seg].last = idx;
    nodes.push_back(n);
    ++st.frames;
    ++frames_since_solve;
    // A frame at or before the newest fix: it lies between fixes already known.
    if (!fixes.empty() && stamp <= fixes.back().stamp) attach_to_node(idx);
    return static_cast<NodeId>(idx);
  }

  void start_segment(Node& n, std::size_t idx) {
    Segment s;
    s.id = n.segment;
    s.first = s.last = idx;
    s.knots.push_back(Knot{n.stamp, 0.0, 0.0, 0.0});
    ++st.scale_knots;
    n.knot = 0;
    Eigen::Vector3d p0 = Eigen::Vector3d::Zero();
    Eigen::Quaterniond q0 = n.odo_q;
    if (!segments.empty()) {
      // After a tracking loss: continue from the previous segment's last pose, at constant velocity,
      // with its body yaw (the odometry yaw of a new segment is arbitrary) and its scale.
      const Segment& prev = segments.back();
      const Node& last = nodes[prev.last];
      s.knots.front().log_scale = prev.knots.back().log_scale;
      p0 = pos(last);
      const std::size_t back = prev.last >= prev.first + 5 ? prev.last - 5 : prev.first;
      const double dt_v = to_seconds(last.stamp - nodes[back].stamp);
      if (dt_v > 0) {
        const Eigen::Vector3d v = (pos(last) - pos(nodes[back])) / dt_v;
        p0 += v * std::min(to_seconds(n.stamp - last.stamp), kMaxExtrapolationS);
      }
      const double dyaw = yaw_of(rot(last)) - yaw_of(n.odo_q);
      q0 = yaw_quaternion(dyaw) * n.odo_q;
    } else if (!fixes.empty() && std::abs(to_seconds(n.stamp - fixes.back().stamp)) <= prm.gps_max_interpolation_s) {
      p0 = fixes.back().enu;
    }
    set_state(n, p0, q0);
    n.seg = segments.size();
    segments.push_back(s);
    ++st.segments;
  }

  // ---- GPS ----
  bool add_gps(TimeNs stamp, const Eigen::Vector3d& enu, double sigma_h) {
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
  bool predict(TimeNs t, Eigen::Vector3d& p, std::size_t& seg) const {
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

  [[nodiscard]] double gate_distance(const Eigen::Vector3d& d) const {
    const double vf = prm.gps_vertical_factor > 0 ? prm.gps_vertical_factor : 1.0;
    return std::hypot(d.head<2>().norm(), d.z() / vf);
  }
  [[nodiscard]] double gate_limit(double sigma_h) const { return std::max(prm.gps_gate_sigmas * sigma_h, prm.gps_gate_floor_m); }

  bool beyond_gate(TimeNs t, const Eigen::Vector3d& enu, double sigma_h) const {
    if (prm.gps_gate_sigmas <= 0) return false;
    Eigen::Vector3d p;
    std::size_t seg = 0;
    if (!predict(t, p, seg) || !segments[seg].initialised) return false;
    return gate_distance(enu - p) > gate_limit(sigma_h);
  }

  // Gives node i its GPS factor if two consecutive fixes close enough in time bracket it (or one hits it).
  void attach_to_node(std::size_t i) {
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

  void drop_factor(Node& n) {
    if (!n.has_gps) return;
    n.has_gps = false;
    --st.gps_factors;
  }

  // Closed-form yaw/scale/translation of segment `si`'s odometry onto its GPS factors; drops the worst
  // fix while it lies beyond the gate. On success resets every node of the segment and marks it pending.
  void align(std::size_t si) {
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

  void recount(Segment& s) const {
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

  // ---- solve ----
  bool update(bool force) {
    bool pending = false;
    for (const Segment& s : segments) pending = pending || s.pending;
    // A young segment (its scale and yaw from a short baseline) is re-solved whenever it has grown by
    // a third, so that the predictions chained from it do not run away before the regular solve.
    int every = std::max(prm.solve_every_frames, 1);
    if (!segments.empty() && segments.back().aligned) {
      const auto age = static_cast<int>(std::min<std::size_t>(segments.back().last - segments.back().first + 1, 1U << 20));
      every = std::min(every, std::max(3, age / 4));
    }
    if (!force && !pending && frames_since_solve < every) return false;
    frames_since_solve = 0;
    if (nodes.empty()) return false;
    const double t0 = thread_cpu_ms();
    const bool ran = solve();
    if (!ran) return false;
    st.last_solve_ms = thread_cpu_ms() - t0;
    ++st.solves;
    return true;
  }

  // Folds the between-factors whose nodes are both older than w0 (held constant from now on) into their
  // segment's scale information.
  void accumulate_scale_info(std::size_t w0) {
    const double inv_var = 1.0 / (std::max(prm.between_sigma_m, 1e-9) * std::max(prm.between_sigma_m, 1e-9));
    const double fade = std::exp(-1.0 / static_cast<double>(std::max(prm.window_frames, 1)));
    for (Segment& s : segments) {
      if (!s.aligned || s.pending) continue;
      std::size_t k = std::max(s.info_until, s.first + 1);
      const std::size_t end = std::min(w0, s.last + 1);  // pairs (k-1, k) with k < w0
      for (; k < end; ++k) {
        const Node& m = nodes[k - 1];
        const Node& n = nodes[k];
        const Eigen::Vector3d a = rot(m).conjugate() * (pos(n) - pos(m));
        const Eigen::Vector3d b = m.odo_q.conjugate() * (n.odo_p - m.odo_p);
        Knot& kn = s.knots[n.knot];
        kn.info_a = fade * kn.info_a + inv_var * a.dot(b);
        kn.info_b = fade * kn.info_b + inv_var * b.squaredNorm();
      }
      s.info_until = std::max(s.info_until, k);
    }
  }

  bool solve() {
    const std::size_t n_nodes = nodes.size();
    std::size_t w0 = prm.window_frames > 0 && n_nodes > static_cast<std::size_t>(prm.window_frames)
                         ? n_nodes - static_cast<std::size_t>(prm.window_frames)
                         : 0;
    // A segment's first solve covers all of it (it was placed by the alignment only).
    for (const Segment& s : segments)
      if (s.pending && s.last >= w0) w0 = std::min(w0, s.first);
    accumulate_scale_info(w0);

    ceres::Problem::Options popts;
    popts.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    popts.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    popts.enable_fast_removal = false;
    ceres::Problem problem(popts);

    const double inv_bt = 1.0 / std::max(prm.between_sigma_m, 1e-9);
    const double inv_br = 1.0 / std::max(prm.between_sigma_rad, 1e-9);
    const bool gravity = prm.gravity_sigma_rad > 0;
    const double inv_g = gravity ? 1.0 / prm.gravity_sigma_rad : 0.0;
    const double vf = prm.gps_vertical_factor > 0 ? prm.gps_vertical_factor : 1.0;

    std::vector<std::size_t> segs_in;
    std::size_t variable_nodes = 0;
    const auto add_node = [&](Node& n, bool constant) {
      problem.AddParameterBlock(n.p, 3);
      problem.AddParameterBlock(n.q, 4, &quat_manifold);
      if (constant) {
        problem.SetParameterBlockConstant(n.p);
        problem.SetParameterBlockConstant(n.q);
      }
    };
    for (std::size_t i = w0; i < n_nodes; ++i) {
      Node& n = nodes[i];
      Segment& s = segments[n.seg];
      if (!s.aligned) continue;
      add_node(n, false);
      ++variable_nodes;
      if (segs_in.empty() || segs_in.back() != n.seg) segs_in.push_back(n.seg);
      if (i > s.first) {
        Node& m = nodes[i - 1];
        if (i - 1 < w0) add_node(m, true);
        const Eigen::Quaterniond qinv = m.odo_q.conjugate();
        auto* c = new ceres::AutoDiffCostFunction<BetweenCost, 6, 3, 4, 3, 4, 1>(
            new BetweenCost{qinv * (n.odo_p - m.odo_p), (qinv * n.odo_q).normalized(), inv_bt, inv_br});
        problem.AddResidualBlock(c, nullptr, m.p, m.q, n.p, n.q, &s.knots[n.knot].log_scale);
      }
      if (gravity) {
        auto* c = new ceres::AutoDiffCostFunction<GravityCost, 3, 4>(
            new GravityCost{n.odo_q.conjugate() * Eigen::Vector3d::UnitZ(), inv_g});
        problem.AddResidualBlock(c, nullptr, n.q);
      }
      if (n.has_gps) {
        const double ih = 1.0 / n.gps_sigma_h;
        auto* c = new ceres::AutoDiffCostFunction<GpsCost, 3, 3>(new GpsCost{n.gps, Eigen::Vector3d(ih, ih, ih / vf)});
        problem.AddResidualBlock(c, gps_loss.get(), n.p);
      }
    }
    if (variable_nodes == 0) return false;
    // Free knots: from the knot of the segment's first step in the window to its newest; the knot before
    // them is held constant and pulls the first free one through the random-walk prior.
    std::vector<double*> free_knots;
    const double drift = std::max(prm.scale_drift_per_sqrt_s, 1e-9);
    for (const std::size_t si : segs_in) {
      Segment& s = segments[si];
      const std::size_t k0 = nodes[std::max(w0, s.first)].knot;
      for (std::size_t k = k0; k < s.knots.size(); ++k) {
        Knot& kn = s.knots[k];
        if (!problem.HasParameterBlock(&kn.log_scale)) problem.AddParameterBlock(&kn.log_scale, 1);
        free_knots.push_back(&kn.log_scale);
        if (kn.info_b > 1e-9) {
          auto* c = new ceres::AutoDiffCostFunction<ScaleInfoCost, 1, 1>(new ScaleInfoCost{kn.info_a / kn.info_b, std::sqrt(kn.info_b)});
          problem.AddResidualBlock(c, nullptr, &kn.log_scale);
        }
        auto* c = new ceres::AutoDiffCostFunction<ScalarPriorCost, 1, 1>(new ScalarPriorCost{kn.log_scale, 1.0 / kScaleMemorySigma});
        problem.AddResidualBlock(c, nullptr, &kn.log_scale);
        if (k == 0) continue;
        Knot& prev = s.knots[k - 1];
        if (k == k0) {
          problem.AddParameterBlock(&prev.log_scale, 1);
          problem.SetParameterBlockConstant(&prev.log_scale);
        }
        const double dt = std::max(to_seconds(kn.start - prev.start), 1e-3);
        auto* w = new ceres::AutoDiffCostFunction<RandomWalkCost, 1, 1, 1>(new RandomWalkCost{1.0 / (drift * std::sqrt(dt))});
        problem.AddResidualBlock(w, nullptr, &prev.log_scale, &kn.log_scale);
      }
    }

    // Backup, in case the solver fails.
    std::vector<std::array<double, 7>> backup;
    backup.reserve(n_nodes - w0);
    for (std::size_t i = w0; i < n_nodes; ++i) {
      const Node& n = nodes[i];
      backup.push_back({n.p[0], n.p[1], n.p[2], n.q[0], n.q[1], n.q[2], n.q[3]});
    }
    std::vector<double> scale_backup;
    scale_backup.reserve(free_knots.size());
    for (const double* k : free_knots) scale_backup.push_back(*k);

    ceres::Solver::Options o;
    o.minimizer_type = ceres::TRUST_REGION;
    o.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
    o.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
    o.sparse_linear_algebra_library_type = ceres::EIGEN_SPARSE;
    o.num_threads = 1;
    o.max_num_iterations = std::max(prm.max_iterations, 1);
    o.logging_type = ceres::SILENT;
    o.minimizer_progress_to_stdout = false;
    ceres::Solver::Summary summary;
    ceres::Solve(o, &problem, &summary);

    bool ok = summary.termination_type != ceres::FAILURE && std::isfinite(summary.final_cost);
    for (const double* k : free_knots) ok = ok && std::isfinite(*k);
    if (!ok) {
      for (std::size_t i = w0; i < n_nodes; ++i) {
        Node& n = nodes[i];
        const auto& b = backup[i - w0];
        std::copy(b.begin(), b.begin() + 3, n.p);
        std::copy(b.begin() + 3, b.end(), n.q);
      }
      for (std::size_t k = 0; k < free_knots.size(); ++k) *free_knots[k] = scale_backup[k];
      return false;
    }
    for (std::size_t i = w0; i < n_nodes; ++i) {
      Node& n = nodes[i];
      if (segments[n.seg].aligned) set_state(n, pos(n), rot(n));
    }
    for (const std::size_t si : segs_in) {
      Segment& s = segments[si];
      s.pending = false;
      s.initialised = std::isfinite(s.knots.back().log_scale) && std::exp(s.knots.back().log_scale) > 0;
    }
    st.last_final_cost = summary.final_cost;
    st.last_free_nodes = variable_nodes;
    st.last_iterations = static_cast<std::uint64_t>(summary.iterations.size());
    st.last_free_knots = free_knots.size();
    return true;
  }
};

PoseGraph::PoseGraph(const PoseGraphParams& params) : impl_(std::make_unique<Impl>(params)) {}
PoseGraph::~PoseGraph() = default;

NodeId PoseGraph::add_frame(TimeNs stamp, std::uint32_t segment, const Pose3& odometry_pose) {
  return impl_->add_frame(stamp, segment, odometry_pose);
}

bool PoseGraph::add_gps(TimeNs stamp, const Eigen::Vector3d& enu, double sigma_h_m) { return impl_->add_gps(stamp, enu, sigma_h_m); }

bool PoseGraph::update(bool force) { return impl_->update(force); }

bool PoseGraph::initialised() const noexcept {
  return !impl_->nodes.empty() && impl_->segments[impl_->nodes.back().seg].initialised;
}

bool PoseGraph::segment_initialised(std::uint32_t segment) const noexcept {
  const auto* s = impl_->find_segment(segment);
  return s != nullptr && s->initialised;
}

Eigen::Isometry3d PoseGraph::pose(NodeId node) const noexcept {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  if (node < 0 || static_cast<std::size_t>(node) >= impl_->nodes.size()) return t;
  const auto& n = impl_->nodes[static_cast<std::size_t>(node)];
  t.linear() = Impl::rot(n).normalized().toRotationMatrix();
  t.translation() = Impl::pos(n);
  return t;
}

TimeNs PoseGraph::stamp(NodeId node) const noexcept {
  if (node < 0 || static_cast<std::size_t>(node) >= impl_->nodes.size()) return 0;
  return impl_->nodes[static_cast<std::size_t>(node)].stamp;
}

std::uint32_t PoseGraph::segment_of(NodeId node) const noexcept {
  if (node < 0 || static_cast<std::size_t>(node) >= impl_->nodes.size()) return 0;
  return impl_->nodes[static_cast<std::size_t>(node)].segment;
}

double PoseGraph::scale(std::uint32_t segment) const noexcept {
  const auto* s = impl_->find_segment(segment);
  return s != nullptr && !s->knots.empty() ? std::exp(s->knots.back().log_scale) : 0.0;
}

double PoseGraph::scale_at(NodeId node) const noexcept {
  if (node < 0 || static_cast<std::size_t>(node) >= impl_->nodes.size()) return 0.0;
  const auto& n = impl_->nodes[static_cast<std::size_t>(node)];
  return std::exp(impl_->segments[n.seg].knots[n.knot].log_scale);
}

std::size_t PoseGraph::size() const noexcept { return impl_->nodes.size(); }

NodeId PoseGraph::last() const noexcept { return impl_->nodes.empty() ? kNoNode : static_cast<NodeId>(impl_->nodes.size() - 1); }

const PoseGraphStats& PoseGraph::stats() const noexcept { return impl_->st; }

const PoseGraphParams& PoseGraph::params() const noexcept { return impl_->prm; }

}  // namespace ag::mapping
