// The lockstep team runner: one quadrotor and N ground robots, their role tables on a simulated clock,
// the world's sensors, vehicles and radio stepped deterministically, every sensor stream recorded.
#pragma once

#include <Eigen/Core>

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "airground/messages/geometry.hpp"
#include "airground/platform/result.hpp"
#include "airground/platform/time.hpp"
#include "airground/sim/compute_time.hpp"
#include "airground/sim/world.hpp"

namespace ag {
class Config;
class RoleInstance;
struct LidarScanMsg;
struct WheelOdometryMsg;
struct MapTileMsg;
struct InitialPoseMsg;
struct LocalizationMsg;
}

namespace ag::sim {

struct TruthSample {
  TimeNs t{0};
  Pose3 pose;
};

// What a caller may look at when the run ends (before the reports are written): evaluation commands
// read the robots' stages and compare them with the ground truth here.
struct RunInspection {
  const World& world;
  RoleInstance* uav{nullptr};                 // the quadrotor's role instance (nullptr without one)
  const std::vector<TruthSample>* uav_truth{nullptr};  // at the physics rate (RunOptions::keep_uav_truth)
  double vo_scale{0};                         // true visual-odometry scale at the end [VO units per metre]
  std::uint64_t vo_segments{0};
  std::uint64_t vo_tracking_losses{0};
  double survey_x0{0}, survey_y0{0}, survey_x1{0}, survey_y1{0};  // [m] the area the survey covers
  // Every robot's role configuration as the simulator gave it: the quadrotor (with one), the ground
  // robots in order, the base station (RunOptions::base). The shipped file's sections of the device
  // stages the simulator replaces are kept.
  const std::vector<Config>* role_configs{nullptr};
};

// The robots' shipped configuration built into the simulator at build time (firmware_host/<role>/<role>.yaml
// for "uav", "ugv", "base"; empty for another name): what every simulated robot starts from.
[[nodiscard]] std::string_view shipped_config_yaml(std::string_view role) noexcept;

// What a run writes besides its summary: nothing, recording.mcap only (the evaluations), recording.mcap with
// the CSV streams and every 20th camera frame as PNG (light), or every frame and the LiDAR's .bin (full).
enum class RecordLevel { kNone, kMcap, kLight, kFull };

// Where the ground robots' "map_tiles" channel gets the aerial map from.
enum class UgvMapSource {
  kNone,         // no tiles
  kGroundTruth,  // the world's class raster resampled to the map's 0.5 m cells, every tile once at start
  kOnline,       // the quadrotor's ortho-map: every tile whose version changed, to every ground robot at once
                 // (perfect comms for now; the radio's gossip replaces this in a later issue)
};

// Hold ground robot `ugv` (0-based) standing still from at_s for duration_s simulated seconds.
struct UgvHold {
  int ugv{0};
  double at_s{0};        // [s] simulated time
  double duration_s{0};  // [s]
};

// What the sampling callback sees of one ground robot (RunOptions::sample), read after the robot's own
// stages ran in that tick.
struct UgvSample {
  TimeNs now{0};
  int ugv{0};                      // 0-based
  Pose2 truth;                     // [m, rad] true pose, map frame
  Pose2 odometry;                  // [m, rad] wheel odometry in its own frame (the pose at the start is 0)
  Pose2 odometry_in_map;           // the odometry put into the map frame by the true start pose
  Pose2 initial_guess;             // the pose published on "initial_pose" at the start
  bool localization_received{false};  // the robot's "localization" channel was published at least once
  const LocalizationMsg* localization{nullptr};  // the newest value on that channel (never nullptr)
  Pose2 truth_at_localization;     // true pose at localization->stamp (within the last ~2.5 s), else `truth`
  double distance_m{0};            // [m] travelled so far
  bool released{false};            // driving has begun (false while it waits for the online map)
  bool held{false};                // standing still by a UgvHold now
  bool route_done{false};          // its scripted route (RunOptions::ugv_routes) is finished
  bool killed{false};              // powered off (RunOptions::kills)
  RoleInstance* role{nullptr};     // the robot's role instance (channels are sealed: read stages, not channels)
};

// Test-side readers on a ground robot's input channels (a simulator-only stage appended to the robot's
// table subscribes them when set): what the robot's stages receive, as they receive it.
struct UgvChannelTap {
  std::function<void(int ugv, const LidarScanMsg&)> scan{};
  std::function<void(int ugv, const WheelOdometryMsg&)> odometry{};
  std::function<void(int ugv, const MapTileMsg&)> tile{};
  std::function<void(int ugv, const InitialPoseMsg&)> initial_pose{};
  [[nodiscard]] bool any() const noexcept { return scan || odometry || tile || initial_pose; }
};

struct RunOptions {
  std::string world{"default"};  // a world directory or "default"
  std::string out_dir{"sim-run"};
  int ugvs{3};
  bool uav{true};
  std::uint64_t seed{1};
  double duration_s{60};          // simulated seconds
  // > 0 with a quadrotor: run at least this many times the survey's estimated flying time (with its
  // return), so a longer survey (lower altitude, bigger area) does not cut a mission short.
  double duration_survey_factor{0};
  double physics_hz{50};          // vehicle dynamics, odometry, GPS/VO sampling
  double camera_hz{5};            // quadrotor camera frames (1 m apart at 5 m/s, for keyframes every 2 m)
  double camera_scale{0.5};       // 0.5 = 640x400, the size the mapper matches stereo at; 1.0 = 1280x800
  double lidar_hz{10};
  int lidar_columns{1024};        // 512, 1024 or 2048
  double lidar_mount_height_m{0.5};  // [m] the simulated LiDAR above the base: the shipped ugv.yaml's lidar.mount_z_m (ShippedConfig checks)
  double uav_altitude_m{40};
  double uav_speed_mps{5};
  double survey_overlap{0.6};
  double ugv_speed_mps{1.2};
  double heartbeat_hz{1};         // radio: each robot's status datagram
  std::string config_dir{};       // optional YAML overrides: gps.yaml, visual_odometry.yaml, wheel_odometry.yaml, radio.yaml, diff_drive.yaml, quadrotor.yaml, camera.yaml, lidar_noise.yaml
  RecordLevel record{RecordLevel::kLight};
  // recording.mcap (Foxglove's schemas, docs/simulator.md "Recordings") unless record is kNone; its
  // /scheduler channel every this many simulated seconds (0 = none: stage times are CPU times, the one
  // channel two runs of a seed do not repeat).
  bool record_mcap{true};
  double record_scheduler_period_s{10};
  int threads{0};                 // sensor worker threads, 0 = all cores
  bool parallel_robots{true};     // with threads > 1, the robots' stages of one release time run side by side (same results)
  bool progress{true};
  bool keep_uav_truth{false};     // keep the quadrotor's true poses for RunInspection
  bool stop_when_survey_done{false};  // end the run when the quadrotor finished its survey (duration_s caps it)
  double survey_margin_m{20};     // [m] the survey area is the world minus this margin
  // After the survey the quadrotor flies back over its launch point at survey height and hovers there (as
  // PX4 and ArduPilot return to launch at the end of a mission): a team with a short radio range hears
  // the last regions there. The run's "survey done" includes the return.
  bool uav_return_home{false};
  // Tell the ground robots when the survey (with the return) should end, as mission.survey_end_s (the
  // route's flying time, estimate_route_time_s): until then one with nothing to do waits for regions.
  bool ugv_survey_end{false};
  std::function<Status(const RunInspection&)> inspect{};  // called after the run, before the reports

  // --- the ground robots' drivers in simulation (channels "lidar_scan", "wheel_odometry", "initial_pose",
  // "map_tiles" of every ground robot's role instance)
  UgvMapSource ugv_map{UgvMapSource::kNone};
  // The quadrotor cache (a directory; empty: none): a mission with gossip records its quadrotor's mapping
  // output there the first time and replays it in every later run with the same uav_replay_key (the
  // study's missions on one world, seed and altitude), skipping the camera, VO, ErfNet and the mapping.
  std::string uav_cache{};
  // Replay the recordings another build of airground-sim made (its executable, hashed into the key in place
  // of this one's): for a change that leaves the quadrotor's flight and mapping as they were. Only replays:
  // a mission whose recording that build did not make is an error, and nothing is recorded under its key.
  std::string uav_cache_build{};
  int map_tiles_per_tick{16};     // at most this many tiles pushed to one robot per physics step (and
                                  // never more than its ring takes: the rest follow on the next steps)
  double init_error_m{0};         // [m] the initial pose published at start is the truth moved this far (random direction by seed)
  double init_yaw_error_deg{0};   // [deg] ... and turned by this much (random sign); sigmas given = these (at least 0.5 m / 2 deg)
  // [m] the sigma given to the localizer with the guess; 0 = init_error_m, or with init_error_uniform half
  // of it: a guess "up to R off" is one within 2 sigma (the error's own per-axis spread is R / sqrt(6)).
  double init_sigma_m{0};
  std::vector<std::string> ugv_config{};  // "section.key=value" set on every ground robot's role config
  std::vector<std::string> uav_config{};  // "section.key=value" set on the quadrotor's role config
  // Ground truth handed to the robots, by name, for an ablation the user asks for; none by default.
  // "vo": the quadrotor's odometry from the simulator's VO model (true motion, scaled, with noise and losses)
  // instead of its own vo stage on the rendered frames.
  // "labels": the camera frames carry the renderer's true classes and the LiDAR points the world's, and the
  // robots use them (segmentation.labels gt, localization.labels gt) instead of ErfNet and the geometric
  // labeller.
  std::vector<std::string> oracles{};
  // The oracle list as JSON ("[]" or ["vo", ...]) and as the report's first line.
  [[nodiscard]] std::string oracles_json() const {
    std::string s = "[";
    for (std::size_t i = 0; i < oracles.size(); ++i) s += (i ? ", \"" : "\"") + oracles[i] + "\"";
    return s + "]";
  }
  [[nodiscard]] std::string oracles_line() const {
    if (oracles.empty()) return "Field mode: no ground truth reached a robot (oracles: none).";
    std::string s = "ABLATION: ground truth handed to the robots by name (oracles:";
    for (const std::string& o : oracles) s += " " + o;
    return s + "); these figures are not field-mode figures.";
  }
  [[nodiscard]] bool oracle(std::string_view name) const noexcept {
    for (const std::string& o : oracles)
      if (o == name) return true;
    return false;
  }
  // Compute time (docs/simulator.md, "Compute time"): a robot stage's outputs show when its step's compute
  // time on the robot's CPU has passed, and a stage still busy at its next release starts late or slips.
  // model: from the cost table (deterministic, the default); measured: this machine's CPU time, scaled
  // (profiling); off: outputs at the release instant (the old simulator).
  ComputeTimeMode compute_time{ComputeTimeMode::kModel};
  // The robots' CPU; unset: the paper's computers (quadrotor and base station NUC, ground robots Ryzen).
  std::optional<TargetCpu> target_cpu{};
  std::function<void(const StepSample&)> step_sampler{};  // benchmarks: every robot step, on executor threads
  [[nodiscard]] TargetCpu target_of(std::string_view robot) const noexcept {
    if (target_cpu) return *target_cpu;
    return robot.starts_with("ugv") ? TargetCpu::kRyzen : TargetCpu::kNuc;
  }
  // Per ground robot (0-based) with its true start pose: more "section.key=value" (its priority, its start).
  std::function<std::vector<std::string>(int ugv, const Pose2& start)> ugv_config_for{};
  std::vector<std::string> base_config{};  // "section.key=value" set on the base station's role config
  bool init_error_uniform{false};
  // Per ground robot (0-based), from a mission file: its true start pose (else the staging-pad lineup) and
  // the initial guess given to its localizer with that sigma (else from init_error_m).
  struct UgvStart {
    bool has_start{false};
    Pose2 start;
    bool has_guess{false};
    Pose2 guess;
    double guess_sigma_m{16};
  };
  std::vector<UgvStart> ugv_starts{};
  // The quadrotor's survey area [m, map frame] (x0 < x1 and y0 < y1; else the world minus survey_margin_m).
  double survey_x0{0}, survey_y0{0}, survey_x1{0}, survey_y1{0};  // the initial guess is U(0, init_error_m) off (per robot), not exactly init_error_m

  // --- scripted ground robots
  // Per ground robot (index 0-based), a road route to drive once (a polyline in the map frame, e.g. from
  // RoadRouter): the robot starts at its first point facing along it, drives it, then stands. Robots
  // without one (empty or missing) drive random legs from the staging pad as before.
  std::vector<std::vector<Eigen::Vector2d>> ugv_routes{};
  std::vector<UgvHold> ugv_holds{};
  bool stop_when_routes_done{false};  // end the run when every scripted route is driven (duration_s caps it)
  // With ugv_map == kOnline: a robot stays at its start until the quadrotor's map has a class for this
  // fraction of the cells within ugv_wait_map_radius_m of it (0 = start at once).
  double ugv_wait_map_radius_m{0};
  double ugv_wait_map_fraction{0.5};
  // ... and, for a scripted robot, until the map has a class for this fraction of the cells within 3 m of
  // its route (0 = not waited for): it then drives where the quadrotor has been, as a mission would send it.
  double ugv_wait_map_route_fraction{0};

  // --- missions: the team as it runs in the field
  // Every robot's comms stage talks gossip over the simulated radio (sim::RadioNet, comms.transport =
  // inproc, a team key in out_dir): the quadrotor shares its map tiles, the ground robots get them (and
  // each other's poses, claims, failures) only through it, the base station listens. ugv_map must be kNone
  // (or kGroundTruth: the runner's tiles, and gossip for everything else).
  bool gossip{false};
  double comm_range_m{0};          // [m] the radio's range (0 = radio.yaml's / the model's default)
  // The ground robots move by their own drive stage's "wheel_command" (planner -> drive -> wheels), not
  // the simulator's scripted pursuit; the planner's area is set to the world's extent.
  bool drive_by_stages{false};
  // Per ground robot (0-based): a goal the runner writes once on its "goal" channel at the start (tests of
  // planner -> drive); the robots' table then has no mission stage. NaN = none.
  std::vector<Eigen::Vector2d> ugv_goals{};
  // Power a robot off at at_s: it stops moving and its radio falls silent (nothing it sends reaches
  // anyone, nothing reaches it). ugv = -1 is the base station.
  struct Kill {
    int ugv{0};
    double at_s{0};
  };
  std::vector<Kill> kills{};
  // Checked every simulated second; true ends the run (duration_s caps it).
  std::function<bool(TimeNs now, bool survey_done)> stop_when{};  // survey_done: the quadrotor flew its whole survey (or there is none)
  // Called at sample_hz at the start of a physics step (what the roles did up to the step before): a
  // read-only look at every role, e.g. for mission logs. ugvs[i] is nullptr never; base may be nullptr.
  std::function<void(TimeNs now, RoleInstance* uav, const std::vector<RoleInstance*>& ugvs, RoleInstance* base)> observe{};

  // --- evaluation
  double sample_hz{10};
  std::function<void(const UgvSample&)> sample{};  // per ground robot at sample_hz (from t = 0)
  UgvChannelTap ugv_tap{};
};

// The sigma [m] a robot's localizer is given with its initial guess (RunOptions::init_sigma_m).
inline double initial_sigma_m(const RunOptions& o) noexcept {
  if (o.init_sigma_m > 0) return o.init_sigma_m;
  return o.init_error_uniform ? 0.5 * o.init_error_m : o.init_error_m;
}

struct RobotSummary {
  std::string name;
  double distance_m{0};
  std::uint64_t collisions{0};
  std::uint64_t goals_reached{0};
  std::uint64_t scans{0};
  std::uint64_t odometry_samples{0};
  double odometry_final_error_m{0};  // |odometry pose - truth| at the end (odometry frame aligned at start)
  // What the simulated drivers published into the robot's channels.
  std::uint64_t scans_published{0};     // "lidar_scan" messages
  std::uint64_t odometry_published{0};  // "wheel_odometry" messages
  std::uint64_t tiles_published{0};     // "map_tiles" messages pushed
  std::uint64_t tiles_refused{0};       // pushes a full ring refused (that tile was pushed again later)
  std::uint64_t channel_drops{0};       // scans or odometry messages a full ring refused
  bool initial_pose_published{false};
  double released_s{0};                 // [s] when it began to drive (waiting for the online map before)
  bool route_done{false};               // its scripted route was driven to the end
  double killed_s{-1};                  // [s] when it was powered off (RunOptions::kills), -1 never
  std::uint64_t wheel_commands{0};      // drive_by_stages: new "wheel_command" values applied to the wheels
  // Its own localization ("localization" channel) against the truth, sampled at sample_hz once it drives.
  std::string loc_status{"none"};       // at the end: none (never published), no map, initialising, tracking, lost
  double loc_tracking_fraction{0};      // samples with status tracking / samples while driving
  double loc_first_tracking_s{-1};      // [s] simulated time of the first tracking sample
  double loc_error_mean_m{-1};          // [m] over the tracking samples: |estimate - truth at its stamp|
  double loc_error_p95_m{-1};
  double loc_error_max_m{-1};
};

// What the runner did with the quadrotor cache (RunOptions::uav_cache), for the summary and the report.
struct UavReplayInfo {
  std::string mode{"live"};   // "live" (no cache), "recorded" (live, written to the cache), "replayed"
  std::string file{};         // the recording
  std::string build{};        // the executable that recorded it, when another build's (RunOptions::uav_cache_build)
  double recording_end_s{0};  // [s] replayed: where the recording ends
  double last_output_s{0};    // [s] ... and its last map tile or region batch
  double beyond_end_s{0};     // [s] replayed: how long this run went on past the recording's end
};

struct RunSummary {
  double sim_s{0};
  double wall_s{0};
  double real_time_factor{0};
  // CPU time [s] over the run's loop (start-up excluded), summed over every thread: the simulated
  // sensors (camera, LiDAR), each robot's stages ("uav", "ugv1", ..., "base") and the whole process
  // (world, vehicles, radio, recording, threads' overhead included). cpu_s / sim_s is the cost of a
  // simulated second in core-seconds: the machine's cores divided by it bound the real-time factor.
  double sensor_cpu_s{0};  // camera_cpu_s + lidar_cpu_s
  double camera_cpu_s{0}, lidar_cpu_s{0};
  double process_cpu_s{0};
  std::vector<std::pair<std::string, double>> robot_cpu_s;
  std::uint64_t camera_frames{0};
  std::uint64_t camera_frames_ahead{0};  // of them, rendered ahead on a thread of their own (two threads or more)
  std::uint64_t gps_fixes{0};
  std::uint64_t vo_samples{0};
  std::uint64_t vo_segments{0};
  double uav_distance_m{0};
  double uav_route_estimate_s{0};  // the survey's estimated flying time with its return (estimate_route_time_s)
  double duration_cap_s{0};        // the run's cap: duration_s, or more with duration_survey_factor
  std::uint64_t uav_waypoints_reached{0};
  std::uint64_t radio_sent{0}, radio_delivered{0}, radio_dropped_range{0}, radio_dropped_loss{0}, radio_dropped_queue{0};
  std::uint64_t radio_bytes_sent{0}, radio_bytes_delivered{0};  // payload bytes put on the air / received
  std::uint64_t stage_overruns{0};
  std::uint64_t stage_slips{0};
  // Every robot stage's scheduler counters (runs, overruns, slips, modelled exec p99 on its target CPU).
  struct StageCounters {
    std::string name;  // "<robot>/<stage>"
    std::uint64_t runs{0}, overruns{0}, slips{0};
    double exec_p99_ms{0}, budget_ms{0};
  };
  std::vector<StageCounters> stages;
  std::string compute_time{"model"};
  std::uint64_t recording_messages{0}, recording_bytes{0};  // recording.mcap (0 without one)
  UavReplayInfo uav_replay{};  // the quadrotor cache: live, recorded or replayed
  std::vector<RobotSummary> ugvs;
};

using ProgressFn = std::function<void(double sim_s, double total_s, double rtf)>;

// Runs the team for options.duration_s and writes the recordings, summary.yaml/json and report.md
// (with trajectories.png) into options.out_dir.
Result<RunSummary> run_team(const RunOptions& options, const ProgressFn& progress = {});

// Loads a world directory, or generates the built-in default for "default".
Result<std::shared_ptr<const World>> resolve_world(const std::string& world_arg);

// A team key as an operator makes one (64 hex digits, owner-only), drawn from `seed` so a run repeats;
// the lockstep runner and the HIL mode write one per run. The error names the file.
Status write_team_key(const std::string& path, std::uint64_t seed);

}  // namespace ag::sim
