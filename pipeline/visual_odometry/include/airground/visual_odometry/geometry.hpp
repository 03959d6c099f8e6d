// Two-view and pose geometry of the VO on normalised (undistorted) image coordinates: translation with
// a known rotation (the essential matrix E = [t]x R when the autopilot gives R), triangulation, and the
// camera pose against map points (PnP) by RANSAC on the translation and a robust 6-DoF refinement
// with the autopilot's gravity as a prior.
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <span>

namespace ag::vo {

// World-to-camera transform: x_cam = R * X_world + t (camera frame: OpenCV, x right, y down, z forward).
struct CameraPose {
  Eigen::Matrix3d R{Eigen::Matrix3d::Identity()};
  Eigen::Vector3d t{Eigen::Vector3d::Zero()};

  [[nodiscard]] Eigen::Vector3d centre() const noexcept { return -R.transpose() * t; }
  [[nodiscard]] Eigen::Vector3d to_camera(const Eigen::Vector3d& X) const noexcept { return R * X + t; }
};

// The camera pose that sees world point X at normalised coordinates; inverse of a pose.
[[nodiscard]] CameraPose inverse(const CameraPose& p) noexcept;
// a then b: x = b(a(X)).
[[nodiscard]] CameraPose compose(const CameraPose& a, const CameraPose& b) noexcept;
// Rotation exp map (Rodrigues).
[[nodiscard]] Eigen::Matrix3d so3_exp(const Eigen::Vector3d& w) noexcept;

// Deterministic sampling for RANSAC (splitmix64): the same inputs give the same answer on every run.
class SampleStream {
 public:
  explicit SampleStream(std::uint64_t seed) noexcept : s_(seed) {}
  [[nodiscard]] std::uint64_t next() noexcept;
  [[nodiscard]] std::size_t below(std::size_t n) noexcept { return static_cast<std::size_t>(next() % n); }

 private:
  std::uint64_t s_;
};

struct RansacParams {
  int iterations{60};
  double threshold{2.0 / 483.5};  // [normalised units] ~2 px at fx 483.5
  double min_inlier_ratio{0.5};
};

// Direction of t21 (x2 ~ R21 * x1 + t21) from correspondences with a known rotation: each pair gives
// t . ((R21 x1) x x2) = 0; two pairs are a minimal sample. Returns the unit translation (sign such that
// most points lie in front of both cameras) and marks inliers; false if no consensus.
bool translation_known_rotation(std::span<const Eigen::Vector2d> x1, std::span<const Eigen::Vector2d> x2,
                                const Eigen::Matrix3d& R21, const RansacParams& p, SampleStream& rng,
                                Eigen::Vector3d& t21, std::span<std::uint8_t> inlier) noexcept;

// Linear triangulation (two views) of normalised observations; false if behind either camera or the
// rays are nearly parallel (angle below min_parallax_rad).
bool triangulate(const CameraPose& a, const Eigen::Vector2d& xa, const CameraPose& b, const Eigen::Vector2d& xb,
                 double min_parallax_rad, Eigen::Vector3d& X) noexcept;

// Squared reprojection error [normalised^2]; +inf behind the camera.
[[nodiscard]] double reprojection_error2(const CameraPose& p, const Eigen::Vector3d& X, const Eigen::Vector2d& x) noexcept;

struct PoseRefineParams {
  int iterations{8};
  double huber{1.5 / 483.5};        // [normalised] Huber threshold of a reprojection residual
  double gravity_sigma_rad{0.005};  // prior on the camera's "up" direction from the autopilot; <=0 off
  double pixel_sigma{1.0 / 483.5};  // [normalised] a reprojection residual's sigma
};

// The camera's "up" (world +z) expressed in the camera frame, as the autopilot sees it; valid = false
// when there is no attitude.
struct GravityPrior {
  Eigen::Vector3d up_in_camera{0, 0, -1};
  bool valid{false};
};

// Camera pose from 3D-2D matches: RANSAC over the translation with the rotation held at `pose.R`
// (predicted from the autopilot or the previous frame), then a robust Gauss-Newton on all six degrees of
// freedom over the inliers, with the gravity prior. `pose` holds the prediction on entry.
// Returns the number of inliers (marked in `inlier`).
int solve_pose(std::span<const Eigen::Vector3d> X, std::span<const Eigen::Vector2d> x, const GravityPrior& g,
               const RansacParams& rp, const PoseRefineParams& pp, SampleStream& rng, CameraPose& pose,
               std::span<std::uint8_t> inlier) noexcept;

// Robust 6-DoF refinement only (the second half of solve_pose), over the points marked in `use`.
void refine_pose(std::span<const Eigen::Vector3d> X, std::span<const Eigen::Vector2d> x, std::span<const std::uint8_t> use,
                 const GravityPrior& g, const PoseRefineParams& pp, CameraPose& pose) noexcept;

}  // namespace ag::vo
