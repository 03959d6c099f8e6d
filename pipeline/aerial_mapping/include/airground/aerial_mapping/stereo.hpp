// Dense stereo between two keyframes of the nadir camera: rectify the pair for its real relative pose
// (the baseline becomes the rectified x axis, lens distortion removed), block-match (StereoBM's method:
// x-Sobel prefilter clipped to +-prefilter_cap, SAD over block_size^2, winner-take-all with texture and
// uniqueness checks, sub-pixel parabola, speckle filter), mask invalid borders, and project every valid
// disparity to a point in the map frame carrying the colour (bilinear) and class (nearest neighbour)
// of the current frame. Eigen only (the static role binary cannot link OpenCV); tests compare against
// OpenCV's stereoRectify/initUndistortRectifyMap/StereoBM.
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <memory>
#include <vector>

#include "airground/core/camera.hpp"
#include "airground/platform/result.hpp"

namespace ag::mapping {

struct StereoParams {
  int min_disparity{1};           // [px] (ASOOM: 1)
  int num_disparities{112};       // [px] multiple of 16; 112 covers a 30 m roof 10 m under a 2 m baseline at 640 px
  int block_size{9};              // [px] odd (ASOOM: 9)
  int prefilter_cap{31};
  int texture_threshold{10};      // minimum sum of |prefiltered| over the block
  int uniqueness_ratio{10};       // [%] best SAD must beat every other (beyond +-1 px) by this margin
  int speckle_window{100};        // [px] connected regions of at most this many pixels are removed; 0 = off
  int speckle_range{2};           // [px] disparity step that still connects a region (StereoBM's speckleRange is in 1/16 px: 16x this)
  int border_dilate_px{5};        // [px] the invalid (black) rectification border is grown by this
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
};

// The rectified window: rows where both images have content (+ half a block), columns from the first
// reference column a disparity in range can match to the last reference column, plus StereoBM's dead
// band (min_disparity + num_disparities - 1 + block_size / 2 columns on the left, where it computes
// nothing) placed over pixels no disparity could match anyway. For the 640x400 nadir camera flying
// forward that is about 530x670 px. Buffers are sized in the constructor for the largest window (any
// baseline direction in the image); a larger window is clamped (right columns, top/bottom rows).
class DenseStereo {
 public:
  // Precomputes what does not depend on the pair and allocates every buffer. Throws
  // std::invalid_argument for parameters StereoBM would refuse (num_disparities not a positive multiple
  // of 16, block_size not odd in [5, 255], block_size^2 * 2 * prefilter_cap >= 65536, prefilter_cap not in
  // [1, 63], min_disparity not in [0, 1000], negative texture_threshold / uniqueness_ratio / speckle
  // values, depth range not 0 <= min < max) or a camera without size.
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
  // image is); rectified size = rectified().width x rectified().height, row-major.
  [[nodiscard]] const std::vector<std::uint8_t>& rectified_reference() const noexcept;
  [[nodiscard]] const std::vector<std::uint8_t>& rectified_other() const noexcept;
  [[nodiscard]] const std::vector<std::int16_t>& disparity() const noexcept;
  // The block matcher's own output before the border mask, as cv::StereoBM::compute into CV_16S followed
  // by its speckle filter: invalid = (min_disparity - 1) * 16 (StereoBM's convention). For tests.
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
