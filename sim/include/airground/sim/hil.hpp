// Hardware in the loop: the simulated world served to the unmodified role binaries over the wire
// protocols of the real devices, in real time. Per ground robot: Ouster OS-1 packets (RNG19_RFL8_SIG16_NIR16,
// the surface's albedo in the reflectivity byte) to its lidar UDP port, and its two ODrive controllers
// (CAN Simple over the cannelloni UDP bridge: Set_Input_Vel in, Heartbeat and Get_Encoder_Estimates
// out) moving the simulated base. For the quadrotor: UBX NAV-PVT bytes on a pseudo-terminal (the
// receiver's serial port), a simulated PX4's MAVLink (HEARTBEAT, ATTITUDE) on a second one (TELEM2),
// and the camera's RGB frames through the camera stage's frame-stream replay seam (a FIFO); the
// quadrotor's own VO stage tracks them. airground-uav, airground-ugv (one per team member) and airground-base run as separate
// processes configured only by the YAML files written into the output folder, and talk gossip to each
// other over real UDP on the loopback interface. The base station's /api/state tells when the mission
// is over; each process's final stage timing is read from its log and reported against its budget.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "airground/platform/result.hpp"

namespace ag::sim {

struct HilOptions {
  std::string world{"default"};     // a world folder or "default"
  std::string mission_file;         // the mission (team, starts, guesses, waypoints, survey); required
  std::string out_dir{"build/hil"};
  bool record{true};                // DIR/recording.mcap (truth, estimates, sensors; docs/simulator.md "Recordings")
  std::string bin_dir;              // where airground-uav/-ugv/-base are; empty = next to this executable
  double max_duration_s{300};       // [s] wall clock; the mission is cut off (and reported) after this
  std::uint64_t seed{1};
  int lidar_columns{1024};          // 512, 1024 or 2048 (the sensor's lidar_mode, at 10 Hz)
  std::string lidar_profile{"RNG19_RFL8_SIG16_NIR16"};  // the Ouster packet profile sent (any the driver supports)
  double camera_hz{5};
  bool progress{true};
  // Ground truth for the robots by name (RunOptions::oracles), an ablation: "labels" puts the true class
  // in the frames and in the Ouster reflectivity byte, and the robots use it (segmentation.labels and
  // localization.labels gt); "vo" writes the simulator's odometry into the frame stream and the pose
  // graph takes it instead of the quadrotor's own VO. Without them the reflectivity byte is the
  // surface's albedo and the frames carry RGB only.
  std::vector<std::string> oracles{};
};

struct HilStageTiming {
  std::string robot, stage;
  std::uint64_t runs{0}, overruns{0};
  double p50_us{0}, p99_us{0}, max_us{0}, budget_us{0};
};

struct HilRobot {
  std::string name;
  int exit_code{-1};                 // of its process (-1: killed or not run)
  std::string final_state;           // ground robots: the mission state the base last saw
  double distance_m{0};              // ground robots: driven (simulated truth)
  double final_error_m{-1};          // ground robots: |estimate (as the base heard it) - truth of that time| at the end
  double mean_error_m{-1}, max_error_m{0};  // over every poll of the base while the robot tracked
  std::uint64_t collisions{0};
};

struct HilResult {
  bool mission_done{false};          // every ground robot reported "done" to the base station
  double duration_s{0};
  std::vector<HilRobot> robots;      // uav, ugv1.., base
  std::vector<HilStageTiming> timing;
  std::uint64_t lidar_packets{0}, ubx_messages{0}, camera_frames{0}, camera_frames_dropped{0}, vo_records{0};
  std::uint64_t lidar_revolutions{0}, lidar_revolutions_skipped{0};  // per ground robot; skipped: cast too late
  std::uint64_t camera_frames_skipped{0};                            // the render took longer than the period
  std::uint64_t can_frames_in{0}, can_frames_out{0};
  std::uint64_t arm_requests{0};             // POST /api/arm?robot=N the base station accepted (the operator's arm)
  std::uint64_t mavlink_frames{0};           // HEARTBEAT and ATTITUDE written to the autopilot's serial port
  std::uint64_t mavlink_bytes_in{0};         // what the uav's autopilot stage sent back (SET_MESSAGE_INTERVAL)
};

// Runs the mission; writes DIR/config/*.yaml, DIR/logs/*.log, DIR/hil.json, DIR/hil_report.md,
// DIR/base_state.json and DIR/trajectories.png. Errors name what could not be set up.
Result<HilResult> run_hil(const HilOptions& options);

}  // namespace ag::sim
