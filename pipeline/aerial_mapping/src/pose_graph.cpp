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
//
// This file: frames and segments, and the public interface; pose_graph_gps.cpp: GPS factors, the gate
// and the alignment; pose_graph_solve.cpp: the solves.
#include "airground/aerial_mapping/pose_graph.hpp"

#include <algorithm>
#include <cmath>

#include "airground/messages/pose_math.hpp"
#include "pose_graph_internal.hpp"

namespace ag::mapping {
namespace {

// [s] the anchor of a new segment is extrapolated at constant velocity over at most this long a gap.
constexpr double kMaxExtrapolationS = 5.0;

double yaw_of(const Eigen::Quaterniond& q) {
  const Eigen::Matrix3d r = q.toRotationMatrix();
  return std::atan2(r(1, 0), r(0, 0));
}

}  // namespace

using detail::yaw_quaternion;

NodeId PoseGraph::Impl::add_frame(TimeNs stamp, std::uint32_t segment, const Pose3& odo) {
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

void PoseGraph::Impl::start_segment(Node& n, std::size_t idx) {
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
