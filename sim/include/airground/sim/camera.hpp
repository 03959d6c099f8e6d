// The simulated nadir camera of the quadrotor: a pinhole with OpenCV distortion that ray-casts the World.
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "airground/messages/camera.hpp"
#include "airground/messages/geometry.hpp"
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
  // The same intrinsics as the robot's camera model (messages/), for the stages and their tests.
  [[nodiscard]] PinholeCamera pinhole() const noexcept {
    PinholeCamera c;
    c.width = width;
    c.height = height;
    c.fx = fx;
    c.fy = fy;
    c.cx = cx;
    c.cy = cy;
    c.k1 = k1;
    c.k2 = k2;
    c.p1 = p1;
    c.p2 = p2;
    c.k3 = k3;
    return c;
  }

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

// What the image sensor and its lens add to the rendered scene (same YAML file, section `camera_sensor:`):
// photon shot and read noise with 8-bit quantisation, the exposure and gain an auto-exposure loop picks,
// motion blur over the exposure, vignetting. The renderer's value 255 is a white, sun-lit flat surface at
// full well after `full_scale_exposure_s` at gain 1. A default-constructed CameraSensor is the ideal camera
// (every effect off: the renderer's unit tests); what the simulator's robots get is field(): every effect
// on, as on a real camera, and the defaults of the YAML section. Sources: docs/simulator.md.
struct CameraSensor {
  bool noise{false};                   // photon shot noise + read noise, then gain and 8-bit quantisation
  double full_well_e{10500};           // [e-] per sensor pixel
  double read_noise_e{2.3};            // [e- rms] per sensor pixel (temporal dark noise)
  int sensor_width_px{1280};           // [px] native width: a rendered pixel averages (this / width)^2 sensor pixels
  double full_scale_exposure_s{3e-4};  // [s] exposure at gain 1 that fills the well on a white sun-lit surface
  bool auto_exposure{false};           // false: every frame at exposure_s and gain
  double exposure_s{3e-4};             // [s] the fixed exposure, and the auto-exposure's first
  double gain{1.0};                    // [-] the fixed gain, and the auto-exposure's first
  double exposure_min_s{1e-5};         // [s]
  double exposure_max_s{5e-3};         // [s] beyond it the auto-exposure raises the gain
  double gain_max{16.0};               // [-] (24 dB)
  double ae_target{0.45};              // [-] frame mean the auto-exposure aims at, share of full scale
  double ae_speed{0.5};                // [-] share of the (log) error corrected per frame
  double ae_tolerance{0.03};           // [-] relative error within which the exposure is held
  bool motion_blur{false};             // average sub-exposure samples along the camera's motion
  int blur_max_samples{15};            // [-] odd; about two samples per pixel of blur up to this
  bool vignetting{false};              // cos^k falloff of the illumination toward the corners
  double corner_illumination{0.6};     // [-] corner / centre (1: none; 0.39 is the pure cos^4 law at fx 967)

  // Cross-field checks (exposure and gain inside their limits); errors name the keys.
  [[nodiscard]] Status check() const;
  // Any effect on, or an exposure that scales the image: the renderer runs the sensor model.
  [[nodiscard]] bool active() const noexcept {
    return noise || auto_exposure || motion_blur || vignetting || exposure_s * gain != full_scale_exposure_s;
  }

  // The camera the robots fly with: noise, auto-exposure, motion blur and vignetting on, the rest as above
  // (a typical global-shutter camera; the YAML section's defaults).
  [[nodiscard]] static constexpr CameraSensor field() noexcept {
    CameraSensor s;
    s.noise = s.auto_exposure = s.motion_blur = s.vignetting = true;
    return s;
  }

  static Result<CameraSensor> load_file(const std::string& path);
  static Result<CameraSensor> load_string(std::string_view yaml, std::string_view origin);
};

// The exposure of one frame.
struct CameraExposure {
  double exposure_s{3e-4};  // [s]
  double gain{1.0};         // [-]
};

// What one frame needs beyond its pose, fixed before it renders (so bands and frames rendered ahead agree).
struct CameraShot {
  std::uint64_t seed{0};             // run seed: noise is a hash of (seed, frame, pixel, channel)
  std::uint64_t frame{0};            // frame sequence number
  CameraExposure exposure{};
  Eigen::Vector3d velocity{0, 0, 0};  // [m/s] body velocity in the map frame during the exposure
  double yaw_rate{0};                 // [rad/s] about the map's z axis

  // Bit for bit: a frame rendered ahead is used only for the shot it would have when due.
  friend bool operator==(const CameraShot& a, const CameraShot& b) noexcept {
    return a.seed == b.seed && a.frame == b.frame && a.exposure.exposure_s == b.exposure.exposure_s &&
           a.exposure.gain == b.exposure.gain && a.velocity == b.velocity && a.yaw_rate == b.yaw_rate;
  }
};

struct CameraFrame {
  cv::Mat rgb;    // CV_8UC3, RGB channel order; sky black (read noise only with the sensor's noise on)
  cv::Mat cls;    // CV_8UC1 class id of the surface seen; 255 (unknown) for sky
  cv::Mat depth;  // CV_32FC1 [m] z-depth in the camera frame; 0 for sky
  Pose3 pose;     // body pose in the map frame the frame was rendered from
  std::int64_t stamp_ns{0};
  CameraShot shot;         // exposure, motion and noise key the frame was rendered with
  int blur_samples{1};     // sub-exposure samples per pixel (odd; the middle one gives cls and depth)
};

// The camera's auto-exposure loop: after each frame it meters the frame's mean and sets the next frame's
// exposure (longer first, up to exposure_max_s, then gain), correcting ae_speed of the log error per frame,
// so a brightness step settles over a few frames as on a real camera. Deterministic: its state advances
// only in observe(), once per finished frame, in frame order.
class CameraAutoExposure {
 public:
  CameraAutoExposure() = default;
  explicit CameraAutoExposure(const CameraSensor& sensor) noexcept;
  // The exposure of the next frame (the fixed one with auto-exposure off).
  [[nodiscard]] CameraExposure next() const noexcept { return next_; }
  // Meters a finished frame rendered with frame.shot.exposure; no-op with auto-exposure off.
  void observe(const CameraFrame& frame) noexcept;
  [[nodiscard]] double last_mean() const noexcept { return last_mean_; }  // [-] share of full scale

 private:
  CameraSensor sensor_{};
  CameraExposure next_{};
  double last_mean_{0};
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
  // With a sensor model (throws std::invalid_argument if it fails check()).
  CameraRenderer(const World& world, const CameraModel& model, const CameraShading& shading, const CameraSensor& sensor,
                 std::shared_ptr<const HeightfieldRaycaster> raycaster = nullptr);

  // Without a shot: frame 0, seed 0, at rest, at the sensor's fixed exposure.
  void render(const Pose3& body_pose_in_map, CameraFrame& out, std::int64_t stamp_ns = 0) const;
  void render(const Pose3& body_pose_in_map, CameraFrame& out, std::int64_t stamp_ns, const CameraShot& shot) const;
  // Sizes the three images of `out` (allocates only when they differ) and sets pose, stamp and shot.
  void prepare(const Pose3& body_pose_in_map, CameraFrame& out, std::int64_t stamp_ns = 0) const;
  void prepare(const Pose3& body_pose_in_map, CameraFrame& out, std::int64_t stamp_ns, const CameraShot& shot) const;
  // Renders rows [row_begin, row_end) of a frame already prepared for the same pose; the pixels depend on
  // the pose and the frame's shot only, never on how the rows are split.
  void render_rows(const Pose3& body_pose_in_map, int row_begin, int row_end, CameraFrame& out) const noexcept;

  // The blur's length [px] for a shot: image motion of the ground at the nadir (v t f / height above it)
  // plus the yaw's sweep of the image corner.
  [[nodiscard]] double blur_length_px(const Pose3& body_pose_in_map, const CameraShot& shot) const noexcept;
  // Relative illumination of a pixel (1 at the centre; corner_illumination at the farthest corner).
  [[nodiscard]] float vignetting(int col, int row) const noexcept;

  [[nodiscard]] const CameraModel& model() const noexcept { return model_; }
  [[nodiscard]] const CameraShading& shading() const noexcept { return shading_; }
  [[nodiscard]] const CameraSensor& sensor() const noexcept { return sensor_; }
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
  CameraSensor sensor_;
  std::vector<float> vignette_;  // per pixel, row-major; empty with vignetting off
  std::shared_ptr<const HeightfieldRaycaster> raycaster_;
  std::vector<float> rays_;  // 3 per pixel, row-major: unit direction in the camera frame
  Eigen::Vector3d sun_{0, 0, 1};
  std::vector<float> sun_ceiling_;  // per 4x4-cell block, row-major
  std::int32_t sun_blocks_w_{0};
};

}  // namespace ag::sim
