// The `vo` stage of the uav: each camera frame through the visual odometry, with the autopilot's
// attitude at the frame's time as gravity, onto 'visual_odometry' (VoMsg) for the pose graph.
#pragma once

#include <array>
#include <memory>
#include <span>
#include <string>

#include "airground/messages/channels.hpp"
#include "airground/messages/messages.hpp"
#include "airground/platform/param_binding.hpp"
#include "airground/platform/stage.hpp"
#include "airground/visual_odometry/visual_odometry.hpp"

namespace ag::vo {

struct VoStageCounters {
  std::uint64_t frames{0}, tracked{0}, lost{0}, keyframes{0}, segments{0};
  std::uint64_t frames_with_attitude{0}, frames_without_attitude{0};  // no attitude within attitude_max_gap_s
  std::uint64_t frames_dropped_busy{0};  // output ring full
  std::uint64_t attitude_samples{0};
};

inline constexpr ParamField<VoParams> kVoFields[] = {
    field::integer("max_features", &VoParams::max_features, 50, 1000, "corners", "tracked corners at most (one per cell of a 20x12 grid)"),
    field::real("keyframe_parallax_px", &VoParams::keyframe_parallax_px, 4.0, 200.0, "px", "median image motion that makes a new keyframe (24 px: 2 m at 40 m)"),
    field::integer("window_keyframes", &VoParams::window_keyframes, 3, 12, "keyframes", "keyframes in the bundle-adjusted window (the oldest two fixed)"),
    field::integer("min_pose_inliers", &VoParams::min_pose_inliers, 6, 500, "points", "fewer map points agreeing on a frame's pose: tracking lost, a new segment"),
    field::real("max_reprojection_px", &VoParams::max_reprojection_px, 0.3, 10.0, "px", "inlier threshold of the pose and of new map points"),
    field::real("gravity_sigma_rad", &VoParams::gravity_sigma_rad, 0.0, 1.0, "rad", "the autopilot's up direction as a prior on each pose; 0 = vision only"),
};
// The stage's own parameters (the attitude waits are converted to TimeNs in init()).
struct VoStageSettings {
  double attitude_max_gap_s{0.05};  // [s]
  double attitude_max_wait_s{0.2};  // [s]
  int frames_per_step{2};
  std::string output_channel{chan::kVisualOdometry.name};
};
inline constexpr ParamField<VoStageSettings> kVoStageFields[] = {
    field::real("attitude_max_gap_s", &VoStageSettings::attitude_max_gap_s, 0.001, 1.0, "s", "an attitude sample further than this from a frame is not used for it"),
    field::real("attitude_max_wait_s", &VoStageSettings::attitude_max_wait_s, 0.0, 2.0, "s", "a frame waits this long for the attitude after it, then goes without"),
    field::integer("frames_per_step", &VoStageSettings::frames_per_step, 1, 8, "frames", "frames processed per release at most (a backlog is worked off)"),
    field::text("output_channel", &VoStageSettings::output_channel, chan::kVisualOdometry.name, "", "ring channel the odometry is published on (the pose graph reads visual_odometry)"),
};
inline constexpr auto kVoStageParams = param_specs(kVoFields, kVoStageFields);

class VoStage final : public Stage {
 public:
  static constexpr std::span<const ParamSpec> kParams{kVoStageParams};
  static std::unique_ptr<Stage> make() { return std::make_unique<VoStage>(); }

  Status init(StageContext& ctx) override;
  void step(TimeNs now) noexcept override;
  // Logs the counters once ("vo: frames=... tracked=..."), as the pose graph's user wants to see them.
  void stop() noexcept override;

  [[nodiscard]] const VoStageCounters& counters() const noexcept { return c_; }
  [[nodiscard]] const VisualOdometry& odometry() const noexcept { return *vo_; }

 private:
  // The autopilot's world_from_body at t, interpolated between the samples around it.
  [[nodiscard]] bool attitude_at(TimeNs t, Eigen::Matrix3d& R) const noexcept;

  static constexpr std::size_t kHistory = 256;
  std::unique_ptr<VisualOdometry> vo_;
  RingReader<CameraImageMsg, kCameraRing> camera_;
  RingReader<AttitudeMsg, kAttitudeRing> attitude_;
  RingWriter<VoMsg, kVoRing> out_;
  const Clock* clock_{nullptr};
  std::array<AttitudeMsg, kHistory> history_{};
  std::size_t history_head_{0}, history_size_{0};
  TimeNs max_gap_{0}, max_wait_{0};
  int frames_per_step_{2};
  bool was_tracking_{false};
  VoStageCounters c_;
};

}  // namespace ag::vo
