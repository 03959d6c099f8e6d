// The HIL run's role processes: their binaries, the YAML each is configured by, starting, reaping, stopping.
#include <arpa/inet.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>

#include "airground/platform/config.hpp"
#include "airground/platform/role_instance.hpp"
#include "airground/sim/runner.hpp"
#include "hil_run.hpp"
#include "roles.hpp"
#include "sensor_labels_check.hpp"
#include "team_setup.hpp"

namespace ag::sim::hil {
namespace {

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

}  // namespace

std::string num(double v) {
  char b[64];
  std::snprintf(b, sizeof b, "%.6f", v);
  return b;
}

std::uint16_t any_port(int type) {
  auto p = free_port(type);
  return p ? p.value() : 0;
}

mission::Area world_area(const World& w) {
  const GridGeometry& g = w.grid();
  return mission::Area{g.origin_x, g.origin_y - g.size_y(), g.origin_x + g.size_x(), g.origin_y};
}

Result<fs::path> find_role_binaries(const std::string& bin_dir) {
  // Installed, the role binaries sit beside airground-sim; in the build tree, in firmware_host/.
  fs::path bin = bin_dir;
  if (bin.empty()) {
    std::error_code ec;
    const fs::path self = fs::read_symlink("/proc/self/exe", ec).parent_path();
    bin = fs::exists(self / "airground-ugv") ? self : self.parent_path() / "firmware_host";
  }
  for (const char* b : {"airground-uav", "airground-ugv", "airground-base"})
    if (!fs::exists(bin / b))
      return Error::make(ErrorCode::kIo, (bin / b).string() + " not found (build the role binaries, or give --bin-dir)");
  return bin;
}

Settings common_settings(const Run& run, int id, const std::string& name, std::size_t node) {
  std::string peers;
  for (std::size_t i = 0; i < run.gossip.size(); ++i)
    if (i != node) peers += (peers.empty() ? "" : ",") + std::string("127.0.0.1:") + std::to_string(run.gossip[i]);
  // Real-time scheduling off: on a desk machine SCHED_FIFO stages would starve the simulator itself.
  return Settings{
      {"robot.id", std::to_string(id)}, {"robot.name", name}, {"scheduler.realtime", "false"}, {"scheduler.lock_memory", "false"},
      {"scheduler.pin_cpus", "false"}, {"status.log_every", "10"}, {"comms.transport", "udp"}, {"comms.key_file", run.key.string()},
      {"comms.journal", ""}, {"comms.port", std::to_string(run.gossip[node])}, {"comms.broadcast", ""}, {"comms.peers", peers}};
}

Settings ugv_shared_settings(const Run& run) {
  const mission::Area a = world_area(run.world);
  const mission::MissionParameters& mp = run.mf.params;
  Settings s{
      {"localization.area_x0_m", num(a.x0)}, {"localization.area_y0_m", num(a.y0)}, {"localization.area_x1_m", num(a.x1)}, {"localization.area_y1_m", num(a.y1)},
      {"planner.area_x0_m", num(a.x0)}, {"planner.area_y0_m", num(a.y0)}, {"planner.area_x1_m", num(a.x1)}, {"planner.area_y1_m", num(a.y1)},
      {"base.can_backend", "cannelloni"}, {"base.estop_backend", "none"}, {"base.led_backend", "none"},
      {"mission.visit_radius_m", num(mp.visit_radius_m)}, {"mission.max_sigma_m", num(mp.max_sigma_m)},
      {"mission.claim_timeout_s", num(mp.claim_timeout_s)}, {"mission.idle_return_s", num(mp.idle_return_s)},
      {"mission.mission_end_s", num(mp.mission_end_s)},
      {"mission.survey_end_s", num(mp.survey_end_s)}};
  // The Ouster gives no class: the shipped geometric labeller, or (an ablation) the truth in the reflectivity byte.
  if (run.labels_oracle) s.emplace_back("localization.labels", "gt");
  return s;
}

// One role's YAML: its shipped configuration (built in from firmware_host/<role>/<role>.yaml) with the
// "section.key=value" pairs the simulator must set, every key written out.
Status write_role_yaml(const fs::path& path, const std::string& title, const RoleDescription& role, const Settings& kv,
                       bool labels_oracle) {
  const std::string origin = "firmware_host/" + std::string(role.name) + "/" + std::string(role.name) + ".yaml (built into airground-sim)";
  auto c = Config::load_string(role_schema(role), shipped_config_yaml(role.name), origin);
  if (!c) return c.error();
  for (const auto& [k, v] : kv)
    if (auto st = c.value().set(k + "=" + v, "airground-sim hil"); !st) return st.error();
  if (auto st = check_sensor_labels(c.value(), origin + " with airground-sim hil's settings", labels_oracle); !st) return st.error();
  std::ofstream f(path);
  f << "# " << title << " — written by airground-sim hil: the shipped " << role.name << ".yaml and the keys the simulator sets\n"
    << c.value().to_yaml();
  if (!f) return Error::make(ErrorCode::kIo, "cannot write " + path.string());
  return ok_status();
}

Status write_ugv_yaml(Run& run, int i, const mission::TeamMember& tm, const Ugv& u, const Settings& shared,
                      const fs::path& meta_path, std::uint16_t can_robot, std::uint16_t can_sim) {
  const fs::path& out = run.out;
  auto kv = common_settings(run, tm.id, u.name, static_cast<std::size_t>(1 + i));
  kv.insert(kv.end(), shared.begin(), shared.end());
  for (const auto& p : Settings{
           {"lidar.source", "udp"}, {"lidar.metadata", meta_path.string()}, {"lidar.bind_address", "127.0.0.1"},
           {"localization.set_initial_pose", "true"}, {"localization.initial_x_m", num(tm.guess_x)}, {"localization.initial_y_m", num(tm.guess_y)},
           {"localization.initial_yaw_rad", num(tm.guess_yaw)}, {"localization.initial_sigma_m", num(std::max(0.5, tm.guess_sigma_m))},
           {"base.can_bridge_port", std::to_string(can_robot)}, {"base.can_bridge_remote", "127.0.0.1:" + std::to_string(can_sim)},
           {"base.can_record_path", (out / "logs" / ("can-" + u.name + ".log")).string()},
           {"base.odometry_log_path", (out / "logs" / ("odometry-" + u.name + ".csv")).string()},
           {"mission.priority", std::to_string(tm.priority)}, {"mission.start_x_m", num(tm.start_x)}, {"mission.start_y_m", num(tm.start_y)}})
    kv.push_back(p);
  if (run.labels_oracle) kv.emplace_back("lidar.classes", "reflectivity");
  if (run.mf.type == mission::MissionType::kWaypoints && !tm.waypoints.empty()) {
    std::string wp;
    for (std::size_t k = 0; k < tm.waypoints.size(); ++k) wp += (k ? ";" : "") + num(tm.waypoints[k].x) + "," + num(tm.waypoints[k].y);
    kv.emplace_back("mission.waypoints", wp);
  }
  const fs::path cfg = out / "config" / (u.name + ".yaml");
  if (auto st = write_role_yaml(cfg, u.name + " (ground robot " + std::to_string(tm.id) + ")", ugv_role(), kv, run.labels_oracle); !st) return st.error();
  run.children.push_back(RoleProcess{u.name, "ugv", -1, out / "logs" / (u.name + ".log")});
  return ok_status();
}

Status write_uav_yaml(Run& run) {
  const World& w = run.world;
  const mission::Area a = world_area(w);
  const mission::MissionParameters& mp = run.mf.params;
  auto kv = common_settings(run, 0, "uav", 0);
  for (const auto& p : Settings{
           {"gps.source", "serial"}, {"gps.device", run.gps_pty.path}, {"gps.datum_lat_deg", num(w.header.datum.lat_deg)},
           {"gps.datum_lon_deg", num(w.header.datum.lon_deg)}, {"gps.datum_height_m", num(w.header.datum.height_m)},
           {"autopilot.source", "serial"}, {"autopilot.device", run.autopilot_pty.path},
           {"camera.source", "replay"}, {"camera.replay", run.fifo.string()}, {"camera.stamps", "record"},
           // The shipped weights: the source tree's copy when not installed.
           {"segmentation.weights", lockstep::erfnet_weights_path()},
           {"regions.area_x0_m", num(a.x0)}, {"regions.area_y0_m", num(a.y0)}, {"regions.area_x1_m", num(a.x1)}, {"regions.area_y1_m", num(a.y1)},
           {"regions.merge_distance_m", num(mp.merge_distance_m)}, {"regions.min_region_cells", std::to_string(mp.min_region_cells)}})
    kv.push_back(p);
  // Ablations by name: the renderer's classes in the frames, the simulator's odometry to the pose graph
  // (the robot's own VO then runs beside it on a channel nobody reads).
  if (run.labels_oracle) kv.emplace_back("segmentation.labels", "gt");
  if (run.vo_oracle) {
    kv.emplace_back("camera.vo_channel", "visual_odometry");
    kv.emplace_back("vo.output_channel", "visual_odometry_own");
  }
  if (auto st = write_role_yaml(run.out / "config" / "uav.yaml", "uav (quadrotor)", uav_role(), kv, run.labels_oracle); !st) return st.error();
  run.children.insert(run.children.begin(), RoleProcess{"uav", "uav", -1, run.out / "logs" / "uav.log"});
  return ok_status();
}

Status write_base_yaml(Run& run) {
  auto kv = common_settings(run, 250, "base", run.mf.team.size() + 1);
  kv.emplace_back("comms.deliver_map_tiles", "true");
  kv.emplace_back("web.port", std::to_string(run.web_port));
  kv.emplace_back("web.bind", "127.0.0.1");
  kv.emplace_back("web.log_path", (run.out / "mission.jsonl").string());
  if (auto st = write_role_yaml(run.out / "config" / "base.yaml", "base station", base_role(), kv, run.labels_oracle); !st) return st.error();
  run.children.push_back(RoleProcess{"base", "base", -1, run.out / "logs" / "base.log"});
  return ok_status();
}

Status start_roles(Run& run) {
  std::vector<std::size_t> order;
  for (const char* role : {"base", "ugv", "uav"})
    for (std::size_t i = 0; i < run.children.size(); ++i)
      if (run.children[i].role == role) order.push_back(i);
  for (std::size_t i : order) {
    RoleProcess& c = run.children[i];
    const fs::path cfg = run.out / "config" / (c.name + ".yaml");
    std::vector<std::string> argv{(run.bin / ("airground-" + c.role)).string(), "--config", cfg.string()};
    if (run.labels_oracle) argv.emplace_back("--oracle=labels");  // the ablation the user named, passed on by name
    auto pid = spawn(argv, c.log);
    if (!pid) {
      signal_roles(run.children, SIGTERM);
      return pid.error();
    }
    c.pid = pid.value();
  }
  return ok_status();
}

void signal_roles(std::vector<RoleProcess>& children, int sig) {
  for (RoleProcess& c : children)
    if (c.pid > 0 && !c.exited) ::kill(c.pid, sig);
}

std::string reap_exited(std::vector<RoleProcess>& children) {
  std::string failure;
  for (RoleProcess& c : children) {
    int st = 0;
    if (!c.exited && ::waitpid(c.pid, &st, WNOHANG) == c.pid) {
      c.exited = true;
      c.exit_code = WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
      failure = c.name + " exited with status " + std::to_string(c.exit_code) + " (see " + c.log.string() + ")";
    }
  }
  return failure;
}

void stop_roles(std::vector<RoleProcess>& children) {
  signal_roles(children, SIGTERM);
  for (RoleProcess& c : children) {
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
}

}  // namespace ag::sim::hil
