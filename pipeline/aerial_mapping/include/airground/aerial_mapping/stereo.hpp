// Dense stereo between two keyframes of the nadir camera: rectify the pair for its real relative pose
// (the baseline becomes the rectified x axis, lens distortion removed), block-match (StereoBM's method:
// x-Sobel prefilter clipped to +-prefilter_cap, SAD over block_size^2, winner-take-all with texture and
// uniqueness checks, sub-pixel parabola, speckle filter) with a left-right consistency check before the
// speckle filter (StereoSGBM's disp12MaxDiff), mask invalid borders, drop disparities fattened over depth
// edges, and project every valid disparity to a point in the map frame carrying the colour (bilinear)
// and class (nearest neighbour) of the current frame. Eigen only (the static role binary cannot link
// OpenCV); tests compare against OpenCV's stereoRectify/initUndistortRectifyMap/StereoBM (with the
// left-right check and the edge guard off, the block matcher is exactly StereoBM).
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <memory>
#include <vector>

#include "airground/messages/camera.hpp"
#include "airground/platform/result.hpp"

namespace ag::mapping {

struct StereoParams {
  int min_disparity{1};           // [px] (ASOOM: 1)
  int num_disparities{112};       // [px] multiple of 16, tested up to 256; 112 covers a 30 m roof 10 m under a 2 m baseline at 640 px
                                  //      (a 10 m baseline at 50 m: ground ~97 px, 30 m roofs ~242 px, needs 256)
  int block_size{9};              // [px] odd (ASOOM: 9)
  int prefilter_cap{31};
  int texture_threshold{10};      // minimum sum of |prefiltered| over the block
  int uniqueness_ratio{10};       // [%] best SAD must beat every other (beyond +-1 px) by this margin
  int speckle_window{100};        // [px] connected regions of at most this many pixels are removed; 0 = off
  int speckle_range{2};           // [px] disparity step that still connects a region (StereoBM's speckleRange is in 1/16 px: 16x this)
  // Left-right check (StereoSGBM's disp12MaxDiff), before the speckle filter: the other image's disparity
  // per column is its own winner-take-all over the same SAD costs; a disparity that the other view's, at
  // the matched column, contradicts by more than this is dropped (occlusions, wrong matches). < 0 = off.
  int lr_max_diff{1};             // [px]
  int border_dilate_px{5};        // [px] the invalid (black) rectification border is grown by this
  // Foreground-fattening guard: a block straddling a depth edge takes the disparity of the side with more
  // texture, spreading roof disparities up to block_size / 2 px over the ground beside it. A disparity more
  // than edge_jump_px above the smallest valid one within edge_margin_px (square window, in the reference
  // image's columns and in the other image's, which catches the side next to an occlusion) is dropped.
  int edge_margin_px{4};          // [px] 0..64, 0 = off; ~block_size / 2
  int edge_jump_px{1};            // [px] 0..1000
  double min_depth_m{1.0};        // [m] (ASOOM: keep 1-150 m)
  double max_depth_m{150.0};      // [m]
  double min_baseline_m{0.5};     // [m] pairs closer than this are refused
};

// One keyframe: packed RGB (row-major, 3 bytes per pixel) and class ids of a `camera`-sized image, and
// the camera's pose in the map frame (camera frame: OpenCV x right, y down, z forward).
struct StereoImage {
  const std::uint8_t* rgb{nullptr};
  const std::uint8_t* cls{nullptr};
  Eigen::Isometry3d map_from_camera{Eigen::Isometry3d::Identity()};
};

struct MapPoint {
  float x, y, z;           // [m] map frame
  std::uint8_t r, g, b;    // colour of the current frame, bilinear
  std::uint8_t cls;        // class id of the current frame, nearest neighbour
  float cos_axis;          // cosine of the angle between the pixel's ray and the current camera's optical axis
};

struct StereoTiming {
  double rectify_ms{0}, match_ms{0}, project_ms{0};  // [ms] wall time of the three steps
  double edge_ms{0};                                  // [ms] the foreground-fattening guard (part of match_ms)
};

// The rectified pair of the last compute(). Both rectified cameras share rotation, intrinsics (no
// distortion) and size; the reference (current frame) is the left image and the other (previous
// keyframe) camera sits at (+baseline_m, 0, 0) in the reference's rectified frame, so a point at depth z
// is seen at x_other = x_ref - f * baseline_m / z (positive disparity). The baseline is the rectified x
// axis, so for the forward-flying nadir camera the rectified images are the originals turned by ~90
// degrees. Width, height and principal point are fitted per pair (see DenseStereo).
struct RectifiedGeometry {
  int width{0}, height{0};      // [px] of both rectified images
  double f{0}, cx{0}, cy{0};    // [px] shared pinhole intrinsics; f = camera.fx
  double baseline_m{0};         // [m] distance between the two camera centres
  Eigen::Matrix3d rect_from_reference{Eigen::Matrix3d::Identity()};  // rotation: reference camera -> rectified
  Eigen::Matrix3d rect_from_other{Eigen::Matrix3d::Identity()};      // rotation: other camera -> rectified
  Eigen::Isometry3d map_from_rect{Eigen::Isometry3d::Identity()};    // the reference's rectified camera
};

struct StereoStats {
  std::uint64_t pairs{0}, refused{0};  // pairs offered to compute(), and the refused ones among them
  std::uint64_t valid_disparities{0};  // in the last pair
  std::uint64_t lr_rejected{0};        // in the last pair: disparities the left-right check dropped (before the speckle filter)
  std::uint64_t edge_rejected{0};      // in the last pair: disparities the foreground-fattening guard dropped
};

// The rectified window: rows where both images have content (+ half a block), columns from the first
// reference column a disparity in range whose depth is in [min_depth_m, max_depth_m] can match to the
// last reference column, plus StereoBM's dead band (min_disparity + num_disparities - 1 + block_size / 2
// columns on the left, where it computes nothing) placed over pixels no disparity could match anyway.
// For the 640x400 nadir camera flying forward that is about 530x670 px with 112 disparities, 650x670 px
// with 256. Buffers are sized in the constructor for the largest window (any baseline direction in the
// image, the dead band of num_disparities included); a larger window is clamped (right columns,
// top/bottom rows).
class DenseStereo {
 public:
  // Precomputes what does not depend on the pair and allocates every buffer. Throws
  // std::invalid_argument for parameters StereoBM would refuse (num_disparities not a positive multiple
  // of 16, block_size not odd in [5, 255], block_size^2 * 2 * prefilter_cap >= 65536, prefilter_cap not in
  // [1, 63], min_disparity not in [0, 1000], negative texture_threshold / uniqueness_ratio / speckle
  // values, depth range not 0 <= min < max), an edge guard outside its range, or a camera without size.
  DenseStereo(const PinholeCamera& camera, const StereoParams& params);
  ~DenseStereo();
  DenseStereo(const DenseStereo&) = delete;
  DenseStereo& operator=(const DenseStereo&) = delete;

  // `prev` and `cur` must be images of `camera`; `cur` is the reference (left) image and gives the
  // points' colour and class. Appends points to `out` (cleared first) and returns their number; an error
  // (counted in stats().refused) for missing image data, a baseline below min_baseline_m, or a pair that
  // does not overlap: no common rectified rows/columns, a camera looking more than ~84 degrees off the
  // rectified axis (baseline along the view), or a baseline so long that the largest disparity searched
  // means a depth beyond max_depth_m. Allocation-free once `out` has grown to its working size.
  Result<std::size_t> compute(const StereoImage& prev, const StereoImage& cur, std::vector<MapPoint>& out,
                              StereoTiming* timing = nullptr);

  // The last pair's rectified grey images and disparity (for tests and debugging PNGs): disparity in
  // 1/16 px (StereoBM's fixed point), negative = invalid (also where the dilated black border of either
  // image is, and what the edge guard dropped); rectified size = rectified().width x rectified().height,
  // row-major.
  [[nodiscard]] const std::vector<std::uint8_t>& rectified_reference() const noexcept;
  [[nodiscard]] const std::vector<std::uint8_t>& rectified_other() const noexcept;
  [[nodiscard]] const std::vector<std::int16_t>& disparity() const noexcept;
  // The block matcher's own output before the border mask, as cv::StereoBM::compute into CV_16S followed
  // by its speckle filter: invalid = (min_disparity - 1) * 16 (StereoBM's convention). With the
  // left-right check on, the check runs between the two, so this is StereoBM's output minus the pixels
  // the check (and the speckle filter after it) dropped. For tests.
  [[nodiscard]] const std::vector<std::int16_t>& raw_disparity() const noexcept;
  // 1 where the rectified reference pixel has source pixels and is further than border_dilate_px from
  // any pixel that has none.
  [[nodiscard]] const std::vector<std::uint8_t>& valid_mask() const noexcept;
  // Remap tables: per rectified pixel, the source (x, y) in the original distorted image, like the two
  // CV_32FC1 maps of cv::initUndistortRectifyMap: 2 * width * height floats, the row-major x plane then
  // the y plane; -1 in both where the ray leaves the source image.
  [[nodiscard]] const std::vector<float>& map_reference() const noexcept;
  [[nodiscard]] const std::vector<float>& map_other() const noexcept;
  [[nodiscard]] const RectifiedGeometry& rectified() const noexcept;
  [[nodiscard]] const StereoStats& stats() const noexcept;
  [[nodiscard]] const PinholeCamera& camera() const noexcept;
  [[nodiscard]] const StereoParams& params() const noexcept;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace ag::mapping
