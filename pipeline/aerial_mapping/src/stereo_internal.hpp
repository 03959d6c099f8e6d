// Private parts of DenseStereo: the rectification planner and the StereoBM-equivalent block matcher.
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <string>
#include <vector>

#include "airground/aerial_mapping/stereo.hpp"
#include "airground/messages/camera.hpp"
#include "airground/platform/result.hpp"

namespace ag::mapping::detail {

// Rotations of cv::stereoRectify for two cameras, except that the baseline always becomes the x axis
// (OpenCV picks x or y, whichever the baseline is closer to) with the `other` camera at +x, so that
// `reference` is the left image. `other_from_reference` is R, T with X_other = R X_ref + T.
// rect_from_reference = wR * Q * r_r^T and rect_from_other = wR * Q * r_r, with r_r the half rotation
// of R's Rodrigues vector, Q the quarter turn (k * 90 degrees about z) that brings r_r * T nearest to -x,
// and wR OpenCV's smallest rotation taking Q * r_r * T onto -x. This is exactly what cv::stereoRectify
// returns for the same cameras turned by Q about their optical axes (R1 * Q, R2 * Q); the rectified z is
// the mean optical axis tilted by the baseline's elevation.
struct RectifyRotations {
  Eigen::Matrix3d rect_from_reference, rect_from_other;
};
[[nodiscard]] RectifyRotations rectify_rotations(const Eigen::Matrix3d& other_from_reference_r,
                                                 const Eigen::Vector3d& other_from_reference_t);

// Chooses the rectified image window of a pair: focal length = camera.fx, rows = where both cameras'
// content overlaps (+ block margin), columns = the reference content that a disparity in
// [min_disparity, max_disparity] whose depth f * baseline / d is in [min_depth_m, max_depth_m] can
// match, shifted right by the matcher's dead band (max disparity + half block) so that StereoBM's first
// valid column falls on the first matchable column. The window is clamped to max_width x max_height.
// Errors when the pair cannot overlap.
Result<RectifiedGeometry> plan_rectification(const PinholeCamera& camera, const StereoParams& params,
                                             int max_width, int max_height,
                                             const Eigen::Isometry3d& map_from_reference,
                                             const Eigen::Isometry3d& map_from_other);

// The largest squared radius (x/z)^2 + (y/z)^2 of a ray through the image border, undistorted.
[[nodiscard]] double max_undistorted_r2(const PinholeCamera& camera);

// Rays computed at once when building a rectified image (float vector lanes); row scratch buffers
// need width + kRectifyLanes floats each.
#if defined(__AVX2__)
inline constexpr int kRectifyLanes = 8;
#else
inline constexpr int kRectifyLanes = 4;
#endif

// One rectified image: per pixel the source position in the distorted original (planar maps, -1
// without source), the bilinear grey value (rect, 0 without source) and invalid (1 without source).
// Rays further out than max_r2 (where a distortion polynomial may fold back) have no source. scratch:
// 2 * (width + kRectifyLanes) floats.
void build_rectified(const PinholeCamera& camera, const RectifiedGeometry& geometry,
                     const Eigen::Matrix3d& rect_from_camera, double max_r2, const std::uint8_t* grey,
                     float* map_x, float* map_y, std::uint8_t* rect, std::uint8_t* invalid, float* scratch);

// valid = 1 where no invalid pixel lies within `radius` (square window); tmp: width * height bytes,
// pad: width + 2 * radius + 64 bytes.
void dilate_invalid(const std::uint8_t* invalid, int width, int height, int radius, std::uint8_t* valid,
                    std::uint8_t* tmp, std::uint8_t* pad);

// StereoBM with PREFILTER_XSOBEL on two rectified grey images of up to max_width x max_height, the same
// results as cv::StereoBM::compute into CV_16S (1/16 px, invalid = (min_disparity - 1) * 16) followed by
// its filterSpeckles, with speckle range speckle_range * 16 -- when lr_max_diff < 0. With lr_max_diff >= 0
// a left-right consistency check (cv::StereoSGBM's disp12MaxDiff) runs between matching and the speckle
// filter: the right image's disparity at column x_r is the d minimising SAD(x_r + d, d) over the textured
// left blocks (taken from the same SAD vectors, no second match), and a left disparity d (1/16 px) is
// invalidated when the right disparities at both x - floor(d) and x - ceil(d) exist and differ from
// floor(d) resp. ceil(d) by more than lr_max_diff. Every buffer is allocated in the constructor.
class BlockMatcher {
 public:
  BlockMatcher(const StereoParams& params, int max_width, int max_height);

  // left, right: width x height grey, row-major, no padding; disp: width x height.
  void compute(const std::uint8_t* left, const std::uint8_t* right, int width, int height, std::int16_t* disp);
  [[nodiscard]] std::int16_t filtered_value() const noexcept { return filtered_; }
  // Left disparities the left-right check removed in the last compute() (before the speckle filter).
  [[nodiscard]] std::uint64_t lr_rejected() const noexcept { return lr_rejected_; }

 private:
  void prefilter(const std::uint8_t* src, int width, int height, std::uint8_t* dst) const;
  void match(int width, int height, std::int16_t* disp);
  void filter_speckles(std::int16_t* disp, int width, int height);

  StereoParams p_;
  int max_width_, max_height_;
  int ndisp_, max_disp_, half_;
  std::int16_t filtered_;
  std::uint64_t lr_rejected_{0};
  std::vector<std::uint8_t> pre_left_, pre_right_;
  std::vector<std::uint16_t> colsad_;   // [column][disparity index] vertical SAD sums of the current row band
  std::vector<std::uint16_t> sad_;      // [disparity index] the sliding block SAD
  std::vector<std::int32_t> coltex_;    // [column] vertical sums of |prefiltered - cap|
  std::vector<std::uint16_t> rcost_;    // left-right check, per right column of the current row: least SAD
  std::vector<std::uint16_t> rcol_;     //   and the left column it came from (0 = none)
  std::vector<std::uint32_t> labels_;   // speckle filter: region label per pixel (0 = none)
  std::vector<std::uint32_t> stack_;    // speckle filter: wavefront of pixel indices
  std::vector<std::uint8_t> small_;     // speckle filter: per label, 1 = region too small
};

}  // namespace ag::mapping::detail
