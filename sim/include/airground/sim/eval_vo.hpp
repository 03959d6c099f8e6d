// `airground-sim eval vo`: the quadrotor's visual odometry on rendered frames of a survey flight,
// scored against the true trajectory (relative pose errors, scale drift, tracking, cost per frame).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "airground/platform/result.hpp"

namespace ag::sim {

struct EvalVoOptions {
  std::string world{"default"};
  std::uint64_t seed{1};
  std::string out_dir{"eval-vo"};
  bool record{true};  // DIR/recording.mcap (docs/simulator.md "Recordings"); --record none: off
  double altitude_m{40};
  double speed_mps{5};
  double overlap{0.3};           // survey side overlap
  double camera_hz{5};           // frame rate (the team runner's camera rate)
  double max_duration_s{1e9};    // the flight ends when the survey is flown, or at this
  double pair_distance_m{2.0};   // relative errors over pairs of frames this far apart (keyframe spacing)
  std::string camera_config{};   // camera YAML (intrinsics, shading, sensor realism); empty = the defaults
  std::string attitude_config{}; // autopilot attitude error model YAML; empty = its defaults
  bool attitude{true};           // false: vision only (no gravity prior)
  bool quiet{false};
  std::vector<std::string> set{};  // "key=value" on the vo stage's parameters
};

struct VoMetrics {
  std::uint64_t frames{0}, tracked_frames{0}, segments{0}, keyframes{0};
  double tracked_fraction{0};
  double rpe_rotation_deg_p50{0}, rpe_rotation_deg_p95{0};
  double rpe_translation_direction_deg_p50{0}, rpe_translation_direction_deg_p95{0};
  std::uint64_t rpe_pairs{0};
  Eigen::Vector3d rpe_rotation_mean_deg{0, 0, 0};  // signed mean of the pair errors about body x, y, z (a bias the stereo feels)
  double scale_drift_percent_per_100m{0};  // |drift| per 100 m flown, mean over segments weighted by length
  double tilt_error_deg_p95{0};            // the published roll/pitch against the true gravity
  double ms_per_frame_p50{0}, ms_per_frame_p99{0};  // thread CPU of the VO per frame
  double render_ms_per_frame{0};
  double distance_m{0}, duration_s{0};
};

using EvalVoProgress = std::function<void(double fraction)>;

Result<VoMetrics> eval_vo(const EvalVoOptions& o, const EvalVoProgress& progress = {});

}  // namespace ag::sim
