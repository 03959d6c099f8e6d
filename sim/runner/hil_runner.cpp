// airground-sim hil: the world served over the devices' wire protocols to the real role processes.
// Two threads: the physics thread (200 Hz: the ODrive controllers on the CAN bridge, the bases, the
// quadrotor) must never stall, or a robot sees its controllers fall silent; the sensor thread (this
// one) renders and sends what is due (GPS, VO, camera, LiDAR) and watches the mission through the base.
#include "airground/sim/hil.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <termios.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <deque>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <thread>

#include "airground/core/messages.hpp"
#include "airground/drivers/base/diff_drive_base.hpp"
#include "airground/drivers/base/odrive_sim.hpp"
#include "airground/drivers/camera/frame_stream.hpp"
#include "airground/drivers/can/cannelloni.hpp"
#include "airground/drivers/ouster/frame.hpp"
#include "airground/drivers/ouster/metadata.hpp"
#include "airground/drivers/ouster/packet_format.hpp"
#include "airground/drivers/ublox/ubx.hpp"
#include "airground/mission/mission_file.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/log.hpp"
#include "airground/platform/role_instance.hpp"
#include "airground/platform/time.hpp"
#include "airground/sim/camera.hpp"
#include "airground/sim/diff_drive.hpp"
#include "airground/sim/gps.hpp"
#include "airground/sim/lidar.hpp"
#include "airground/sim/quadrotor.hpp"
#include "airground/core/geometry.hpp"
#include "airground/platform/rng.hpp"
#include "airground/sim/runner.hpp"
#include "airground/sim/survey.hpp"
#include "airground/sim/visual_odometry.hpp"
#include "airground/sim/world_png.hpp"
#include "roles.hpp"
#include "sensor_labels_check.hpp"
#include "team_recording.hpp"
#include "worker_pool.hpp"

namespace ag::sim {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

// A port nobody holds right now (the kernel's choice; the tiny race with another process is accepted).
Result<std::uint16_t> free_port(int type) {
  const int fd = ::socket(AF_INET, type, 0);
  if (fd < 0) return Error::make(ErrorCode::kIo, std::string("socket: ") + std::strerror(errno));
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof a;
  if (::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 || ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) != 0) {
    ::close(fd);
    return Error::make(ErrorCode::kIo, std::string("bind: ") + std::strerror(errno));
  }
  ::close(fd);
  return static_cast<std::uint16_t>(ntohs(a.sin_port));
}

// The Ouster reflectivity byte of a surface (calibrated reflectivity, 0-100 for diffuse targets): the
// world's albedo under the point, grey, scaled to 0-100; 0 outside the world.
std::uint8_t albedo_reflectivity(const World& w, double x, double y) noexcept {
  const GridGeometry& g = w.header.grid;
  const auto c = g.col(x), r = g.row(y);
  if (!g.contains(c, r) || w.albedo.empty()) return 0;
  const cv::Vec3b a = w.albedo.at<cv::Vec3b>(r, c);
  return static_cast<std::uint8_t>((static_cast<int>(a[0]) + static_cast<int>(a[1]) + static_cast<int>(a[2])) * 100 / (3 * 255));
}

// The shipped ErfNet weights where the package installs them, else the source tree's copy.
std::string hil_erfnet_weights() {
  const std::string installed = "/usr/share/airground/erfnet_c7.agw";
  std::error_code ec;
  return fs::exists(installed, ec) ? installed : std::string(AG_SOURCE_DIR) + "/config/erfnet/erfnet_c7.agw";
}

// One role's YAML: its shipped configuration (built in from firmware_host/<role>/<role>.yaml) with the
// "section.key=value" pairs the simulator must set, every key written out.
Status write_role_yaml(const fs::path& path, const std::string& title, const RoleDescription& role,
                       const std::vector<std::pair<std::string, std::string>>& kv) {
  const std::string origin = "firmware_host/" + std::string(role.name) + "/" + std::string(role.name) + ".yaml (built into airground-sim)";
  auto c = Config::load_string(role_schema(role), shipped_config_yaml(role.name), origin);
  if (!c) return c.error();
  for (const auto& [k, v] : kv)
    if (auto st = c.value().set(k + "=" + v, "airground-sim hil"); !st) return st.error();
  if (auto st = check_sensor_labels(c.value(), origin + " with airground-sim hil's settings"); !st) return st.error();
  std::ofstream f(path);
  f << "# " << title << " — written by airground-sim hil: the shipped " << role.name << ".yaml and the keys the simulator sets\n"
    << c.value().to_yaml();
  if (!f) return Error::make(ErrorCode::kIo, "cannot write " + path.string());
  return ok_status();
}


std::string num(double v) {
  char b[64];
  std::snprintf(b, sizeof b, "%.6f", v);
  return b;
}
std::string fixed(double v, int digits) {
  char b[64];
  std::snprintf(b, sizeof b, "%.*f", digits, v);
  return b;
}

struct Child {
  std::string name, role;
  pid_t pid{-1};
  fs::path log;
  int exit_code{-1};
  bool exited{false};
};

Result<pid_t> spawn(const std::vector<std::string>& argv, const fs::path& log) {
  const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return Error::make(ErrorCode::kIo, "cannot open " + log.string() + ": " + std::strerror(errno));
  std::vector<char*> args;
  for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  const pid_t pid = ::fork();
  if (pid < 0) {
    ::close(fd);
    return Error::make(ErrorCode::kIo, std::string("fork: ") + std::strerror(errno));
  }
  if (pid == 0) {
    ::dup2(fd, 1);
    ::dup2(fd, 2);
    ::setpgid(0, 0);  // our Ctrl-C is ours to pass on, in order
    ::execv(args[0], args.data());
    std::fprintf(stderr, "exec %s: %s\n", args[0], std::strerror(errno));
    ::_exit(127);
  }
  ::close(fd);
  return pid;
}

// GET http://127.0.0.1:port/path with a short timeout; empty on any failure (the base may be starting).
std::string http_get(std::uint16_t port, const char* path) {
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return {};
  timeval tv{1, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  ::setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  std::string out;
  if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0) {
    const std::string req = std::string("GET ") + path + " HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n";
    if (::send(fd, req.data(), req.size(), MSG_NOSIGNAL) == static_cast<ssize_t>(req.size())) {
      char buf[65536];
      for (;;) {
        const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
        if (n <= 0) break;
        out.append(buf, static_cast<std::size_t>(n));
      }
    }
  }
  ::close(fd);
  const auto body = out.find("\r\n\r\n");
  return body == std::string::npos ? std::string() : out.substr(body + 4);
}

struct HilUgv {
  HilUgv(std::string n, int i, DiffDriveRobot v) : name(std::move(n)), id(i), vehicle(std::move(v)) {}
  std::string name;
  int id{1};
  DiffDriveRobot vehicle;
  std::unique_ptr<can::CannelloniBus> bus;
  std::unique_ptr<base::OdriveSimulator> odrive;
  base::BaseParams bp;
  int udp{-1};
  sockaddr_in lidar_to{};
  ouster::SensorInfo info;
  std::unique_ptr<ouster::PacketFormat> fmt;
  ouster::LidarFrame frame;
  std::vector<LidarPoint> scan;
  std::uint16_t frame_id{0};
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

}  // namespace

Result<HilResult> run_hil(const HilOptions& opt) {
  if (opt.mission_file.empty()) return Error::make(ErrorCode::kInvalidArgument, "hil needs --mission FILE.yaml");
  auto mf_r = mission::load_mission_file(opt.mission_file);
  if (!mf_r) return mf_r.error();
  const mission::MissionFile mf = std::move(mf_r).value();
  if (mf.team.empty()) return Error::make(ErrorCode::kConfig, opt.mission_file + ": the team has no ground robot");
  auto world_r = resolve_world(opt.world);
  if (!world_r) return world_r.error();
  const std::shared_ptr<const World> world = world_r.value();
  const World& w = *world;
  const fs::path out(opt.out_dir);
  std::error_code ec;
  for (const char* d : {"config", "logs"}) fs::create_directories(out / d, ec);
  if (ec) return Error::make(ErrorCode::kIo, "cannot create " + out.string() + ": " + ec.message());
  // Installed, the role binaries sit beside airground-sim; in the build tree, in firmware_host/.
  fs::path bin = opt.bin_dir;
  if (bin.empty()) {
    const fs::path self = fs::read_symlink("/proc/self/exe", ec).parent_path();
    bin = fs::exists(self / "airground-ugv") ? self : self.parent_path() / "firmware_host";
  }
  for (const char* b : {"airground-uav", "airground-ugv", "airground-base"})
    if (!fs::exists(bin / b))
      return Error::make(ErrorCode::kIo, (bin / b).string() + " not found (build the role binaries, or give --bin-dir)");

  // The team key, as an operator would make it.
  const fs::path key = out / "config" / "team.key";
  if (auto st = write_team_key(key.string(), derive_seed(opt.seed, std::uint64_t{0x68696C})); !st) return st.error();

  // Ports: gossip per process, lidar + IMU per ground robot, the CAN bridge's two ends per ground robot, the page.
  const int n = static_cast<int>(mf.team.size());
  auto port = [](int type) -> std::uint16_t {
    auto p = free_port(type);
    return p ? p.value() : 0;
  };
  std::vector<std::uint16_t> gossip(static_cast<std::size_t>(n) + 2);
  for (auto& p : gossip) p = port(SOCK_DGRAM);
  const std::uint16_t web_port = port(SOCK_STREAM);
  auto peers_except = [&](std::size_t self) {
    std::string s;
    for (std::size_t i = 0; i < gossip.size(); ++i)
      if (i != self) s += (s.empty() ? "" : ",") + std::string("127.0.0.1:") + std::to_string(gossip[i]);
    return s;
  };
  auto common = [&](int id, const std::string& name, std::size_t node) {
    // Real-time scheduling off: on a desk machine SCHED_FIFO stages would starve the simulator itself.
    return std::vector<std::pair<std::string, std::string>>{
        {"robot.id", std::to_string(id)}, {"robot.name", name}, {"scheduler.realtime", "false"}, {"scheduler.lock_memory", "false"},
        {"scheduler.pin_cpus", "false"}, {"status.log_every", "10"}, {"comms.transport", "udp"}, {"comms.key_file", key.string()},
        {"comms.journal", ""}, {"comms.port", std::to_string(gossip[node])}, {"comms.broadcast", ""}, {"comms.peers", peers_except(node)}};
  };
  const GridGeometry& g = w.grid();
  const double ax0 = g.origin_x, ay0 = g.origin_y - g.size_y(), ax1 = g.origin_x + g.size_x(), ay1 = g.origin_y;
  const mission::Area area = mf.area.x1 > mf.area.x0 ? mf.area : mission::Area{ax0, ay0, ax1, ay1};

  // The sensor models (the simulator's defaults, as the lockstep runner uses them).
  const CameraModel cam_model = CameraModel{}.scaled(0.5);
  const DiffDriveConfig dd;
  const GpsConfig gps_cfg;
  const VoConfig vo_cfg;
  const QuadrotorConfig quad_cfg;
  // The Ouster metadata every ground robot's driver reads: the OS-1-64 of the fixture, in the chosen
  // packet profile (every profile has at least 8-bit reflectivity: the class id) at the chosen lidar mode.
  json meta;
  {
    std::ifstream mf_in(OusterBeamModel::default_metadata_path());
    if (!mf_in) return Error::make(ErrorCode::kIo, "cannot read " + OusterBeamModel::default_metadata_path());
    try {
      mf_in >> meta;
    } catch (const std::exception& e) {
      return Error::make(ErrorCode::kMalformed, OusterBeamModel::default_metadata_path() + ": " + e.what());
    }
  }
  if (opt.lidar_columns != 512 && opt.lidar_columns != 1024 && opt.lidar_columns != 2048)
    return Error::make(ErrorCode::kInvalidArgument, "--lidar-columns must be 512, 1024 or 2048");
  meta["lidar_mode"] = std::to_string(opt.lidar_columns) + "x10";
  if (auto p = ouster::parse_udp_profile(opt.lidar_profile); !p)
    return Error::make(ErrorCode::kInvalidArgument, "--lidar-profile: " + p.error().message);
  meta["udp_profile_lidar"] = opt.lidar_profile;
  if (meta.contains("data_format")) {
    meta["data_format"]["udp_profile_lidar"] = opt.lidar_profile;
    meta["data_format"]["columns_per_frame"] = opt.lidar_columns;
    meta["data_format"]["column_window"] = json::array({0, opt.lidar_columns - 1});
  }

  std::vector<Child> children;
  std::vector<std::unique_ptr<HilUgv>> ugvs;
  HilResult res;
  const bool labels_oracle = std::find(opt.oracles.begin(), opt.oracles.end(), "labels") != opt.oracles.end();
  std::vector<std::pair<std::string, std::string>> ugv_kv_common = {
      // The Ouster gives no class: the shipped geometric labeller, or the truth in the reflectivity byte.
      {"localization.labels", labels_oracle ? "gt" : "geometric"},
      {"localization.area_x0_m", num(ax0)}, {"localization.area_y0_m", num(ay0)}, {"localization.area_x1_m", num(ax1)}, {"localization.area_y1_m", num(ay1)},
      {"planner.area_x0_m", num(ax0)}, {"planner.area_y0_m", num(ay0)}, {"planner.area_x1_m", num(ax1)}, {"planner.area_y1_m", num(ay1)},
      {"drive.track_m", num(dd.track_width_m)},
      {"base.can_backend", "cannelloni"}, {"base.estop_backend", "none"}, {"base.led_backend", "none"}, {"base.start_armed", "true"},
      {"base.wheel_radius_m", num(dd.wheel_radius_m)}, {"base.track_m", num(dd.track_width_m)},
      {"mission.visit_radius_m", num(mf.params.visit_radius_m)}, {"mission.max_sigma_m", num(mf.params.max_sigma_m)},
      {"mission.claim_timeout_s", num(mf.params.claim_timeout_s)}, {"mission.idle_return_s", num(mf.params.idle_return_s)},
      {"mission.mission_end_s", num(mf.params.mission_end_s)},
      {"mission.survey_end_s", num(mf.params.survey_end_s)}, {"comms.send_pose", "true"}, {"comms.deliver_map_tiles", "true"}};

  for (int i = 0; i < n; ++i) {
    const mission::TeamMember& tm = mf.team[static_cast<std::size_t>(i)];
    auto u = std::make_unique<HilUgv>("ugv" + std::to_string(tm.id), tm.id, DiffDriveRobot(dd, Pose2{tm.start_x, tm.start_y, tm.start_yaw}));
    const std::uint16_t lidar_port = port(SOCK_DGRAM), imu_port = port(SOCK_DGRAM), can_robot = port(SOCK_DGRAM), can_sim = port(SOCK_DGRAM);
    json m = meta;
    m["udp_port_lidar"] = lidar_port;
    m["udp_port_imu"] = imu_port;
    const fs::path meta_path = out / "config" / ("ouster-" + u->name + ".json");
    std::ofstream(meta_path) << m.dump(2) << "\n";
    auto info = ouster::read_metadata_file(meta_path.string());
    if (!info) return info.error();
    u->info = info.value();
    u->fmt = std::make_unique<ouster::PacketFormat>(u->info);
    u->frame = ouster::LidarFrame(u->info.mode.columns, static_cast<int>(u->info.beam_altitude_deg.size()),
                                  ouster::has_second_return(u->info.profile));
    u->udp = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
    int sndbuf = 4 << 20;
    ::setsockopt(u->udp, SOL_SOCKET, SO_SNDBUF, &sndbuf, sizeof sndbuf);
    u->lidar_to.sin_family = AF_INET;
    u->lidar_to.sin_port = htons(lidar_port);
    u->lidar_to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    can::CannelloniConfig cc;
    cc.bind_address = "127.0.0.1";
    cc.local_port = can_sim;
    cc.remote_port = can_robot;
    auto bus = can::CannelloniBus::open(cc);
    if (!bus) return bus.error();
    u->bus = std::move(bus).value();
    u->bp = base::BaseParams{};
    u->odrive = std::make_unique<base::OdriveSimulator>(*u->bus, std::array<std::uint8_t, 2>{u->bp.left_node, u->bp.right_node});
    u->last_pose = u->vehicle.pose();

    auto kv = common(tm.id, u->name, static_cast<std::size_t>(1 + i));
    kv.insert(kv.end(), ugv_kv_common.begin(), ugv_kv_common.end());
    for (const auto& p : std::vector<std::pair<std::string, std::string>>{
             {"lidar.source", "udp"}, {"lidar.metadata", meta_path.string()}, {"lidar.bind_address", "127.0.0.1"},
             {"lidar.mount_z_m", num(opt.lidar_mount_height_m)}, {"lidar.classes", labels_oracle ? "reflectivity" : "none"},
             {"localization.set_initial_pose", "true"}, {"localization.initial_x_m", num(tm.guess_x)}, {"localization.initial_y_m", num(tm.guess_y)},
             {"localization.initial_yaw_rad", num(tm.guess_yaw)}, {"localization.initial_sigma_m", num(std::max(0.5, tm.guess_sigma_m))},
             {"base.can_bridge_port", std::to_string(can_robot)}, {"base.can_bridge_remote", "127.0.0.1:" + std::to_string(can_sim)},
             {"base.can_record_path", (out / "logs" / ("can-" + u->name + ".log")).string()},
             {"base.odometry_log_path", (out / "logs" / ("odometry-" + u->name + ".csv")).string()},
             {"mission.priority", std::to_string(tm.priority)}, {"mission.start_x_m", num(tm.start_x)}, {"mission.start_y_m", num(tm.start_y)}})
      kv.push_back(p);
    if (mf.type == mission::MissionType::kWaypoints && !tm.waypoints.empty()) {
      std::string wp;
      for (std::size_t k = 0; k < tm.waypoints.size(); ++k) wp += (k ? ";" : "") + num(tm.waypoints[k].x) + "," + num(tm.waypoints[k].y);
      kv.emplace_back("mission.waypoints", wp);
    }
    const fs::path cfg = out / "config" / (u->name + ".yaml");
    if (auto st = write_role_yaml(cfg, u->name + " (ground robot " + std::to_string(tm.id) + ")", ugv_role(), kv); !st) return st.error();
    children.push_back(Child{u->name, "ugv", -1, out / "logs" / (u->name + ".log")});
    ugvs.push_back(std::move(u));
  }

  // The quadrotor's serial port: a pseudo-terminal in raw mode (no echo, no line discipline).
  const int pty = ::posix_openpt(O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (pty < 0 || ::grantpt(pty) != 0 || ::unlockpt(pty) != 0) return Error::make(ErrorCode::kIo, std::string("pseudo-terminal: ") + std::strerror(errno));
  const std::string pty_path = ::ptsname(pty);
  const int pty_slave = ::open(pty_path.c_str(), O_RDWR | O_NOCTTY | O_CLOEXEC);  // held open: no hang-up while the robot reopens
  if (pty_slave >= 0) {
    termios tio{};
    ::tcgetattr(pty_slave, &tio);
    ::cfmakeraw(&tio);
    ::tcsetattr(pty_slave, TCSANOW, &tio);
  }
  fs::remove(out / "gps.pty", ec);
  fs::create_symlink(pty_path, out / "gps.pty", ec);
  // The camera's frame stream: a FIFO the uav's camera stage reads.
  const fs::path fifo = out / "camera.agfs";
  fs::remove(fifo, ec);
  if (::mkfifo(fifo.c_str(), 0600) != 0) return Error::make(ErrorCode::kIo, "mkfifo " + fifo.string() + ": " + std::strerror(errno));
  {
    auto kv = common(0, "uav", 0);
    for (const auto& p : std::vector<std::pair<std::string, std::string>>{
             {"gps.source", "serial"}, {"gps.device", pty_path}, {"gps.datum_lat_deg", num(w.header.datum.lat_deg)},
             {"gps.datum_lon_deg", num(w.header.datum.lon_deg)}, {"gps.datum_height_m", num(w.header.datum.height_m)},
             {"camera.source", "replay"}, {"camera.replay", fifo.string()}, {"camera.stamps", "record"},
             // HIL still hands the pose graph the simulator's odometry (an oracle, in the frame stream); the
             // robot's own VO runs beside it on the same frames, on a channel nobody reads.
             {"camera.vo_channel", "visual_odometry"}, {"vo.output_channel", "visual_odometry_own"},
             // ErfNet with the shipped weights (the source tree's copy when not installed), or the frames' true classes.
             {"segmentation.labels", labels_oracle ? "gt" : "erfnet"}, {"segmentation.weights", hil_erfnet_weights()},
             {"comms.send_map_tiles", "true"},
             {"regions.area_x0_m", num(ax0)}, {"regions.area_y0_m", num(ay0)}, {"regions.area_x1_m", num(ax1)}, {"regions.area_y1_m", num(ay1)},
             {"regions.merge_distance_m", num(mf.params.merge_distance_m)}, {"regions.min_region_cells", std::to_string(mf.params.min_region_cells)}})
      kv.push_back(p);
    if (auto st = write_role_yaml(out / "config" / "uav.yaml", "uav (quadrotor)", uav_role(), kv); !st) return st.error();
    children.insert(children.begin(), Child{"uav", "uav", -1, out / "logs" / "uav.log"});
  }
  {
    auto kv = common(250, "base", static_cast<std::size_t>(n) + 1);
    kv.emplace_back("comms.deliver_map_tiles", "true");
    kv.emplace_back("web.port", std::to_string(web_port));
    kv.emplace_back("web.bind", "127.0.0.1");
    kv.emplace_back("web.log_path", (out / "mission.jsonl").string());
    if (auto st = write_role_yaml(out / "config" / "base.yaml", "base station", base_role(), kv); !st) return st.error();
    children.push_back(Child{"base", "base", -1, out / "logs" / "base.log"});
  }
  fs::remove(out / "mission.jsonl", ec);

  // The quadrotor: the survey of the mission file, from the first ground robot's start.
  const mission::TeamMember& lead = mf.team.front();
  const float z0 = w.terrain.at<float>(g.row(lead.start_y), g.col(lead.start_x));
  Quadrotor quad(quad_cfg, Pose3{lead.start_x, lead.start_y, z0, 0, 0, 0});
  {
    SurveyOptions so;
    so.speed_mps = mf.survey.speed_mps;
    const double hfov = 2.0 * std::atan(0.5 * cam_model.width / cam_model.fx);
    const mission::Area& sa = mf.survey.area.x1 > mf.survey.area.x0 ? mf.survey.area : area;
    auto route = survey_lawnmower(sa.x0, sa.y0, sa.x1, sa.y1, mf.survey.altitude_m, mf.survey.overlap, hfov, so);
    if (!route) return route.error();
    quad.set_waypoints(std::move(route).value());
  }
  GpsSimulator gps(gps_cfg, w.header.datum, opt.seed ^ std::uint64_t{0x67707331});
  VisualOdometrySimulator vo(vo_cfg, opt.seed ^ std::uint64_t{0x766f3031});
  auto raycaster = std::make_shared<HeightfieldRaycaster>(w);
  CameraRenderer camera(w, cam_model, CameraShading{}, raycaster);
  auto beams = OusterBeamModel::from_metadata_json((out / "config" / ("ouster-" + ugvs.front()->name + ".json")).string(), opt.lidar_columns);
  if (!beams) return beams.error();
  LidarSimulator lidar(w, beams.value(), LidarNoise{}, raycaster);

  // Start the robots: base first (it only listens), then the ground robots, then the quadrotor.
  std::vector<std::size_t> order;
  for (std::size_t i = 0; i < children.size(); ++i)
    if (children[i].role == "base") order.push_back(i);
  for (std::size_t i = 0; i < children.size(); ++i)
    if (children[i].role == "ugv") order.push_back(i);
  for (std::size_t i = 0; i < children.size(); ++i)
    if (children[i].role == "uav") order.push_back(i);
  auto stop_all = [&](int sig) {
    for (Child& c : children)
      if (c.pid > 0 && !c.exited) ::kill(c.pid, sig);
  };
  for (std::size_t i : order) {
    Child& c = children[i];
    const fs::path cfg = out / "config" / (c.name + ".yaml");
    auto pid = spawn({(bin / ("airground-" + c.role)).string(), "--config", cfg.string()}, c.log);
    if (!pid) {
      stop_all(SIGTERM);
      return pid.error();
    }
    c.pid = pid.value();
  }
  if (opt.progress)
    std::fprintf(stderr, "hil: %zu processes started (base page http://127.0.0.1:%u/); configs and logs in %s\n", children.size(),
                 static_cast<unsigned>(web_port), out.c_str());

  std::atomic<std::uint64_t> cam_written{0}, cam_dropped{0}, cam_skipped{0}, vo_written{0};
  // recording.mcap: the truth, the poses the base heard, GPS, LiDAR and camera frames; log times from
  // here on (wall clock: HIL runs in real time), written by the sensor loop and the camera thread in turn.
  std::unique_ptr<TeamRecording> rec;
  std::mutex rec_mu;
  const TimeNs rec0 = monotonic_now();
  if (opt.record) {
    TeamRecordingOptions ro;
    ro.scheduler_period_s = 0;  // the robots' stages run in their own processes (their hil_report.md timing)
    ro.mission = false;
    ro.lidar_mount_height_m = opt.lidar_mount_height_m;
    auto r = TeamRecording::open((out / "recording.mcap").string(), w, true, static_cast<int>(ugvs.size()), opt.seed, ro);
    if (!r) {
      stop_all(SIGTERM);
      return r.error();
    }
    rec = std::move(r).value();
  }
  // Physics thread.
  std::mutex mu;
  std::atomic<bool> stop{false};
  std::thread physics([&] {
    TimeNs last = monotonic_now();
    TimeNs next = last;
    while (!stop.load(std::memory_order_relaxed)) {
      next += 5 * kNsPerMs;
      timespec ts{static_cast<time_t>(next / kNsPerS), static_cast<long>(next % kNsPerS)};
      ::clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
      const TimeNs now = monotonic_now();
      const double dt = to_seconds(now - last);
      last = now;
      std::lock_guard<std::mutex> lk(mu);
      for (auto& up : ugvs) {
        HilUgv& u = *up;
        u.odrive->step(now);
        constexpr double kTwoPi = 2.0 * M_PI;
        const double l = u.bp.left_sign * u.odrive->vel_turns_s(0) * kTwoPi / u.bp.gear_ratio;
        const double r = u.bp.right_sign * u.odrive->vel_turns_s(1) * kTwoPi / u.bp.gear_ratio;
        u.vehicle.command_wheels(l, r);
        if (u.vehicle.step(dt, w)) ++u.collisions;
        const Pose2 p = u.vehicle.pose();
        u.distance_m += std::hypot(p.x - u.last_pose.x, p.y - u.last_pose.y);
        u.last_pose = p;
      }
      quad.step(dt);
    }
  });

  // Camera thread: renders a frame every 1/camera_hz (or as fast as it can) and writes it, after the VO
  // queued since the last one, to the frame stream (opened once the uav reads the FIFO). On its own
  // thread so a slow render never holds back the LiDAR or the GNSS.
  std::mutex vo_mu;
  std::deque<VoMsg> vo_queue;
  std::atomic<bool> stop_camera{false};
  std::thread camera_thread([&] {
    std::optional<camera::FrameStreamWriter> frames;
    auto image = std::make_unique<CameraImageMsg>();
    CameraFrame cf;
    std::uint32_t image_seq = 0;
    const TimeNs period = static_cast<TimeNs>(1e9 / opt.camera_hz);
    TimeNs next = monotonic_now() + kNsPerS;
    std::vector<VoMsg> vo_out;
    WorkerPool cam_pool(2);
    std::uint64_t rendered = 0;
    while (!stop_camera.load(std::memory_order_relaxed)) {
      timespec ts{static_cast<time_t>(next / kNsPerS), static_cast<long>(next % kNsPerS)};
      ::clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
      if (stop_camera.load(std::memory_order_relaxed)) break;
      const TimeNs now = monotonic_now();
      next += period;
      if (next < now) {
        cam_skipped.fetch_add(static_cast<std::uint64_t>((now - next) / period) + 1, std::memory_order_relaxed);
        next = now + period;
      }
      if (!frames) {
        const int fd = ::open(fifo.c_str(), O_WRONLY | O_NONBLOCK | O_CLOEXEC);
        if (fd >= 0) {
          (void)::fcntl(fd, F_SETPIPE_SZ, 4 << 20);  // a whole frame fits: the reader drains it in one step
          auto wr = camera::FrameStreamWriter::from_fd(fd, fifo.string());
          if (wr) frames.emplace(std::move(wr).value());
        }
      }
      Pose3 qp;
      {
        std::lock_guard<std::mutex> lk(mu);
        qp = quad.pose();
      }
      camera.prepare(qp, cf, now);
      constexpr int kBands = 8;
      cam_pool.run(kBands, [&](std::size_t j) {
        const int h = cf.rgb.rows, b = static_cast<int>(j);
        camera.render_rows(qp, h * b / kBands, h * (b + 1) / kBands, cf);
      });
      if (rec) {
        std::lock_guard<std::mutex> lk(rec_mu);
        rec->camera_frame(monotonic_now() - rec0, ++rendered, cf.rgb);
      }
      vo_out.clear();
      {
        std::lock_guard<std::mutex> lk(vo_mu);
        vo_out.assign(vo_queue.begin(), vo_queue.end());
        vo_queue.clear();
      }
      if (!frames) {
        cam_dropped.fetch_add(1, std::memory_order_relaxed);
        continue;
      }
      // (A failed write is counted, the stream kept: the camera stage does not reopen a FIFO that ended.)
      for (const VoMsg& m : vo_out)
        if (frames->write_vo(m)) vo_written.fetch_add(1, std::memory_order_relaxed);
      CameraImageMsg& m = *image;
      m.stamp = now;
      m.published = now;
      m.seq = image_seq++;
      m.labels = labels_oracle ? LabelSource::kGroundTruth : LabelSource::kNone;  // a camera gives no classes
      if (!labels_oracle) m.cls.fill(255);
      for (int r = 0; r < kImageHeight; ++r) {
        std::memcpy(m.rgb.data() + static_cast<std::size_t>(r) * kImageWidth * 3, cf.rgb.ptr<std::uint8_t>(r), kImageWidth * 3);
        if (labels_oracle) std::memcpy(m.cls.data() + static_cast<std::size_t>(r) * kImageWidth, cf.cls.ptr<std::uint8_t>(r), kImageWidth);
      }
      if (frames->write_image(m)) cam_written.fetch_add(1, std::memory_order_relaxed);
      else cam_dropped.fetch_add(1, std::memory_order_relaxed);
    }
  });

  // Sensor loop.
  const TimeNs t0 = monotonic_now();
  const TimeNs lidar_period = kNsPerS / 10, state_period = kNsPerS;
  TimeNs next_lidar = t0 + kNsPerS, next_state = t0 + 2 * kNsPerS, next_progress = t0 + 5 * kNsPerS;
  TimeNs next_trail = t0, next_rec = t0;
  std::vector<std::uint8_t> pkt(ouster::kMaxPacketSize);
  std::string last_state;
  std::string failure;
  TimeNs done_seen = -1;
  const TimeNs deadline = t0 + static_cast<TimeNs>(opt.max_duration_s * 1e9);
  while (true) {
    const TimeNs now = monotonic_now();
    if (now >= deadline) break;
    // A robot process that died ends the run.
    for (Child& c : children) {
      int st = 0;
      if (!c.exited && ::waitpid(c.pid, &st, WNOHANG) == c.pid) {
        c.exited = true;
        c.exit_code = WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
        failure = c.name + " exited with status " + std::to_string(c.exit_code) + " (see " + c.log.string() + ")";
      }
    }
    if (!failure.empty()) break;
    Pose3 qp;
    std::vector<Pose3> lidar_poses;
    {
      std::lock_guard<std::mutex> lk(mu);
      qp = quad.pose();
      for (auto& u : ugvs) {
        Pose3 p = u->vehicle.pose3();
        p.z += opt.lidar_mount_height_m;
        lidar_poses.push_back(p);
        if (now >= next_trail) u->truth_trail.emplace_back(u->vehicle.pose().x, u->vehicle.pose().y);
        u->history.emplace_back(now, u->vehicle.pose());
        while (!u->history.empty() && u->history.front().first < now - 30 * kNsPerS) u->history.pop_front();
      }
    }
    if (now >= next_trail) next_trail += kNsPerS / 2;
    if (rec && now >= next_rec) {
      next_rec += kNsPerS / 10;
      std::lock_guard<std::mutex> lk(rec_mu);
      const TimeNs t = monotonic_now() - rec0;
      rec->uav_pose(t, qp);
      for (std::size_t k = 0; k < ugvs.size(); ++k) {
        Pose3 p = lidar_poses[k];
        p.z -= opt.lidar_mount_height_m;
        rec->ugv_pose(t, static_cast<int>(k), p, nullptr, ugvs[k]->has_est ? &ugvs[k]->est : nullptr);
      }
      rec->tick(t, nullptr);
    }
    // GNSS: UBX NAV-PVT on the serial line.
    GpsFix fix;
    if (gps.sample(now, qp, fix)) {
      if (rec) {
        std::lock_guard<std::mutex> lk(rec_mu);
        rec->uav_gps(monotonic_now() - rec0, fix.lat_deg, fix.lon_deg, fix.height_m, fix.h_accuracy_m);
      }
      ublox::NavPvt p;
      p.itow_ms = static_cast<std::uint32_t>((now / kNsPerMs) % (7 * 24 * 3600 * 1000LL));
      p.fix_type = fix.fix_type == GpsFixType::kNoFix ? ublox::FixType::kNone : ublox::FixType::k3D;
      p.flags_raw = fix.fix_type == GpsFixType::kNoFix ? 0 : 1;  // gnssFixOK
      p.valid_raw = 0x07;
      p.num_sv = 14;
      p.lat_e7 = static_cast<std::int32_t>(std::lround(fix.lat_deg * 1e7));
      p.lon_e7 = static_cast<std::int32_t>(std::lround(fix.lon_deg * 1e7));
      p.height_mm = static_cast<std::int32_t>(std::lround(fix.height_m * 1e3));
      p.hmsl_mm = p.height_mm;
      p.h_acc_mm = static_cast<std::uint32_t>(std::lround(fix.h_accuracy_m * 1e3));
      p.v_acc_mm = static_cast<std::uint32_t>(std::lround(fix.v_accuracy_m * 1e3));
      p.vel_ned_mm_s[0] = static_cast<std::int32_t>(std::lround(fix.vel_north_mps * 1e3));
      p.vel_ned_mm_s[1] = static_cast<std::int32_t>(std::lround(fix.vel_east_mps * 1e3));
      p.vel_ned_mm_s[2] = static_cast<std::int32_t>(std::lround(-fix.vel_up_mps * 1e3));
      p.pdop_e2 = 120;
      std::array<std::uint8_t, ublox::kNavPvtLength> payload{};
      ublox::encode_nav_pvt(p, payload);
      std::uint8_t msg[ublox::kNavPvtLength + 8];
      const std::size_t len = ublox::ubx_encode(ublox::kClassNav, ublox::kIdNavPvt, payload, msg);
      if (::write(pty, msg, len) == static_cast<ssize_t>(len)) ++res.ubx_messages;
    }
    // Visual odometry: queued for the camera thread, which writes it to the frame stream before each image.
    VoSample vs;
    if (vo.sample(now, qp, vs)) {
      VoMsg m;
      m.stamp = vs.stamp;
      m.published = now;
      m.segment = vs.segment;
      m.tracking = vs.tracking;
      m.pose = vs.pose;
      std::lock_guard<std::mutex> lk(vo_mu);
      if (vo_queue.size() < 256) vo_queue.push_back(m);
    }
    const bool lidar_due = now >= next_lidar;
    if (lidar_due) {
      for (std::size_t k = 0; k < ugvs.size(); ++k) lidar.scan(lidar_poses[k], opt.seed ^ static_cast<std::uint64_t>(now) ^ k, ugvs[k]->scan);
      if (rec) {
        std::lock_guard<std::mutex> lk(rec_mu);
        for (std::size_t k = 0; k < ugvs.size(); ++k) rec->ugv_scan(monotonic_now() - rec0, static_cast<int>(k), res.lidar_revolutions + 1, &ugvs[k]->scan, 1);
      }
      {
        // A revolution every 100 ms; one the simulator could not cast in time is skipped, not sent late.
        next_lidar += lidar_period;
        if (next_lidar < now) {
          res.lidar_revolutions_skipped += static_cast<std::uint64_t>((now - next_lidar) / lidar_period) + 1;
          next_lidar = now + lidar_period;
        }
        ++res.lidar_revolutions;
        for (auto& up : ugvs) {
          HilUgv& u = *up;
          ouster::LidarFrame& f = u.frame;
          f.clear();
          f.frame_id = u.frame_id++;
          const TimeNs col_dt = lidar_period / f.width;
          for (int c = 0; c < f.width; ++c) {
            f.column_timestamp_ns[static_cast<std::size_t>(c)] = static_cast<std::uint64_t>(now + c * col_dt);
            f.column_valid[static_cast<std::size_t>(c)] = 1;
          }
          f.columns_received = f.width;
          const Pose3& sp = lidar_poses[static_cast<std::size_t>(&up - ugvs.data())];
          const double cy = std::cos(sp.yaw), sy = std::sin(sp.yaw);
          for (const LidarPoint& q : u.scan) {
            if (q.ring >= f.height || q.col >= f.width) continue;
            const std::size_t k = f.index(q.ring, q.col);
            f.range_mm[k] = static_cast<std::uint32_t>(std::lround(q.range * 1000.0f));
            // An Ouster measures reflectivity, not class: the surface's albedo (the true class only with --oracle labels).
            f.reflectivity[k] = labels_oracle ? q.cls : albedo_reflectivity(w, sp.x + cy * static_cast<double>(q.x) - sy * static_cast<double>(q.y),
                                                                             sp.y + sy * static_cast<double>(q.x) + cy * static_cast<double>(q.y));
            f.signal[k] = 200;
          }
          const int cpp = u.fmt->columns_per_packet();
          for (int c0 = 0; c0 < f.width; c0 += cpp) {
            const std::size_t len = ouster::encode_lidar_packet(*u.fmt, f, c0, pkt);
            if (len > 0 && ::sendto(u.udp, pkt.data(), len, 0, reinterpret_cast<const sockaddr*>(&u.lidar_to), sizeof u.lidar_to) == static_cast<ssize_t>(len))
              ++res.lidar_packets;
          }
        }
      }
    }
    // The mission as the base station sees it.
    if (now >= next_state) {
      next_state += state_period;
      const std::string body = http_get(web_port, "/api/state");
      if (!body.empty()) {
        last_state = body;
        try {
          const json s = json::parse(body);
          int done = 0;
          for (auto& up : ugvs) {
            HilUgv& u = *up;
            for (const json& r : s.value("robots", json::array())) {
              if (r.value("id", -1) != u.id) continue;
              if (r.value("has_pose", false)) {
                u.has_est = true;
                u.est = Pose2{r.value("x", 0.0), r.value("y", 0.0), r.value("yaw", 0.0)};
                u.est_trail.emplace_back(u.est.x, u.est.y);
                // The pose is as old as the base's copy of it: compare with the truth of that time.
                std::lock_guard<std::mutex> lk(mu);
                const Pose2 tr = u.truth_at(now - static_cast<TimeNs>(r.value("age_s", 0.0) * 1e9));
                u.est_error_m = std::hypot(u.est.x - tr.x, u.est.y - tr.y);
                if (r.value("status", std::string()) == "tracking") u.errors.push_back(u.est_error_m);
              }
              if (r.contains("claim") && r["claim"].is_object()) u.state = r["claim"].value("state", std::string("-"));
            }
            if (u.state == "done") ++done;
          }
          // Done: a few more polls with the robots standing, so the final error is not the base's lag.
          if (done == n && done_seen < 0) done_seen = now;
          if (done == n && now - done_seen >= 3 * kNsPerS) {
            res.mission_done = true;
            break;
          }
        } catch (const std::exception&) {
          // a half-written answer: the next poll reads it again
        }
      }
    }
    if (opt.progress && now >= next_progress) {
      next_progress += 5 * kNsPerS;
      std::fprintf(stderr, "hil %5.0f s  uav (%.0f, %.0f, %.0f) wp %zu  frames %llu  lidar pkts %llu", to_seconds(now - t0), qp.x, qp.y, qp.z,
                   quad.waypoints_reached(), static_cast<unsigned long long>(cam_written.load()), static_cast<unsigned long long>(res.lidar_packets));
      std::lock_guard<std::mutex> lk(mu);
      for (auto& u : ugvs)
        std::fprintf(stderr, " | %s %s %.1f m%s", u->name.c_str(), u->state.c_str(), u->distance_m,
                     u->est_error_m >= 0 ? (" err " + fixed(u->est_error_m, 2) + " m").c_str() : "");
      std::fprintf(stderr, "\n");
    }
    const TimeNs wake = std::min({next_lidar, next_state, now + 20 * kNsPerMs});
    if (wake > monotonic_now()) {
      timespec ts{static_cast<time_t>(wake / kNsPerS), static_cast<long>(wake % kNsPerS)};
      ::clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
    }
  }
  res.duration_s = to_seconds(monotonic_now() - t0);

  // Stop: SIGTERM in reverse start order, then wait (10 s each at most), then SIGKILL.
  stop_all(SIGTERM);
  for (Child& c : children) {
    for (int k = 0; k < 100 && !c.exited; ++k) {
      int st = 0;
      if (::waitpid(c.pid, &st, WNOHANG) == c.pid) {
        c.exited = true;
        c.exit_code = WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
      } else {
        ::usleep(100000);
      }
    }
    if (!c.exited) {
      ::kill(c.pid, SIGKILL);
      int st = 0;
      ::waitpid(c.pid, &st, 0);
      c.exited = true;
      c.exit_code = -1;
    }
  }
  stop_camera.store(true);
  camera_thread.join();
  res.camera_frames = cam_written.load();
  res.camera_frames_dropped = cam_dropped.load();
  res.camera_frames_skipped = cam_skipped.load();
  res.vo_records = vo_written.load();
  stop.store(true);
  physics.join();
  ::close(pty);
  if (pty_slave >= 0) ::close(pty_slave);
  for (auto& u : ugvs) {
    ::close(u->udp);
    res.can_frames_in += u->odrive->commands_received();
  }
  if (!last_state.empty()) std::ofstream(out / "base_state.json") << last_state << "\n";
  if (rec)
    if (Status st = rec->close(to_seconds(monotonic_now() - rec0)); !st) return st.error();

  // Each process's final stage timing, against its table's budget.
  auto budgets = [](const std::string& role) {
    std::map<std::string, double> b;
    const RoleDescription& d = role == "uav" ? uav_role() : role == "ugv" ? ugv_role() : base_role();
    for (const StageSpec& s : d.stages) b[std::string(s.name)] = s.budget_us;
    return b;
  };
  for (const Child& c : children) {
    HilRobot r;
    r.name = c.name;
    r.exit_code = c.exit_code;
    const auto b = budgets(c.role);
    std::ifstream log(c.log);
    std::string line;
    while (std::getline(log, line)) {
      const auto at = line.find("final stage=");
      if (at == std::string::npos) continue;
      std::istringstream ss(line.substr(at + 6));
      HilStageTiming t;
      t.robot = c.name;
      std::string tok;
      while (ss >> tok) {
        const auto eq = tok.find('=');
        if (eq == std::string::npos) continue;
        const std::string k = tok.substr(0, eq), v = tok.substr(eq + 1);
        if (k == "stage") t.stage = v;
        else if (k == "runs") t.runs = std::stoull(v);
        else if (k == "exec_p50_us") t.p50_us = std::stod(v);
        else if (k == "exec_p99_us") t.p99_us = std::stod(v);
        else if (k == "exec_max_us") t.max_us = std::stod(v);
        else if (k == "overruns") t.overruns = std::stoull(v);
      }
      if (auto it = b.find(t.stage); it != b.end()) t.budget_us = it->second;
      res.timing.push_back(t);
    }
    for (const auto& u : ugvs)
      if (u->name == c.name) {
        r.final_state = u->state;
        r.distance_m = u->distance_m;
        r.collisions = u->collisions;
        r.final_error_m = u->est_error_m;
        if (!u->errors.empty()) {
          double sum = 0;
          for (double e : u->errors) {
            sum += e;
            r.max_error_m = std::max(r.max_error_m, e);
          }
          r.mean_error_m = sum / static_cast<double>(u->errors.size());
        }
      }
    res.robots.push_back(r);
  }

  // The report: JSON, Markdown and the trajectories over the world's class map.
  {
    json j;
    // HIL always hands the pose graph the simulator's odometry in the frame stream: the vo oracle.
    RunOptions oracle_list;
    oracle_list.oracles = opt.oracles;
    if (!oracle_list.oracle("vo")) oracle_list.oracles.emplace_back("vo");
    j["mission"] = opt.mission_file;
    j["oracles"] = oracle_list.oracles;
    j["world"] = opt.world;
    j["mission_done"] = res.mission_done;
    j["duration_s"] = res.duration_s;
    j["failure"] = failure;
    const double secs = std::max(1.0, res.duration_s);
    j["rates_hz"] = {{"lidar", static_cast<double>(res.lidar_revolutions) / secs}, {"camera", static_cast<double>(res.camera_frames) / secs}};
    j["traffic"] = {{"lidar_packets", res.lidar_packets}, {"lidar_revolutions", res.lidar_revolutions}, {"lidar_revolutions_skipped", res.lidar_revolutions_skipped},
                    {"camera_frames_skipped", res.camera_frames_skipped}, {"ubx_nav_pvt", res.ubx_messages}, {"camera_frames", res.camera_frames},
                    {"camera_frames_dropped", res.camera_frames_dropped}, {"vo_records", res.vo_records}, {"can_commands_received", res.can_frames_in}};
    for (const HilRobot& r : res.robots)
      j["robots"].push_back({{"name", r.name}, {"exit_code", r.exit_code}, {"state", r.final_state}, {"distance_m", r.distance_m},
                             {"final_error_m", r.final_error_m}, {"mean_error_m", r.mean_error_m}, {"max_error_m", r.max_error_m}, {"collisions", r.collisions}});
    for (const HilStageTiming& t : res.timing)
      j["stage_timing"].push_back({{"robot", t.robot}, {"stage", t.stage}, {"runs", t.runs}, {"p50_us", t.p50_us}, {"p99_us", t.p99_us},
                                   {"max_us", t.max_us}, {"budget_us", t.budget_us}, {"overruns", t.overruns}});
    std::ofstream(out / "hil.json") << j.dump(2) << "\n";
    std::ofstream md(out / "hil_report.md");
    md << "# HIL run: " << opt.mission_file << "\n\n" << oracle_list.oracles_line() << "\n\n"
       << (res.mission_done ? "Mission **done**" : "Mission **not finished**") << " after " << fixed(res.duration_s, 1) << " s"
       << (failure.empty() ? "" : " — " + failure) << ".\n\nLocalization error: the pose the base station last heard against the truth of that time (every poll while tracking: mean, max).\n\n| robot | exit | state | driven [m] | final error [m] | mean / max error [m] | collisions |\n|---|---|---|---|---|---|---|\n";
    for (const HilRobot& r : res.robots)
      md << "| " << r.name << " | " << r.exit_code << " | " << r.final_state << " | " << fixed(r.distance_m, 1) << " | "
         << (r.final_error_m >= 0 ? fixed(r.final_error_m, 2) : "-") << " | "
         << (r.mean_error_m >= 0 ? fixed(r.mean_error_m, 2) + " / " + fixed(r.max_error_m, 2) : "-") << " | " << r.collisions << " |\n";
    md << "\nWire traffic: " << res.lidar_packets << " Ouster packets (" << res.lidar_revolutions << " revolutions, "
       << res.lidar_revolutions_skipped << " skipped: the simulator was late), " << res.ubx_messages << " UBX NAV-PVT, " << res.camera_frames
       << " camera frames (" << res.camera_frames_dropped << " not delivered, " << res.camera_frames_skipped << " skipped), " << res.vo_records << " VO records, " << res.can_frames_in
       << " Set_Input_Vel frames.\n\n## Stage timing (wall time per step, as each process's real-time executor measured it: "
          "preemption by the other processes on this machine counts; from their final counters)\n\n"
       << "| robot | stage | runs | p50 [us] | p99 [us] | max [us] | budget [us] | overruns |\n|---|---|---|---|---|---|---|---|\n";
    for (const HilStageTiming& t : res.timing)
      md << "| " << t.robot << " | " << t.stage << " | " << t.runs << " | " << fixed(t.p50_us, 1) << " | " << fixed(t.p99_us, 1)
         << " | " << fixed(t.max_us, 1) << " | " << t.budget_us << " | " << t.overruns << " |\n";
    cv::Mat img;
    cv::cvtColor(class_display_image(w.class_id), img, cv::COLOR_RGB2BGR);
    auto px = [&](const cv::Point2d& p) { return cv::Point(g.col(p.x), g.row(p.y)); };
    for (const auto& u : ugvs) {
      for (std::size_t k = 1; k < u->truth_trail.size(); ++k) cv::line(img, px(u->truth_trail[k - 1]), px(u->truth_trail[k]), cv::Scalar(255, 255, 255), 2);
      for (std::size_t k = 1; k < u->est_trail.size(); ++k) cv::line(img, px(u->est_trail[k - 1]), px(u->est_trail[k]), cv::Scalar(0, 0, 255), 1);
    }
    cv::imwrite((out / "trajectories.png").string(), img);
  }
  if (!failure.empty()) return Error::make(ErrorCode::kIo, "hil: " + failure);
  return res;
}

}  // namespace ag::sim
