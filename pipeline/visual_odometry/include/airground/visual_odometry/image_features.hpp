// Grey image pyramids, Shi-Tomasi corners on a grid and pyramidal Lucas-Kanade tracking: the VO's
// front end, on buffers sized once (no allocation after the first frame of a given size).
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

namespace ag::vo {

// A float grey image, row-major.
struct GreyImage {
  int width{0}, height{0};
  std::vector<float> px;

  void resize(int w, int h);  // allocates only when the size grows
  [[nodiscard]] float at(int x, int y) const noexcept {
    return px[static_cast<std::size_t>(y) * static_cast<std::size_t>(width) + static_cast<std::size_t>(x)];
  }
  // Bilinear sample; the caller keeps (x, y) inside [0, width-1] x [0, height-1].
  [[nodiscard]] float sample(float x, float y) const noexcept;
};

inline constexpr int kPyramidLevels = 3;

// Level 0 is the frame; each next level halves it (2x2 mean). Gradients (central differences) per level.
struct ImagePyramid {
  std::array<GreyImage, kPyramidLevels> level, grad_x, grad_y;

  // From packed RGB (Rec. 601 luma).
  void build_from_rgb(const std::uint8_t* rgb, int width, int height);
  // From 8-bit grey.
  void build_from_grey(const std::uint8_t* grey, int width, int height);

 private:
  void build_levels();
};

struct CornerParams {
  int grid_cols{20}, grid_rows{12};  // one corner per empty cell at most
  int window_half{3};                // structure tensor summed over (2h+1)^2 pixels
  float min_score{6.0F};              // smallest accepted min eigenvalue [grey^2 per pixel]
  int border_px{12};                 // no corners this close to the image edge (KLT window)
  float min_distance_px{10.0F};      // to any existing feature
};

struct Pixel {
  float u{0}, v{0};
};

// Shi-Tomasi (minimum eigenvalue of the structure tensor) corners, the best one per grid cell that holds
// no existing feature, on level 0 of the pyramid. Appends at most out.capacity() - out.size() corners.
class CornerDetector {
 public:
  explicit CornerDetector(const CornerParams& p = {}) : p_(p) {}
  // existing: features already tracked; out: receives new corners (cleared first); max_new: cap.
  void detect(const ImagePyramid& pyr, std::span<const Pixel> existing, std::vector<Pixel>& out, std::size_t max_new);
  [[nodiscard]] const CornerParams& params() const noexcept { return p_; }

 private:
  CornerParams p_;
  std::vector<double> ixx_, ixy_, iyy_;  // integral images (width+1) x (height+1)
  std::vector<std::uint8_t> occupied_;
};

struct FlowParams {
  int window_half{7};          // 15x15 window at every level
  int max_iterations{12};      // per level
  float epsilon_px{0.02F};     // stop when the update is smaller
  float max_residual{14.0F};   // [grey] mean absolute residual after convergence; larger = lost
  float min_eigen{1.0F};       // [grey^2] the window's structure tensor must be this well conditioned
};

// Pyramidal Lucas-Kanade with offset compensation (zero-mean windows, robust to exposure steps).
class OpticalFlow {
 public:
  explicit OpticalFlow(const FlowParams& p = {}) : p_(p) {}
  // Tracks prev_pts from `prev` into `next`; next_pts holds an initial guess on entry (or equals
  // prev_pts) and the result on exit; ok[i] says whether point i was tracked.
  void track(const ImagePyramid& prev, const ImagePyramid& next, std::span<const Pixel> prev_pts,
             std::span<Pixel> next_pts, std::span<std::uint8_t> ok) const noexcept;
  [[nodiscard]] const FlowParams& params() const noexcept { return p_; }

 private:
  bool track_one(const ImagePyramid& prev, const ImagePyramid& next, Pixel p, Pixel& q) const noexcept;
  FlowParams p_;
};

}  // namespace ag::vo
