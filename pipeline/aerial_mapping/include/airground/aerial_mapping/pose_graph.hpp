// The ASOOM pose graph on Ceres: one node per camera frame (body pose in the map frame), odometry
// between-factors whose translation is multiplied by the scale of the frame's odometry segment at the
// frame's time (monocular scale drifts: a log-scale knot every scale_knot_s seconds of the segment, tied
// to the previous knot by a random-walk prior),
// roll/pitch factors from the gravity-aligned odometry, and position-only GPS factors interpolated to
// frame times with a sigma that grows with the gap. After a tracking loss the odometry restarts in a new
// segment (own origin, yaw and scale): no between-factor links it to the previous one, GPS places it.
// Bounded cost: only the newest `window_frames` nodes are free in a solve, older ones are held constant.
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <memory>
#include <vector>

#include "airground/messages/geometry.hpp"
#include "airground/platform/time.hpp"

namespace ag::mapping {

struct PoseGraphParams {
  double between_sigma_m{0.05};       // [m] per frame-to-frame odometry factor, translation (ASOOM)
  double between_sigma_rad{0.05};     // [rad] the same, rotation (ASOOM)
  double gravity_sigma_rad{0.02};     // [rad] roll and pitch from the gravity-aligned odometry; 0 = off
  double gps_sigma_m{0.5};            // [m] horizontal sigma of an interpolated fix at zero gap (ASOOM)
  double gps_sigma_per_gap_s{0.5};    // [m/s] added per second between the frame and the nearer fix (ASOOM)
  double gps_vertical_factor{2.0};    // [-] vertical sigma = factor x horizontal
  double gps_max_interpolation_s{1.0};  // [s] fixes further apart than this are not interpolated between
  double gps_robust_sigmas{2.0};      // [-] Cauchy loss scale on GPS residuals, in sigmas
  double gps_gate_sigmas{6.0};        // [-] once initialised, a fix further than this from the estimate is rejected
  double gps_gate_floor_m{5.0};       // [m] ... but never a fix closer than this
  int solve_every_frames{30};         // solve after this many new frames (ASOOM: ~30)
  int window_frames{600};             // [frames] free nodes per solve; older nodes held constant; 0 = all
  int min_gps_fixes{3};               // GPS fixes a segment needs before it counts as initialised
  double min_gps_baseline_m{4.0};     // [m] spread of those fixes (scale and yaw need motion)
  int max_iterations{30};             // Levenberg-Marquardt iterations per solve
  // Drifting monocular scale: piecewise-constant log-scale, one knot per scale_knot_s of a segment, each
  // between-factor on the knot of its time; consecutive knots tied by a random-walk prior of sigma
  // scale_drift_per_sqrt_s x sqrt(scale_knot_s). scale_knot_s = 0: one scale per segment (ASOOM).
  // 1, 2, 5 and 10 s measured alike (the random-walk prior sets how fast the scale may move).
  double scale_knot_s{2.0};           // [s] knot spacing; 0 = one scale per segment
  double scale_drift_per_sqrt_s{0.002};  // [1/sqrt(s)] random walk of the odometry's log-scale
};

using NodeId = std::int64_t;
inline constexpr NodeId kNoNode = -1;

struct PoseGraphStats {
  std::uint64_t frames{0};            // nodes added
  std::uint64_t frames_rejected{0};   // odometry stamped at or before the previous frame (out of order)
  std::uint64_t gps_fixes{0};         // fixes received
  std::uint64_t gps_rejected_order{0};  // fixes stamped at or before the previous fix
  std::uint64_t gps_rejected_gate{0}; // outliers refused by the gate
  std::uint64_t gps_factors{0};       // GPS factors in the graph
  std::uint64_t segments{0};          // odometry segments seen
  std::uint64_t solves{0};
  std::uint64_t scale_flips{0};       // solves whose scale came out negative and were re-solved flipped
  double last_solve_ms{0};            // [ms] thread CPU time of the last solve
  double last_final_cost{0};
  std::uint64_t last_free_nodes{0};   // nodes the last solve could move (<= window_frames, except a new segment's first solve)
  std::uint64_t last_iterations{0};   // Levenberg-Marquardt iterations of the last solve
  std::uint64_t last_free_knots{0};   // log-scale knots the last solve could move
  std::uint64_t scale_knots{0};       // log-scale knots in all segments
};

class PoseGraph {
 public:
  explicit PoseGraph(const PoseGraphParams& params = {});
  ~PoseGraph();
  PoseGraph(const PoseGraph&) = delete;
  PoseGraph& operator=(const PoseGraph&) = delete;

  // One camera frame's odometry: body pose in the segment's frame (position in odometry units, unknown
  // scale; roll and pitch gravity-aligned). Returns the node, or kNoNode (counted) when the stamp is not
  // after the previous frame's. A new `segment` value starts a new segment.
  NodeId add_frame(TimeNs stamp, std::uint32_t segment, const Pose3& odometry_pose);

  // A GPS fix in the map frame (ENU metres). sigma_h_m: receiver's 1-sigma horizontal accuracy; the
  // factor uses max(sigma_h_m, params.gps_sigma_m). Returns false (counted) for out-of-order fixes.
  // Fixes are interpolated to the frames that lie between two consecutive fixes.
  bool add_gps(TimeNs stamp, const Eigen::Vector3d& enu, double sigma_h_m);

  // Solves when `solve_every_frames` frames arrived since the last solve (or `force`). Returns true
  // when a solve ran. Warm-started; a negative scale is flipped and re-solved.
  bool update(bool force = false);

  // True once the newest frame's segment has enough GPS fixes spread far enough and a solve gave it a
  // positive scale: poses are then georeferenced and metric.
  [[nodiscard]] bool initialised() const noexcept;
  [[nodiscard]] bool segment_initialised(std::uint32_t segment) const noexcept;

  // Body pose in the map frame after the latest solve (frames added since are predicted from the
  // odometry of their segment). Undefined node ids return identity.
  [[nodiscard]] Eigen::Isometry3d pose(NodeId node) const noexcept;
  [[nodiscard]] TimeNs stamp(NodeId node) const noexcept;
  [[nodiscard]] std::uint32_t segment_of(NodeId node) const noexcept;
  // [m per odometry unit] the segment's current scale: its newest knot (0 for an unknown segment).
  [[nodiscard]] double scale(std::uint32_t segment) const noexcept;
  // [m per odometry unit] the scale the node's odometry step (from the previous node) is multiplied by;
  // 0 for an undefined node id.
  [[nodiscard]] double scale_at(NodeId node) const noexcept;
  [[nodiscard]] std::size_t size() const noexcept;                   // nodes
  [[nodiscard]] NodeId last() const noexcept;                        // newest node or kNoNode
  [[nodiscard]] const PoseGraphStats& stats() const noexcept;
  [[nodiscard]] const PoseGraphParams& params() const noexcept;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace ag::mapping
