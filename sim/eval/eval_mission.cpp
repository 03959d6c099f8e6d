// A team mission in the lockstep runner, scored against the world's targets and the true poses.
#include "airground/sim/eval_mission.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <optional>
#include <thread>

#include "airground/aerial_mapping/stages.hpp"
#include "airground/comms/stage.hpp"
#include "airground/messages/messages.hpp"
#include "airground/mission/mission_file.hpp"
#include "airground/mission/stages.hpp"
#include "airground/platform/role_instance.hpp"
#include "airground/sim/eval_scoring.hpp"
#include "airground/sim/generator.hpp"
#include "airground/sim/survey_plan.hpp"
#include "airground/sim/uav_replay.hpp"
#include "mission_log.hpp"

namespace ag::sim {

namespace mission_eval {

namespace {

namespace fs = std::filesystem;

// Class accuracy of the quadrotor's map: a mapped cell is right when any world cell inside it has its class.
double class_accuracy(const World& w, const mapping::MapRaster& r) {
  const GridGeometry& wg = w.grid();
  const GridGeometry& g = r.grid;
  const int sub = std::max(1, static_cast<int>(std::lround(g.resolution / wg.resolution)));
  std::uint64_t classified = 0, correct = 0;
  for (std::int32_t row = 0; row < g.height; ++row)
    for (std::int32_t col = 0; col < g.width; ++col) {
      const std::uint8_t mc = r.cls[static_cast<std::size_t>(row) * static_cast<std::size_t>(g.width) + static_cast<std::size_t>(col)];
      if (mc == 255) continue;
      const double x0 = g.origin_x + col * g.resolution, y0 = g.origin_y - row * g.resolution;
      const std::int32_t wc0 = wg.col(x0 + 0.25 * wg.resolution), wr0 = wg.row(y0 - 0.25 * wg.resolution);
      bool inside = false, match = false;
      for (int dr = 0; dr < sub; ++dr)
        for (int dc = 0; dc < sub; ++dc) {
          if (!wg.contains(wc0 + dc, wr0 + dr)) continue;
          inside = true;
          match = match || w.class_id.at<std::uint8_t>(wr0 + dr, wc0 + dc) == mc;
        }
      if (!inside) continue;
      ++classified;
      if (match) ++correct;
    }
  return classified ? static_cast<double>(correct) / static_cast<double>(classified) : 0.0;
}

std::string kv(const char* key, double v) {
  char b[96];
  std::snprintf(b, sizeof b, "%s=%.3f", key, v);
  return std::string(b);
}

// A mission file: the team (starts, guesses, priorities, waypoints), the parameters and the survey; what
// it says of the team size, radio range and altitude goes into o.
Result<std::optional<mission::MissionFile>> load_team(MissionOptions& o) {
  if (o.mission_file.empty()) return std::optional<mission::MissionFile>{};
  auto f = mission::load_mission_file(o.mission_file);
  if (!f) return f.error();
  std::optional<mission::MissionFile> mf = std::move(f).value();
  if (mf->team.empty()) return Error::make(ErrorCode::kConfig, o.mission_file + ": the team has no ground robot");
  o.ugvs = static_cast<int>(mf->team.size());
  if (mf->params.comm_range_m > 0 && o.comm_range_m <= 0) o.comm_range_m = mf->params.comm_range_m;
  o.uav_altitude_m = mf->survey.altitude_m;
  for (std::size_t i = 0; i < mf->team.size(); ++i)
    if (mf->team[i].id != static_cast<int>(i) + 1)
      std::fprintf(stderr, "airground-sim mission: %s: team member %zu has id %d; the simulator numbers ground robots 1..N in file order\n",
                   o.mission_file.c_str(), i + 1, mf->team[i].id);
  return mf;
}

std::vector<TargetCluster> mission_targets(const std::string& world) {
  if (world == "default") return default_targets();
  auto tf = load_targets(world);
  if (tf) return tf.value().targets;
  std::fprintf(stderr, "airground-sim mission: %s: no targets.yaml (%s); targets are not scored\n", world.c_str(), tf.error().message.c_str());
  return {};
}

// The mission file's team, parameters and survey over the run's options.
void apply_mission_file(RunOptions& r, const mission::MissionFile& mf, const std::string& path) {
  for (const mission::TeamMember& tm : mf.team) {
    RunOptions::UgvStart st;
    st.has_start = true;
    st.start = Pose2{tm.start_x, tm.start_y, tm.start_yaw};
    st.has_guess = true;
    st.guess = Pose2{tm.guess_x, tm.guess_y, tm.guess_yaw};
    st.guess_sigma_m = tm.guess_sigma_m;
    r.ugv_starts.push_back(st);
  }
  const mission::MissionParameters& mp = mf.params;
  for (const std::string& s : {kv("mission.visit_radius_m", mp.visit_radius_m), kv("mission.max_sigma_m", mp.max_sigma_m),
                               kv("mission.claim_timeout_s", mp.claim_timeout_s), kv("mission.idle_return_s", mp.idle_return_s),
                               kv("mission.mission_end_s", mp.mission_end_s)})
    r.ugv_config.insert(r.ugv_config.begin(), s);  // the command line's --set still wins
  r.uav_config.insert(r.uav_config.begin(), kv("regions.merge_distance_m", mp.merge_distance_m));
  r.uav_config.insert(r.uav_config.begin(), "regions.min_region_cells=" + std::to_string(mp.min_region_cells));
  if (mp.survey_end_s > 0) r.ugv_config.insert(r.ugv_config.begin(), kv("mission.survey_end_s", mp.survey_end_s));
  r.uav_return_home = mf.survey.return_home;
  r.uav_speed_mps = mf.survey.speed_mps;
  r.survey_overlap = mf.survey.overlap;
  const mission::Area& sa = mf.survey.area;
  if (sa.x1 > sa.x0 && sa.y1 > sa.y0) {
    r.survey_x0 = sa.x0;
    r.survey_y0 = sa.y0;
    r.survey_x1 = sa.x1;
    r.survey_y1 = sa.y1;
  }
  if (mf.survey.line_spacing_m > 0 || mf.survey.heading_deg != 0.0 || mf.survey.pattern != "lawnmower")
    std::fprintf(stderr, "airground-sim mission: %s: the simulated quadrotor flies an east-west lawnmower spaced by its overlap; "
                 "line_spacing_m / heading_deg / pattern are for the robot\n", path.c_str());
}

// The team run: the quadrotor over the whole world, the ground robots driven by their own stages. `mf`
// must outlive the run (the robots' configuration reads it).
RunOptions team_run_options(const MissionOptions& o, const World& w, const std::optional<mission::MissionFile>& mf) {
  const GridGeometry& g = w.grid();
  const double ax0 = g.origin_x, ay0 = g.origin_y - g.size_y(), ax1 = g.origin_x + g.size_x(), ay1 = g.origin_y;
  RunOptions r;
  r.world = o.world;
  r.out_dir = o.out_dir;
  r.ugvs = o.ugvs;
  r.uav = true;
  r.seed = o.seed;
  if (o.max_duration_s > 0) {
    r.duration_s = o.max_duration_s;
  } else {
    // The robots cannot finish before the survey does and then still drive to the last regions and home:
    // 4x the flying time: the slowest runs of the study (50 m radio range: robots idle until the quadrotor is back) took 3x.
    r.duration_s = kMinMissionCapS;
    r.duration_survey_factor = 4.0;
  }
  r.uav_altitude_m = o.uav_altitude_m;
  r.lidar_columns = o.lidar_columns;
  r.record = o.record;
  r.threads = o.threads;
  r.parallel_robots = o.parallel_robots;
  r.progress = o.progress;
  r.gossip = true;
  r.drive_by_stages = true;
  r.comm_range_m = o.comm_range_m;
  r.init_error_m = o.init_error_m;
  r.init_error_uniform = true;
  r.init_sigma_m = o.init_sigma_m;
  r.init_yaw_error_deg = o.init_yaw_error_deg;
  r.kills = o.kills;
  r.sample_hz = 5;
  r.uav_return_home = true;  // a mission file may say otherwise (survey.return_home)
  r.ugv_survey_end = true;
  r.uav_config = {kv("regions.area_x0_m", ax0), kv("regions.area_y0_m", ay0), kv("regions.area_x1_m", ax1), kv("regions.area_y1_m", ay1)};
  r.uav_config.insert(r.uav_config.end(), o.uav_config.begin(), o.uav_config.end());
  r.oracles = o.oracles;
  r.compute_time = o.compute_time;
  r.uav_cache = o.uav_cache;
  r.uav_cache_build = o.uav_cache_build;
  r.target_cpu = o.target_cpu;
  r.step_sampler = o.step_sampler;
  r.ugv_config = o.ugv_config;
  r.ugv_config_for = [&mf](int i, const Pose2& start) {
    char b[3][96];
    const mission::TeamMember* tm = mf ? &mf->team[static_cast<std::size_t>(i)] : nullptr;
    std::snprintf(b[0], sizeof b[0], "mission.priority=%d", tm != nullptr ? tm->priority : i + 1);
    std::snprintf(b[1], sizeof b[1], "mission.start_x_m=%.3f", start.x);
    std::snprintf(b[2], sizeof b[2], "mission.start_y_m=%.3f", start.y);
    std::vector<std::string> out{b[0], b[1], b[2]};
    if (tm != nullptr && mf->type == mission::MissionType::kWaypoints && !tm->waypoints.empty()) {
      std::string wp = "mission.waypoints=";
      for (std::size_t k = 0; k < tm->waypoints.size(); ++k) {
        char p[64];
        std::snprintf(p, sizeof p, "%s%.3f,%.3f", k ? ";" : "", tm->waypoints[k].x, tm->waypoints[k].y);
        wp += p;
      }
      out.push_back(wp);
    }
    return out;
  };
  if (mf) apply_mission_file(r, *mf, o.mission_file);
  if (o.web_port > 0) r.base_config = {"web.port=" + std::to_string(o.web_port)};
  return r;
}

void record_sample(MissionLog& log, const UgvSample& s) {
  Sample x;
  x.t = to_seconds(s.now);
  x.truth = s.truth;
  x.odom = s.odometry_in_map;
  static constexpr const char* kLoc[] = {"no-map", "converging", "tracking", "lost"};
  if (s.localization_received) x.loc = kLoc[static_cast<int>(s.localization->status) & 3];
  if (s.localization_received) {
    x.have_est = true;
    x.est = s.localization->pose;
    x.tracking = s.localization->status == LocalizationStatus::kTracking;
    x.err = std::hypot(s.localization->pose.x - s.truth_at_localization.x, s.localization->pose.y - s.truth_at_localization.y);
  }
  // Visits are read here, after the robot's own stages ran in this tick (its 5 Hz mission stage with
  // them), so the truth is the robot's pose when it marked the visit.
  const auto ui = static_cast<std::size_t>(s.ugv);
  if (const auto* ms = find_stage<const mission::MissionStage>(s.role)) {
    const mission::VisitedRecord& v = ms->manager().own_visited();
    for (std::uint16_t k = log.visits_seen[ui]; k < v.count; ++k) {
      Visit vis{x.t, s.ugv, v.entries[k].region_id, v.entries[k].x, v.entries[k].y};
      if (log.last_claim[ui].region == vis.region) {
        vis.have_goal = true;
        vis.goal_x = log.last_claim[ui].goal_x;
        vis.goal_y = log.last_claim[ui].goal_y;
      }
      vis.true_x = s.truth.x;
      vis.true_y = s.truth.y;
      vis.radius = ms->manager().params().visit_radius_m;
      log.visits.push_back(vis);
    }
    log.visits_seen[ui] = v.count;
  }
  log.killed[ui] = s.killed;
  log.last_sample[ui] = x;
  log.samples[ui].push_back(x);
}

// The quadrotor's regions: its regions stage's, or the replay's when its mapping is replayed.
const mission::RegionsMsg* quadrotor_regions(RoleInstance* uav) {
  if (const auto* rs = find_stage<const mission::RegionsStage>(uav)) return &rs->published();
  if (const auto* rp = find_stage<const UavReplayStage>(uav)) return &rp->published();
  return nullptr;
}

// A status line per robot on stderr (--status-period).
void print_status(const MissionLog& log, double t, RoleInstance* uav, std::size_t ugvs) {
  const auto* rs = find_stage<const mission::RegionsStage>(uav);
  std::fprintf(stderr, "t=%.0f s: quadrotor: %zu regions, %llu map tiles in, %llu extractions\n", t, log.regions.size(),
               rs ? static_cast<unsigned long long>(rs->counters().tiles_in) : 0ULL, rs ? static_cast<unsigned long long>(rs->counters().extractions) : 0ULL);
  for (std::size_t i = 0; i < ugvs; ++i) {
    const Sample& x = log.last_sample[i];
    const mission::MissionStatusMsg& st = log.status[i];
    std::fprintf(stderr, "  ugv%zu %-10s region %-10d goal (%.0f, %.0f) at (%.0f, %.0f) est (%.0f, %.0f) loc %s err %.1f m sigma %.1f m visited %u failed %u regions %u%s\n", i + 1,
                 mission::to_string(st.state), st.region_id == mission::kNoRegion ? -1 : static_cast<int>(st.region_id), st.goal_x,
                 st.goal_y, x.truth.x, x.truth.y, x.est.x, x.est.y, x.loc, x.err, st.pose_sigma_m, st.visited_own,
                 st.failed_own, st.regions_known, log.killed[i] ? " (off)" : "");
  }
}

// The team at 5 Hz: the quadrotor's regions, each robot's claims and the radio traffic.
void observe_team(MissionLog& log, const MissionOptions& o, TimeNs now, RoleInstance* uav, const std::vector<RoleInstance*>& ugvs,
                  RoleInstance* base) {
  const double t = to_seconds(now);
  if (const mission::RegionsMsg* rm = quadrotor_regions(uav)) {
    const mission::RegionsMsg& m = *rm;
    for (std::uint32_t k = 0; k < std::min<std::uint32_t>(m.count, static_cast<std::uint32_t>(m.regions.size())); ++k) log.regions[m.regions[k].id] = m.regions[k];
  }
  std::uint64_t bytes = 0;
  auto add_bytes = [&](RoleInstance* role) {
    if (const auto* c = find_stage<const comms::CommsStage>(role)) bytes += c->stats().bytes_out;
  };
  add_bytes(uav);
  add_bytes(base);
  for (std::size_t i = 0; i < ugvs.size(); ++i) {
    add_bytes(ugvs[i]);
    const auto* ms = find_stage<const mission::MissionStage>(ugvs[i]);
    if (ms == nullptr) continue;
    const mission::MissionManager& mg = ms->manager();
    const mission::MissionStatusMsg& st = mg.status();
    auto& changes = log.changes[i];
    if (changes.empty() || changes.back().state != st.state || changes.back().region != st.region_id)
      changes.push_back(StateChange{t, st.state, st.region_id});
    log.status[i] = st;
    // Back at its start with nothing left; a new region can still send it out again.
    if (st.done && log.done_at[i] < 0) log.done_at[i] = t;
    if (!st.done) log.done_at[i] = -1;
    if (st.state == mission::ClaimState::kGoing && st.region_id != mission::kNoRegion) log.last_claim[i] = Claim{st.region_id, st.goal_x, st.goal_y};
  }
  if (o.during) o.during(t);
  if (o.status_period_s > 0 && t >= log.next_status) {
    log.next_status += o.status_period_s;
    print_status(log, t, uav, ugvs.size());
  }
  if (t - log.last_traffic_t >= 5.0) {
    log.traffic_t.push_back(t);
    log.traffic_kbps.push_back(static_cast<double>(bytes - log.last_bytes) * 8.0 / 1000.0 / std::max(1e-9, t - log.last_traffic_t));
    log.last_bytes = bytes;
    log.last_traffic_t = t;
  }
}

// Hooks the log into the run; it must outlive the run.
void watch_mission(RunOptions& r, MissionLog& log, const MissionOptions& o) {
  r.sample = [&log](const UgvSample& s) { record_sample(log, s); };
  r.observe = [&log, &o](TimeNs now, RoleInstance* uav, const std::vector<RoleInstance*>& ugvs, RoleInstance* base) {
    observe_team(log, o, now, uav, ugvs, base);
  };
  // The mission is over when the quadrotor has flown its survey (no region can appear any more) and
  // every robot still running is back at its start.
  r.stop_when = [&log, n = o.ugvs](TimeNs, bool survey_done) {
    if (!survey_done) return false;
    for (int i = 0; i < n; ++i)
      if (!log.killed[static_cast<std::size_t>(i)] && log.done_at[static_cast<std::size_t>(i)] < 0) return false;
    return true;
  };
  r.inspect = [&log](const RunInspection& in) -> Status {
    if (const auto* om = find_stage<const mapping::OrthoMapStage>(in.uav)) log.raster = om->map().raster();
    if (const auto* rp = find_stage<const UavReplayStage>(in.uav)) {
      auto map = rp->final_map();
      if (!map) return map.error();
      log.raster = std::move(map).value();
    }
    return ok_status();
  };
}

// The run's own figures, and when the mission ended.
MissionMetrics score_run(const RunSummary& sum, const std::vector<TargetCluster>& targets, const MissionLog& log, int n) {
  MissionMetrics m;
  m.sim_s = sum.sim_s;
  m.wall_s = sum.wall_s;
  m.time_cap_s = sum.duration_cap_s;
  m.survey_estimate_s = sum.uav_route_estimate_s;
  m.realtime_factor = sum.real_time_factor;
  m.bytes_on_air = sum.radio_bytes_sent;
  m.compute_time = sum.compute_time;
  m.stage_overruns = sum.stage_overruns;
  m.stage_slips = sum.stage_slips;
  m.stages = sum.stages;
  m.uav_replay = sum.uav_replay;
  m.targets_total = static_cast<std::uint32_t>(targets.size());
  m.regions_found = static_cast<std::uint32_t>(log.regions.size());
  bool all_done = true;
  double last_done = 0;
  for (int i = 0; i < n; ++i) {
    const auto ui = static_cast<std::size_t>(i);
    if (log.killed[ui]) continue;
    if (log.done_at[ui] < 0) all_done = false;
    else last_done = std::max(last_done, log.done_at[ui]);
  }
  m.completed = all_done;
  m.mission_time_s = all_done ? last_done : sum.sim_s;
  return m;
}

// The targets within 10 m of a region (its centre to the target's centre or any of its cars).
std::vector<std::size_t> targets_near(const std::vector<TargetCluster>& targets, const mission::RegionRecord& rg) {
  std::vector<std::size_t> near;
  for (std::size_t ti = 0; ti < targets.size(); ++ti) {
    double dmin = std::hypot(targets[ti].x - static_cast<double>(rg.cx), targets[ti].y - static_cast<double>(rg.cy));
    for (const Pose2& c : targets[ti].car_poses) dmin = std::min(dmin, std::hypot(c.x - static_cast<double>(rg.cx), c.y - static_cast<double>(rg.cy)));
    if (dmin <= 10.0) near.push_back(ti);
  }
  return near;
}

// A visit is true when the robot's true position at the moment it marked it was within its visit radius
// of the goal; a true visit to a region with no target within 10 m is a non-target visit, counted apart.
VisitJudgement judge_visits(const std::vector<TargetCluster>& targets, const MissionLog& log, MissionMetrics& m) {
  VisitJudgement jd;
  jd.target_hit.assign(targets.size(), false);
  jd.verdict.assign(log.visits.size(), VisitVerdict::kFalse);
  for (std::size_t k = 0; k < log.visits.size(); ++k) {
    const Visit& v = log.visits[k];
    const auto it = log.regions.find(v.region);
    const double gx = v.have_goal ? v.goal_x : it != log.regions.end() ? static_cast<double>(it->second.goal_x) : v.est_x;
    const double gy = v.have_goal ? v.goal_y : it != log.regions.end() ? static_cast<double>(it->second.goal_y) : v.est_y;
    const std::vector<std::size_t> near = it != log.regions.end() ? targets_near(targets, it->second) : std::vector<std::size_t>{};
    jd.verdict[k] = judge_visit(v.true_x, v.true_y, gx, gy, v.radius, !near.empty());
    if (jd.verdict[k] == VisitVerdict::kFalse) {
      ++m.false_visits;
      continue;
    }
    jd.region_visited[v.region] = true;
    if (jd.verdict[k] == VisitVerdict::kNonTarget) {
      ++m.non_target_visits;
      continue;
    }
    for (const std::size_t ti : near) jd.target_hit[ti] = true;
  }
  m.regions_visited = static_cast<std::uint32_t>(jd.region_visited.size());
  for (const bool h : jd.target_hit) m.targets_visited += h ? 1U : 0U;
  return jd;
}

// Each robot's figures and the team's: localization against the truth, odometry alone, visits, claims.
void score_robots(const RunSummary& sum, const MissionLog& log, const VisitJudgement& jd, int n, MissionMetrics& m) {
  LocErrorScore team_loc(kLocGoodRadiusM);
  double odom_sum = 0;
  std::size_t odom_n = 0;
  for (int i = 0; i < n; ++i) {
    const auto ui = static_cast<std::size_t>(i);
    const RobotSummary& rs = sum.ugvs.at(ui);
    const mission::MissionStatusMsg& st = log.status[ui];
    MissionRobot mr;
    mr.name = rs.name;
    mr.distance_m = rs.distance_m;
    mr.collisions = rs.collisions;
    mr.killed_s = rs.killed_s;
    mr.done_s = log.done_at[ui];
    mr.visited = st.visited_own;
    mr.failed = st.failed_own;
    mr.final_state = mission::to_string(st.state);
    m.takeovers += st.takeovers;
    m.clashes_lost += st.clashes_lost;
    std::vector<LocErrorSample> loc;
    double od = 0;
    for (const Sample& s : log.samples[ui]) {
      loc.push_back(LocErrorSample{s.have_est, s.tracking, s.err});
      od += std::hypot(s.odom.x - s.truth.x, s.odom.y - s.truth.y);
      if (mr.first_tracking_s < 0 && s.tracking) mr.first_tracking_s = s.t;
    }
    for (std::size_t k = 0; k < log.visits.size(); ++k) {
      if (log.visits[k].robot != i) continue;
      if (jd.verdict[k] == VisitVerdict::kFalse) ++mr.false_visits;
      if (jd.verdict[k] == VisitVerdict::kNonTarget) ++mr.non_target_visits;
    }
    LocErrorScore own(kLocGoodRadiusM);
    own.add_robot(loc);
    team_loc.add_robot(loc);
    mr.loc = own.stats();
    mr.loc_error_mean_m = mr.loc.mean_m;
    mr.loc_error_p95_m = mr.loc.p95_m;
    mr.odom_only_error_mean_m = log.samples[ui].empty() ? 0.0 : od / static_cast<double>(log.samples[ui].size());
    odom_sum += od;
    odom_n += log.samples[ui].size();
    m.collisions += rs.collisions;
    m.failed_goals += st.failed_own;
    m.robots.push_back(mr);
  }
  m.loc = team_loc.stats();
  m.loc_error_mean_m = m.loc.mean_m;
  m.loc_error_p95_m = m.loc.p95_m;
  m.odom_only_error_mean_m = odom_n ? odom_sum / static_cast<double>(odom_n) : 0.0;
}

}  // namespace

}  // namespace mission_eval

Result<MissionMetrics> run_mission(const MissionOptions& options, const ProgressFn& progress) {
  using namespace mission_eval;
  MissionOptions o = options;
  auto mf = load_team(o);
  if (!mf) return mf.error();
  if (o.ugvs < 1 || o.ugvs > 32) return Error::make(ErrorCode::kInvalidArgument, "--ugvs must be 1..32");
  if (!(o.max_duration_s >= 0)) return Error::make(ErrorCode::kInvalidArgument, "--max-duration must be >= 0 (0: four times the survey time)");
  auto world = resolve_world(o.world);
  if (!world) return world.error();
  const World& w = *world.value();
  std::error_code ec;
  fs::create_directories(fs::path(o.out_dir) / "maps", ec);
  if (ec) return Error::make(ErrorCode::kIo, "cannot create " + o.out_dir + ": " + ec.message());

  const int n = o.ugvs;
  RunOptions r = team_run_options(o, w, mf.value());
  std::vector<int> outside;
  const MapRect surveyed = survey_area(w, UavSurveyOptions{r.uav_altitude_m, r.survey_overlap, r.uav_speed_mps, r.survey_margin_m, r.survey_x0,
                                                            r.survey_y0, r.survey_x1, r.survey_y1});
  const std::vector<TargetCluster> targets = targets_in_area(mission_targets(o.world), surveyed, outside);
  if (!outside.empty()) {
    std::string ids;
    for (const int id : outside) ids += (ids.empty() ? "" : ", ") + std::to_string(id);
    std::fprintf(stderr, "airground-sim mission: the world's target%s %s %s no car in the surveyed area (x %.0f..%.0f, y %.0f..%.0f m): not scored\n",
                 outside.size() > 1 ? "s" : "", ids.c_str(), outside.size() > 1 ? "have" : "has", surveyed.x0, surveyed.x1, surveyed.y0, surveyed.y1);
  }
  MissionLog log(static_cast<std::size_t>(n), o.status_period_s);
  watch_mission(r, log, o);
  const auto wall0 = std::chrono::steady_clock::now();
  auto paced = [&](double sim_s, double total_s, double rtf) {
    if (o.web_pace > 0) {
      const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
      const double want = sim_s / o.web_pace;
      if (want > wall) std::this_thread::sleep_for(std::chrono::duration<double>(want - wall));
    }
    if (progress) progress(sim_s, total_s, rtf);
  };
  auto run = run_team(r, paced);
  if (!run) return run.error();
  const RunSummary& sum = run.value();

  MissionMetrics m = score_run(sum, targets, log, n);
  m.targets_outside_survey = static_cast<std::uint32_t>(outside.size());
  m.outside_survey_ids = outside;
  const VisitJudgement judged = judge_visits(targets, log, m);
  score_robots(sum, log, judged, n, m);
  if (!log.raster.cls.empty()) m.map_class_accuracy = class_accuracy(w, log.raster);
  if (auto st = write_mission_files(o, w, targets, log, judged, m); !st) return st.error();
  return m;
}

}  // namespace ag::sim
