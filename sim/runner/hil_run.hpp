// One HIL run's state and the steps of run_hil (hil_runner.cpp): the role processes and their YAML
// (hil_roles.cpp), the devices' wire bridges (hil_devices.cpp), the three threads (hil_loop.cpp) and
// the report (hil_report.cpp).
#pragma once

#include <netinet/in.h>
#include <sys/types.h>

#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <deque>
#include <filesystem>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "airground/messages/geometry.hpp"
#include "airground/messages/messages.hpp"
#include "airground/drivers/base/diff_drive_base.hpp"
#include "airground/drivers/base/odrive_sim.hpp"
#include "airground/drivers/autopilot/mavlink/link.hpp"
#include "airground/drivers/camera/frame_stream/frame_stream.hpp"
#include "airground/drivers/can/cannelloni.hpp"
#include "autopilot_device.hpp"
#include "ouster_device.hpp"
#include "airground/drivers/lidar/ouster/frame.hpp"
#include "airground/drivers/lidar/ouster/metadata.hpp"
#include "airground/drivers/lidar/ouster/packet_format.hpp"
#include "airground/mission/mission_file.hpp"
#include "airground/platform/result.hpp"
#include "airground/platform/role_table.hpp"
#include "airground/platform/time.hpp"
#include "airground/sim/attitude.hpp"
#include "airground/sim/camera.hpp"
#include "airground/sim/diff_drive.hpp"
#include "airground/sim/gps.hpp"
#include "airground/sim/hil.hpp"
#include "airground/sim/lidar.hpp"
#include "airground/sim/quadrotor.hpp"
#include "airground/sim/visual_odometry.hpp"
#include "airground/sim/world.hpp"
#include "team_recording.hpp"

namespace ag::sim::hil {

namespace fs = std::filesystem;
using json = nlohmann::json;
// "section.key" = value pairs a role's YAML gets on top of its shipped configuration.
using Settings = std::vector<std::pair<std::string, std::string>>;

// One role process: airground-<role> --config DIR/config/<name>.yaml, its output in `log`.
struct RoleProcess {
  std::string name, role;
  pid_t pid{-1};
  fs::path log;
  int exit_code{-1};
  bool exited{false};
};

// A ground robot: its simulated base, its wire bridges (ODrives on CAN, Ouster on UDP) and what the
// base station last heard of it.
struct Ugv {
  Ugv(std::string n, int i, DiffDriveRobot v) : name(std::move(n)), id(i), vehicle(std::move(v)) {}
  std::string name;
  int id{1};
  DiffDriveRobot vehicle;
  std::unique_ptr<can::CannelloniBus> bus;
  std::unique_ptr<base::OdriveSimulator> odrive;
  base::BaseParams bp;
  int udp{-1};
  sockaddr_in lidar_to{};
  std::unique_ptr<OusterPackets> ouster;
  std::vector<LidarPoint> scan;
  std::uint64_t collisions{0};
  double distance_m{0};
  Pose2 last_pose{};
  std::vector<cv::Point2d> truth_trail, est_trail;
  // The newest estimate the base station saw.
  bool has_est{false};
  Pose2 est{};
  double est_error_m{-1};            // against the truth when the base heard the pose
  std::vector<double> errors;        // every poll's
  std::deque<std::pair<TimeNs, Pose2>> history;  // truth, the last 30 s
  std::string state{"-"};
  bool armed_by_operator{false};  // the base station took our POST /api/arm for it
  [[nodiscard]] Pose2 truth_at(TimeNs t) const {
    Pose2 best = vehicle.pose();
    TimeNs best_dt = INT64_MAX;
    for (const auto& [ht, hp] : history)
      if (std::llabs(ht - t) < best_dt) {
        best_dt = std::llabs(ht - t);
        best = hp;
      }
    return best;
  }
};

// A pseudo-terminal in raw mode: the simulator writes the master (fd), the robot opens `path`; the slave
// is held open so that the robot's reopening never hangs the line up.
struct Pty {
  int fd{-1}, slave{-1};
  std::string path;
};

// Everything one run holds, set up in order by run_hil and shared by its threads.
struct Run {
  Run(const HilOptions& o, const World& w, const mission::MissionFile& m);
  const HilOptions& opt;
  const World& world;
  const mission::MissionFile& mf;
  const fs::path out;
  const bool labels_oracle;          // --oracle labels: the true classes in the frames and the reflectivity byte
  const bool vo_oracle;              // --oracle vo: the simulator's odometry in the frame stream, to the pose graph
  double lidar_mount_z_m{0.5};       // [m] where the shipped ugv.yaml mounts the LiDAR (lidar.mount_z_m)
  fs::path bin;                      // the role binaries
  fs::path key;                      // the team key
  std::vector<std::uint16_t> gossip;  // per process: uav, ugv1.., base
  std::uint16_t web_port{0};
  std::vector<RoleProcess> children;  // uav, ugv1.., base
  std::vector<std::unique_ptr<Ugv>> ugvs;
  Pty gps_pty;                       // the quadrotor's u-blox (DIR/gps.pty)
  Pty autopilot_pty;                 // the quadrotor's PX4 TELEM2 (DIR/autopilot.pty)
  mavlink::SimAutopilotLink px4_link;  // the simulated PX4's side, pumped to and from autopilot_pty
  SimPx4 px4{px4_link};
  fs::path fifo;                     // the camera's frame stream
  std::optional<Quadrotor> quad;
  std::optional<GpsSimulator> gps;
  std::optional<VisualOdometrySimulator> vo;  // only with the vo oracle
  std::optional<AttitudeSimulator> attitude;
  std::optional<CameraRenderer> camera;
  std::optional<LidarSimulator> lidar;
  // recording.mcap, written by the sensor loop and the camera thread in turn; log times from rec0.
  std::unique_ptr<TeamRecording> rec;
  std::mutex rec_mu;
  TimeNs rec0{0};
  std::mutex mu;                     // the vehicles: the physics thread steps them
  std::atomic<bool> stop{false}, stop_camera{false};
  std::mutex vo_mu;                  // the VO queued for the camera thread
  std::deque<VoMsg> vo_queue;
  std::atomic<std::uint64_t> cam_written{0}, cam_dropped{0}, cam_skipped{0}, vo_written{0};
  HilResult res;
  std::string last_state;            // the base station's last /api/state
  std::string failure;
  TimeNs t0{0};                      // the sensor loop's start
};

// hil_roles.cpp: the role processes and their configuration.
[[nodiscard]] std::string num(double v);
// A free port of `type` (SOCK_DGRAM, SOCK_STREAM) on the loopback, 0 when none could be had.
[[nodiscard]] std::uint16_t any_port(int type);
// The world's extent, the area the robots map and plan in.
[[nodiscard]] mission::Area world_area(const World& w);
// The directory of airground-uav/-ugv/-base: --bin-dir, else beside this executable or the build tree's.
Result<fs::path> find_role_binaries(const std::string& bin_dir);
// The settings every role shares (who it is, gossip port and peers, team key); `node` indexes run.gossip.
[[nodiscard]] Settings common_settings(const Run& run, int id, const std::string& name, std::size_t node);
// The settings every ground robot shares (labels, area, drive, base, mission parameters).
[[nodiscard]] Settings ugv_shared_settings(const Run& run);
Status write_role_yaml(const fs::path& path, const std::string& title, const RoleDescription& role, const Settings& kv,
                       bool labels_oracle);
// Ground robot i's YAML (team member tm, `shared` from ugv_shared_settings, its devices on the given
// ports); adds its process.
Status write_ugv_yaml(Run& run, int i, const mission::TeamMember& tm, const Ugv& u, const Settings& shared,
                      const fs::path& meta_path, std::uint16_t can_robot, std::uint16_t can_sim);
// The quadrotor's and the base station's YAML; each adds its process (the quadrotor's first).
Status write_uav_yaml(Run& run);
Status write_base_yaml(Run& run);
// Base first (it only listens), then the ground robots, then the quadrotor; on failure the started ones get SIGTERM.
Status start_roles(Run& run);
void signal_roles(std::vector<RoleProcess>& children, int sig);
// Reaps the processes that exited; the failure naming the last of them, empty when none did.
[[nodiscard]] std::string reap_exited(std::vector<RoleProcess>& children);
// SIGTERM in reverse start order, then wait (10 s each at most), then SIGKILL.
void stop_roles(std::vector<RoleProcess>& children);

// hil_devices.cpp: the wire bridges.
// Writes the robot's Ouster metadata to meta_path (with its ports) and opens its lidar socket and CAN bridge.
Status open_ugv_devices(Ugv& u, const json& meta, const fs::path& meta_path, std::uint16_t lidar_port, std::uint16_t imu_port,
                        std::uint16_t can_robot, std::uint16_t can_sim);
// A raw pseudo-terminal, linked as DIR/<name>.pty: the quadrotor's serial ports.
Status open_pty(Run& run, const char* name, Pty& p);
// The quadrotor's camera FIFO (run.fifo).
Status make_camera_fifo(Run& run);
// One physics step of a ground robot: its ODrives turn the wheels.
void step_base(Ugv& u, TimeNs now, double dt, const World& w);
// The simulated PX4's frames to its serial port, and what the robot wrote there back to it.
void pump_autopilot(Run& run);
// A GNSS fix as UBX NAV-PVT on the serial line; true when all of it was written.
bool send_nav_pvt(int pty, TimeNs now, const GpsFix& fix);
// The robot's last scan as one revolution of Ouster packets from sensor pose sp; the packets sent.
std::uint64_t send_revolution(Ugv& u, const Pose3& sp, TimeNs now, TimeNs lidar_period, bool labels_oracle, const World& w);
// The uav's frame stream once it opened the FIFO's other end; empty until then.
std::optional<camera::FrameStreamWriter> open_frame_stream(const fs::path& fifo);
// A rendered frame as the camera stage's image message (classes only with the labels oracle).
void fill_image(CameraImageMsg& m, const CameraFrame& cf, TimeNs now, std::uint32_t seq, bool labels_oracle);
// Closes the serial ports and the lidar sockets; counts the CAN commands the ODrives received.
void close_devices(Run& run);

// hil_loop.cpp: the threads.
void physics_thread(Run& run);
void camera_thread(Run& run);
void sensor_loop(Run& run);

// hil_report.cpp: the results and the report.
[[nodiscard]] std::string fixed(double v, int digits);
// Each process's final stage timing (from its log, against its table's budget) and each ground robot's figures.
void collect_results(Run& run);
// DIR/hil.json, DIR/hil_report.md and DIR/trajectories.png.
void write_report(const Run& run);

}  // namespace ag::sim::hil
