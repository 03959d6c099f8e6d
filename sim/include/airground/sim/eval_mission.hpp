// `airground-sim mission`: a whole team mission in the lockstep runner — the quadrotor surveys and maps,
// finds the regions of interest, the ground robots localize in its map (GPS-denied, a rough initial guess),
// claim regions among themselves over the radio's gossip, plan, drive and report; the base station only
// listens. Scored against the world's targets and the true poses; a report folder a person can read.
#pragma once

#include <cstdint>
#include <optional>
#include <functional>
#include <string>
#include <vector>

#include "airground/platform/result.hpp"
#include "airground/sim/compute_time.hpp"
#include "airground/sim/eval_scoring.hpp"
#include "airground/sim/runner.hpp"

namespace ag::sim {

inline constexpr double kMinMissionCapS = 1800;  // [s] the shortest default mission cap
inline constexpr double kLocGoodRadiusM = 3.0;   // [m] a tracking sample this close to the truth starts the scoring

struct MissionOptions {
  std::string world{"default"};
  std::string out_dir{"mission"};
  std::string mission_file{};      // optional mission YAML (config/missions/*.yaml); empty = region investigation
  int ugvs{3};
  std::uint64_t seed{1};
  double comm_range_m{0};          // [m] 0 = the radio model's default
  double uav_altitude_m{40};
  double init_error_m{16};         // [m] each robot's initial guess is up to this far off (uniform)
  double init_sigma_m{0};          // [m] the sigma its localizer is given with it; 0 = half of init_error_m
  double init_yaw_error_deg{10};
  // [s] simulated cap; the mission normally ends earlier (every robot back). 0 = four times the survey's
  // estimated flying time, at least kMinMissionCapS.
  double max_duration_s{0};
  int lidar_columns{1024};
  int threads{0};
  bool parallel_robots{true};      // robots of one release time side by side on the workers (same results)
  bool progress{true};
  double status_period_s{0};       // > 0: a status line per robot on stderr this often (simulated seconds)
  RecordLevel record{RecordLevel::kLight};
  std::vector<RunOptions::Kill> kills{};   // ugv -1 = the base station
  std::vector<std::string> ugv_config{}, uav_config{};
  std::vector<std::string> oracles{};  // ground truth for the robots by name (RunOptions::oracles), an ablation
  ComputeTimeMode compute_time{ComputeTimeMode::kModel};  // RunOptions::compute_time
  std::optional<TargetCpu> target_cpu{};                 // RunOptions::target_cpu (unset: the paper's computers)
  std::string uav_cache{};         // RunOptions::uav_cache: record the quadrotor's mapping once, replay it after
  std::string uav_cache_build{};   // RunOptions::uav_cache_build: replay the recordings of that executable
  int web_port{0};                 // > 0: the base station serves its page on this port during the run
  double web_pace{0};              // > 0: hold the simulation to this many times real time (to watch it)
  std::function<void(double t_s)> during{};  // called at 5 Hz of simulated time while the mission runs (tests)
  std::function<void(const StepSample&)> step_sampler{};  // RunOptions::step_sampler (benchmarks)
};

struct MissionRobot {
  std::string name;
  double distance_m{0};
  std::uint64_t collisions{0};
  std::uint32_t visited{0}, failed{0}, false_visits{0};
  std::uint32_t non_target_visits{0};  // true visits to regions with no target near
  double loc_error_mean_m{-1}, loc_error_p95_m{-1};  // [m] = loc.mean_m / loc.p95_m (every sample after the first good one)
  LocErrorStats loc;
  double odom_only_error_mean_m{0};
  double first_tracking_s{-1};
  double done_s{-1};    // [s] back at its start with nothing left
  double killed_s{-1};
  std::string final_state;
};

struct MissionMetrics {
  std::uint32_t targets_total{0}, targets_visited{0};
  // The world's targets with no car in the area the quadrotor surveys (an imported map's cluster in the
  // survey's border): not part of the mission, so not in targets_total; their ids are in the report.
  std::uint32_t targets_outside_survey{0};
  std::vector<int> outside_survey_ids;
  std::uint32_t regions_found{0}, regions_visited{0};
  double mission_time_s{0};        // [s] until every robot still running was back (or the cap)
  bool completed{false};           // every running robot finished its mission before the cap
  // [m] every robot's samples from its first good one (tracking, within kLocGoodRadiusM) on, tracking or not;
  // loc has the max, the tracking-only figures, tracking_fraction and within_3m_fraction beside them.
  double loc_error_mean_m{-1}, loc_error_p95_m{-1};
  LocErrorStats loc;
  double odom_only_error_mean_m{0};
  std::uint64_t collisions{0};
  std::uint32_t failed_goals{0}, false_visits{0};
  std::uint32_t non_target_visits{0};  // true visits to regions with no target within 10 m (not false, not targets)
  std::uint32_t takeovers{0}, clashes_lost{0};
  double map_class_accuracy{0};
  std::uint64_t bytes_on_air{0};   // [B] payload bytes the radio carried (every copy)
  double realtime_factor{0};
  double sim_s{0}, wall_s{0};
  double time_cap_s{0};       // [s] the run's cap (--max-duration, or 4x the survey's estimated flying time)
  double survey_estimate_s{0};  // [s] the quadrotor's route with its return, estimated before take-off
  std::vector<MissionRobot> robots;
  // The robots' scheduler counters on their target CPUs (RunSummary::stages), and the compute-time mode.
  std::string compute_time{"model"};
  std::uint64_t stage_overruns{0}, stage_slips{0};
  std::vector<RunSummary::StageCounters> stages;
  UavReplayInfo uav_replay{};  // the quadrotor: live, recorded into the cache, or replayed from it
};

Result<MissionMetrics> run_mission(const MissionOptions& options, const ProgressFn& progress = {});

}  // namespace ag::sim

namespace ag::sim {

// Reads DIR/runs/*/metrics.json (and visits.csv where present: first and last visit times) of a study
// and writes DIR/study.csv, DIR/study.md and the plots (mission_time.png, pose_error.png, targets.png);
// returns the summary printed at the end. Repeat visits: the robots' visits (robots[].visited) beyond
// the regions visited, i.e. visits to a region another robot had reached already.
Result<std::string> summarise_study(const std::string& dir);

}  // namespace ag::sim
