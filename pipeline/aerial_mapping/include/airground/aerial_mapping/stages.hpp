// The UAV's mapping stages (thin wrappers; the algorithms are in pose_graph, stereo and ortho_map):
//   pose_graph  camera + visual_odometry + gps -> pose graph, keyframes, keyframe_poses
//   ortho_map   keyframes + keyframe_poses -> dense stereo -> ortho-map tiles, map_status
// They run on their own threads at low priority: a solve or a stereo pair takes tens of milliseconds
// and allocates inside Ceres, so they are not real-time paths (the drivers and the status stage are).
#pragma once

#include <array>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "airground/aerial_mapping/ortho_map.hpp"
#include "airground/aerial_mapping/pose_graph.hpp"
#include "airground/aerial_mapping/stereo.hpp"
#include "airground/messages/messages.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/param_binding.hpp"
#include "airground/platform/stage.hpp"

namespace ag::mapping {

// Role-wide section "camera_calibration": the nadir camera at the 640x400 the mapper works at.
// Defaults: the simulator's 1280x800 camera (fx 967, k1 -0.05, k2 0.01) resampled to 640x400.
// PinholeCamera's own k1, k2 are a lens without distortion; the section's are the simulator's.
struct NadirDistortion {
  double k1{-0.05}, k2{0.01};
};
inline constexpr ParamField<PinholeCamera> kCameraIntrinsicsFields[] = {
    field::real("fx", &PinholeCamera::fx, 1.0, 1e5, "px", "focal length x at 640x400"),
    field::real("fy", &PinholeCamera::fy, 1.0, 1e5, "px", "focal length y at 640x400"),
    field::real("cx", &PinholeCamera::cx, 0.0, 640.0, "px", "principal point x (pixel centres at integers)"),
    field::real("cy", &PinholeCamera::cy, 0.0, 400.0, "px", "principal point y"),
};
inline constexpr ParamField<NadirDistortion> kNadirDistortionFields[] = {
    field::real("k1", &NadirDistortion::k1, -5.0, 5.0, "", "radial distortion r^2 (OpenCV model)"),
    field::real("k2", &NadirDistortion::k2, -5.0, 5.0, "", "radial distortion r^4"),
};
inline constexpr ParamField<PinholeCamera> kCameraTangentialFields[] = {
    field::real("p1", &PinholeCamera::p1, -1.0, 1.0, "", "tangential distortion"),
    field::real("p2", &PinholeCamera::p2, -1.0, 1.0, "", "tangential distortion"),
    field::real("k3", &PinholeCamera::k3, -5.0, 5.0, "", "radial distortion r^6"),
};
inline constexpr auto kCameraCalibrationParams = param_specs(kCameraIntrinsicsFields, kNadirDistortionFields, kCameraTangentialFields);
PinholeCamera load_camera_calibration(const Config& config);

struct PoseGraphStageCounters {
  std::uint64_t frames_in{0}, frames_keyframed{0};
  std::uint64_t frames_without_odometry{0};  // no odometry around the image time (or a segment change)
  std::uint64_t frames_before_init{0};       // the graph was not georeferenced yet
  std::uint64_t frames_settling{0};          // a new odometry segment whose scale GPS has not pinned yet
  std::uint64_t frames_out_of_order{0};
  std::uint64_t frames_dropped_busy{0};      // keyframe ring full
  std::uint64_t odometry_lost{0};            // samples flagged tracking lost
  std::uint64_t gps_no_fix{0};
};

// The pose_graph stage's own parameters; between_sigma_rad is the stage's (PoseGraphParams keeps ASOOM's 0.05).
struct PoseGraphStageSettings {
  double keyframe_distance_m{2.0};  // [m]
  double segment_settle_m{15.0};    // [m]
  double max_image_wait_s{1.0};     // [s]
  double between_sigma_rad{0.005};  // [rad]
};
inline constexpr ParamField<PoseGraphStageSettings> kPoseGraphStageFields[] = {
    field::real("keyframe_distance_m", &PoseGraphStageSettings::keyframe_distance_m, 0.2, 50.0, "m", "a new keyframe once the optimised position moved this far (ASOOM: 2 m)"),
    field::real("segment_settle_m", &PoseGraphStageSettings::segment_settle_m, 0.0, 1000.0, "m",
                "after a tracking loss, no keyframes until GPS saw the new odometry segment travel this far (its scale is a guess until then); 0 = off"),
    field::real("max_image_wait_s", &PoseGraphStageSettings::max_image_wait_s, 0.05, 10.0, "s", "an image waits this long for the odometry after it, then is dropped (counted)"),
};
inline constexpr ParamField<PoseGraphParams> kPoseGraphSolveFields[] = {
    field::integer("solve_every_frames", &PoseGraphParams::solve_every_frames, 1, 1000, "frames", "re-solve the graph after this many frames (ASOOM: ~30)"),
    field::integer("window_frames", &PoseGraphParams::window_frames, 0, 100000, "frames", "free nodes per solve, older ones held constant; 0 = all"),
    field::integer("max_iterations", &PoseGraphParams::max_iterations, 1, 500, "iterations", "Levenberg-Marquardt iterations per solve"),
    field::real("between_sigma_m", &PoseGraphParams::between_sigma_m, 1e-4, 10.0, "m", "odometry between-factor sigma, translation (ASOOM: 0.05)"),
};
inline constexpr ParamField<PoseGraphStageSettings> kPoseGraphBetweenRotationFields[] = {
    field::real("between_sigma_rad", &PoseGraphStageSettings::between_sigma_rad, 1e-5, 1.0, "rad", "odometry between-factor sigma, rotation (ASOOM: 0.05; 0.005 measured: yaw rms 0.033 -> 0.004 rad)"),
};
inline constexpr ParamField<PoseGraphParams> kPoseGraphFactorFields[] = {
    field::real("gravity_sigma_rad", &PoseGraphParams::gravity_sigma_rad, 0.0, 1.0, "rad", "roll/pitch from the gravity-aligned odometry; 0 = off"),
    field::real("gps_sigma_m", &PoseGraphParams::gps_sigma_m, 0.01, 100.0, "m", "GPS factor sigma at zero interpolation gap (ASOOM: 0.5)"),
    field::real("gps_sigma_per_gap_s", &PoseGraphParams::gps_sigma_per_gap_s, 0.0, 100.0, "m/s", "added to the sigma per second of interpolation gap (ASOOM: 0.5)"),
    field::real("gps_max_interpolation_s", &PoseGraphParams::gps_max_interpolation_s, 0.05, 60.0, "s", "fixes further apart are not interpolated between"),
    field::real("gps_robust_sigmas", &PoseGraphParams::gps_robust_sigmas, 0.1, 100.0, "", "Cauchy loss scale on GPS residuals, in sigmas"),
    field::real("gps_gate_sigmas", &PoseGraphParams::gps_gate_sigmas, 1.0, 1000.0, "", "once initialised, fixes further than this many sigmas are rejected"),
    field::real("gps_gate_floor_m", &PoseGraphParams::gps_gate_floor_m, 0.0, 1000.0, "m", "... but never fixes closer than this"),
    field::integer("min_gps_fixes", &PoseGraphParams::min_gps_fixes, 2, 1000, "fixes", "GPS fixes a segment needs before it is georeferenced"),
    field::real("min_gps_baseline_m", &PoseGraphParams::min_gps_baseline_m, 0.0, 1000.0, "m", "spread those fixes need (scale and yaw need motion)"),
    field::real("scale_knot_s", &PoseGraphParams::scale_knot_s, 0.0, 600.0, "s", "a log-scale knot of the odometry every this many seconds; 0 = one scale per segment (ASOOM)"),
    field::real("scale_drift_per_sqrt_s", &PoseGraphParams::scale_drift_per_sqrt_s, 0.0, 1.0, "1/sqrt(s)", "random walk allowed to the odometry's log-scale between knots"),
};
inline constexpr auto kPoseGraphStageParams =
    param_specs(kPoseGraphStageFields, kPoseGraphSolveFields, kPoseGraphBetweenRotationFields, kPoseGraphFactorFields);

class PoseGraphStage final : public Stage {
 public:
  static constexpr std::span<const ParamSpec> kParams{kPoseGraphStageParams};
  static std::unique_ptr<Stage> make() { return std::make_unique<PoseGraphStage>(); }

  Status init(StageContext& ctx) override;
  void step(TimeNs now) noexcept override;

  [[nodiscard]] const PoseGraph& graph() const noexcept { return *graph_; }
  [[nodiscard]] const PoseGraphStageCounters& counters() const noexcept { return c_; }
  // Keyframe k's node interpolation, for evaluation: current optimised body pose.
  [[nodiscard]] Eigen::Isometry3d keyframe_pose(std::uint32_t id) const noexcept;
  [[nodiscard]] std::uint32_t keyframes() const noexcept { return next_id_; }
  [[nodiscard]] TimeNs keyframe_stamp(std::uint32_t id) const noexcept;

 private:
  struct NodeRef {
    TimeNs stamp{0};
    NodeId node{kNoNode};
    std::uint32_t segment{0};
  };
  struct KeyframeRef {
    NodeId a{kNoNode}, b{kNoNode};
    double alpha{0};
    TimeNs stamp{0};
  };
  bool interpolate(TimeNs t, KeyframeRef& ref, std::uint32_t& segment) const noexcept;
  [[nodiscard]] Eigen::Isometry3d pose_of(const KeyframeRef& r) const noexcept;
  void publish_poses(TimeNs now) noexcept;

  std::unique_ptr<PoseGraph> graph_;
  const Clock* clock_{nullptr};
  RingReader<CameraImageMsg, kCameraRing> camera_;
  RingReader<VoMsg, kVoRing> vo_;
  RingReader<GpsMsg, kGpsRing> gps_;
  RingWriter<KeyframeMsg, kKeyframeRing> keyframes_out_;
  LatestWriter<KeyframePosesMsg> poses_out_;
  std::unique_ptr<KeyframeMsg> kf_;
  std::unique_ptr<KeyframePosesMsg> poses_msg_;
  std::array<NodeRef, 512> history_{};  // newest nodes, ring
  std::size_t history_head_{0}, history_size_{0};
  std::vector<KeyframeRef> keyframe_refs_;  // every keyframe's interpolation (small: 40 bytes each)
  double keyframe_distance_m_{2.0};
  double max_image_wait_s_{1.0};
  std::uint32_t next_id_{0};
  std::uint32_t last_kf_segment_{0};
  // The newest fix, and where it was when the current odometry segment began (segment_settle_m).
  double segment_settle_m_{15.0};
  bool have_fix_{false}, have_seg_{false}, seg_settled_{false};
  std::uint32_t seg_{0};
  Eigen::Vector3d last_fix_{Eigen::Vector3d::Zero()}, seg_origin_{Eigen::Vector3d::Zero()};
  Eigen::Vector3d last_kf_position_{0, 0, 0};
  bool have_kf_{false};
  TimeNs last_image_stamp_{-1};
  std::uint64_t solves_published_{0};
  PoseGraphStageCounters c_;
};

struct OrthoMapStageCounters {
  std::uint64_t keyframes_in{0}, pairs_matched{0}, pairs_refused{0}, segment_starts{0};
  double last_stereo_ms{0}, last_bin_ms{0};
  double last_baseline_m{0};      // [m] of the last matched pair
  double ground_depth_m{0};       // [m] median depth of the last matched pair's points
};

// The ortho_map stage's own parameters; num_disparities is the stage's (StereoParams keeps 112, a 2 m
// baseline's); max_tiles is read here since OrthoMapParams holds it as a size_t.
struct OrthoMapStageSettings {
  int num_disparities{160};        // [px]
  double baseline_depth_ratio{0.18};
  int pair_history{8};             // [keyframes]
  int max_tiles{16384};            // [tiles]
  std::string keyframes_channel{"keyframes"};
  int tiles_per_step{16};          // [tiles]
};
inline constexpr ParamField<StereoParams> kStereoMinDisparityFields[] = {
    field::integer("min_disparity", &StereoParams::min_disparity, 0, 256, "px", "block matching: smallest disparity (ASOOM: 1)"),
};
inline constexpr ParamField<OrthoMapStageSettings> kStereoRangeFields[] = {
    field::integer("num_disparities", &OrthoMapStageSettings::num_disparities, 16, 256, "px", "block matching: disparity range, multiple of 16 (160: a 30 m roof at 50 m flight with a 6 m baseline)"),
};
inline constexpr ParamField<StereoParams> kStereoFields[] = {
    field::integer("block_size", &StereoParams::block_size, 5, 31, "px", "block matching: odd SAD window (ASOOM: 9)"),
    field::integer("prefilter_cap", &StereoParams::prefilter_cap, 1, 63, "", "block matching: x-Sobel prefilter clip"),
    field::integer("texture_threshold", &StereoParams::texture_threshold, 0, 10000, "", "block matching: minimum block texture"),
    field::integer("uniqueness_ratio", &StereoParams::uniqueness_ratio, 0, 100, "%", "block matching: margin of the best match over the others"),
    field::integer("speckle_window", &StereoParams::speckle_window, 0, 10000, "px", "speckle filter region size; 0 = off"),
    field::integer("speckle_range", &StereoParams::speckle_range, 0, 64, "px", "speckle filter disparity step"),
    field::integer("border_dilate_px", &StereoParams::border_dilate_px, 0, 64, "px", "invalid rectification border grown by this"),
    field::integer("lr_max_diff", &StereoParams::lr_max_diff, -1, 64, "px", "left-right check: drop disparities the other view contradicts by more (-1 = off)"),
    field::integer("edge_margin_px", &StereoParams::edge_margin_px, 0, 64, "px", "depth-edge guard: window around each disparity (0 = off)"),
    field::integer("edge_jump_px", &StereoParams::edge_jump_px, 0, 1000, "px", "depth-edge guard: drop disparities this far above the window's smallest"),
    field::real("min_depth_m", &StereoParams::min_depth_m, 0.1, 1000.0, "m", "points nearer are dropped (ASOOM: 1)"),
    field::real("max_depth_m", &StereoParams::max_depth_m, 1.0, 10000.0, "m", "points further are dropped (ASOOM: 150)"),
    field::real("min_baseline_m", &StereoParams::min_baseline_m, 0.01, 100.0, "m", "keyframe pairs closer than this are not matched"),
};
inline constexpr ParamField<OrthoMapStageSettings> kStereoPairingFields[] = {
    field::real("baseline_depth_ratio", &OrthoMapStageSettings::baseline_depth_ratio, 0.0, 1.0, "", "pair each keyframe with the earlier one whose baseline is nearest this x the ground depth (0 = the previous keyframe, ASOOM)"),
    field::integer("pair_history", &OrthoMapStageSettings::pair_history, 1, 32, "keyframes", "earlier keyframes kept as stereo partners"),
};
inline constexpr ParamField<OrthoMapParams> kOrthoMapFields[] = {
    field::real("resolution_m", &OrthoMapParams::resolution_m, 0.05, 10.0, "m", "map cell size"),
    field::integer("tile_cells", &OrthoMapParams::tile_cells, 8, 1024, "cells", "tile edge"),
    field::real("elevation_gate_m", &OrthoMapParams::elevation_gate_m, 0.05, 100.0, "m", "colour/class accepted only this close to the cell's mean elevation (ASOOM: 1)"),
    field::integer("min_points", &OrthoMapParams::min_points, 1, 10000, "points", "points a cell needs before it takes a class"),
    field::boolean("class_consistent_elevation", &OrthoMapParams::class_consistent_elevation, "a cell's height from its points of the same kind (raised: tree, building, vehicle; or flat) as its class"),
    field::integer("min_keyframe_points", &OrthoMapParams::min_keyframe_points, 1, 1000, "points", "one keyframe's points in a cell below this are dropped"),
    field::real("ground_check_m", &OrthoMapParams::ground_check_m, 0.0, 100.0, "m", "flat-class points further than this from the local ground are dropped (0 = off)"),
    field::integer("ground_window_cells", &OrthoMapParams::ground_window_cells, 0, 32, "cells", "half-width of the window whose flat-class median is the local ground"),
    field::real("raised_min_height_m", &OrthoMapParams::raised_min_height_m, 0.0, 100.0, "m", "tree/building/vehicle points lower than this above the local ground are dropped"),
    field::integer("min_elevation_points", &OrthoMapParams::min_elevation_points, 1, 100000, "points", "a cell reports an elevation once it has this many points (else unknown)"),
    field::integer("window_keyframes", &OrthoMapParams::window_keyframes, 2, 512, "keyframes", "keyframes kept re-binnable after pose-graph corrections"),
    field::real("rebuild_translation_m", &OrthoMapParams::rebuild_translation_m, 0.0, 100.0, "m", "a keyframe moved further than this is re-binned (ASOOM: 2)"),
    field::real("rebuild_rotation_rad", &OrthoMapParams::rebuild_rotation_rad, 0.0, 3.2, "rad", "... or turned more than this (ASOOM: 0.1)"),
    field::boolean("rescale_depth", &OrthoMapParams::rescale_depth, "re-scale a keyframe's stereo depth by its baseline as the pose graph corrects it (off: ASOOM)"),
};
inline constexpr ParamField<OrthoMapStageSettings> kOrthoMapStageFields[] = {
    field::integer("max_tiles", &OrthoMapStageSettings::max_tiles, 1, 1000000, "tiles", "map size limit; points beyond are refused (counted)"),
    field::text("keyframes_channel", &OrthoMapStageSettings::keyframes_channel, "keyframes", "keyframes|keyframes_labelled",
                "keyframes from pose_graph directly (their camera classes), or relabelled by the segmentation stage"),
    field::integer("tiles_per_step", &OrthoMapStageSettings::tiles_per_step, 1, 1024, "tiles", "changed tiles published on 'map_tiles' per step (the rest follow)"),
};
inline constexpr auto kOrthoMapStageParams = param_specs(kStereoMinDisparityFields, kStereoRangeFields, kStereoFields, kStereoPairingFields,
                                                         kOrthoMapFields, kOrthoMapStageFields);

class OrthoMapStage final : public Stage {
 public:
  static constexpr std::span<const ParamSpec> kParams{kOrthoMapStageParams};
  static std::unique_ptr<Stage> make() { return std::make_unique<OrthoMapStage>(); }

  Status init(StageContext& ctx) override;
  void step(TimeNs now) noexcept override;

  [[nodiscard]] const OrthoMap& map() const noexcept { return *map_; }
  [[nodiscard]] const OrthoMapStageCounters& counters() const noexcept { return c_; }
  [[nodiscard]] const DenseStereo& stereo() const noexcept { return *stereo_; }
  [[nodiscard]] std::uint64_t tiles_published() const noexcept { return tiles_published_; }
  [[nodiscard]] std::size_t tiles_pending() const noexcept { return queue_n_; }

 private:
  [[nodiscard]] Eigen::Isometry3d camera_pose(const Pose3& body) const noexcept;
  void publish_tiles(TimeNs now) noexcept;

  // Changed tiles for "map_tiles": every tile's last published version (open addressing, sized from
  // max_tiles at init; tiles are never removed from the map) and a FIFO of tiles waiting to go out.
  struct TileSlot {
    std::uint64_t key{0};
    const Tile* tile{nullptr};
    std::uint64_t version{0};
    bool used{false}, queued{false};
  };
  std::vector<TileSlot> slots_;
  std::vector<std::uint32_t> queue_;
  std::size_t queue_head_{0}, queue_n_{0};
  std::uint64_t seen_version_{~std::uint64_t{0}};
  std::uint64_t tiles_published_{0};
  std::size_t tiles_per_step_{16};
  std::uint32_t min_elevation_points_{1};
  bool tiles_enabled_{false};
  RingWriter<MapTileMsg, kMapTileRing> tiles_out_;
  std::unique_ptr<MapTileMsg> tile_msg_;

  std::unique_ptr<OrthoMap> map_;
  std::unique_ptr<DenseStereo> stereo_;
  const Clock* clock_{nullptr};
  RingReader<KeyframeMsg, kKeyframeRing> keyframes_;
  LatestReader<KeyframePosesMsg> poses_;
  LatestWriter<MapStatusMsg> status_out_;
  // Earlier keyframes (newest last), the candidates for the next keyframe's stereo partner.
  std::vector<std::unique_ptr<KeyframeMsg>> history_;
  std::size_t history_count_{0}, history_head_{0};  // ring over history_
  double baseline_depth_ratio_{0.18};
  std::vector<float> depth_scratch_;
  std::vector<MapPoint> points_;
  std::vector<std::pair<std::uint32_t, Eigen::Isometry3d>> corrections_;
  Eigen::Matrix3d body_from_camera_{Eigen::Matrix3d::Identity()};
  MapStatusMsg status_{};
  bool initialised_{false};
  double scale_{0};
  double max_baseline_axis_cos_{0.5};  // baselines within 60 deg of the optical axis are not matched
  OrthoMapStageCounters c_;
};

}  // namespace ag::mapping
