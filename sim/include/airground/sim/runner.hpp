// The lockstep team runner: one quadrotor and N ground robots, their role tables on a simulated clock,
// the world's sensors, vehicles and radio stepped deterministically, every sensor stream recorded.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "airground/core/geometry.hpp"
#include "airground/platform/result.hpp"
#include "airground/platform/time.hpp"
#include "airground/sim/world.hpp"

namespace ag {
class RoleInstance;
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
};

enum class RecordLevel { kNone, kLight, kFull };

struct RunOptions {
  std::string world{"default"};  // a world directory or "default"
  std::string out_dir{"sim-run"};
  int ugvs{3};
  bool uav{true};
  std::uint64_t seed{1};
  double duration_s{60};          // simulated seconds
  double physics_hz{50};          // vehicle dynamics, odometry, GPS/VO sampling
  double camera_hz{5};            // quadrotor camera frames (1 m apart at 5 m/s, for keyframes every 2 m)
  double camera_scale{0.5};       // 0.5 = 640x400, the size the mapper matches stereo at; 1.0 = 1280x800
  double lidar_hz{10};
  int lidar_columns{1024};        // 512, 1024 or 2048
  double lidar_mount_height_m{0.6};
  double uav_altitude_m{40};
  double uav_speed_mps{5};
  double survey_overlap{0.6};
  double ugv_speed_mps{1.2};
  double heartbeat_hz{1};         // radio: each robot's status datagram
  std::string config_dir{};       // optional YAML overrides: gps.yaml, visual_odometry.yaml, wheel_odometry.yaml, radio.yaml, diff_drive.yaml, quadrotor.yaml, camera.yaml, lidar_noise.yaml
  RecordLevel record{RecordLevel::kLight};
  int threads{0};                 // sensor worker threads, 0 = all cores
  bool progress{true};
  bool keep_uav_truth{false};     // keep the quadrotor's true poses for RunInspection
  bool stop_when_survey_done{false};  // end the run when the quadrotor finished its survey (duration_s caps it)
  double survey_margin_m{20};     // [m] the survey area is the world minus this margin
  std::function<Status(const RunInspection&)> inspect{};  // called after the run, before the reports
};

struct RobotSummary {
  std::string name;
  double distance_m{0};
  std::uint64_t collisions{0};
  std::uint64_t goals_reached{0};
  std::uint64_t scans{0};
  std::uint64_t odometry_samples{0};
  double odometry_final_error_m{0};  // |odometry pose - truth| at the end (odometry frame aligned at start)
};

struct RunSummary {
  double sim_s{0};
  double wall_s{0};
  double real_time_factor{0};
  double sensor_cpu_s{0};
  std::uint64_t camera_frames{0};
  std::uint64_t gps_fixes{0};
  std::uint64_t vo_samples{0};
  std::uint64_t vo_segments{0};
  double uav_distance_m{0};
  std::uint64_t uav_waypoints_reached{0};
  std::uint64_t radio_sent{0}, radio_delivered{0}, radio_dropped_range{0}, radio_dropped_loss{0}, radio_dropped_queue{0};
  std::uint64_t stage_overruns{0};
  std::vector<RobotSummary> ugvs;
};

using ProgressFn = std::function<void(double sim_s, double total_s, double rtf)>;

// Runs the team for options.duration_s and writes the recordings, summary.yaml/json and report.md
// (with trajectories.png) into options.out_dir.
Result<RunSummary> run_team(const RunOptions& options, const ProgressFn& progress = {});

// Loads a world directory, or generates the built-in default for "default".
Result<std::shared_ptr<const World>> resolve_world(const std::string& world_arg);

}  // namespace ag::sim
