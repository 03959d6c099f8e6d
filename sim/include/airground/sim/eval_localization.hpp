// `airground-sim eval localization`: one ground robot drives a long loop over the roads (planned from
// ground truth) with a wrong initial pose guess, its real role table localizes it in the aerial map (the
// world's true class map, or the one the quadrotor's stages build online), and the pose it publishes on
// its "localization" channel is scored against the truth.
#pragma once

#include <Eigen/Core>

#include <cstdint>
#include <optional>
#include <functional>
#include <string>
#include <vector>

#include "airground/platform/result.hpp"
#include "airground/sim/compute_time.hpp"
#include "airground/sim/eval_scoring.hpp"
#include "airground/sim/runner.hpp"
#include "airground/sim/world.hpp"

namespace ag::sim {

struct EvalLocalizationOptions {
  std::string world{"default"};
  std::uint64_t seed{1};
  std::string out_dir{"eval-localization"};
  bool record{true};  // DIR/recording.mcap (docs/simulator.md "Recordings"); --record none: off
  UgvMapSource map{UgvMapSource::kGroundTruth};
  double init_error_m{16};          // [m] the initial guess is exactly this far off (direction by seed)
  double init_yaw_error_deg{30};    // [deg] ... and turned by exactly this much (sign by seed)
  double route_km{2};               // length of the road loop to drive
  double speed_mps{1.2};            // scripted driving speed
  std::string labels{};             // "gt" or "geometric": the ground robot's localization.labels (empty: the shipped
                                    // geometric, or gt with the labels oracle); gt needs the labels oracle
  std::vector<std::string> oracles{};  // ground truth for the robot by name (RunOptions::oracles), an ablation
  ComputeTimeMode compute_time{ComputeTimeMode::kModel};  // RunOptions::compute_time
  std::optional<TargetCpu> target_cpu{};                 // RunOptions::target_cpu (unset: the paper's computers)
  std::vector<std::string> set{};   // "section.key=value" on the ground robot's role config
  double stand_still_s{0};          // > 0: the robot stands this long ...
  double stand_still_at_s{120};     // [s] ... from this simulated time
  double yaw_drift_at_rest{0};      // [rad/s] the wheel odometry's yaw drift while standing (the paper's failure)
  bool yaw_drift_at_rest_set{false};
  double convergence_radius_m{3};   // see LocalizationMetrics::converged
  double stale_after_s{0.5};        // a localization older than this when sampled counts as not tracking
  double wait_map_radius_m{30};     // --map online: start driving once the map knows wait_map_fraction of
  double wait_map_fraction{0.5};    //   the cells within this radius (0 = at once)
  double wait_map_route{0.8};       // --map online: ... and this share of the cells within 3 m of the route (0 = not)
  int lidar_columns{1024};
  double max_duration_s{0};         // 0 = from the route length (the run ends when the route is driven)
  std::string config_dir{};         // simulator model overrides (as for `run --config-dir`)
  int threads{0};
  bool quiet{false};
};

// Scored over the samples (10 Hz) taken after the robot began to drive. A sample is "good" when the
// robot's "localization" channel has been published, its status is tracking, its stamp is at most
// stale_after_s old, and its position is within convergence_radius_m of the true pose at that stamp.
// The error figures are over every sample from the first good one on, good or not: one excursion past the
// radius counts in them instead of restarting them (it only makes `converged` later).
struct LocalizationMetrics {
  bool converged{false};              // some sample is good and every later one is too
  double convergence_time_s{-1};      // [s] from the start of driving to the first of those good samples
  double convergence_distance_m{-1};  // [m] driven by then
  double loc_error_mean_m{-1};        // [m] over the samples from the first good one on: |estimate - truth at its stamp|
  double loc_error_p95_m{-1};         // 95th percentile (nearest rank) of the same
  double loc_error_max_m{-1};
  LocErrorStats loc;                  // the same, with the tracking-only figures, tracking and within-radius fractions
  double converged_error_mean_m{-1};  // [m] over the samples from convergence on only (the old figure)
  double yaw_error_mean_deg{-1};      // mean |yaw error| over the samples from the first good one on
  double odom_only_error_mean_m{0};   // wheel odometry aligned with the true pose at the start, over the same
                                      // samples (all samples after the start of driving when not converged)
  double odom_only_error_final_m{0};  // ... at the last sample
  bool localization_published{false}; // the channel was ever published (false: no localization stage)
  double first_tracking_s{-1};        // [s] driving time of the first good sample
  std::uint64_t divergences{0};       // good -> not good transitions after the first good sample
  double good_fraction{0};            // good samples / samples after the start of driving
  double tracking_fraction{0};        // tracking (and fresh) samples / samples from the first good one on
  double within_fraction{0};          // samples within convergence_radius_m / samples from the first good one on
  std::uint64_t samples{0}, samples_scored{0};
  double route_length_m{0}, distance_m{0}, released_s{0}, sim_s{0}, wall_s{0};
  std::uint64_t tiles_published{0}, scans_published{0};
  std::string labels;                 // what the robot was told to use ("default" when not set, "n/a" without the key)
};

struct LocalizationProgress {
  double sim_s{0}, total_s{0}, rtf{0};
  double distance_m{0}, route_m{0};
  bool released{false};
  const char* status{"no map"};  // the robot's localization status
  double error_m{-1};            // [m] current estimate error (-1 when none)
};
using LocalizationProgressFn = std::function<void(const LocalizationProgress&)>;

// A closed loop over the roads of about length_m, from the drivable point nearest the staging pad through
// far-apart drivable points and back, planned with RoadRouter on ground truth; deterministic by seed.
Result<std::vector<Eigen::Vector2d>> plan_road_loop(const World& world, double length_m, std::uint64_t seed,
                                                    double clearance_m = 0.5);
[[nodiscard]] double polyline_length(const std::vector<Eigen::Vector2d>& path) noexcept;

// Runs the evaluation and writes DIR/metrics.json, report.md, samples.csv, trajectory.png and error.png.
Result<LocalizationMetrics> eval_localization(const EvalLocalizationOptions& options,
                                              const LocalizationProgressFn& progress = {});

}  // namespace ag::sim
