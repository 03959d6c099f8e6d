// `airground-sim eval mapping`: fly a survey over a world with the simulator's camera, GPS and odometry
// noise, run the quadrotor's real mapping stages in lockstep, and score the map against the world.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "airground/platform/result.hpp"
#include "airground/sim/compute_time.hpp"
#include "airground/sim/runner.hpp"

namespace ag::sim {

struct EvalMappingOptions {
  std::string world{"default"};
  std::uint64_t seed{1};
  std::string out_dir{"eval-mapping"};
  bool record{true};  // DIR/recording.mcap (docs/simulator.md "Recordings"); --record none: off
  double altitude_m{40};
  double speed_mps{5};
  double overlap{0.3};            // survey side overlap
  double max_duration_s{3600};    // the run ends when the survey is flown, or at this
  std::string config_dir{};       // simulator model overrides (as for `run --config-dir`)
  double vo_scale{0};             // > 0: the odometry starts with exactly this scale (VO units per metre)
  double tracking_loss_at_s{-1};  // >= 0: one odometry tracking loss at this time
  double gps_outlier_at_s{-1};    // >= 0: one GPS fix this long after the start is off by gps_outlier_m
  double gps_outlier_m{50};
  bool random_faults{true};       // the models' own random tracking losses and GPS dropouts
  bool quiet{false};
  std::vector<std::string> set{};  // "section.key=value" on the quadrotor's role config (e.g. segmentation.labels=erfnet)
  std::vector<std::string> oracles{};  // ground truth for the quadrotor by name (RunOptions::oracles): "vo"
  ComputeTimeMode compute_time{ComputeTimeMode::kModel};  // RunOptions::compute_time
  std::optional<TargetCpu> target_cpu{};                 // RunOptions::target_cpu (unset: the paper's computers)
};

struct MappingMetrics {
  double map_class_accuracy{0};     // classified cells whose class is one the world has in that cell
  double map_coverage{0};           // classified cells / cells of the surveyed area
  double elevation_rmse_ground_m{0};  // cells wholly on flat ground (road, dirt, grass, water)
  double elevation_rmse_m{0};       // every mapped cell, against the world's surface range in the cell
  double elevation_coverage{0};     // cells with an elevation (enough support) / cells of the surveyed area
  double elevation_bias_ground_m{0};    // mean signed error (map - world) on flat ground: pose/scale bias
  double elevation_p50_ground_m{0}, elevation_p95_ground_m{0};  // |error| quantiles on flat ground
  double elevation_p95_m{0};        // |error| 95% quantile over every mapped cell
  double elevation_outliers{0};     // fraction of mapped cells more than 2 m off the world's surface range
  double georeg_error_m{0};         // RMS horizontal error of the keyframes' optimised positions
  double pose_z_rmse_m{0};          // RMS height error of the keyframes' optimised positions
  double pose_tilt_rmse_deg{0}, pose_yaw_rmse_deg{0};  // RMS attitude errors of the keyframes (tilt of the body z axis, heading)
  double scale_error{0};            // |estimated x true odometry scale - 1| at the end
  std::uint64_t keyframes{0};
  std::uint64_t cells_evaluated{0};
  std::uint64_t tiles{0}, tiles_rebuilt{0};
  std::uint64_t gps_rejected{0}, vo_segments{0}, stage_overruns{0};
  double sim_s{0}, wall_s{0};
  double pose_graph_p99_ms{0}, ortho_map_p99_ms{0};  // stage step times: modelled on the target CPU (compute_time model), else thread CPU
  double resident_mb{0};            // process resident set at the end (simulator world, sensors and the UAV stages)
  double resident_growth_mb{0};     // resident set at the end minus after the first 2 s of flight: what the UAV stages grew by
  double map_memory_mb{0};          // the ortho-map's tiles and keyframe window, counted by the map
};

// Runs the evaluation and writes DIR/metrics.json, DIR/report.md, the map PNGs and GeoTIFFs.
Result<MappingMetrics> eval_mapping(const EvalMappingOptions& options, const ProgressFn& progress = {});

}  // namespace ag::sim
