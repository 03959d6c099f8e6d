// The lockstep team runner: robots' role tables and the simulated world on one SimClock.
#include "team_recording.hpp"
#include "airground/sim/runner.hpp"

#include <yaml-cpp/yaml.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <ctime>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstring>
#include <deque>
#include <filesystem>
#include <fstream>
#include <limits>
#include <mutex>
#include <optional>
#include <sstream>
#include <thread>
#include <unordered_map>
#include <unordered_set>

#include "airground/aerial_mapping/stages.hpp"
#include "airground/comms/stage.hpp"
#include "airground/core/drive_messages.hpp"
#include "airground/core/messages.hpp"
#include "airground/platform/clock.hpp"
#include "airground/platform/executor.hpp"
#include "airground/platform/log.hpp"
#include "airground/platform/role_instance.hpp"
#include "airground/sim/camera.hpp"
#include "airground/sim/compute_time.hpp"
#include "airground/sim/diff_drive.hpp"
#include "airground/sim/generator.hpp"
#include "airground/sim/attitude.hpp"
#include "airground/sim/gps.hpp"
#include "airground/sim/lidar.hpp"
#include "airground/sim/model_params.hpp"
#include "airground/sim/quadrotor.hpp"
#include "airground/sim/radio.hpp"
#include "airground/sim/radio_link.hpp"
#include "airground/sim/raycast.hpp"
#include "airground/core/geometry.hpp"
#include "airground/platform/rng.hpp"
#include "airground/sim/scripted_driver.hpp"
#include "airground/sim/survey.hpp"
#include "airground/sim/survey_plan.hpp"
#include "airground/sim/visual_odometry.hpp"
#include "airground/sim/wheel_odometry.hpp"
#include "airground/sim/world_png.hpp"
#include "airground/sim/shipped_configs.hpp"
#include "roles.hpp"
#include "sensor_labels_check.hpp"
#include "worker_pool.hpp"

namespace ag::sim {

Status write_team_key(const std::string& path, std::uint64_t seed) {
  {
    std::ofstream k(path);
    Rng rng(seed);
    static constexpr char kHex[] = "0123456789abcdef";
    for (int i = 0; i < 64; ++i) k << kHex[rng.below(16)];
    k << "\n";
    if (!k) return Error::make(ErrorCode::kIo, "cannot write the team key " + path);
  }
  std::error_code ec;
  std::filesystem::permissions(path, std::filesystem::perms::owner_read | std::filesystem::perms::owner_write, std::filesystem::perm_options::replace, ec);
  return ok_status();
}

Result<std::shared_ptr<const World>> resolve_world(const std::string& world_arg) {
  if (world_arg == "default") return std::shared_ptr<const World>(&default_world(), [](const World*) {});
  auto w = load_world(world_arg);
  if (!w) return w.error();
  return std::shared_ptr<const World>(std::make_shared<World>(std::move(w).value()));
}

namespace {

double process_cpu_seconds() noexcept {
  timespec ts{};
  if (clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts) != 0) return 0.0;
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

// The quadrotor's next camera frame, rendered ahead on a thread of its own. The survey flight takes no
// input from the robots, so a copy of the vehicle stepped like the world stage steps it gives the pose
// of the next exposure bit for bit; the frame renders while the robots' stages and the LiDAR run, and
// fills the core a long keyframe step leaves idle. When the frame is due, whatever bands are left are
// rendered by whoever gets there (the world stage's pool jobs), so it is never later than rendering
// it then; the pose is checked before use, and the image is the one a render at that instant gives.
class CameraPrefetch {
 public:
  static constexpr int kBands = 25;  // 16 rows each at 640x400: fine enough to share out at the end

  CameraPrefetch(const CameraRenderer& camera, CameraFrame& frame) : camera_(camera), frame_(frame), thread_([this] { loop(); }) {}
  ~CameraPrefetch() {
    stop_requested_.store(true, std::memory_order_relaxed);
    {
      std::lock_guard<std::mutex> lk(mu_);
      stop_ = true;
    }
    wake_.notify_all();
    thread_.join();
  }
  CameraPrefetch(const CameraPrefetch&) = delete;
  CameraPrefetch& operator=(const CameraPrefetch&) = delete;

  // Starts the frame of `pose` at `stamp` (the caller has prepared frame_ for it; the last one finished).
  void start(const Pose3& pose, TimeNs stamp) {
    {
      std::lock_guard<std::mutex> lk(mu_);
      pose_ = pose;
      stamp_ = stamp;
      done_ = 0;
      active_ = true;
      ++generation_;
      // Last, releasing: a thread still looping in help() from the frame before may take a band of this
      // one straight away, and then sees the pose and the prepared frame.
      next_.store(0, std::memory_order_release);
    }
    wake_.notify_all();
  }
  [[nodiscard]] bool active() const noexcept { return active_; }
  [[nodiscard]] bool matches(const Pose3& pose, TimeNs stamp) const noexcept {
    return active_ && stamp == stamp_ && pose.x == pose_.x && pose.y == pose_.y && pose.z == pose_.z && pose.roll == pose_.roll &&
           pose.pitch == pose_.pitch && pose.yaw == pose_.yaw;
  }
  // Renders bands nobody has taken yet, on the calling thread.
  void help() noexcept {
    for (int b = next_.fetch_add(1, std::memory_order_acq_rel); b < kBands; b = next_.fetch_add(1, std::memory_order_acq_rel)) {
      if (stop_requested_.load(std::memory_order_relaxed)) return;  // shutting down: the frame is dropped
      const TimeNs c0 = thread_cpu_now();
      const int h = frame_.rgb.rows;
      camera_.render_rows(pose_, h * b / kBands, h * (b + 1) / kBands, frame_);
      cpu_.fetch_add(thread_cpu_now() - c0, std::memory_order_relaxed);
      std::lock_guard<std::mutex> lk(mu_);
      if (++done_ == kBands) finished_.notify_all();
    }
  }
  // Helps, then waits for the bands others are still rendering: the frame is complete on return.
  void finish() {
    help();
    std::unique_lock<std::mutex> lk(mu_);
    finished_.wait(lk, [&] { return done_ >= kBands; });
    active_ = false;
  }
  [[nodiscard]] TimeNs cpu_ns() const noexcept { return cpu_.load(std::memory_order_relaxed); }

 private:
  void loop() {
    std::uint64_t seen = 0;
    for (;;) {
      {
        std::unique_lock<std::mutex> lk(mu_);
        wake_.wait(lk, [&] { return stop_ || generation_ != seen; });
        if (stop_) return;
        seen = generation_;
      }
      help();
    }
  }

  const CameraRenderer& camera_;
  CameraFrame& frame_;
  std::mutex mu_;
  std::condition_variable wake_, finished_;
  Pose3 pose_;
  TimeNs stamp_{0};
  std::atomic<int> next_{kBands};
  int done_{kBands};
  bool active_{false};
  bool stop_{false};
  std::atomic<bool> stop_requested_{false};
  std::uint64_t generation_{0};
  std::atomic<TimeNs> cpu_{0};
  std::thread thread_;  // last: starts once everything above exists
};

constexpr int kCameraBands = 16;        // a camera frame is rendered as this many row bands (jobs)
constexpr std::size_t kScanParts = 4;   // a LiDAR scan as this many column ranges: both cores busy when only LiDAR is due

// The role stages that talk to devices; in lockstep the simulator writes their channels instead.
bool is_simulated_driver(std::string_view stage) noexcept {
  return stage == "base" || stage == "lidar" || stage == "gps" || stage == "camera" || stage == "autopilot";
}

namespace fs = std::filesystem;

// The shipped ErfNet weights: where the package installs them (segmentation.weights' shipped value), else
// the source tree's copy for a simulator run from the build tree.
std::string erfnet_weights_path(const std::string& shipped) {
  std::error_code ec;
  if (fs::exists(shipped, ec)) return shipped;
  return std::string(AG_SOURCE_DIR) + "/config/erfnet/erfnet_c7.agw";
}

// Optional model overrides from --config-dir: <dir>/<name> when it exists. The file holds the model's
// mapping either at the top level or under its section name (as `airground-sim config` writes it).
template <typename T, typename Loader>
Result<T> model_config(const std::string& dir, const char* name, std::string_view section, Loader load) {
  if (dir.empty()) return T{};
  const fs::path p = fs::path(dir) / name;
  if (!fs::exists(p)) return T{};
  YAML::Node root;
  try {
    root = YAML::LoadFile(p.string());
  } catch (const YAML::Exception& e) {
    return Error::make(ErrorCode::kConfig, "config error: " + p.string() + ":" + std::to_string(e.mark.line + 1) + ": malformed YAML: " + e.msg);
  }
  return load(model_mapping(root, section), p.string());
}

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

  // The robot's drivers in simulation: what the LiDAR, the wheel encoders, the operator (initial pose)
  // and the map source publish to its stages.
  int index{0};
  RingWriter<LidarScanMsg, kLidarRing> scan_out{};
  RingWriter<WheelOdometryMsg, kWheelOdometryRing> odom_out{};
  RingWriter<MapTileMsg, kMapTileRing> tiles_out{};
  LatestWriter<InitialPoseMsg> init_out{};
  std::unique_ptr<LidarScanMsg> scan_msg{};  // one preallocated revolution, filled in place
  std::uint32_t scan_seq{0};
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

Pose2 Ugv::truth_at(TimeNs t) const noexcept {
  if (history_n == 0) return vehicle.pose();
  const std::size_t n = std::min(history_n, kHistory);
  auto at = [&](std::size_t back) -> const std::pair<TimeNs, Pose2>& { return history[(history_n - 1 - back) % kHistory]; };
  if (t >= at(0).first) return at(0).second;
  for (std::size_t k = 1; k < n; ++k) {
    const auto& a = at(k);
    if (a.first > t) continue;
    const auto& b = at(k - 1);
    const double w = static_cast<double>(t - a.first) / static_cast<double>(std::max<TimeNs>(1, b.first - a.first));
    return Pose2{a.second.x + w * (b.second.x - a.second.x), a.second.y + w * (b.second.y - a.second.y),
                 wrap_angle(a.second.yaw + w * wrap_angle(b.second.yaw - a.second.yaw))};
  }
  return at(n - 1).second;
}

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
  RingWriter<CameraImageMsg, kCameraRing> camera_out{};
  RingWriter<VoMsg, kVoRing> vo_out{};  // the oracle VO (RunOptions::oracles "vo")
  bool vo_oracle{false};
  bool labels_oracle{false};  // the frames carry the renderer's classes (RunOptions::oracles "labels")
  RingWriter<GpsMsg, kGpsRing> gps_out{};
  std::unique_ptr<CameraImageMsg> image{};
  cv::Mat rgb_small{}, cls_small{};
  std::uint32_t image_seq{0};
  std::vector<TruthSample> truth{};
  AttitudeSimulator attitude{};  // the autopilot's ATTITUDE (PX4 EKF2 error model, attitude.yaml)
  RingWriter<AttitudeMsg, kAttitudeRing> attitude_out{};
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
  double wheel_radius_m{0.098};
  std::vector<RoleInstance*> ugv_roles;  // for RunOptions::observe
  TimeNs next_observe{0};
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
};

Pose3 lidar_pose(const Ugv& u, double mount) {
  Pose3 p = u.vehicle.pose3();
  p.z += mount;
  return p;
}

void new_leg(Team& t, Ugv& u, TimeNs now) {
  std::vector<Eigen::Vector2d> path;
  u.on_route = false;
  for (int attempt = 0; attempt < 20; ++attempt) {
    const std::uint64_t key = t.opt.seed * std::uint64_t{1000003} + static_cast<std::uint64_t>(u.node) * std::uint64_t{10007} + u.leg++;
    const Eigen::Vector2d goal = t.router->pick_drivable(key);
    const Pose2& p = u.vehicle.pose();
    const double d = (goal - Eigen::Vector2d(p.x, p.y)).norm();
    if (d < 20.0 || (d > 150.0 && attempt < 15)) continue;  // legs of 20-150 m, like an errand across the block
    if (t.router->route(p.x, p.y, goal.x(), goal.y(), path) && path.size() >= 2) {
      u.pursuit.set_path(std::move(path));
      u.on_route = true;
      return;
    }
  }
  u.pursuit.set_path({});
  u.retry_at = now + 2 * kNsPerS;  // stay put and try again later rather than search every tick
  AG_LOG_WARN("sim", "%s: no road route from (%.1f, %.1f); retrying in 2 s", u.name.c_str(), u.vehicle.pose().x, u.vehicle.pose().y);
}

// A route with a vertex at least every `step` metres: pure pursuit looks for its progress on the next
// few segments only, so on a route that comes back along the same road (out and back) long segments
// would let it mistake the way back for the way out.
std::vector<Eigen::Vector2d> densify(const std::vector<Eigen::Vector2d>& route, double step) {
  std::vector<Eigen::Vector2d> out;
  if (route.empty()) return out;
  out.push_back(route.front());
  for (std::size_t i = 1; i < route.size(); ++i) {
    const Eigen::Vector2d a = route[i - 1], d = route[i] - a;
    const int n = std::max(1, static_cast<int>(std::ceil(d.norm() / step)));
    for (int k = 1; k <= n; ++k) out.push_back(a + d * (static_cast<double>(k) / n));
  }
  return out;
}

// A scripted robot that hit something: route from here back onto its route a vertex ahead, then on.
void rejoin_route(Team& t, Ugv& u, TimeNs now) {
  const Pose2& p = u.vehicle.pose();
  const std::size_t k = std::min(u.route_progress + 1, u.route.size() - 1);
  std::vector<Eigen::Vector2d> path;
  if (!t.router->route(p.x, p.y, u.route[k].x(), u.route[k].y(), path) || path.empty()) path.assign(1, Eigen::Vector2d(p.x, p.y));
  path = densify(path, 1.0);
  path.insert(path.end(), u.route.begin() + static_cast<std::ptrdiff_t>(k) + 1, u.route.end());
  u.route.assign(path.begin(), path.end());
  u.route_progress = 0;
  u.pursuit.set_path(std::move(path));
  (void)now;
}

// Ground-truth map tiles: the world's class raster resampled to the map's cells. A map cell takes the
// majority class of the world cells whose centres lie in it (ties: the first in row-major order from the
// north-west; the world cell under its centre when none does, as for worlds coarser than the map) and
// the mean surface elevation (terrain + height) of those cells. Cells outside the world are unknown.
void build_gt_tile(const World& w, std::int32_t tx, std::int32_t ty, MapTileMsg& m) {
  const double res = kMapResolutionM;
  m.tx = tx;
  m.ty = ty;
  m.version = 1;
  for (int r = 0; r < kTileCells; ++r) {
    for (int c = 0; c < kTileCells; ++c) {
      const auto i = static_cast<std::size_t>(r) * kTileCells + static_cast<std::size_t>(c);
      const double x = (static_cast<double>(tx) * kTileCells + c + 0.5) * res;
      const double y = (static_cast<double>(ty) * kTileCells + r + 0.5) * res;
      const WorldCellSummary cell = summarise_cell(w, x, y, res);
      m.cls[i] = cell.cls;
      m.elevation[i] = static_cast<float>(cell.surface);
    }
  }
}

void build_online_tile(const mapping::Tile& tile, std::uint32_t min_elevation_points, MapTileMsg& m) {
  m.tx = tile.key.tx;
  m.ty = tile.key.ty;
  m.version = tile.version;
  for (std::size_t i = 0; i < kTileCellCount; ++i) {
    const mapping::Cell& c = tile.live[i];
    m.cls[i] = c.cls;
    m.elevation[i] = c.reported_elevation(min_elevation_points);
  }
}

// The tiles of the world's extent, nearest to `p` first (ties by index, so the order is fixed).
std::vector<std::pair<std::int32_t, std::int32_t>> gt_tile_order(const World& w, const Pose2& p) {
  const GridGeometry& g = w.grid();
  const double tile_m = kTileCells * kMapResolutionM;
  const auto tx0 = static_cast<std::int32_t>(std::floor(g.origin_x / tile_m));
  const auto tx1 = static_cast<std::int32_t>(std::ceil((g.origin_x + g.size_x()) / tile_m)) - 1;
  const auto ty0 = static_cast<std::int32_t>(std::floor((g.origin_y - g.size_y()) / tile_m));
  const auto ty1 = static_cast<std::int32_t>(std::ceil(g.origin_y / tile_m)) - 1;
  std::vector<std::pair<std::int32_t, std::int32_t>> out;
  for (std::int32_t ty = ty0; ty <= ty1; ++ty)
    for (std::int32_t tx = tx0; tx <= tx1; ++tx) out.emplace_back(tx, ty);
  auto d2 = [&](const std::pair<std::int32_t, std::int32_t>& k) {
    const double cx = (k.first + 0.5) * tile_m - p.x, cy = (k.second + 0.5) * tile_m - p.y;
    return cx * cx + cy * cy;
  };
  std::stable_sort(out.begin(), out.end(), [&](const auto& a, const auto& b) { return d2(a) < d2(b); });
  return out;
}

// Online source: note every tile whose version changed since the last look, for every ground robot.
void scan_online_map(Team& t) {
  const mapping::OrthoMap& m = *t.ortho;
  if (m.version() == t.ortho_version_seen) return;
  t.ortho_version_seen = m.version();
  t.changed.clear();
  m.for_each_tile([&](const mapping::Tile& tile) {
    const std::uint64_t key = tile.key.packed();
    t.tile_ptrs[key] = &tile;
    auto [it, fresh] = t.tile_versions.try_emplace(key, tile.version);
    if (!fresh && it->second == tile.version) return;
    it->second = tile.version;
    t.changed.push_back(key);
  });
  std::sort(t.changed.begin(), t.changed.end());  // the map's hash order is not an order to rely on
  for (auto& up : t.ugvs)
    for (const std::uint64_t key : t.changed)
      if (up->pending_set.insert(key).second) up->pending.push_back(key);
}

// Pushes this robot's next tiles while every reader's ring has room (the rest follow on later steps, so
// each reader gets each version once; a refused push would be retried, as a driver's would).
void publish_tiles(Team& t, Ugv& u, TimeNs now) {
  MapTileMsg& m = *t.tile_msg;
  for (int pushed = 0; pushed < t.opt.map_tiles_per_tick && u.tiles_out.free_slots() > 0; ++pushed) {
    if (t.opt.ugv_map == UgvMapSource::kGroundTruth) {
      if (u.gt_next >= u.gt_order.size()) return;
      build_gt_tile(*t.world, u.gt_order[u.gt_next].first, u.gt_order[u.gt_next].second, m);
      m.stamp = 0;  // the world never changes
    } else {
      if (u.pending.empty()) return;
      build_online_tile(*t.tile_ptrs.at(u.pending.front()), static_cast<std::uint32_t>(std::max(1, t.ortho->params().min_elevation_points)), m);
      m.stamp = now;
    }
    m.published = now;
    if (u.tiles_out.push(m) > 0) {
      ++u.tiles_refused;
      return;
    }
    ++u.tiles_published;
    if (t.opt.ugv_map == UgvMapSource::kGroundTruth) {
      ++u.gt_next;
    } else {
      u.pending_set.erase(u.pending.front());
      u.pending.pop_front();
    }
  }
}

// Online source: a robot waits at its start until the map knows most of its surroundings.
bool map_covers(const mapping::OrthoMap& m, const Pose2& p, double radius, double fraction) {
  std::uint64_t known = 0, total = 0;
  const double res = kMapResolutionM;
  for (double dy = -radius; dy <= radius; dy += res)
    for (double dx = -radius; dx <= radius; dx += res) {
      if (dx * dx + dy * dy > radius * radius) continue;
      ++total;
      const mapping::Cell* c = m.cell_at(p.x + dx, p.y + dy);
      if (c != nullptr && c->cls != 255) ++known;
    }
  return total == 0 || static_cast<double>(known) >= fraction * static_cast<double>(total);
}

// Online source: the share of the cells within 3 m of a route (sampled every 2 m) that have a class.
double route_covered(const mapping::OrthoMap& m, const std::vector<Eigen::Vector2d>& route) {
  std::uint64_t known = 0, total = 0;
  for (std::size_t i = 0; i < route.size(); i += 2)
    for (double dy = -3.0; dy <= 3.0; dy += 1.0)
      for (double dx = -3.0; dx <= 3.0; dx += 1.0) {
        ++total;
        const mapping::Cell* c = m.cell_at(route[i].x() + dx, route[i].y() + dy);
        if (c != nullptr && c->cls != 255) ++known;
      }
  return total == 0 ? 1.0 : static_cast<double>(known) / static_cast<double>(total);
}

// The simulator's reader on the quadrotor's own odometry (its vo stage's output, as the pose graph gets it),
// appended to its table in field mode: counts segments and writes vo_uav.csv.
class SimVoTapStage final : public Stage {
 public:
  static constexpr ParamSpec kParams[] = {ParamSpec::boolean("log", true, "count and log 'visual_odometry'")};
  static std::unique_ptr<Stage> make() { return std::make_unique<SimVoTapStage>(); }
  Status init(StageContext& ctx) override {
    auto r = ctx.channels.ring_reader<VoMsg, kVoRing>("visual_odometry");
    if (!r) return r.error();
    in_ = r.value();
    return ok_status();
  }
  void step(TimeNs) noexcept override;
  Uav* uav{nullptr};

 private:
  RingReader<VoMsg, kVoRing> in_{};
};

// The simulator's reader on a ground robot's channels, appended to its table: the newest "localization"
// for the sampling callback and, for tests, what arrives on the robot's input channels.
void SimVoTapStage::step(TimeNs) noexcept {
  while (const VoMsg* m = in_.front()) {
    if (uav != nullptr) {
      Uav& a = *uav;
      ++a.vo_samples;
      if (m->segment != a.last_segment || a.vo_samples == 1) {
        a.last_segment = m->segment;
        ++a.segments;
      }
      if (a.vo_log)
        std::fprintf(a.vo_log.get(), "%.3f,%u,%d,%.4f,%.4f,%.4f,%.5f,%.5f,%.5f\n", to_seconds(m->stamp), m->segment, m->tracking ? 1 : 0, m->pose.x,
                     m->pose.y, m->pose.z, m->pose.roll, m->pose.pitch, m->pose.yaw);
    }
    in_.pop();
  }
}

class SimProbeStage final : public Stage {
 public:
  static constexpr ParamSpec kParams[] = {
      ParamSpec::boolean("scans", false, "read lidar_scan"),
      ParamSpec::boolean("odometry", false, "read wheel_odometry"),
      ParamSpec::boolean("tiles", false, "read map_tiles"),
      ParamSpec::boolean("initial_pose", false, "read initial_pose"),
  };
  static std::unique_ptr<Stage> make() { return std::make_unique<SimProbeStage>(); }

  Status init(StageContext& ctx) override {
    const SectionView p = ctx.params();
    auto loc = ctx.channels.latest_reader<LocalizationMsg>("localization");
    if (!loc) return loc.error();
    loc_ = loc.value();
    auto cmd = ctx.channels.latest_reader<WheelCommandMsg>("wheel_command");
    if (!cmd) return cmd.error();
    cmd_ = cmd.value();
    if (p.boolean("scans")) {
      auto r = ctx.channels.ring_reader<LidarScanMsg, kLidarRing>("lidar_scan");
      if (!r) return r.error();
      scans_ = r.value();
      read_scans_ = true;
    }
    if (p.boolean("odometry")) {
      auto r = ctx.channels.ring_reader<WheelOdometryMsg, kWheelOdometryRing>("wheel_odometry");
      if (!r) return r.error();
      odom_ = r.value();
      read_odom_ = true;
    }
    if (p.boolean("tiles")) {
      auto r = ctx.channels.ring_reader<MapTileMsg, kMapTileRing>("map_tiles");
      if (!r) return r.error();
      tiles_ = r.value();
      read_tiles_ = true;
    }
    if (p.boolean("initial_pose")) {
      auto r = ctx.channels.latest_reader<InitialPoseMsg>("initial_pose");
      if (!r) return r.error();
      init_ = r.value();
      read_init_ = true;
    }
    return ok_status();
  }

  void step(TimeNs now) noexcept override {
    const UgvChannelTap& tap = team->opt.ugv_tap;
    const int i = ugv->index;
    if (read_scans_)
      for (LidarScanMsg* m = scans_.front(); m != nullptr; m = scans_.front()) {
        if (tap.scan) tap.scan(i, *m);
        scans_.pop();
      }
    if (read_odom_)
      for (WheelOdometryMsg* m = odom_.front(); m != nullptr; m = odom_.front()) {
        if (tap.odometry) tap.odometry(i, *m);
        odom_.pop();
      }
    if (read_tiles_)
      for (MapTileMsg* m = tiles_.front(); m != nullptr; m = tiles_.front()) {
        if (tap.tile) tap.tile(i, *m);
        tiles_.pop();
      }
    if (read_init_ && init_.fresh()) {
      const InitialPoseMsg& m = init_.read();
      if (tap.initial_pose) tap.initial_pose(i, m);
    }
    if (cmd_.fresh()) {
      command_ = cmd_.read();
      new_command_ = true;
    }
    if (loc_.fresh()) received_ = true;
    const LocalizationMsg& loc = loc_.read();
    if (now >= next_sample_) {
      next_sample_ += team->sample_period;
      if (received_) ugv->loc_last = loc.status;
      if (received_ && ugv->released && !ugv->held) {
        ++ugv->loc_samples;
        if (loc.status == LocalizationStatus::kTracking) {
          const Pose2 tr = ugv->truth_at(loc.stamp);
          ++ugv->loc_tracking;
          ugv->loc_errors.push_back(static_cast<float>(std::hypot(loc.pose.x - tr.x, loc.pose.y - tr.y)));
          if (ugv->loc_first_tracking < 0) ugv->loc_first_tracking = now;
          ugv->loc_pose = loc.pose;
          ugv->loc_has_pose = true;
          if (ugv->est_trail.empty() || (ugv->est_trail.back() - Eigen::Vector2d(loc.pose.x, loc.pose.y)).norm() > 1.0)
            ugv->est_trail.emplace_back(loc.pose.x, loc.pose.y);
        }
      }
    }
    if (team->opt.sample && now >= next_user_sample_) {
      next_user_sample_ += team->sample_period;
      UgvSample s;
      s.now = now;
      s.ugv = i;
      s.truth = ugv->vehicle.pose();
      s.odometry = ugv->odom_last;
      s.odometry_in_map = ugv->odometry_in_map(ugv->odom_last);
      s.initial_guess = ugv->init_pose.pose;
      s.localization_received = received_;
      s.localization = &loc;
      s.truth_at_localization = received_ ? ugv->truth_at(loc.stamp) : s.truth;
      s.distance_m = ugv->vehicle.distance_travelled();
      s.released = ugv->released;
      s.held = ugv->held;
      s.route_done = ugv->route_done;
      s.killed = ugv->killed;
      s.role = ugv->role.get();
      if (team->parallel_robots) {  // called from this robot's worker: hand it over at the end of the release time
        ugv->pending_sample = s;
        ugv->has_pending_sample = true;
      } else {
        team->opt.sample(s);
      }
    }
  }

  [[nodiscard]] bool received() const noexcept { return received_; }
  // The drive stage's newest wheel command, once per new value (drive_by_stages).
  bool take_command(WheelCommandMsg& out) noexcept {
    if (!new_command_) return false;
    new_command_ = false;
    out = command_;
    return true;
  }

  Team* team{nullptr};
  Ugv* ugv{nullptr};

 private:
  LatestReader<LocalizationMsg> loc_{};
  RingReader<LidarScanMsg, kLidarRing> scans_{};
  RingReader<WheelOdometryMsg, kWheelOdometryRing> odom_{};
  RingReader<MapTileMsg, kMapTileRing> tiles_{};
  LatestReader<InitialPoseMsg> init_{};
  LatestReader<WheelCommandMsg> cmd_{};
  WheelCommandMsg command_{};
  bool new_command_{false};
  bool read_scans_{false}, read_odom_{false}, read_tiles_{false}, read_init_{false};
  bool received_{false};
  TimeNs next_sample_{0}, next_user_sample_{0};
};

// The camera driver's job in simulation: the rendered frame at the mapper's 640x400, with its labels.
// LidarPoints as the .bin recording keeps them: the struct's layout with its padding bytes zeroed, so
// that one seed gives the same file byte for byte.
void write_points(const std::vector<LidarPoint>& pts, std::vector<unsigned char>& scratch, std::FILE* f) {
  scratch.assign(pts.size() * sizeof(LidarPoint), 0);
  unsigned char* d = scratch.data();
  for (const LidarPoint& q : pts) {
    std::memcpy(d + offsetof(LidarPoint, x), &q.x, sizeof q.x);
    std::memcpy(d + offsetof(LidarPoint, y), &q.y, sizeof q.y);
    std::memcpy(d + offsetof(LidarPoint, z), &q.z, sizeof q.z);
    std::memcpy(d + offsetof(LidarPoint, range), &q.range, sizeof q.range);
    std::memcpy(d + offsetof(LidarPoint, cls), &q.cls, sizeof q.cls);
    std::memcpy(d + offsetof(LidarPoint, ring), &q.ring, sizeof q.ring);
    std::memcpy(d + offsetof(LidarPoint, col), &q.col, sizeof q.col);
    d += sizeof(LidarPoint);
  }
  std::fwrite(scratch.data(), 1, scratch.size(), f);
}

void publish_image(Uav& a, TimeNs now) {
  CameraImageMsg& m = *a.image;
  const cv::Mat* rgb = &a.frame.rgb;
  const cv::Mat* cls = &a.frame.cls;
  if (rgb->cols != kImageWidth || rgb->rows != kImageHeight) {
    cv::resize(a.frame.rgb, a.rgb_small, cv::Size(kImageWidth, kImageHeight), 0, 0, cv::INTER_AREA);
    cv::resize(a.frame.cls, a.cls_small, cv::Size(kImageWidth, kImageHeight), 0, 0, cv::INTER_NEAREST);
    rgb = &a.rgb_small;
    cls = &a.cls_small;
  }
  m.stamp = now;
  m.published = now;
  m.seq = a.image_seq++;
  // A camera measures light, not classes: the truth only in the ablation the user names.
  m.labels = a.labels_oracle ? LabelSource::kGroundTruth : LabelSource::kNone;
  if (!a.labels_oracle) m.cls.fill(255);
  for (int r = 0; r < kImageHeight; ++r) {
    std::memcpy(m.rgb.data() + static_cast<std::size_t>(r) * kImageWidth * 3, rgb->ptr<std::uint8_t>(r), kImageWidth * 3);
    if (a.labels_oracle) std::memcpy(m.cls.data() + static_cast<std::size_t>(r) * kImageWidth, cls->ptr<std::uint8_t>(r), kImageWidth);
  }
  (void)a.camera_out.push(m);
}

// A frame's exposure, motion (blur) and noise key: the same whether it is rendered ahead or when due.
CameraShot camera_shot(const Team& t, const Quadrotor& q, double yaw_rate, std::uint64_t frame) {
  return CameraShot{t.opt.seed, frame, t.camera_ae.next(), Eigen::Vector3d(q.vx(), q.vy(), q.vz()), yaw_rate};
}

// The world side of the lockstep tick: vehicles, odometry, GPS, VO, camera, LiDAR, radio, recording.
class SimWorldStage final : public Stage {
 public:
  explicit SimWorldStage(Team& t) : t_(t) {}
  Status init(StageContext&) override { return ok_status(); }
  void step(TimeNs now) noexcept override;

 private:
  Team& t_;
  TimeNs last_{-1};
};

void SimWorldStage::step(TimeNs now) noexcept {
  Team& t = t_;
  const double dt = last_ < 0 ? 0.0 : to_seconds(now - last_);
  last_ = now;
  const bool log_now = now >= t.next_log;
  if (log_now) t.next_log += t.log_period;

  // The quadrotor's map as the ground robots' source: which tiles changed (as of the last step).
  if (t.ortho != nullptr) scan_online_map(t);
  if (t.opt.observe && now >= t.next_observe) {
    t.next_observe += t.sample_period;
    t.opt.observe(now, t.uav ? t.uav->role.get() : nullptr, t.ugv_roles, t.base.get());
  }
  for (const RunOptions::Kill& k : t.opt.kills) {
    if (now < from_seconds(k.at_s)) continue;
    if (k.ugv < 0) {
      if (!t.base_killed) AG_LOG_WARN("sim", "base station powered off at %.1f s", to_seconds(now));
      t.base_killed = true;
    } else if (!t.ugvs[static_cast<std::size_t>(k.ugv)]->killed) {
      Ugv& u = *t.ugvs[static_cast<std::size_t>(k.ugv)];
      u.killed = true;
      u.killed_at = now;
      AG_LOG_WARN("sim", "%s powered off at %.1f s at (%.1f, %.1f)", u.name.c_str(), to_seconds(now), u.vehicle.pose().x, u.vehicle.pose().y);
    }
  }
  // A powered-off node is moved far out of everyone's range: nothing it sends arrives, nothing reaches it.
  constexpr double kFarAway = 1e9;
  if (t.air && t.base_killed) t.air->set_position(t.base_node, -kFarAway, -kFarAway);

  // Ground robots: scripted pursuit from ground truth, exact arcs, wheel odometry.
  for (auto& up : t.ugvs) {
    Ugv& u = *up;
    if (!u.init_published) {  // the operator's (or mission file's) guess of the start pose
      u.init_pose.stamp = now;
      u.init_pose.published = now;
      u.init_out.publish(u.init_pose);
      u.init_published = true;
    }
    if (u.goal_pending) {  // a test's goal for a table without a mission stage
      u.goal.stamp = now;
      u.goal.published = now;
      u.goal_out.publish(u.goal);
      u.goal_pending = false;
    }
    if (!u.released && now >= u.next_wait_check) {
      u.next_wait_check += kNsPerS;
      if (map_covers(*t.ortho, u.vehicle.pose(), t.opt.ugv_wait_map_radius_m, t.opt.ugv_wait_map_fraction) &&
          (!u.scripted || t.opt.ugv_wait_map_route_fraction <= 0 || route_covered(*t.ortho, u.route) >= t.opt.ugv_wait_map_route_fraction)) {
        u.released = true;
        u.released_at = now;
        AG_LOG_INFO("sim", "%s: the map covers its surroundings at %.1f s; driving", u.name.c_str(), to_seconds(now));
      }
    }
    u.held = false;
    for (const UgvHold& h : t.opt.ugv_holds)
      if (h.ugv == u.index && now >= from_seconds(h.at_s) && now < from_seconds(h.at_s + h.duration_s)) u.held = true;
    if (u.scripted) {
      if (!u.route_done && u.pursuit.done()) {
        u.route_done = true;
        ++u.goals_reached;
        AG_LOG_INFO("sim", "%s: route driven at %.1f s (%.0f m)", u.name.c_str(), to_seconds(now), u.vehicle.distance_travelled());
      }
      // Progress along the route (for rejoining it after a collision): the nearest vertex, never back.
      const Pose2& p = u.vehicle.pose();
      auto d2 = [&](std::size_t k) { return (u.route[k] - Eigen::Vector2d(p.x, p.y)).squaredNorm(); };
      while (u.route_progress + 1 < u.route.size() && d2(u.route_progress + 1) < d2(u.route_progress)) ++u.route_progress;
    } else if (u.pursuit.done() && now >= u.retry_at) {
      if (u.on_route) ++u.goals_reached;
      new_leg(t, u, now);
    }
    if (t.opt.drive_by_stages) {
      // The robot's own drive stage: its newest wheel command (the vehicle's command timeout stops it
      // when the stage falls silent, like the base's watchdog).
      WheelCommandMsg cmd;
      if (u.probe != nullptr && u.probe->take_command(cmd)) {
        ++u.wheel_commands;
        if (u.killed || u.held) u.vehicle.command_wheels(0, 0);
        else u.vehicle.command_wheels(cmd.left_mps / t.wheel_radius_m, cmd.right_mps / t.wheel_radius_m);
      } else if (u.killed || u.held) {
        u.vehicle.command_wheels(0, 0);
      }
    } else {
      double v = 0, w = 0;
      if (u.released && !u.held && !u.killed) u.pursuit.command(u.vehicle.pose(), v, w);
      u.vehicle.command_twist(v, w);
    }
    if (dt > 0 && u.vehicle.step(dt, *t.world)) {  // a collision: the vehicle stopped; replan from here
      AG_LOG_WARN("sim", "%s: collision at (%.2f, %.2f) yaw %.2f; replanning", u.name.c_str(), u.vehicle.pose().x,
                  u.vehicle.pose().y, u.vehicle.pose().yaw);
      if (t.opt.drive_by_stages) {
        // nothing to do: the robot's own stages see it stop and go on
      } else if (u.scripted) {
        if (!u.route_done) rejoin_route(t, u, now);
      } else {
        new_leg(t, u, now);
      }
    }
    u.history[u.history_n % Ugv::kHistory] = {now, u.vehicle.pose()};
    ++u.history_n;
    const OdometrySample od = u.odometry.step(now, u.vehicle.pose(), u.vehicle.wheel_left_rad_s(), u.vehicle.wheel_right_rad_s());
    ++u.odom_samples;
    u.odom_last = od.pose;
    {  // the base's odometry over CAN, as the robot computes it with its nominal wheel radius and track
      WheelOdometryMsg m;
      m.stamp = od.stamp;
      m.published = now;
      m.pose = od.pose;
      const WheelOdometryConfig& oc = u.odometry.config();
      m.v_mps = 0.5 * oc.wheel_radius_m * (od.wheel_left_rad_s + od.wheel_right_rad_s);
      m.w_radps = oc.wheel_radius_m * (od.wheel_right_rad_s - od.wheel_left_rad_s) / oc.track_width_m;
      m.moving = od.moving;
      if (u.odom_out.push(m) > 0) ++u.channel_drops;
      ++u.odom_published;
    }
    if (t.opt.ugv_map != UgvMapSource::kNone) publish_tiles(t, u, now);
    if (log_now) {
      const Pose3 p = u.vehicle.pose3();
      if (u.truth_log) std::fprintf(u.truth_log.get(), "%.3f,%.3f,%.3f,%.3f,%.4f,%.4f,%.4f\n", to_seconds(now), p.x, p.y, p.z, p.roll, p.pitch, p.yaw);
      if (u.odom_log) std::fprintf(u.odom_log.get(), "%.3f,%.3f,%.3f,%.4f,%.4f,%.4f\n", to_seconds(now), od.pose.x, od.pose.y, od.pose.yaw, od.wheel_left_rad_s, od.wheel_right_rad_s);
      u.trail.emplace_back(p.x, p.y);
      if (t.mcap) {
        const Pose2 om = u.odometry_in_map(od.pose);
        t.mcap->ugv_pose(now, u.index, p, &om, u.loc_has_pose ? &u.loc_pose : nullptr);
      }
      if (t.mcap && !t.opt.drive_by_stages) t.mcap->ugv_route(now, u.index, u.pursuit.path());
    }
    if (t.air) t.air->set_position(u.node, u.killed ? kFarAway : u.vehicle.pose().x, u.killed ? kFarAway : u.vehicle.pose().y);
  }

  // Quadrotor: survey flight, GPS, visual odometry.
  if (t.uav) {
    Uav& a = *t.uav;
    if (dt > 0) {
      const double yaw0 = a.vehicle.pose().yaw;
      a.vehicle.step(dt);
      t.uav_yaw_rate = wrap_angle(a.vehicle.pose().yaw - yaw0) / dt;
    }
    const Pose3& p = a.vehicle.pose();
    if (t.opt.keep_uav_truth) a.truth.push_back(TruthSample{now, p});
    GpsFix fix;
    if (a.gps.sample(now, p, fix)) {
      ++a.fixes;
      GpsMsg m;
      m.stamp = fix.stamp;
      m.published = now;
      m.fix_type = static_cast<std::uint8_t>(fix.fix_type);
      m.east_m = fix.east_m;
      m.north_m = fix.north_m;
      m.up_m = fix.up_m;
      m.h_accuracy_m = fix.h_accuracy_m;
      m.v_accuracy_m = fix.v_accuracy_m;
      (void)a.gps_out.push(m);  // a full ring is counted by the channel
      if (t.mcap) t.mcap->uav_gps(now, fix.lat_deg, fix.lon_deg, fix.height_m, fix.h_accuracy_m);
      if (a.gps_log) std::fprintf(a.gps_log.get(), "%.3f,%d,%.9f,%.9f,%.3f,%.3f,%.3f,%.3f,%.2f\n", to_seconds(now), static_cast<int>(fix.fix_type), fix.lat_deg, fix.lon_deg, fix.height_m, fix.east_m, fix.north_m, fix.up_m, fix.h_accuracy_m);
    }
    AttitudeSample as;
    if (a.attitude.sample(now, p, as)) {
      ++a.attitudes;
      AttitudeMsg m;
      m.stamp = as.stamp;
      m.published = now;
      m.roll = as.roll;
      m.pitch = as.pitch;
      m.yaw = as.yaw;
      m.roll_rate = as.roll_rate;
      m.pitch_rate = as.pitch_rate;
      m.yaw_rate = as.yaw_rate;
      (void)a.attitude_out.push(m);
    }
    if (a.vo_oracle) {
      VoSample vs;
      if (a.vo.sample(now, p, vs)) {
        ++a.vo_samples;
        VoMsg m;
        m.stamp = vs.stamp;
        m.published = now;
        m.segment = vs.segment;
        m.tracking = vs.tracking;
        m.pose = vs.pose;
        (void)a.vo_out.push(m);
        if (vs.segment != a.last_segment || a.vo_samples == 1) {
          a.last_segment = vs.segment;
          ++a.segments;
        }
        if (a.vo_log) std::fprintf(a.vo_log.get(), "%.3f,%u,%d,%.4f,%.4f,%.4f,%.5f,%.5f,%.5f\n", to_seconds(now), vs.segment, vs.tracking ? 1 : 0, vs.pose.x, vs.pose.y, vs.pose.z, vs.pose.roll, vs.pose.pitch, vs.pose.yaw);
      }
    }
    if (log_now) {
      if (a.truth_log) std::fprintf(a.truth_log.get(), "%.3f,%.3f,%.3f,%.3f,%.4f,%.4f,%.4f\n", to_seconds(now), p.x, p.y, p.z, p.roll, p.pitch, p.yaw);
      a.trail.emplace_back(p.x, p.y);
      if (t.mcap) t.mcap->uav_pose(now, p);
    }
    if (t.air) t.air->set_position(0, p.x, p.y);
  }

  // Sensors due now, rendered in parallel: camera rows in bands, one job per LiDAR scan. A camera frame
  // rendered ahead (CameraPrefetch) is finished by the same jobs instead.
  const bool camera_due = t.uav && t.camera && now >= t.next_camera;
  const bool lidar_due = !t.ugvs.empty() && now >= t.next_lidar;
  if (camera_due || lidar_due) {
    const int bands = camera_due ? kCameraBands : 0;
    constexpr std::size_t kParts = kScanParts;
    const std::size_t jobs = static_cast<std::size_t>(bands) + (lidar_due ? kParts * t.ugvs.size() : 0);
    const Pose3 uav_pose = t.uav ? t.uav->vehicle.pose() : Pose3{};
    const CameraShot shot = camera_due ? camera_shot(t, t.uav->vehicle, t.uav_yaw_rate, t.uav->frames) : CameraShot{};
    bool ahead = false;  // this frame was started ahead for exactly this pose, instant and shot
    if (camera_due && t.prefetch && t.prefetch->active()) {
      ahead = t.prefetch->matches(uav_pose, now) && t.uav->frame.shot == shot;
      if (!ahead) t.prefetch->finish();  // a stale guess (never seen): let it end, then render as usual
      else ++t.frames_ahead;
    }
    const TimeNs cpu0 = thread_cpu_now();
    if (camera_due && !ahead) t.camera->prepare(uav_pose, t.uav->frame, now, shot);
    const TimeNs prepare_cpu = thread_cpu_now() - cpu0;
    std::function<void(std::size_t)> job = [&](std::size_t j) {
      if (static_cast<int>(j) < bands && ahead) {  // the prefetch counts its own CPU
        t.prefetch->help();
        t.job_cpu[j] = 0;
        return;
      }
      const TimeNs job0 = thread_cpu_now();  // each job its own slot: no sharing between the threads
      if (static_cast<int>(j) < bands) {
        const int h = t.uav->frame.rgb.rows;
        const int b = static_cast<int>(j);
        t.camera->render_rows(uav_pose, h * b / bands, h * (b + 1) / bands, t.uav->frame);
      } else {
        const std::size_t idx = j - static_cast<std::size_t>(bands);
        Ugv& u = *t.ugvs[idx / kParts];
        const auto part = static_cast<int>(idx % kParts);
        const int cols = t.opt.lidar_columns;
        const std::uint64_t seed = t.opt.seed ^ (static_cast<std::uint64_t>(now) * std::uint64_t{0x9E3779B97F4A7C15}) ^ static_cast<std::uint64_t>(u.node);
        t.lidar->scan_columns(lidar_pose(u, t.opt.lidar_mount_height_m), seed, cols * part / static_cast<int>(kParts),
                              cols * (part + 1) / static_cast<int>(kParts), u.scan_parts[static_cast<std::size_t>(part)]);
      }
      t.job_cpu[j] = thread_cpu_now() - job0;
    };
    t.pool->run(jobs, job);
    if (ahead) t.prefetch->finish();
    t.camera_cpu += prepare_cpu;
    for (std::size_t j = 0; j < jobs; ++j) (static_cast<int>(j) < bands ? t.camera_cpu : t.lidar_cpu) += t.job_cpu[j];
    if (camera_due) {
      t.next_camera += t.camera_period;
      Uav& a = *t.uav;
      ++a.frames;
      t.camera_ae.observe(a.frame);
      publish_image(a, now);
      if (t.mcap) t.mcap->camera_frame(now, a.frames, a.frame.rgb);
      if (a.frame_log) std::fprintf(a.frame_log.get(), "%.3f,%llu,%.3f,%.3f,%.3f,%.4f\n", to_seconds(now), static_cast<unsigned long long>(a.frames), uav_pose.x, uav_pose.y, uav_pose.z, uav_pose.yaw);
      const bool keep = t.opt.record == RecordLevel::kFull || (t.opt.record == RecordLevel::kLight && (a.frames - 1) % 20 == 0);
      if (keep) {
        char name[64];
        std::snprintf(name, sizeof name, "frame_%06llu", static_cast<unsigned long long>(a.frames));
        cv::Mat bgr;
        cv::cvtColor(a.frame.rgb, bgr, cv::COLOR_RGB2BGR);
        cv::imwrite((t.out / "camera" / (std::string(name) + "_rgb.png")).string(), bgr);
        cv::cvtColor(class_display_image(a.frame.cls), bgr, cv::COLOR_RGB2BGR);
        cv::imwrite((t.out / "camera" / (std::string(name) + "_class.png")).string(), bgr);
        ++t.frame_pngs;
      }
      if (t.prefetch) {  // the next exposure: step a copy of the vehicle as this stage will step it
        if (!t.uav_ahead) t.uav_ahead.emplace(a.vehicle);
        else *t.uav_ahead = a.vehicle;  // reuses the route's storage
        TimeNs due = now;
        double yaw_rate = t.uav_yaw_rate;
        while (due < t.next_camera) {
          due += t.physics_period;
          const double yaw0 = t.uav_ahead->pose().yaw;
          t.uav_ahead->step(to_seconds(t.physics_period));
          yaw_rate = wrap_angle(t.uav_ahead->pose().yaw - yaw0) / to_seconds(t.physics_period);
        }
        const TimeNs c0 = thread_cpu_now();
        t.camera->prepare(t.uav_ahead->pose(), a.frame, due, camera_shot(t, *t.uav_ahead, yaw_rate, a.frames));
        t.camera_cpu += thread_cpu_now() - c0;
        t.prefetch->start(t.uav_ahead->pose(), due);
      }
    }
    if (lidar_due) {
      t.next_lidar += t.lidar_period;
      for (auto& up : t.ugvs) {
        Ugv& u = *up;
        std::size_t total = 0;
        for (const auto& part : u.scan_parts) total += part.size();
        ++u.scans;
        {  // the Ouster driver's revolution: range, XYZ, no class (the world's classes only with --oracle labels)
          const bool truth = t.opt.oracle("labels");
          LidarScanMsg& m = *u.scan_msg;
          m.stamp = now;
          m.published = now;
          m.seq = u.scan_seq++;
          m.rings = static_cast<std::uint16_t>(t.lidar_rings);
          m.columns = static_cast<std::uint16_t>(t.opt.lidar_columns);
          m.labels = truth ? LabelSource::kGroundTruth : LabelSource::kNone;
          m.sensor_in_body = Pose3{0, 0, t.opt.lidar_mount_height_m, 0, 0, 0};
          std::size_t n = 0;
          for (const auto& part : u.scan_parts)
            for (const LidarPoint& q : part) {
              if (n == kMaxScanPoints) break;
              m.points[n++] = ScanReturn{q.x, q.y, q.z, q.range, truth ? q.cls : std::uint8_t{255}, q.ring, q.col};
            }
          m.count = static_cast<std::uint32_t>(n);
          if (u.scan_out.push(m) > 0) ++u.channel_drops;
          ++u.scans_published;
        }
        if (t.mcap) t.mcap->ugv_scan(now, u.index, u.scans, u.scan_parts.data(), u.scan_parts.size());
        if (u.scan_log) std::fprintf(u.scan_log.get(), "%.3f,%llu,%zu\n", to_seconds(now), static_cast<unsigned long long>(u.scans), total);
        if (u.scan_bin != nullptr) {  // per scan: int64 stamp, uint32 count, then packed points
          const std::uint32_t n = static_cast<std::uint32_t>(total);
          std::fwrite(&now, sizeof now, 1, u.scan_bin);
          std::fwrite(&n, sizeof n, 1, u.scan_bin);
          for (const auto& part : u.scan_parts) write_points(part, u.bin_scratch, u.scan_bin);
        }
      }
    }
  }

  // Radio: with gossip, what the comms stages sent reaches the receivers' inboxes; without, every robot
  // broadcasts a small status datagram and the runner counts what arrives where.
  if (t.net) t.net->pump(now);
  if (t.radio) {
    if (now >= t.next_heartbeat) {
      t.next_heartbeat += t.heartbeat_period;
      std::uint8_t msg[64] = {};
      for (int n = 0; n < t.radio->num_nodes(); ++n) {
        msg[0] = static_cast<std::uint8_t>(n);
        std::memcpy(msg + 8, &now, sizeof now);
        t.radio->send(now, n, RadioModel::kBroadcast, msg);
      }
    }
    t.deliveries.clear();
    t.radio->deliver(now, t.deliveries);
  }
  if (t.mcap) {
    const LinkStats radio = t.air ? t.air->total() : LinkStats{};
    t.mcap->tick(now, t.air ? &radio : nullptr);
  }
}

cv::Mat trajectories_image(const Team& t) {
  const World& w = *t.world;
  cv::Mat img = class_display_image(w.class_id);
  cv::Mat bgr;
  cv::cvtColor(img, bgr, cv::COLOR_RGB2BGR);
  const double scale = std::min(1.0, 1600.0 / std::max(bgr.cols, bgr.rows));
  if (scale < 1.0) cv::resize(bgr, bgr, cv::Size(), scale, scale, cv::INTER_AREA);
  const GridGeometry& g = w.grid();
  auto px = [&](const Eigen::Vector2d& p) {
    return cv::Point(static_cast<int>(g.col_f(p.x()) * scale), static_cast<int>(g.row_f(p.y()) * scale));
  };
  const cv::Scalar colours[] = {{0, 200, 255}, {255, 0, 255}, {255, 255, 0}, {0, 128, 255}, {255, 128, 0}, {128, 255, 128}};
  auto draw = [&](const std::vector<Eigen::Vector2d>& trail, const cv::Scalar& c, int thick) {
    for (std::size_t i = 1; i < trail.size(); ++i) cv::line(bgr, px(trail[i - 1]), px(trail[i]), c, thick, cv::LINE_AA);
    if (!trail.empty()) cv::circle(bgr, px(trail.back()), 4, c, cv::FILLED, cv::LINE_AA);
  };
  if (t.uav) draw(t.uav->trail, cv::Scalar(255, 255, 255), 1);
  for (std::size_t i = 0; i < t.ugvs.size(); ++i) draw(t.ugvs[i]->trail, colours[i % 6], 2);
  // Each robot's own localization while tracking: white dots over its true trail.
  for (const auto& u : t.ugvs)
    for (const Eigen::Vector2d& p : u->est_trail) cv::circle(bgr, px(p), 1, cv::Scalar(255, 255, 255), cv::FILLED);
  return bgr;
}

Status write_reports(const Team& t, const RunSummary& s) {
  cv::imwrite((t.out / "trajectories.png").string(), trajectories_image(t));
  std::ofstream y(t.out / "summary.yaml");
  y << "# airground-sim run summary\n"
    << "oracles: " << t.opt.oracles_json() << "\n"
    << "world: " << t.opt.world << "\nseed: " << t.opt.seed << "\nugvs: " << t.opt.ugvs << "\nuav: " << (t.opt.uav ? "true" : "false")
    << "\nsim_s: " << s.sim_s << "\nwall_s: " << s.wall_s << "\nreal_time_factor: " << s.real_time_factor
    << "\nsensor_cpu_s: " << s.sensor_cpu_s << "\ncamera_cpu_s: " << s.camera_cpu_s << "\nlidar_cpu_s: " << s.lidar_cpu_s
    << "\nprocess_cpu_s: " << s.process_cpu_s << "\ncpu_per_sim_s: " << (s.sim_s > 0 ? s.process_cpu_s / s.sim_s : 0.0)
    << "\nrobot_cpu_s: {" << [&] {
         std::string r;
         for (const auto& [name, cpu] : s.robot_cpu_s) r += (r.empty() ? "" : ", ") + name + ": " + std::to_string(cpu);
         return r;
       }() << "}\ncamera_frames: " << s.camera_frames << "\ncamera_frames_ahead: " << s.camera_frames_ahead << "\ngps_fixes: " << s.gps_fixes
    << "\nvo_samples: " << s.vo_samples << "\nvo_segments: " << s.vo_segments << "\nuav_distance_m: " << s.uav_distance_m
    << "\nuav_route_estimate_s: " << s.uav_route_estimate_s << "\nduration_cap_s: " << s.duration_cap_s
    << "\nuav_waypoints_reached: " << s.uav_waypoints_reached << "\nradio:\n  sent: " << s.radio_sent
    << "\n  delivered: " << s.radio_delivered << "\n  dropped_range: " << s.radio_dropped_range
    << "\n  dropped_loss: " << s.radio_dropped_loss << "\n  dropped_queue: " << s.radio_dropped_queue
    << "\ncompute_time: " << s.compute_time << "\nstage_overruns: " << s.stage_overruns << "\nstage_slips: " << s.stage_slips << "\nstages:\n";
  for (const auto& c : s.stages)
    y << "  - {name: " << c.name << ", runs: " << c.runs << ", overruns: " << c.overruns << ", slips: " << c.slips
      << ", exec_p99_ms: " << c.exec_p99_ms << ", budget_ms: " << c.budget_ms << "}\n";
  y << "ground_robots:\n";
  for (const auto& r : s.ugvs)
    y << "  - {name: " << r.name << ", distance_m: " << r.distance_m << ", collisions: " << r.collisions
      << ", goals_reached: " << r.goals_reached << ", scans: " << r.scans << ", odometry_final_error_m: " << r.odometry_final_error_m
      << ", published: {scans: " << r.scans_published << ", odometry: " << r.odometry_published << ", tiles: " << r.tiles_published
      << ", tiles_refused: " << r.tiles_refused << ", drops: " << r.channel_drops << ", initial_pose: " << (r.initial_pose_published ? "true" : "false") << "}"
      << ", localization: {status: \"" << r.loc_status << "\", tracking_fraction: " << r.loc_tracking_fraction << ", first_tracking_s: " << r.loc_first_tracking_s
      << ", error_mean_m: " << r.loc_error_mean_m << ", error_p95_m: " << r.loc_error_p95_m << ", error_max_m: " << r.loc_error_max_m << "}}\n";
  std::ofstream j(t.out / "summary.json");
  j << "{\"oracles\": " << t.opt.oracles_json() << ", \"sim_s\": " << s.sim_s << ", \"wall_s\": " << s.wall_s << ", \"real_time_factor\": " << s.real_time_factor
    << ", \"cpu_s\": {\"process\": " << s.process_cpu_s << ", \"camera\": " << s.camera_cpu_s << ", \"lidar\": " << s.lidar_cpu_s;
  for (const auto& [name, cpu] : s.robot_cpu_s) j << ", \"" << name << "\": " << cpu;
  j << "}"
    << ", \"camera_frames\": " << s.camera_frames << ", \"gps_fixes\": " << s.gps_fixes << ", \"vo_samples\": " << s.vo_samples
    << ", \"vo_segments\": " << s.vo_segments << ", \"uav_distance_m\": " << s.uav_distance_m
    << ", \"uav_route_estimate_s\": " << s.uav_route_estimate_s << ", \"duration_cap_s\": " << s.duration_cap_s
    << ", \"radio\": {\"sent\": " << s.radio_sent << ", \"delivered\": " << s.radio_delivered << "}"
    << ", \"compute_time\": \"" << s.compute_time << "\", \"stage_overruns\": " << s.stage_overruns << ", \"stage_slips\": " << s.stage_slips
    << ", \"stages\": [";
  for (std::size_t i = 0; i < s.stages.size(); ++i) {
    const auto& c = s.stages[i];
    j << (i ? ", " : "") << "{\"name\": \"" << c.name << "\", \"runs\": " << c.runs << ", \"overruns\": " << c.overruns << ", \"slips\": " << c.slips
      << ", \"exec_p99_ms\": " << c.exec_p99_ms << ", \"budget_ms\": " << c.budget_ms << "}";
  }
  j << "], \"ground_robots\": [";
  for (std::size_t i = 0; i < s.ugvs.size(); ++i) {
    const auto& r = s.ugvs[i];
    j << (i ? ", " : "") << "{\"name\": \"" << r.name << "\", \"distance_m\": " << r.distance_m << ", \"collisions\": " << r.collisions
      << ", \"goals_reached\": " << r.goals_reached << ", \"scans\": " << r.scans << ", \"odometry_final_error_m\": " << r.odometry_final_error_m
      << ", \"published\": {\"scans\": " << r.scans_published << ", \"odometry\": " << r.odometry_published << ", \"tiles\": " << r.tiles_published
      << ", \"tiles_refused\": " << r.tiles_refused << ", \"drops\": " << r.channel_drops << ", \"initial_pose\": " << (r.initial_pose_published ? "true" : "false") << "}"
      << ", \"localization\": {\"status\": \"" << r.loc_status << "\", \"tracking_fraction\": " << r.loc_tracking_fraction
      << ", \"first_tracking_s\": " << r.loc_first_tracking_s << ", \"error_mean_m\": " << r.loc_error_mean_m << ", \"error_p95_m\": " << r.loc_error_p95_m
      << ", \"error_max_m\": " << r.loc_error_max_m << "}}";
  }
  j << "]}\n";
  std::ofstream m(t.out / "report.md");
  m << "# airground-sim run\n\n" << t.opt.oracles_line() << "\n\n"
    << "World `" << t.opt.world << "`, seed " << t.opt.seed << ", " << (t.opt.uav ? "1 quadrotor + " : "") << t.opt.ugvs
    << " ground robots, " << s.sim_s << " s simulated in " << s.wall_s << " s (real-time factor " << s.real_time_factor << "x).\n\n"
    << "CPU over the run, in core-seconds per simulated second (the machine's cores divided by the total bound the "
       "real-time factor): " << [&] {
         const auto per = [&](double cpu) {
           char b[32];
           std::snprintf(b, sizeof b, "%.3f", s.sim_s > 0 ? cpu / s.sim_s : 0.0);
           return std::string(b);
         };
         std::string r = "total " + per(s.process_cpu_s) + "; camera " + per(s.camera_cpu_s) + ", LiDAR " + per(s.lidar_cpu_s);
         for (const auto& [name, cpu] : s.robot_cpu_s) r += ", " + name + " stages " + per(cpu);
         return r + " (the rest: world, vehicles, radio, recording, threads).\n\n";
       }()
    << "![trajectories](trajectories.png)\n\n"
    << "| robot | distance [m] | goals reached | collisions | LiDAR scans | odometry error at end [m] | localization at end | tracking [%] | "
       "localization error mean / p95 / max [m] |\n|---|---|---|---|---|---|---|---|---|\n";
  for (const auto& r : s.ugvs) {
    char err[96];
    if (r.loc_error_mean_m >= 0) std::snprintf(err, sizeof err, "%.2f / %.2f / %.2f", r.loc_error_mean_m, r.loc_error_p95_m, r.loc_error_max_m);
    else std::snprintf(err, sizeof err, "-");
    m << "| " << r.name << " | " << r.distance_m << " | " << r.goals_reached << " | " << r.collisions << " | " << r.scans << " | " << r.odometry_final_error_m
      << " | " << r.loc_status << " | " << static_cast<int>(std::lround(100.0 * r.loc_tracking_fraction)) << " | " << err << " |\n";
  }
  m << "\nLocalization: each robot's own pose on its `localization` channel (no GPS: LiDAR against the aerial map, "
    << (t.opt.ugv_map == UgvMapSource::kOnline ? "the map the quadrotor builds online" : t.opt.ugv_map == UgvMapSource::kGroundTruth ? "the world's class map" : "no map given")
    << ", initial guess " << t.opt.init_error_m << " m / " << t.opt.init_yaw_error_deg << " deg off), sampled at " << t.opt.sample_hz
    << " Hz while driving; errors over the tracking samples. White dots in the picture: the estimates.\n";
  m << "\nQuadrotor: " << s.uav_distance_m << " m flown, " << s.uav_waypoints_reached << " survey waypoints, "
    << s.camera_frames << " camera frames, " << s.gps_fixes << " GPS fixes, " << s.vo_samples << " VO samples in "
    << s.vo_segments << " tracking segments.\n\nRadio: " << s.radio_sent << " datagrams sent, " << s.radio_delivered
    << " delivered, " << s.radio_dropped_range << " out of range, " << s.radio_dropped_loss << " lost, "
    << s.radio_dropped_queue << " dropped by queues.\n\nRecordings: `truth_*.csv`, `odom_*.csv`, `gps_uav.csv`, "
    << "`vo_uav.csv`, `camera_frames.csv` and `camera/*.png`, `lidar_*.csv` (and `lidar_*.bin` with --record full).\n";
  if (!y || !j || !m) return Error::make(ErrorCode::kIo, "cannot write the summary files in " + t.out.string());
  return ok_status();
}

}  // namespace

namespace {
// "<section>.area_x0_m=..." .. "area_y1_m": the world's extent, the mission area the simulator gives a robot.
std::vector<std::string> world_area_keys(const GridGeometry& g, const char* section) {
  const double v[4] = {g.origin_x, g.origin_y - g.size_y(), g.origin_x + g.size_x(), g.origin_y};
  const char* keys[4] = {"area_x0_m", "area_y0_m", "area_x1_m", "area_y1_m"};
  std::vector<std::string> out;
  for (int k = 0; k < 4; ++k) {
    char buf[160];
    std::snprintf(buf, sizeof buf, "%s.%s=%.3f", section, keys[k], v[k]);
    out.emplace_back(buf);
  }
  return out;
}
}  // namespace

Result<RunSummary> run_team(const RunOptions& opt, const ProgressFn& progress) {
  if (opt.ugvs < 0 || opt.ugvs > 32) return Error::make(ErrorCode::kInvalidArgument, "--ugvs must be 0..32");
  if (!(opt.duration_s > 0)) return Error::make(ErrorCode::kInvalidArgument, "--duration must be positive");
  if (opt.lidar_columns != 512 && opt.lidar_columns != 1024 && opt.lidar_columns != 2048)
    return Error::make(ErrorCode::kInvalidArgument, "LiDAR columns must be 512, 1024 or 2048");
  if (!(opt.init_error_m >= 0) || !(opt.init_yaw_error_deg >= 0) || opt.init_yaw_error_deg > 180)
    return Error::make(ErrorCode::kInvalidArgument, "the initial pose error must be >= 0 m and 0..180 deg");
  if (opt.map_tiles_per_tick < 1) return Error::make(ErrorCode::kInvalidArgument, "map_tiles_per_tick must be >= 1");
  if (opt.sample && !(opt.sample_hz > 0 && opt.sample_hz <= opt.physics_hz))
    return Error::make(ErrorCode::kInvalidArgument, "the sampling rate must be in (0, physics rate]");
  if (opt.ugv_map == UgvMapSource::kOnline && !opt.uav)
    return Error::make(ErrorCode::kInvalidArgument, "the online map source needs the quadrotor");
  if (opt.ugv_routes.size() > static_cast<std::size_t>(opt.ugvs))
    return Error::make(ErrorCode::kInvalidArgument, "more scripted routes than ground robots");
  for (const auto& r : opt.ugv_routes)
    if (r.size() == 1) return Error::make(ErrorCode::kInvalidArgument, "a scripted route needs at least two points");
  for (const UgvHold& h : opt.ugv_holds)
    if (h.ugv < 0 || h.ugv >= opt.ugvs || !(h.duration_s >= 0))
      return Error::make(ErrorCode::kInvalidArgument, "a hold names no ground robot or has a negative duration");
  if (opt.gossip && opt.ugv_map == UgvMapSource::kOnline)
    return Error::make(ErrorCode::kInvalidArgument, "with gossip the ground robots get the quadrotor's map over the radio: ugv_map must be none (or ground truth)");
  if (opt.ugv_goals.size() > static_cast<std::size_t>(opt.ugvs)) return Error::make(ErrorCode::kInvalidArgument, "more goals than ground robots");
  for (const RunOptions::Kill& k : opt.kills)
    if (k.ugv < -1 || k.ugv >= opt.ugvs || !(k.at_s >= 0))
      return Error::make(ErrorCode::kInvalidArgument, "a kill names no ground robot (or -1, the base station) or has a negative time");
  if (!(opt.comm_range_m >= 0)) return Error::make(ErrorCode::kInvalidArgument, "the comm range must be >= 0 m");
  auto world = resolve_world(opt.world);
  if (!world) return world.error();

  Team t;
  t.opt = opt;
  t.world = world.value();
  t.out = opt.out_dir;
  std::error_code ec;
  fs::create_directories(t.out / "camera", ec);
  if (ec) return Error::make(ErrorCode::kIo, "cannot create " + t.out.string() + ": " + ec.message());

  using N = const YAML::Node&;
  using O = std::string_view;
  auto gps_cfg = model_config<GpsConfig>(opt.config_dir, "gps.yaml", "gps", [](N y, O o) { return load_gps_config(y, o); });
  auto vo_cfg = model_config<VoConfig>(opt.config_dir, "visual_odometry.yaml", "visual_odometry", [](N y, O o) { return load_vo_config(y, o); });
  auto od_cfg = model_config<WheelOdometryConfig>(opt.config_dir, "wheel_odometry.yaml", "wheel_odometry", [](N y, O o) { return load_wheel_odometry_config(y, o); });
  auto radio_cfg = model_config<RadioConfig>(opt.config_dir, "radio.yaml", "radio", [](N y, O o) { return load_radio_config(y, o); });
  auto dd_cfg = model_config<DiffDriveConfig>(opt.config_dir, "diff_drive.yaml", "diff_drive", [](N y, O o) { return load_diff_drive_config(y, o); });
  auto quad_cfg = model_config<QuadrotorConfig>(opt.config_dir, "quadrotor.yaml", "quadrotor", [](N y, O o) { return load_quadrotor_config(y, o); });
  auto att_cfg = model_config<AttitudeConfig>(opt.config_dir, "attitude.yaml", "attitude", [](N y, O o) { return load_attitude_config(y, o); });
  if (!att_cfg) return att_cfg.error();
  for (const Error* e : {gps_cfg ? nullptr : &gps_cfg.error(), vo_cfg ? nullptr : &vo_cfg.error(), od_cfg ? nullptr : &od_cfg.error(),
                         radio_cfg ? nullptr : &radio_cfg.error(), dd_cfg ? nullptr : &dd_cfg.error(), quad_cfg ? nullptr : &quad_cfg.error()})
    if (e != nullptr) return *e;

  CameraModel cam_model;
  CameraShading shading;
  CameraSensor cam_sensor = CameraSensor::field();  // a real camera unless camera.yaml says otherwise
  LidarNoise lidar_noise;
  if (!opt.config_dir.empty()) {
    const fs::path cam = fs::path(opt.config_dir) / "camera.yaml";
    if (fs::exists(cam)) {
      auto c = CameraModel::load_file(cam.string());
      if (!c) return c.error();
      cam_model = c.value();
      auto s = CameraShading::load_file(cam.string());
      if (!s) return s.error();
      shading = s.value();
      auto se = CameraSensor::load_file(cam.string());
      if (!se) return se.error();
      cam_sensor = se.value();
    }
    const fs::path li = fs::path(opt.config_dir) / "lidar_noise.yaml";
    if (fs::exists(li)) {
      auto n = LidarNoise::load_file(li.string());
      if (!n) return n.error();
      lidar_noise = n.value();
    }
  }
  if (opt.camera_scale != 1.0) cam_model = cam_model.scaled(opt.camera_scale);
  auto beams = OusterBeamModel::load_default(opt.lidar_columns);
  if (!beams) return beams.error();

  const World& w = *t.world;
  try {
    t.raycaster = std::make_shared<HeightfieldRaycaster>(w);
    if (opt.uav) t.camera = std::make_unique<CameraRenderer>(w, cam_model, shading, cam_sensor, t.raycaster);
    t.camera_ae = CameraAutoExposure(cam_sensor);
    if (opt.ugvs > 0) t.lidar = std::make_unique<LidarSimulator>(w, beams.value(), lidar_noise, t.raycaster);
  } catch (const std::exception& e) {
    return Error::make(ErrorCode::kInvalidArgument, std::string("sensor set-up: ") + e.what());
  }
  t.router = std::make_unique<RoadRouter>(w, 1.0, dd_cfg.value().footprint_radius_m + 0.2);
  const int nodes = (opt.uav ? 1 : 0) + opt.ugvs + 1;  // node 0 = quadrotor (or unused), then ground robots, then base
  RadioConfig rcfg = radio_cfg.value();
  if (opt.comm_range_m > 0) rcfg.range_m = opt.comm_range_m;
  const int radio_nodes = std::max(nodes, 2) + (opt.uav ? 0 : 1);
  if (opt.gossip) {
    t.net = std::make_unique<RadioNet>(rcfg, opt.seed ^ std::uint64_t{0x7261646F}, radio_nodes);
    t.air = &t.net->radio();
  } else {
    t.radio = std::make_unique<RadioModel>(rcfg, opt.seed ^ std::uint64_t{0x7261646F}, radio_nodes);
    t.air = t.radio.get();
  }
  t.wheel_radius_m = dd_cfg.value().wheel_radius_m;
  const Pose2 staging = w.header.staging;
  const int base_node = 1 + opt.ugvs;
  t.base_node = base_node;
  t.air->set_position(base_node, staging.x, staging.y);
  // Gossip: every role's comms stage over its radio endpoint, under a team key written for this run.
  std::vector<std::string> comms_common;
  struct LinkRegistration {  // unregisters the names when the run ends (the radio goes with the Team)
    std::vector<std::string> names;
    ~LinkRegistration() {
      for (const auto& n : names) comms::register_inproc_link(n, nullptr);
    }
  } links;
  if (opt.gossip) {
    const fs::path key = t.out / "team.key";
    if (auto st = write_team_key(key.string(), derive_seed(opt.seed, std::uint64_t{0x6B6579})); !st) return st.error();
    comms_common = {"comms.transport=inproc", "comms.key_file=" + key.string(), "comms.epoch_from_clock=false"};
    auto reg = [&](const std::string& name, int node) {
      comms::register_inproc_link(name, &t.net->endpoint(node));
      links.names.push_back(name);
    };
    if (opt.uav) reg("uav", 0);
    for (int i = 0; i < opt.ugvs; ++i) reg("ugv" + std::to_string(i + 1), (opt.uav ? 1 : 0) + i);
    reg("base", base_node);
  }

  const bool rec = opt.record == RecordLevel::kLight || opt.record == RecordLevel::kFull;  // the CSV streams
  SimClock clock(0);
  // Robot role instances: the real stage tables, quiet status stages (the runner reports instead).
  // Each robot starts from its role's shipped configuration (built in from firmware_host/<role>/<role>.yaml),
  // read over its full table's schema plus the simulator's own stages, so the sections of the device
  // stages the simulator replaces stay and the start-up check sees what the simulated devices give. The
  // simulator then sets only what it must: robot id and name, device backends, comms transport, mission
  // area and start keys (tests/unit/sim/test_runner_shipped_config.cpp holds it to that).
  const bool labels_oracle = opt.oracle("labels");
  auto make_role = [&](const RoleDescription& role, const RoleDescription& shipped_role, int id, const std::string& name,
                       std::vector<Config>& cfgs, const std::vector<std::string>& extra = {},
                       const char* what = "") -> Result<std::unique_ptr<RoleInstance>> {
    std::vector<StageSpec> all(shipped_role.stages.begin(), shipped_role.stages.end());
    for (const StageSpec& st : role.stages)
      if (std::none_of(all.begin(), all.end(), [&](const StageSpec& a) { return std::string_view(a.name) == st.name; })) all.push_back(st);
    RoleDescription schema_role = shipped_role;
    schema_role.stages = all;
    const std::string origin = "firmware_host/" + std::string(shipped_role.name) + "/" + std::string(shipped_role.name) + ".yaml (built into airground-sim)";
    auto loaded = Config::load_string(role_schema(schema_role), shipped_config_yaml(shipped_role.name), origin);
    if (!loaded) return loaded.error();
    Config c = std::move(loaded).value();
    std::vector<std::string> sim = {"robot.id=" + std::to_string(id), "robot.name=" + name,
                                    "status.log_counters=false"};  // the runner reports the counters
    if (c.has("comms.journal")) {
      sim.emplace_back("comms.journal=");  // a file on the robot; the simulation keeps its store in memory
      if (!opt.gossip) sim.emplace_back("comms.transport=none");
    }
    if (c.has("segmentation.weights")) sim.push_back("segmentation.weights=" + erfnet_weights_path(c.get_text("segmentation.weights")));
    if (labels_oracle) {  // the ablation: the drivers hand over the truth and the robots use it
      if (c.has("segmentation.labels")) sim.emplace_back("segmentation.labels=gt");
      if (c.has("camera.source")) sim.emplace_back("camera.source=replay");  // frames with classes, as HIL's frame stream
      if (c.has("localization.labels")) sim.emplace_back("localization.labels=gt");
      if (c.has("lidar.classes")) sim.emplace_back("lidar.classes=reflectivity");  // points with classes, as HIL's packets
    }
    for (const auto& kv : sim)
      if (auto st = c.set(kv, "the simulator"); !st) return st.error();
    for (const auto& kv : extra)
      if (auto st = c.set(kv, what); !st) return st.error();
    if (auto st = check_sensor_labels(c, origin + " with the simulator's settings and the " + what); !st) return st.error();
    cfgs.push_back(std::move(c));
    return RoleInstance::create(role, cfgs.back(), clock, name);
  };
  std::vector<Config> cfgs;
  cfgs.reserve(static_cast<std::size_t>(opt.ugvs) + 2);

  double survey_time_s = 0;  // the quadrotor's route, estimated [s]
  if (opt.uav) {
    const Pose3 start = uav_launch_pose(w);
    auto u = std::make_unique<Uav>(Uav{Quadrotor(quad_cfg.value(), start), GpsSimulator(gps_cfg.value(), w.header.datum, opt.seed ^ std::uint64_t{0x67707331}),
                                       VisualOdometrySimulator(vo_cfg.value(), opt.seed ^ std::uint64_t{0x766f3031}), CameraFrame{}, 0, 0, 0, 0, 0, {}, {}, {}, {}, {}, nullptr});
    const double hfov = 2.0 * std::atan(0.5 * cam_model.width / cam_model.fx);
    const UavSurveyOptions so{opt.uav_altitude_m, opt.survey_overlap, opt.uav_speed_mps, opt.survey_margin_m, opt.survey_x0, opt.survey_y0, opt.survey_x1, opt.survey_y1};
    auto route = uav_survey_route(w, so, hfov);
    if (!route) return route.error();
    std::vector<Waypoint> wps = std::move(route).value();
    // The same route as an autopilot's mission (QGroundControl .plan), as a field team would load it.
    if (auto st = write_survey_plan((t.out / "survey.plan").string(), SurveyPlan{wps, start, w.header.datum, AutopilotFirmware::kPx4,
                                                                                 opt.uav_speed_mps > 0 ? opt.uav_speed_mps : quad_cfg.value().cruise_speed_mps,
                                                                                 quad_cfg.value().waypoint_tolerance_m, opt.uav_return_home});
        !st)
      return st.error();
    if (opt.uav_return_home && !wps.empty()) wps.push_back(Waypoint{start.x, start.y, wps.back().z, 0});
    survey_time_s = estimate_route_time_s(quad_cfg.value(), start, wps);
    u->vehicle.set_waypoints(std::move(wps));
    if (rec) {
      u->truth_log = CsvLog(t.out / "truth_uav.csv", "t_s,x_m,y_m,z_m,roll_rad,pitch_rad,yaw_rad");
      u->gps_log = CsvLog(t.out / "gps_uav.csv", "t_s,fix_type,lat_deg,lon_deg,height_m,east_m,north_m,up_m,h_acc_m");
      u->vo_log = CsvLog(t.out / "vo_uav.csv", "t_s,segment,tracking,x,y,z,roll_rad,pitch_rad,yaw_rad");
      u->frame_log = CsvLog(t.out / "camera_frames.csv", "t_s,frame,x_m,y_m,z_m,yaw_rad");
    }
    std::vector<std::string> uav_extra = comms_common;
    if (opt.gossip) uav_extra.emplace_back("comms.send_map_tiles=true");
    for (const std::string& kv : world_area_keys(w.grid(), "regions")) uav_extra.push_back(kv);  // before uav_config: a caller's area wins
    uav_extra.insert(uav_extra.end(), opt.uav_config.begin(), opt.uav_config.end());
    // The simulator is the quadrotor's camera (and its VO) and its GNSS receiver: it writes their channels.
    RoleDescription uav_desc = uav_role();
    u->vo_oracle = opt.oracle("vo");
    u->labels_oracle = labels_oracle;
    for (const StageSpec& st : uav_desc.stages)
      if (!is_simulated_driver(st.name) && !(u->vo_oracle && st.name == "vo")) t.uav_stages.push_back(st);
    if (!u->vo_oracle)
      t.uav_stages.push_back(StageSpec{"sim_vo_tap", &SimVoTapStage::make, 10.0, 90'000, 1, -1, SimVoTapStage::kParams,
                                       "simulator: counts and logs the quadrotor's own odometry"});
    uav_desc.stages = t.uav_stages;
    auto role = make_role(uav_desc, uav_role(), 0, "uav", cfgs, uav_extra, "quadrotor config override");
    if (!role) return role.error();
    u->role = std::move(role).value();
    auto cam_w = u->role->channels().ring_writer<CameraImageMsg, kCameraRing>("camera");
    auto gps_w = u->role->channels().ring_writer<GpsMsg, kGpsRing>("gps");
    if (!cam_w) return cam_w.error();
    if (!gps_w) return gps_w.error();
    u->camera_out = cam_w.value();
    if (u->vo_oracle) {
      auto vo_w = u->role->channels().ring_writer<VoMsg, kVoRing>("visual_odometry");
      if (!vo_w) return vo_w.error();
      u->vo_out = vo_w.value();
    } else {
      for (auto& slot : u->role->stages())
        if (auto* tap = dynamic_cast<SimVoTapStage*>(slot.stage.get())) tap->uav = u.get();
    }
    u->gps_out = gps_w.value();
    auto att_w = u->role->channels().ring_writer<AttitudeMsg, kAttitudeRing>("attitude");
    if (!att_w) return att_w.error();
    u->attitude_out = att_w.value();
    u->attitude = AttitudeSimulator(att_cfg.value(), opt.seed ^ std::uint64_t{0x61747431});
    u->image = std::make_unique<CameraImageMsg>();
    if (opt.ugv_map == UgvMapSource::kOnline) {
      for (auto& slot : u->role->stages())
        if (auto* om = dynamic_cast<const mapping::OrthoMapStage*>(slot.stage.get())) t.ortho = &om->map();
      if (t.ortho == nullptr) return Error::make(ErrorCode::kInvalidArgument, "the online map source needs the quadrotor's ortho_map stage");
      const mapping::OrthoMapParams& mp = t.ortho->params();
      if (std::abs(mp.resolution_m - kMapResolutionM) > 1e-9 || mp.tile_cells != kTileCells)
        return Error::make(ErrorCode::kInvalidArgument, "the online map source needs the ortho-map at 0.5 m cells in 64-cell tiles (the map_tiles format)");
    }
    t.uav = std::move(u);
  }
  // The ground robots' table: their role, plus the simulator's probe when someone reads their channels.
  RoleDescription ugv_desc = ugv_role();
  // Always: the probe also scores every robot's localization for the summary.
  const bool probe = opt.ugvs > 0;
  if (probe) {
    for (const StageSpec& st : ugv_desc.stages) {
      if (!opt.ugv_goals.empty() && std::string_view(st.name) == "mission") continue;  // the runner's goals replace the mission manager's
      // The simulator is the base (it moves the vehicle by 'wheel_command') and the LiDAR (it writes 'lidar_scan').
      if (is_simulated_driver(st.name)) continue;
      t.ugv_stages.push_back(st);
    }
    const double hz = opt.physics_hz;
    t.ugv_stages.push_back(StageSpec{"sim_probe", &SimProbeStage::make, hz, static_cast<std::uint32_t>(0.9e6 / hz), 1, -1,
                                     SimProbeStage::kParams, "simulator: reads the robot's channels for tests and evaluations"});
    ugv_desc.stages = t.ugv_stages;
  }
  std::vector<std::string> ugv_extra = comms_common;
  if (opt.gossip) {
    ugv_extra.emplace_back("comms.send_pose=true");
    if (opt.ugv_map == UgvMapSource::kNone) ugv_extra.emplace_back("comms.deliver_map_tiles=true");
  }
  // The runner is then the robots' map link and writes their map_tiles itself.
  if (!opt.gossip || opt.ugv_map != UgvMapSource::kNone) ugv_extra.emplace_back("comms.deliver_map_tiles=false");
  // The mission area is the world's: the planner's roadmap and the localizer's distance fields cover it
  // (the shipped +-500 m would drop an imported 1.9 km map's tiles outside it and never localize there).
  for (const char* section : {"planner", "localization"})
    for (const std::string& kv : world_area_keys(w.grid(), section)) ugv_extra.push_back(kv);
  if (opt.ugv_survey_end && opt.uav) {
    char buf[96];
    std::snprintf(buf, sizeof buf, "mission.survey_end_s=%.1f", survey_time_s);
    ugv_extra.emplace_back(buf);  // before ugv_config: a mission file's value or --set wins
  }
  ugv_extra.insert(ugv_extra.end(), opt.ugv_config.begin(), opt.ugv_config.end());
  if (opt.ugv_tap.scan) ugv_extra.emplace_back("sim_probe.scans=true");
  if (opt.ugv_tap.odometry) ugv_extra.emplace_back("sim_probe.odometry=true");
  if (opt.ugv_tap.tile) ugv_extra.emplace_back("sim_probe.tiles=true");
  if (opt.ugv_tap.initial_pose) ugv_extra.emplace_back("sim_probe.initial_pose=true");
  if (opt.ugvs > 0) t.tile_msg = std::make_unique<MapTileMsg>();
  t.lidar_rings = beams.value().rings();
  t.sample_period = period_from_hz(opt.sample_hz);
  for (int i = 0; i < opt.ugvs; ++i) {
    const std::string name = "ugv" + std::to_string(i + 1);
    // Lined up on the staging pad, 2.5 m apart across the robots' heading.
    Pose2 start = staging;
    const double off = (i - (opt.ugvs - 1) / 2.0) * 2.5;
    start.x += -std::sin(staging.yaw) * off;
    start.y += std::cos(staging.yaw) * off;
    const RunOptions::UgvStart* given = static_cast<std::size_t>(i) < opt.ugv_starts.size() ? &opt.ugv_starts[static_cast<std::size_t>(i)] : nullptr;
    if (given != nullptr && given->has_start) {
      start = given->start;
      if (!w.grid().contains(w.grid().col(start.x), w.grid().row(start.y)))
        return Error::make(ErrorCode::kInvalidArgument, "ground robot " + std::to_string(i + 1) + ": its start pose is outside the world");
    }
    const bool scripted = static_cast<std::size_t>(i) < opt.ugv_routes.size() && !opt.ugv_routes[static_cast<std::size_t>(i)].empty();
    if (scripted) {  // at the route's first point, facing the first point a few metres along it
      const auto& r = opt.ugv_routes[static_cast<std::size_t>(i)];
      start = Pose2{r.front().x(), r.front().y(), 0};
      for (std::size_t k = 1; k < r.size(); ++k) {
        const Eigen::Vector2d d = r[k] - r.front();
        start.yaw = std::atan2(d.y(), d.x());
        if (d.norm() > 2.0) break;
      }
    }
    auto u = std::make_unique<Ugv>(name, (opt.uav ? 1 : 0) + i, DiffDriveRobot(dd_cfg.value(), start),
                                   WheelOdometrySimulator(od_cfg.value(), opt.seed * 31 + static_cast<std::uint64_t>(i)),
                                   PurePursuit(PursuitParams{1.0, opt.ugv_speed_mps, 1.2, 0.8}), start);
    // Settle the robot on the ground (height and attitude) before the first step: otherwise the scan at
    // t = 0 would be cast from 0.6 m above the datum rather than above the terrain.
    (void)u->vehicle.step(1e-9, w);
    for (auto& part : u->scan_parts) part.reserve(static_cast<std::size_t>(16 * opt.lidar_columns));
    if (rec) {
      u->truth_log = CsvLog(t.out / ("truth_" + name + ".csv"), "t_s,x_m,y_m,z_m,roll_rad,pitch_rad,yaw_rad");
      u->odom_log = CsvLog(t.out / ("odom_" + name + ".csv"), "t_s,x_m,y_m,yaw_rad,wheel_left_rad_s,wheel_right_rad_s");
      u->scan_log = CsvLog(t.out / ("lidar_" + name + ".csv"), "t_s,scan,points");
      if (opt.record == RecordLevel::kFull) u->scan_bin = std::fopen((t.out / ("lidar_" + name + ".bin")).c_str(), "wb");
    }
    std::vector<std::string> extra_i = ugv_extra;
    if (opt.ugv_config_for) {
      const auto more = opt.ugv_config_for(i, start);
      extra_i.insert(extra_i.end(), more.begin(), more.end());
    }
    auto role = make_role(ugv_desc, ugv_role(), i + 1, name, cfgs, extra_i, "ground robot config override");
    if (!role) return role.error();
    u->role = std::move(role).value();
    u->index = i;
    ChannelRegistry& ch = u->role->channels();
    auto scan_w = ch.ring_writer<LidarScanMsg, kLidarRing>("lidar_scan");
    auto odom_w = ch.ring_writer<WheelOdometryMsg, kWheelOdometryRing>("wheel_odometry");
    auto init_w = ch.latest_writer<InitialPoseMsg>("initial_pose");
    if (!scan_w) return scan_w.error();
    if (!odom_w) return odom_w.error();
    if (!init_w) return init_w.error();
    if (!opt.gossip || opt.ugv_map != UgvMapSource::kNone) {  // else the robot's comms stage writes its map_tiles
      auto tile_w = ch.ring_writer<MapTileMsg, kMapTileRing>("map_tiles");
      if (!tile_w) return tile_w.error();
      u->tiles_out = tile_w.value();
    }
    if (static_cast<std::size_t>(i) < opt.ugv_goals.size() && opt.ugv_goals[static_cast<std::size_t>(i)].allFinite()) {
      auto goal_w = ch.latest_writer<GoalMsg>("goal");
      if (!goal_w) return goal_w.error();
      u->goal_out = goal_w.value();
      u->goal.id = 1;
      u->goal.goal = RoutePoint{opt.ugv_goals[static_cast<std::size_t>(i)].x(), opt.ugv_goals[static_cast<std::size_t>(i)].y()};
      u->goal_pending = true;
    }
    u->scan_out = scan_w.value();
    u->odom_out = odom_w.value();
    u->init_out = init_w.value();
    u->scan_msg = std::make_unique<LidarScanMsg>();
    {  // the initial guess: the true start moved init_error_m in a direction and turned by ±init_yaw_error_deg
      Rng rng(derive_seed(opt.seed, std::uint64_t{0x696E6974} + static_cast<std::uint64_t>(i)));
      const double dir = rng.uniform(-kPi, kPi);
      const double sign = rng.bernoulli(0.5) ? 1.0 : -1.0;
      const double dist = opt.init_error_uniform ? rng.uniform(0.0, opt.init_error_m) : opt.init_error_m;
      const double yaw_err = sign * opt.init_yaw_error_deg * kPi / 180.0;
      u->init_pose.pose = Pose2{start.x + dist * std::cos(dir), start.y + dist * std::sin(dir), wrap_angle(start.yaw + yaw_err)};
      u->init_pose.sigma_xy_m = std::max(opt.init_error_m, 0.5);
      u->init_pose.sigma_yaw_rad = std::max(opt.init_yaw_error_deg, 2.0) * kPi / 180.0;
      if (given != nullptr && given->has_guess) {
        u->init_pose.pose = given->guess;
        u->init_pose.sigma_xy_m = std::max(given->guess_sigma_m, 0.5);
      }
    }
    if (opt.ugv_map == UgvMapSource::kGroundTruth) u->gt_order = gt_tile_order(w, start);
    if (scripted) {
      u->scripted = true;
      u->route = densify(opt.ugv_routes[static_cast<std::size_t>(i)], 1.0);
      u->pursuit.set_path(u->route);
    }
    if (opt.ugv_map == UgvMapSource::kOnline && opt.ugv_wait_map_radius_m > 0) u->released = false;
    for (auto& slot : u->role->stages())
      if (auto* pr = dynamic_cast<SimProbeStage*>(slot.stage.get())) u->probe = pr;
    if (u->probe != nullptr) {
      u->probe->team = &t;
      u->probe->ugv = u.get();
    }
    t.ugv_roles.push_back(u->role.get());
    t.ugvs.push_back(std::move(u));
  }
  {
    // The base station's page on any free loopback port unless the caller names one (many simulations
    // run at once; the log names the port).
    std::vector<std::string> base_extra = comms_common;
    base_extra.emplace_back("web.port=0");
    base_extra.emplace_back("web.bind=127.0.0.1");
    if (opt.gossip) base_extra.emplace_back("comms.deliver_map_tiles=true");
    base_extra.emplace_back("web.log_path=" + (t.out / "mission_log.jsonl").string());
    base_extra.insert(base_extra.end(), opt.base_config.begin(), opt.base_config.end());
    auto role = make_role(base_role(), base_role(), 250, "base", cfgs, base_extra, "base station config");
    if (!role) return role.error();
    t.base = std::move(role).value();
  }

  const int threads = opt.threads > 0 ? opt.threads : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  WorkerPool pool(threads);
  t.job_cpu.assign(static_cast<std::size_t>(kCameraBands) + kScanParts * t.ugvs.size(), 0);
  t.physics_period = period_from_hz(opt.physics_hz);
  if (pool.size() > 1 && t.uav && t.camera) t.prefetch = std::make_unique<CameraPrefetch>(*t.camera, t.uav->frame);
  t.pool = &pool;
  t.camera_period = period_from_hz(opt.camera_hz);
  t.lidar_period = period_from_hz(opt.lidar_hz);
  t.heartbeat_period = period_from_hz(opt.heartbeat_hz);
  t.log_period = period_from_hz(10.0);

  // The world runs first at each release time, then the robots in table order.
  LockstepExecutor exec(clock, ExecTimer::kThreadCpu);
  PerfRegistry sim_perf;
  StagePerf& world_perf = sim_perf.add("sim/world", 0, 0);
  SimWorldStage world_stage(t);
  exec.add_stage(world_stage, world_perf, opt.physics_hz);
  if (t.uav) exec.add(*t.uav->role);
  for (auto& u : t.ugvs) exec.add(*u->role);
  exec.add(*t.base);
  // Which robot each runnable belongs to, by its channels (perf names are the stage names alone).
  std::vector<std::pair<const ChannelRegistry*, std::string>> robot_names;
  if (t.uav) robot_names.emplace_back(&t.uav->role->channels(), "uav");
  for (auto& u : t.ugvs) robot_names.emplace_back(&u->role->channels(), u->name);
  robot_names.emplace_back(&t.base->channels(), "base");
  const auto robot_of = [&robot_names](const Runnable& r) {
    for (const auto& [ch, name] : robot_names)
      if (ch == r.channels) return name;
    return std::string{};
  };
  ComputeTime compute(opt.compute_time, exec.runnables(), robot_of, [&opt](std::string_view robot) { return opt.target_of(robot); });
  if (opt.step_sampler) compute.set_sampler(opt.step_sampler);
  compute.attach(exec);
  // Robots side by side on the sensor workers: they share nothing but the radio (sends deferred to the
  // end of each release time, in node order) and the sampling callback (likewise, in robot order), so
  // the run is the serial one bit for bit. Not with channel taps: those hand out messages in place.
  t.parallel_robots = opt.parallel_robots && pool.size() > 1 && !opt.ugv_tap.any();
  if (t.parallel_robots) {
    if (t.net) t.net->set_deferred(true);
    exec.set_parallel(
        [](void* user, std::size_t jobs, LockstepExecutor::JobFn job, void* job_user) {
          const std::function<void(std::size_t)> fn = [job, job_user](std::size_t j) { job(job_user, j); };
          static_cast<Team*>(user)->pool->run(jobs, fn);
        },
        [](void* user) {
          Team& tm = *static_cast<Team*>(user);
          if (tm.net) tm.net->flush();
          for (auto& u : tm.ugvs)
            if (u->has_pending_sample) {
              u->has_pending_sample = false;
              tm.opt.sample(u->pending_sample);
            }
        },
        &t);
  }
  if (opt.record != RecordLevel::kNone && opt.record_mcap) {
    TeamRecordingOptions ro;
    ro.scheduler_period_s = opt.record_scheduler_period_s;
    ro.lidar_mount_height_m = opt.lidar_mount_height_m;
    auto recording = TeamRecording::open((t.out / "recording.mcap").string(), *t.world, t.uav != nullptr, static_cast<int>(t.ugvs.size()), opt.seed, ro);
    if (!recording) return recording.error();
    t.mcap = std::move(recording).value();
    std::vector<std::pair<std::string, RoleInstance*>> roles;
    if (t.uav) roles.emplace_back("uav", t.uav->role.get());
    for (auto& u : t.ugvs) roles.emplace_back(u->name, u->role.get());
    roles.emplace_back("base", t.base.get());
    const auto* om = t.uav ? find_stage<mapping::OrthoMapStage>(t.uav->role.get()) : nullptr;
    t.mcap->watch(std::move(roles), om != nullptr ? &om->map() : nullptr);
  }
  exec.start(0);

  const double duration_s = opt.duration_survey_factor > 0 && opt.uav ? std::max(opt.duration_s, opt.duration_survey_factor * survey_time_s)
                                                                    : opt.duration_s;
  const TimeNs end = from_seconds(duration_s);
  TimeNs chunk = std::max<TimeNs>(kNsPerS / 10, end / 100);
  if (opt.stop_when_survey_done || opt.stop_when_routes_done) chunk = std::min<TimeNs>(chunk, 2 * kNsPerS);
  if (opt.stop_when) chunk = std::min<TimeNs>(chunk, kNsPerS);
  const auto wall0 = std::chrono::steady_clock::now();
  const double process_cpu0 = process_cpu_seconds();
  TimeNs ended = end;
  for (TimeNs tt = 0; tt < end;) {
    tt = std::min(end, tt + chunk);
    exec.run_until(tt);
    if (opt.stop_when_survey_done && t.uav && t.uav->vehicle.finished()) {
      ended = tt;
      break;
    }
    if (opt.stop_when && opt.stop_when(tt, !t.uav || t.uav->vehicle.finished())) {
      ended = tt;
      break;
    }
    if (opt.stop_when_routes_done) {
      bool all = false;
      for (const auto& u : t.ugvs) {
        if (!u->scripted) continue;
        all = u->route_done;
        if (!all) break;
      }
      if (all) {
        ended = tt;
        break;
      }
    }
    if (progress) {
      const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
      progress(to_seconds(tt), duration_s, wall > 0 ? to_seconds(tt) / wall : 0);
    }
  }
  const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();

  RunSummary s;
  s.sim_s = to_seconds(ended);
  s.uav_route_estimate_s = survey_time_s;
  s.duration_cap_s = duration_s;
  s.wall_s = wall_s;
  s.real_time_factor = wall_s > 0 ? s.sim_s / wall_s : 0;
  s.process_cpu_s = process_cpu_seconds() - process_cpu0;
  s.camera_cpu_s = to_seconds(t.camera_cpu + (t.prefetch ? t.prefetch->cpu_ns() : 0));
  s.camera_frames_ahead = t.frames_ahead;
  s.lidar_cpu_s = to_seconds(t.lidar_cpu);
  s.sensor_cpu_s = s.camera_cpu_s + s.lidar_cpu_s;
  const auto stages_cpu = [](RoleInstance& role) {
    TimeNs sum = 0;
    for (std::size_t i = 0; i < role.perf().size(); ++i) sum += role.perf().at(i).exec_total.load(std::memory_order_relaxed);
    return to_seconds(sum);
  };
  if (t.uav) s.robot_cpu_s.emplace_back("uav", stages_cpu(*t.uav->role));
  for (auto& u : t.ugvs) s.robot_cpu_s.emplace_back(u->name, stages_cpu(*u->role));
  if (t.base) s.robot_cpu_s.emplace_back("base", stages_cpu(*t.base));
  if (t.uav) {
    s.camera_frames = t.uav->frames;
    s.gps_fixes = t.uav->fixes;
    s.vo_samples = t.uav->vo_samples;
    s.vo_segments = t.uav->segments;
    s.uav_distance_m = t.uav->vehicle.distance_flown();
    s.uav_waypoints_reached = t.uav->vehicle.waypoints_reached();
  }
  const LinkStats tot = t.air->total();
  s.radio_sent = tot.sent;
  s.radio_delivered = tot.delivered;
  s.radio_dropped_range = tot.dropped_range;
  s.radio_dropped_loss = tot.dropped_loss;
  s.radio_dropped_queue = tot.dropped_queue;
  s.radio_bytes_sent = tot.bytes_sent;
  s.radio_bytes_delivered = tot.bytes_delivered;
  s.compute_time = std::string(compute_time_name(opt.compute_time));
  for (const auto& r : exec.runnables()) {
    if (r.perf == &world_perf) continue;
    const StagePerf& p = *r.perf;
    s.stage_overruns += p.overruns.load();
    s.stage_slips += p.slips.load();
    s.stages.push_back({robot_of(r) + "/" + p.name, p.runs.load(), p.overruns.load(), p.slips.load(), static_cast<double>(p.exec.quantile(0.99)) / 1e6,
                        static_cast<double>(r.budget) / 1e6});
  }
  for (auto& up : t.ugvs) {
    Ugv& u = *up;
    RobotSummary r;
    r.name = u.name;
    r.distance_m = u.vehicle.distance_travelled();
    r.collisions = u.vehicle.collisions();
    r.goals_reached = u.goals_reached;
    r.scans = u.scans;
    r.odometry_samples = u.odom_samples;
    // Odometry starts at the robot's start pose in its own frame: put it into the map frame to compare.
    const double c = std::cos(u.start.yaw), sn = std::sin(u.start.yaw);
    const double ox = u.start.x + c * u.odom_last.x - sn * u.odom_last.y;
    const double oy = u.start.y + sn * u.odom_last.x + c * u.odom_last.y;
    r.odometry_final_error_m = std::hypot(ox - u.vehicle.pose().x, oy - u.vehicle.pose().y);
    r.scans_published = u.scans_published;
    r.odometry_published = u.odom_published;
    r.tiles_published = u.tiles_published;
    r.tiles_refused = u.tiles_refused;
    r.channel_drops = u.channel_drops;
    r.initial_pose_published = u.init_published;
    r.released_s = u.released ? to_seconds(u.released_at) : -1.0;
    r.route_done = u.route_done;
    r.killed_s = u.killed ? to_seconds(u.killed_at) : -1.0;
    r.wheel_commands = u.wheel_commands;
    if (u.probe != nullptr && u.probe->received()) {
      static constexpr const char* kNames[] = {"no map", "initialising", "tracking", "lost"};
      r.loc_status = kNames[static_cast<int>(u.loc_last) & 3];
    }
    r.loc_tracking_fraction = u.loc_samples > 0 ? static_cast<double>(u.loc_tracking) / static_cast<double>(u.loc_samples) : 0.0;
    r.loc_first_tracking_s = u.loc_first_tracking >= 0 ? to_seconds(u.loc_first_tracking) : -1.0;
    if (!u.loc_errors.empty()) {
      std::vector<float> e = u.loc_errors;
      std::sort(e.begin(), e.end());
      double sum = 0;
      for (const float v : e) sum += static_cast<double>(v);
      r.loc_error_mean_m = sum / static_cast<double>(e.size());
      r.loc_error_p95_m = static_cast<double>(e[std::min(e.size() - 1, static_cast<std::size_t>(std::ceil(0.95 * static_cast<double>(e.size()))) - 1)]);
      r.loc_error_max_m = static_cast<double>(e.back());
    }
    s.ugvs.push_back(r);
    if (u.scan_bin != nullptr) std::fclose(u.scan_bin);
    u.scan_bin = nullptr;
  }
  if (opt.inspect) {
    const GridGeometry& g = w.grid();
    RunInspection in{w};
    in.uav = t.uav ? t.uav->role.get() : nullptr;
    in.uav_truth = t.uav ? &t.uav->truth : nullptr;
    in.vo_scale = t.uav && t.uav->vo_oracle ? t.uav->vo.scale() : 0.0;  // unknown for the robot's own VO
    in.vo_segments = s.vo_segments;
    in.vo_tracking_losses = t.uav && t.uav->vo_oracle ? t.uav->vo.tracking_losses() : (t.uav && t.uav->segments > 0 ? t.uav->segments - 1 : 0);
    in.survey_x0 = g.origin_x + opt.survey_margin_m;
    in.survey_y0 = g.origin_y - g.size_y() + opt.survey_margin_m;
    in.survey_x1 = g.origin_x + g.size_x() - opt.survey_margin_m;
    in.survey_y1 = g.origin_y - opt.survey_margin_m;
    in.role_configs = &cfgs;
    if (auto st = opt.inspect(in); !st) return st.error();
  }
  if (t.mcap) {
    if (auto st = t.mcap->close(s.sim_s); !st) return st.error();
    s.recording_messages = t.mcap->stats().messages;
    s.recording_bytes = t.mcap->stats().bytes;
  }
  if (auto st = write_reports(t, s); !st) return st.error();
  return s;
}

std::string_view shipped_config_yaml(std::string_view role) noexcept {
  if (role == "uav") return shipped::k_uav_yaml;
  if (role == "ugv") return shipped::k_ugv_yaml;
  if (role == "base") return shipped::k_base_yaml;
  return {};
}

}  // namespace ag::sim
