// `airground-sim eval planning`: the global planner on the world's true class map (resampled to the
// aerial map's 0.5 m cells), between random reachable pairs of points, against the shortest 8-connected
// grid path through traversable cells that keep the robot's minimum clearance; then each route driven by
// the drive controller on the simulated differential-drive robot (ground-truth pose, collisions with the
// world's obstacles checked by the vehicle model at 0.25 m).
#pragma once

#include <cstdint>
#include <optional>
#include <functional>
#include <string>
#include <vector>

#include "airground/platform/result.hpp"
#include "airground/sim/compute_time.hpp"

namespace ag::sim {

struct EvalPlanningOptions {
  std::string world{"default"};
  std::uint64_t seed{1};
  int pairs{20};
  std::string out_dir{"eval-planning"};
  bool record{true};  // each driven pair's DIR/drive_N/recording.mcap (docs/simulator.md "Recordings"); --record none: off
  double min_pair_distance_m{40};   // pairs at least this far apart (straight line)
  bool drive{true};                 // drive every route (ground-truth pose)
  // Drive every pair with the robot's own stages in the lockstep runner instead: its localizer's pose
  // (LiDAR against the true class map, starting from the true start), planner -> tracker -> drive -> wheels.
  bool localizer_pose{false};
  double speed_mps{1.2};
  std::vector<std::string> set{};   // "planner.key=value" / "drive.key=value" overrides of the ugv role config
  std::vector<std::string> oracles{};  // with localizer_pose: ground truth for the robot by name (RunOptions::oracles)
  ComputeTimeMode compute_time{ComputeTimeMode::kModel};  // RunOptions::compute_time
  std::optional<TargetCpu> target_cpu{};                 // RunOptions::target_cpu (unset: the paper's computers)
  bool quiet{false};
};

struct PlanningPairResult {
  double sx{0}, sy{0}, gx{0}, gy{0};
  bool planned{false};
  std::string status;
  double length_m{0}, grid_length_m{0}, ratio{0};
  double min_clearance_m{0};
  bool through_blocked{false}, too_close{false};
  double query_ms{0};
  bool reached{false};
  std::uint64_t collisions{0};
  double drive_time_s{0}, final_error_m{0};
  double loc_error_mean_m{-1};  // localizer_pose: its error while driving
};

struct PlanningMetrics {
  int pairs{0};
  double path_length_ratio_mean{0}, path_length_ratio_max{0};
  double min_clearance_ratio_mean{0};  // mean over pairs of (path min clearance / min_clearance_m); >= 1 keeps it
  double min_clearance_ratio_min{0};
  int reached{0};
  std::uint64_t collisions{0};
  int failures{0};                     // not planned, through a blocked cell, closer than the clearance, or not reached
  int through_blocked{0}, too_close{0};
  double build_ms{0}, query_ms_mean{0}, query_ms_max{0};
  std::uint32_t nodes{0}, edges{0};
  double min_clearance_m{0};
  std::vector<PlanningPairResult> results;
};

struct PlanningProgress {
  int pair{0}, pairs{0};
  const char* phase{""};
};

Result<PlanningMetrics> eval_planning(const EvalPlanningOptions& o, const std::function<void(const PlanningProgress&)>& progress = {});

}  // namespace ag::sim
