// PoseGraph::Impl, the pose graph's state, shared by pose_graph.cpp (frames and segments),
// pose_graph_gps.cpp (GPS factors, gate, alignment) and pose_graph_solve.cpp (the Ceres solves).
#pragma once

#include <ceres/loss_function.h>
#include <ceres/manifold.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include "airground/aerial_mapping/pose_graph.hpp"

namespace ag::mapping {
namespace detail {

inline Eigen::Quaterniond yaw_quaternion(double yaw) { return Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ())); }

}  // namespace detail

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

  // ---- frames (pose_graph.cpp) ----
  NodeId add_frame(TimeNs stamp, std::uint32_t segment, const Pose3& odo);
  void start_segment(Node& n, std::size_t idx);

  // ---- GPS (pose_graph_gps.cpp) ----
  bool add_gps(TimeNs stamp, const Eigen::Vector3d& enu, double sigma_h);
  bool predict(TimeNs t, Eigen::Vector3d& p, std::size_t& seg) const;
  [[nodiscard]] double gate_distance(const Eigen::Vector3d& d) const;
  [[nodiscard]] double gate_limit(double sigma_h) const;
  bool beyond_gate(TimeNs t, const Eigen::Vector3d& enu, double sigma_h) const;
  void attach_to_node(std::size_t i);
  void drop_factor(Node& n);
  void align(std::size_t si);
  void recount(Segment& s) const;

  // ---- solve (pose_graph_solve.cpp) ----
  bool update(bool force);
  void accumulate_scale_info(std::size_t w0);
  bool solve();
};

}  // namespace ag::mapping
