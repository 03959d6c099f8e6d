// The simulated nadir camera of the quadrotor: a pinhole with OpenCV distortion that ray-casts the World.
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "airground/core/geometry.hpp"
#include "airground/platform/result.hpp"
#include "airground/sim/raycast.hpp"
#include "airground/sim/world.hpp"

namespace ag::sim {

// Intrinsics in pixels (pixel centres at integer coordinates) and the OpenCV k1, k2, p1, p2, k3 model.
// Mount: the camera looks straight down with the image top toward body forward and image right toward
// body right (body REP-103; camera OpenCV x right, y down, z forward), centred on the body origin.
struct CameraModel {
  int width{1280}, height{800};                     // [px]
  double fx{967}, fy{967}, cx{639.5}, cy{399.5};    // [px]
  double k1{-0.05}, k2{0.01}, p1{0}, p2{0}, k3{0};  // [-]

  // The same lens on a sensor resampled by `factor` (0.5: 1280x800 -> 640x400).
  [[nodiscard]] CameraModel scaled(double factor) const;
  // Sizes and focal lengths positive, principal point inside the image; errors name the field.
  [[nodiscard]] Status check() const;
  // Rotation taking camera-frame vectors to the body frame (columns: camera x, y, z in body axes).
  [[nodiscard]] static Eigen::Matrix3d body_from_camera() noexcept;

  // YAML section `camera:` with the keys above; any unknown key, wrong type or out-of-range value is an
  // ErrorCode::kConfig error naming the file and the key. Missing keys keep their defaults.
  static Result<CameraModel> load_file(const std::string& path);
  static Result<CameraModel> load_string(std::string_view yaml, std::string_view origin);
};

// How the scene is lit and textured (same YAML file, section `camera_shading:`).
struct CameraShading {
  double sun_azimuth_deg{150};    // [deg] compass azimuth of the sun, clockwise from north
  double sun_elevation_deg{50};   // [deg] above the horizon
  double ambient{0.35};           // [-] share of light that reaches shadowed and back-facing surfaces
  // Trace a second ray toward the sun from each hit. Off by default: it nearly doubles the render time
  // and takes a 640x400 stream below 10 frames/s on one core (tests/bench/bench_sim_sensors).
  bool shadows{false};
  bool detail_texture{true};      // fine world-fixed value noise, so that stereo matching finds texture
  double max_range_m{5000};       // [m] rays longer than this see sky
  // Skip the shadow ray where a precomputed bound proves the point lit: the same image, faster.
  // Not in the YAML; off only to test that claim.
  bool shadow_culling{true};
  // Start each tile's casts at a height a block max query proves free (see render_rows): the same image,
  // faster. Not in the YAML; off only to test that claim.
  bool tile_start{true};

  static Result<CameraShading> load_file(const std::string& path);
  static Result<CameraShading> load_string(std::string_view yaml, std::string_view origin);
};

struct CameraFrame {
  cv::Mat rgb;    // CV_8UC3, RGB channel order; sky black
  cv::Mat cls;    // CV_8UC1 class id of the surface seen; 255 (unknown) for sky
  cv::Mat depth;  // CV_32FC1 [m] z-depth in the camera frame; 0 for sky
  Pose3 pose;     // body pose in the map frame the frame was rendered from
  std::int64_t stamp_ns{0};
};

// Renders what the camera sees from a body pose. Per pixel: the precomputed undistorted ray is rotated
// into the map, cast against the World, and shaded (bilinear albedo x world-fixed detail texture x
// Lambert with optional cast shadow, traced exactly toward the sun). Steps lower than 0.3 m (terrain
// sampled into flat cells, curbs) are shaded as ground, not as walls. Holds a reference to `world`,
// which must outlive it.
// render() is single-threaded and allocation-free once `out` has the right size; render_rows() lets a
// caller split one frame over threads.
class CameraRenderer {
 public:
  // Throws std::invalid_argument if the model fails check() or the World's layers do not match its grid.
  // A shared raycaster built for the same world may be passed to save memory.
  CameraRenderer(const World& world, const CameraModel& model, const CameraShading& shading = {},
                 std::shared_ptr<const HeightfieldRaycaster> raycaster = nullptr);

  void render(const Pose3& body_pose_in_map, CameraFrame& out, std::int64_t stamp_ns = 0) const;
  // Sizes the three images of `out` (allocates only when they differ) and sets pose and stamp.
  void prepare(const Pose3& body_pose_in_map, CameraFrame& out, std::int64_t stamp_ns = 0) const;
  // Renders rows [row_begin, row_end) of a frame already prepared for the same pose.
  void render_rows(const Pose3& body_pose_in_map, int row_begin, int row_end, CameraFrame& out) const noexcept;

  [[nodiscard]] const CameraModel& model() const noexcept { return model_; }
  [[nodiscard]] const CameraShading& shading() const noexcept { return shading_; }
  [[nodiscard]] const HeightfieldRaycaster& raycaster() const noexcept { return *raycaster_; }
  // Unit ray of a pixel in the camera frame (undistorted); zero for a pixel the lens model cannot invert.
  [[nodiscard]] Eigen::Vector3f pixel_ray(int col, int row) const noexcept;

 private:
  void build_sun_ceiling();
  // A height above which no point of the cell's 4x4 block can be in shadow (conservative).
  [[nodiscard]] float sun_ceiling(std::int32_t col, std::int32_t row) const noexcept {
    return sun_ceiling_[static_cast<std::size_t>(row >> 2) * static_cast<std::size_t>(sun_blocks_w_) +
                        static_cast<std::size_t>(col >> 2)];
  }

  const World& world_;
  CameraModel model_;
  CameraShading shading_;
  std::shared_ptr<const HeightfieldRaycaster> raycaster_;
  std::vector<float> rays_;  // 3 per pixel, row-major: unit direction in the camera frame
  Eigen::Vector3d sun_{0, 0, 1};
  std::vector<float> sun_ceiling_;  // per 4x4-cell block, row-major
  std::int32_t sun_blocks_w_{0};
};

}  // namespace ag::sim
