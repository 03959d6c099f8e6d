// Bundle adjustment of a sliding window of keyframes: Levenberg-Marquardt on the reprojection errors
// (Huber) of every map point the window sees, with the autopilot's gravity as a prior on each free
// keyframe, solved through the Schur complement on the keyframes. All buffers are sized at
// construction: solve() never allocates (Ceres would, in every Solve; the unit test checks this solver
// against Ceres on the same problems).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <span>
#include <vector>

#include "airground/visual_odometry/geometry.hpp"

namespace ag::vo {

struct BaObservation {
  std::int32_t keyframe{0};  // index into the poses span
  std::int32_t point{0};     // index into the points span
  Eigen::Vector2d x{0, 0};   // normalised image coordinates
};

struct WindowAdjustmentParams {
  int iterations{6};
  double pixel_sigma{1.0 / 483.5};    // [normalised] a reprojection residual's sigma
  double huber_sigmas{2.0};           // Huber threshold in sigmas
  double gravity_sigma_rad{0.005};    // prior on each free keyframe's up direction; <= 0 off
  double initial_lambda{1e-4};
};

struct WindowAdjustmentReport {
  int iterations{0};
  double initial_cost{0}, final_cost{0};  // 0.5 * sum of robustified squared whitened residuals
  int free_keyframes{0}, points{0}, observations{0};
};

inline constexpr int kMaxWindowKeyframes = 12;  // the Schur system lives on the stack below this

class WindowAdjustment {
 public:
  using SchurMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, 6 * kMaxWindowKeyframes, 6 * kMaxWindowKeyframes>;
  using SchurVector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, 6 * kMaxWindowKeyframes, 1>;

  WindowAdjustment(int max_keyframes, int max_points, int max_observations);

  // Refines the free keyframes' poses (fixed[k] == 0) and every point in place. Observations of a point
  // must be contiguous in `obs` (grouped by point). Points seen by fewer than two keyframes still move
  // only when one of their keyframes is free; observations of points with a non-finite position are skipped.
  WindowAdjustmentReport solve(std::span<CameraPose> poses, std::span<const std::uint8_t> fixed,
                               std::span<const GravityPrior> gravity, std::span<Eigen::Vector3d> points,
                               std::span<const BaObservation> obs, const WindowAdjustmentParams& p) noexcept;

 private:
  double cost(std::span<const CameraPose> poses, std::span<const GravityPrior> gravity, std::span<const std::uint8_t> fixed,
              std::span<const Eigen::Vector3d> points, std::span<const BaObservation> obs, const WindowAdjustmentParams& p) const noexcept;

  int max_kf_, max_pts_, max_obs_;
  std::vector<int> free_index_;                    // keyframe -> free index or -1
  std::vector<Eigen::Matrix<double, 6, 3>> hcp_;   // per observation
  std::vector<Eigen::Matrix3d> hpp_inv_;           // per point
  std::vector<Eigen::Vector3d> bp_;                // per point
  std::vector<CameraPose> saved_poses_;
  std::vector<Eigen::Vector3d> saved_points_;
  SchurMatrix S_;
  SchurVector s_, dc_;
};

}  // namespace ag::vo
