// The lockstep team runner: robots' role tables and the simulated world on one SimClock. The team is set
// up in team_setup.cpp, the world stage steps it (world_stage.cpp), and this file runs and sums it up.
#include "airground/sim/runner.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "airground/aerial_mapping/stages.hpp"
#include "airground/platform/executor.hpp"
#include "airground/platform/rng.hpp"
#include "airground/sim/compute_time.hpp"
#include "airground/sim/generator.hpp"
#include "airground/sim/shipped_configs.hpp"
#include "sim_probes.hpp"
#include "team.hpp"
#include "team_setup.hpp"
#include "world_stage.hpp"

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

namespace lockstep {
namespace {

double process_cpu_seconds() noexcept {
  timespec ts{};
  if (clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts) != 0) return 0.0;
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

// Robots side by side on the sensor workers: they share nothing but the radio (sends deferred to the
// end of each release time, in node order) and the sampling callback (likewise, in robot order), so
// the run is the serial one bit for bit. Not with channel taps: those hand out messages in place.
void run_robots_in_parallel(Team& t, LockstepExecutor& exec) {
  if (t.net) t.net->set_deferred(true);
  exec.set_parallel(
      [](void* user, std::size_t jobs, LockstepExecutor::JobFn job, void* job_user) {
        static_cast<Team*>(user)->pool->run(jobs, [job, job_user](std::size_t j) { job(job_user, j); });
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

// recording.mcap: what the world stage sees each tick, and the robots' channels it watches.
Status open_recording(Team& t) {
  const RunOptions& opt = t.opt;
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
  return ok_status();
}

// Runs the team to `end` (or until a stop condition of the options holds); returns when it ended.
TimeNs run_until_end(Team& t, LockstepExecutor& exec, TimeNs end, double duration_s, const ProgressFn& progress) {
  const RunOptions& opt = t.opt;
  TimeNs chunk = std::max<TimeNs>(kNsPerS / 10, end / 100);
  if (opt.stop_when_survey_done || opt.stop_when_routes_done) chunk = std::min<TimeNs>(chunk, 2 * kNsPerS);
  if (opt.stop_when) chunk = std::min<TimeNs>(chunk, kNsPerS);
  const auto wall0 = std::chrono::steady_clock::now();
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
  return ended;
}

RobotSummary summarise_ugv(Ugv& u) {
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
  if (u.scan_bin != nullptr) std::fclose(u.scan_bin);
  u.scan_bin = nullptr;
  return r;
}

// What the robots did, their stages' CPU and what the radio carried.
void summarise_team(Team& t, RunSummary& s) {
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
  for (auto& up : t.ugvs) s.ugvs.push_back(summarise_ugv(*up));
}

}  // namespace
}  // namespace lockstep

Result<RunSummary> run_team(const RunOptions& opt, const ProgressFn& progress) {
  using namespace lockstep;
  if (auto st = check_options(opt); !st) return st.error();
  auto world = resolve_world(opt.world);
  if (!world) return world.error();

  Team t;
  t.opt = opt;
  t.world = world.value();
  t.out = opt.out_dir;
  if (auto st = open_uav_cache(t); !st) return st.error();
  std::error_code ec;
  fs::create_directories(t.out / "camera", ec);
  if (ec) return Error::make(ErrorCode::kIo, "cannot create " + t.out.string() + ": " + ec.message());
  auto models = load_models(opt);
  if (!models) return models.error();
  const Models& m = models.value();
  if (auto st = set_up_world(t, m); !st) return st.error();
  LinkRegistration links;
  auto comms_common = set_up_gossip(t, links);
  if (!comms_common) return comms_common.error();

  SimClock clock(0);
  std::vector<Config> cfgs;
  cfgs.reserve(static_cast<std::size_t>(opt.ugvs) + 2);
  RoleFactory roles(t.opt, clock, cfgs);
  double survey_time_s = 0;  // the quadrotor's route, estimated [s]
  if (opt.uav) {
    auto flight = set_up_uav(t, m, roles, comms_common.value());
    if (!flight) return flight.error();
    survey_time_s = flight.value();
  }
  if (auto st = set_up_ugvs(t, m, roles, comms_common.value(), survey_time_s); !st) return st.error();
  if (auto st = set_up_base(t, roles, comms_common.value()); !st) return st.error();
  warn_unwritten_channels(t);

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
  if (t.parallel_robots) run_robots_in_parallel(t, exec);
  if (opt.record != RecordLevel::kNone && opt.record_mcap)
    if (auto st = open_recording(t); !st) return st.error();
  exec.start(0);

  const double duration_s = opt.duration_survey_factor > 0 && opt.uav ? std::max(opt.duration_s, opt.duration_survey_factor * survey_time_s)
                                                                    : opt.duration_s;
  const TimeNs end = from_seconds(duration_s);
  const auto wall0 = std::chrono::steady_clock::now();
  const double process_cpu0 = process_cpu_seconds();
  const TimeNs ended = run_until_end(t, exec, end, duration_s, progress);
  const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();

  if (auto st = finish_uav_cache(t, ended); !st) return st.error();
  RunSummary s;
  s.uav_replay = t.replay_info;
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
  summarise_team(t, s);
  s.compute_time = std::string(compute_time_name(opt.compute_time));
  for (const auto& r : exec.runnables()) {
    if (r.perf == &world_perf) continue;
    const StagePerf& p = *r.perf;
    s.stage_overruns += p.overruns.load();
    s.stage_slips += p.slips.load();
    s.stages.push_back({robot_of(r) + "/" + p.name, p.runs.load(), p.overruns.load(), p.slips.load(), static_cast<double>(p.exec.quantile(0.99)) / 1e6,
                        static_cast<double>(r.budget) / 1e6});
  }
  if (opt.inspect) {
    const World& w = *t.world;
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
