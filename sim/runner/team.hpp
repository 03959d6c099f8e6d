// The lockstep team runner's state: the simulated robots (their vehicles, sensors and drivers' channels)
// and the team around them, shared by the runner's set-up, world stage, map feed and reports.
#pragma once

#include <opencv2/core.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>

#include "airground/aerial_mapping/ortho_map.hpp"
#include "airground/messages/drive_messages.hpp"
#include "airground/messages/messages.hpp"
#include "airground/platform/channels.hpp"
#include "airground/platform/role_instance.hpp"
#include "airground/sim/attitude.hpp"
#include "airground/sim/camera.hpp"
#include "airground/sim/diff_drive.hpp"
#include "airground/sim/gps.hpp"
#include "airground/sim/lidar.hpp"
#include "airground/sim/quadrotor.hpp"
#include "airground/sim/radio.hpp"
#include "airground/sim/radio_link.hpp"
#include "airground/sim/raycast.hpp"
#include "airground/sim/runner.hpp"
#include "airground/sim/scripted_driver.hpp"
#include "airground/sim/visual_odometry.hpp"
#include "airground/sim/wheel_odometry.hpp"
#include "airground/drivers/base/diff_drive_base.hpp"
#include "airground/drivers/base/odrive_sim.hpp"
#include "airground/drivers/can/inprocess_bus.hpp"
#include "airground/drivers/camera/stage/sim_camera.hpp"
#include "airground/drivers/gpio/gpio_line.hpp"
#include "airground/drivers/gps/ublox/byte_source.hpp"
#include "airground/drivers/lidar/ouster/sim_source.hpp"
#include "autopilot_device.hpp"
#include "camera_prefetch.hpp"
#include "gnss_device.hpp"
#include "ouster_device.hpp"
#include "team_recording.hpp"
#include "uav_recording.hpp"
#include "worker_pool.hpp"

namespace ag::sim::lockstep {

namespace fs = std::filesystem;

constexpr int kCameraBands = 16;        // a camera frame is rendered as this many row bands (jobs)
constexpr std::size_t kScanParts = 4;   // a LiDAR scan as this many column ranges: both cores busy when only LiDAR is due

// A CSV recording stream; closed with the robot.
class CsvLog {
 public:
  CsvLog() = default;
  CsvLog(const fs::path& path, const char* header) : f_(std::fopen(path.c_str(), "w")) {
    if (f_ != nullptr) std::fprintf(f_, "%s\n", header);
  }
  CsvLog(CsvLog&& o) noexcept : f_(o.f_) { o.f_ = nullptr; }
  CsvLog& operator=(CsvLog&& o) noexcept {
    std::swap(f_, o.f_);
    return *this;
  }
  ~CsvLog() {
    if (f_ != nullptr) std::fclose(f_);
  }
  [[nodiscard]] std::FILE* get() const noexcept { return f_; }
  explicit operator bool() const noexcept { return f_ != nullptr; }

 private:
  std::FILE* f_{nullptr};
};

class SimProbeStage;

// A ground robot's Ouster as its lidar stage (`source: sim`) sees it: the packets of each cast revolution
// on an in-process link registered under the robot's name while the robot exists.
struct SimLidar {
  SimLidar(std::string robot, const ouster::SensorInfo& info);
  SimLidar(const SimLidar&) = delete;
  SimLidar& operator=(const SimLidar&) = delete;
  ~SimLidar();
  [[nodiscard]] bool registered() const noexcept { return registered_; }
  std::string robot;
  OusterPackets packets;
  ouster::SimPacketLink link;

 private:
  bool registered_{false};
};

// The quadrotor's camera, u-blox and PX4 as its camera, gps and autopilot stages (`source: sim`) see
// them: rendered frames, NAV-PVT bytes and MAVLink on in-process links registered under the robot's name
// while it exists.
struct SimUavDevices {
  explicit SimUavDevices(std::string robot);
  SimUavDevices(const SimUavDevices&) = delete;
  SimUavDevices& operator=(const SimUavDevices&) = delete;
  ~SimUavDevices();
  [[nodiscard]] bool registered() const noexcept { return camera_registered_ && gnss_registered_ && autopilot_registered_; }
  std::string robot;
  camera::SimCameraLink camera;
  ublox::SimSerialLink gnss;
  mavlink::SimAutopilotLink autopilot;
  SimPx4 px4{autopilot};

 private:
  bool camera_registered_{false}, gnss_registered_{false}, autopilot_registered_{false};
};

// A ground robot's wheels as its base stage (`can_backend: sim`) sees them: its two ODrives on an
// in-process CAN link, an e-stop that is not pressed and the status LED as fake lines, registered under
// the robot's name. The controllers' velocities turn the vehicle's wheels; their encoders report what
// the wheels did (turn_shafts), with the wheel odometry model's calibration error and slip.
struct SimBase {
  SimBase(std::string robot, const Clock& clock, const base::BaseParams& bp);
  SimBase(const SimBase&) = delete;
  SimBase& operator=(const SimBase&) = delete;
  ~SimBase();
  // The controller's velocity of `axis` (0 left, 1 right) as the wheel's forward speed [rad/s].
  [[nodiscard]] double wheel_rad_s(int axis) const noexcept;
  // The wheels turned by these angles [rad, forward] over dt: the encoders' new position and velocity.
  void turn_shafts(double left_rad, double right_rad, double dt) noexcept;
  std::string robot;
  base::BaseParams bp;
  can::InProcessCanLink link;
  base::OdriveSimulator odrive;
  gpio::FakeLine estop{false}, led{false};
  std::array<double, 2> shaft_turns{};
};

struct Ugv {
  Ugv(std::string n, int nd, DiffDriveRobot v, WheelOdometrySimulator o, PurePursuit p, const Pose2& s)
      : name(std::move(n)), node(nd), vehicle(std::move(v)), odometry(std::move(o)), pursuit(std::move(p)), start(s) {}
  [[nodiscard]] Pose2 odometry_in_map(const Pose2& od) const noexcept {
    const double c = std::cos(start.yaw), sn = std::sin(start.yaw);
    return Pose2{start.x + c * od.x - sn * od.y, start.y + sn * od.x + c * od.y, wrap_angle(start.yaw + od.yaw)};
  }
  // The true pose at time t from the last kHistory physics steps (interpolated), or the newest.
  [[nodiscard]] Pose2 truth_at(TimeNs t) const noexcept;
  std::string name;
  int node{0};
  DiffDriveRobot vehicle;
  WheelOdometrySimulator odometry;
  PurePursuit pursuit;
  std::unique_ptr<SimLidar> lidar;  // before `role`: its stages use these until the role is gone
  std::unique_ptr<SimBase> base;
  double lidar_mount_z_m{0.5};
  TimeNs last_encoder{0};  // [m] where its configuration says the LiDAR is (lidar.mount_z_m)
  std::uint64_t leg{0};
  std::uint64_t goals_reached{0};
  bool on_route{false};     // following a planned route (not waiting for one)
  TimeNs retry_at{0};       // when to try planning again after no route was found
  std::uint64_t scans{0};
  std::uint64_t odom_samples{0};
  Pose2 start;
  Pose2 odom_last;
  std::array<std::vector<LidarPoint>, kScanParts> scan_parts;  // column quarters, simulated in parallel
  std::vector<unsigned char> bin_scratch;                      // --record full: one part's points, padding zeroed
  std::vector<Eigen::Vector2d> trail;
  CsvLog truth_log, odom_log, scan_log;
  std::FILE* scan_bin{nullptr};
  std::unique_ptr<RoleInstance> role;

  // The robot's drivers in simulation: what the wheel encoders, the operator (initial pose) and the map
  // source publish to its stages (the LiDAR's packets go to its own lidar stage: `lidar` above).
  int index{0};
  RingWriter<MapTileMsg, kMapTileRing> tiles_out{};
  LatestWriter<InitialPoseMsg> init_out{};
  LatestWriter<BaseArmMsg> arm_out{};  // the operator arms the base once it is set up
  InitialPoseMsg init_pose{};
  bool init_published{false};
  std::uint64_t scans_published{0}, odom_published{0}, tiles_published{0}, tiles_refused{0}, channel_drops{0};
  std::vector<std::pair<std::int32_t, std::int32_t>> gt_order{};  // ground-truth tiles, nearest the start first
  std::size_t gt_next{0};
  std::deque<std::uint64_t> pending{};  // online: changed tiles (packed keys) not yet pushed
  std::unordered_set<std::uint64_t> pending_set{};
  // Scripted route, holds, waiting for the map.
  bool scripted{false};
  std::vector<Eigen::Vector2d> route{};
  std::size_t route_progress{0};
  bool route_done{false};
  bool released{true};
  TimeNs released_at{0};
  TimeNs next_wait_check{0};
  bool held{false};
  static constexpr std::size_t kHistory = 128;
  std::array<std::pair<TimeNs, Pose2>, kHistory> history{};
  std::size_t history_n{0};
  SimProbeStage* probe{nullptr};
  bool killed{false};
  TimeNs killed_at{-1};
  // Steps in a row the vehicle has been stopped by an obstacle: logged when it starts and when it ends,
  // not every physics step while a robot pushes against it.
  std::uint64_t blocked_steps{0};
  // Robots stepped in parallel: the sampling callback's sample waits here for the end of the release time.
  UgvSample pending_sample{};
  bool has_pending_sample{false};
  std::uint64_t wheel_commands{0};
  LatestWriter<GoalMsg> goal_out{};
  bool goal_pending{false};
  GoalMsg goal{};
  // The robot's own localization against the truth (the probe samples it).
  std::uint64_t loc_samples{0}, loc_tracking{0};
  std::vector<float> loc_errors{};           // [m] tracking samples
  std::vector<Eigen::Vector2d> est_trail{};  // tracking estimates, for the picture
  TimeNs loc_first_tracking{-1};
  LocalizationStatus loc_last{LocalizationStatus::kNoMap};
  Pose2 loc_pose{};  // its newest tracking estimate (for recording.mcap)
  bool loc_has_pose{false};
};

struct Uav {
  Quadrotor vehicle;
  GpsSimulator gps;
  VisualOdometrySimulator vo;
  CameraFrame frame;
  std::uint64_t frames{0}, fixes{0}, vo_samples{0};
  std::uint32_t last_segment{0};
  std::uint64_t segments{0};
  std::vector<Eigen::Vector2d> trail;
  CsvLog truth_log, gps_log, vo_log, frame_log;
  std::unique_ptr<RoleInstance> role;
  // The quadrotor's drivers in simulation: what the camera, the VO and the GPS publish to its stages.
  RingWriter<VoMsg, kVoRing> vo_out{};  // the oracle VO (RunOptions::oracles "vo")
  bool vo_oracle{false};
  bool labels_oracle{false};  // the frames carry the renderer's classes (RunOptions::oracles "labels")
  cv::Mat rgb_small{}, cls_small{};
  std::uint32_t image_seq{0};
  std::vector<TruthSample> truth{};
  AttitudeSimulator attitude{};  // the autopilot's ATTITUDE (PX4 EKF2 error model, attitude.yaml)
  std::uint64_t attitudes{0};
};

struct Team {
  // The ground robots' table in simulation (their role plus the probe stage); outlives the role instances.
  std::vector<StageSpec> ugv_stages;
  std::vector<StageSpec> uav_stages;  // the quadrotor's table without its device drivers
  RunOptions opt;
  std::shared_ptr<const World> world;
  std::shared_ptr<const HeightfieldRaycaster> raycaster;
  std::unique_ptr<CameraRenderer> camera;
  std::unique_ptr<LidarSimulator> lidar;
  std::unique_ptr<RoadRouter> router;
  std::unique_ptr<RadioModel> radio;   // the heartbeat radio (without gossip)
  std::unique_ptr<RadioNet> net;       // gossip: the radio every comms stage talks over
  RadioModel* air{nullptr};            // whichever of the two is on
  int base_node{0};
  bool base_killed{false};
  std::vector<RoleInstance*> ugv_roles;  // for RunOptions::observe
  TimeNs next_observe{0};
  std::unique_ptr<SimUavDevices> uav_devices;  // before `uav`: its stages read the links until the role is gone
  std::unique_ptr<Uav> uav;
  std::vector<std::unique_ptr<Ugv>> ugvs;
  std::unique_ptr<RoleInstance> base;
  WorkerPool* pool{nullptr};
  bool parallel_robots{false};  // the robots' stages of one release time run side by side (LockstepExecutor::set_parallel)
  fs::path out;
  TimeNs camera_period{0}, lidar_period{0}, heartbeat_period{0}, log_period{0};
  TimeNs next_camera{0}, next_lidar{0}, next_heartbeat{0}, next_log{0};
  TimeNs camera_cpu{0}, lidar_cpu{0};       // thread CPU of the sensor jobs, summed over every thread that ran them
  TimeNs physics_period{0};                  // the world stage's release period
  std::unique_ptr<CameraPrefetch> prefetch;  // with more than one thread: the next frame, rendered ahead
  std::optional<Quadrotor> uav_ahead;        // scratch: the vehicle stepped ahead to the next exposure
  CameraAutoExposure camera_ae;              // meters every frame, in order, before the next is prepared
  double uav_yaw_rate{0};                    // [rad/s] over the last physics step: the camera's motion blur
  std::uint64_t frames_ahead{0};             // camera frames that were rendered ahead and used
  std::vector<TimeNs> job_cpu;           // scratch: one slot per sensor job of a release time (sized at start)
  std::vector<Delivery> deliveries;
  std::uint64_t frame_pngs{0};
  // The ground robots' map feed.
  std::unique_ptr<MapTileMsg> tile_msg;         // scratch: one tile, built in place before each push
  const mapping::OrthoMap* ortho{nullptr};     // the quadrotor's map (online source)
  std::uint64_t ortho_version_seen{std::numeric_limits<std::uint64_t>::max()};
  std::unordered_map<std::uint64_t, std::uint64_t> tile_versions;  // online: version last seen per tile
  std::unordered_map<std::uint64_t, const mapping::Tile*> tile_ptrs;  // tiles are never removed from the map
  std::vector<std::uint64_t> changed;          // scratch
  TimeNs sample_period{0};
  int lidar_rings{64};
  std::unique_ptr<TeamRecording> mcap;  // recording.mcap (unless --record none)
  // The quadrotor cache (RunOptions::uav_cache): a live quadrotor recording into it, or a replay from it.
  std::unique_ptr<UavRecordWriter> uav_rec;
  std::unique_ptr<UavRecordReader> uav_play;
  UavTapStage* uav_tap{nullptr};
  UavReplayInfo replay_info;
};

// ---- the routes of the scripted robots (team_routes.cpp)
Pose3 lidar_pose(const Ugv& u, double mount);
// A new leg of the robot's errands: a random drivable goal 20-150 m away and the road route to it.
void new_leg(Team& t, Ugv& u, TimeNs now);
// A route with a vertex at least every `step` metres.
std::vector<Eigen::Vector2d> densify(const std::vector<Eigen::Vector2d>& route, double step);
// A scripted robot that hit something: route from here back onto its route a vertex ahead, then on.
void rejoin_route(Team& t, Ugv& u, TimeNs now);

// ---- the ground robots' map feed (team_map_feed.cpp)
// The tiles of the world's extent, nearest to `p` first (ties by index, so the order is fixed).
std::vector<std::pair<std::int32_t, std::int32_t>> gt_tile_order(const World& w, const Pose2& p);
// Online source: note every tile whose version changed since the last look, for every ground robot.
void scan_online_map(Team& t);
// Pushes this robot's next tiles while every reader's ring has room.
void publish_tiles(Team& t, Ugv& u, TimeNs now);
// Online source: a robot waits at its start until the map knows `fraction` of its surroundings inside the
// mission area (the world: ground beyond its edge is never mapped; sim/map_coverage.hpp).
bool map_covers(const mapping::OrthoMap& m, const Pose2& p, double radius, double fraction, const GridGeometry& area);
// Online source: the share of the cells within 3 m of a route (sampled every 2 m) that have a class.
double route_covered(const mapping::OrthoMap& m, const std::vector<Eigen::Vector2d>& route);

// ---- the quadrotor cache (team_uav_replay.cpp)
// Opens the cache's recording for this run's key: a replay when it exists, else a recording of this run.
Status open_uav_cache(Team& t);
// The quadrotor's table for the cache: the tap appended (recording), or status, the replay and comms (replay).
void plug_uav_cache(Team& t, std::vector<StageSpec>& stages);
// After the quadrotor's role is made: hands the tap its writer, the replay its reader.
Status attach_uav_cache(Team& t);
// At the end: the recording finished and renamed into place, or the replay's figures.
Status finish_uav_cache(Team& t, TimeNs ended);

// ---- summary.yaml, summary.json, report.md and trajectories.png (team_report.cpp)
Status write_reports(const Team& t, const RunSummary& s);

}  // namespace ag::sim::lockstep
