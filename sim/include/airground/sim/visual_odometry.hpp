// Simulated monocular visual odometry of the quadrotor: right shape, unknown drifting scale, lost tracking.
#pragma once

#include <cstdint>
#include <span>
#include <string_view>

#include "airground/messages/geometry.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/result.hpp"
#include "airground/platform/time.hpp"
#include "airground/platform/rng.hpp"

namespace YAML {
class Node;
}

namespace ag::sim {

// Each tracking segment has its own gravity-aligned frame: its origin is the first frame of the segment,
// its yaw is arbitrary, and its unit of length is 1/scale metres (scale drawn log-uniformly in
// [scale_min, scale_max]). Drifts are random walks: a "per_s" value is the std of the change over 1 s,
// growing with the square root of time.
struct VoConfig {
  double rate_hz{10.0};                    // [Hz] frame rate; 0 = a frame at every sample() call
  double scale_min{0.3};                   // [-] smallest initial scale of a segment (VO units per metre)
  double scale_max{3.0};                   // [-] largest initial scale
  double scale_drift_per_s{0.002};         // [1/sqrt(s)] random walk of log(scale)
  double yaw_drift_rad_per_s{0.0005};      // [rad/sqrt(s)] random walk of the frame's yaw
  double position_noise_m{0.02};           // [m] white noise per axis per frame (true metres, reported scaled)
  double rotation_noise_rad{0.001};        // [rad] white noise on roll, pitch, yaw per frame
  double tracking_loss_rate_per_s{1.0 / 300.0};  // [1/s] mean rate of tracking losses (Poisson), 0 = never
  double tracking_loss_duration_s{2.0};    // [s] mean length of a loss (exponential)
  bool random_initial_yaw{true};           // a segment starts at a random yaw (false: yaw 0 at its first frame)
  // Fault injection: one tracking loss of tracking_loss_duration_s at this time from the first sample()
  // call, besides the random ones. Negative = none.
  double forced_loss_at_s{-1.0};           // [s]
};

std::span<const ParamSection> vo_config_schema() noexcept;  // one section, "visual_odometry"
// Checks every key, and scale_min <= scale_max.
Result<VoConfig> load_vo_config(const YAML::Node& node, std::string_view origin);
Result<VoConfig> load_vo_config(std::string_view yaml, std::string_view origin);

struct VoSample {
  TimeNs stamp{0};        // [ns] time of the frame (= the truth it was made from)
  std::uint32_t segment{0};  // tracking segment, 0 first; a new one after every tracking loss
  bool tracking{false};   // false while tracking is lost: pose then repeats the last tracked pose
  Pose3 pose;             // body pose in the segment's frame (position in VO units, angles in rad)
};

class VisualOdometrySimulator {
 public:
  VisualOdometrySimulator(const VoConfig& cfg, std::uint64_t seed);

  // Call at every simulation step with the true body pose (map frame). True when a frame is due (the
  // first call, then every 1/rate_hz on a fixed grid), also while tracking is lost.
  bool sample(TimeNs t, const Pose3& truth, VoSample& out);

  // Ground truth of the model, for tests and reports (a real VO does not know these).
  [[nodiscard]] double scale() const noexcept { return scale_; }           // VO units per metre, now
  [[nodiscard]] double yaw_offset() const noexcept { return yaw_offset_; } // VO yaw - true yaw [rad]
  [[nodiscard]] std::uint64_t tracking_losses() const noexcept { return losses_; }
  [[nodiscard]] const VoConfig& config() const noexcept { return cfg_; }

 private:
  void advance_losses(TimeNs t);
  void start_segment(const Pose3& truth);

  VoConfig cfg_;
  Rng noise_rng_;
  Rng loss_rng_;
  TimeNs period_{0};
  TimeNs next_frame_{0};
  bool started_{false};
  bool tracking_{false};
  std::uint32_t segment_{0};
  std::uint64_t losses_{0};
  std::uint64_t losses_at_segment_start_{0};
  TimeNs loss_start_{0}, loss_end_{0};
  TimeNs start_t_{0};
  bool forced_done_{false};
  double log_scale_{0}, scale_{1}, yaw_offset_{0};
  double vx_{0}, vy_{0}, vz_{0};  // integrated position in the segment frame [VO units]
  Pose3 last_truth_{};
  TimeNs last_t_{0};
  Pose3 last_out_{};
};

}  // namespace ag::sim
