// A team mission in the lockstep runner, scored against the world's targets and the true poses.
#include <nlohmann/json.hpp>
#include "airground/sim/eval_mission.hpp"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <thread>

#include "airground/aerial_mapping/stages.hpp"
#include "airground/comms/stage.hpp"
#include "airground/core/messages.hpp"
#include "airground/mission/mission_file.hpp"
#include "airground/mission/stages.hpp"
#include "airground/platform/role_instance.hpp"
#include "airground/sim/eval_scoring.hpp"
#include "airground/sim/generator.hpp"
#include "airground/sim/map_export.hpp"
#include "airground/sim/plot.hpp"
#include "airground/sim/world_png.hpp"

namespace ag::sim {

namespace {

namespace fs = std::filesystem;

struct Sample {
  double t{0};
  Pose2 truth, odom;
  bool have_est{false};  // the robot had published a pose
  bool tracking{false};
  double err{-1};        // [m] its estimate against the truth at the estimate's stamp, tracking or not
  const char* loc{"none"};  // localization status
};

struct Visit {
  double t{0};
  int robot{0};
  std::uint32_t region{0};
  double est_x{0}, est_y{0};
  bool have_goal{false};  // the goal the robot was sent to (a region's goal moves as the map grows)
  double goal_x{0}, goal_y{0};
  double true_x{0}, true_y{0};  // [m] where the robot truly stood when it marked the visit
  double radius{3.0};           // [m] its visit radius
};
struct Claim {
  std::uint32_t region{mission::kNoRegion};
  double goal_x{0}, goal_y{0};
};

struct StateChange {
  double t{0};
  mission::ClaimState state{mission::ClaimState::kIdle};
  std::uint32_t region{mission::kNoRegion};
};

cv::Scalar state_colour(mission::ClaimState s) {
  switch (s) {
    case mission::ClaimState::kIdle: return {200, 200, 200};
    case mission::ClaimState::kGoing: return {180, 119, 31};
    case mission::ClaimState::kReturning: return {189, 103, 148};
    case mission::ClaimState::kDone: return {44, 160, 44};
    case mission::ClaimState::kFailedRetrying: return {40, 39, 214};
    case mission::ClaimState::kStopped: return {60, 60, 60};
  }
  return {0, 0, 0};
}

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

}  // namespace

Result<MissionMetrics> run_mission(const MissionOptions& options, const ProgressFn& progress) {
  MissionOptions o = options;
  // A mission file: the team (starts, guesses, priorities, waypoints), the parameters and the survey.
  std::optional<mission::MissionFile> mf;
  if (!o.mission_file.empty()) {
    auto f = mission::load_mission_file(o.mission_file);
    if (!f) return f.error();
    mf = std::move(f).value();
    if (mf->team.empty()) return Error::make(ErrorCode::kConfig, o.mission_file + ": the team has no ground robot");
    o.ugvs = static_cast<int>(mf->team.size());
    if (mf->params.comm_range_m > 0 && o.comm_range_m <= 0) o.comm_range_m = mf->params.comm_range_m;
    o.uav_altitude_m = mf->survey.altitude_m;
    for (std::size_t i = 0; i < mf->team.size(); ++i)
      if (mf->team[i].id != static_cast<int>(i) + 1)
        std::fprintf(stderr, "airground-sim mission: %s: team member %zu has id %d; the simulator numbers ground robots 1..N in file order\n",
                     o.mission_file.c_str(), i + 1, mf->team[i].id);
  }
  if (o.ugvs < 1 || o.ugvs > 32) return Error::make(ErrorCode::kInvalidArgument, "--ugvs must be 1..32");
  if (!(o.max_duration_s >= 0)) return Error::make(ErrorCode::kInvalidArgument, "--max-duration must be >= 0 (0: four times the survey time)");
  auto world = resolve_world(o.world);
  if (!world) return world.error();
  const World& w = *world.value();
  std::vector<TargetCluster> targets;
  if (o.world == "default") {
    targets = default_targets();
  } else {
    auto tf = load_targets(o.world);
    if (tf) targets = tf.value().targets;
    else std::fprintf(stderr, "airground-sim mission: %s: no targets.yaml (%s); targets are not scored\n", o.world.c_str(), tf.error().message.c_str());
  }
  std::error_code ec;
  fs::create_directories(fs::path(o.out_dir) / "maps", ec);
  if (ec) return Error::make(ErrorCode::kIo, "cannot create " + o.out_dir + ": " + ec.message());

  const int n = o.ugvs;
  const GridGeometry& g = w.grid();
  char area[256];
  std::snprintf(area, sizeof area, "%.3f|%.3f|%.3f|%.3f", g.origin_x, g.origin_y - g.size_y(), g.origin_x + g.size_x(), g.origin_y);
  const double ax0 = g.origin_x, ay0 = g.origin_y - g.size_y(), ax1 = g.origin_x + g.size_x(), ay1 = g.origin_y;
  auto kv = [](const char* key, double v) {
    char b[96];
    std::snprintf(b, sizeof b, "%s=%.3f", key, v);
    return std::string(b);
  };

  RunOptions r;
  r.world = o.world;
  r.out_dir = o.out_dir;
  r.ugvs = n;
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
  r.init_yaw_error_deg = o.init_yaw_error_deg;
  r.kills = o.kills;
  r.sample_hz = 5;
  r.uav_return_home = true;  // a mission file may say otherwise (survey.return_home)
  r.ugv_survey_end = true;
  r.uav_config = {kv("regions.area_x0_m", ax0), kv("regions.area_y0_m", ay0), kv("regions.area_x1_m", ax1), kv("regions.area_y1_m", ay1)};
  r.uav_config.insert(r.uav_config.end(), o.uav_config.begin(), o.uav_config.end());
  r.oracles = o.oracles;
  r.compute_time = o.compute_time;
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
  if (mf) {
    for (const mission::TeamMember& tm : mf->team) {
      RunOptions::UgvStart st;
      st.has_start = true;
      st.start = Pose2{tm.start_x, tm.start_y, tm.start_yaw};
      st.has_guess = true;
      st.guess = Pose2{tm.guess_x, tm.guess_y, tm.guess_yaw};
      st.guess_sigma_m = tm.guess_sigma_m;
      r.ugv_starts.push_back(st);
    }
    const mission::MissionParameters& mp = mf->params;
    for (const std::string& s : {kv("mission.visit_radius_m", mp.visit_radius_m), kv("mission.max_sigma_m", mp.max_sigma_m),
                                 kv("mission.claim_timeout_s", mp.claim_timeout_s), kv("mission.idle_return_s", mp.idle_return_s),
                                 kv("mission.mission_end_s", mp.mission_end_s)})
      r.ugv_config.insert(r.ugv_config.begin(), s);  // the command line's --set still wins
    r.uav_config.insert(r.uav_config.begin(), kv("regions.merge_distance_m", mp.merge_distance_m));
    r.uav_config.insert(r.uav_config.begin(), "regions.min_region_cells=" + std::to_string(mp.min_region_cells));
    if (mp.survey_end_s > 0) r.ugv_config.insert(r.ugv_config.begin(), kv("mission.survey_end_s", mp.survey_end_s));
    r.uav_return_home = mf->survey.return_home;
    r.uav_speed_mps = mf->survey.speed_mps;
    r.survey_overlap = mf->survey.overlap;
    const mission::Area& sa = mf->survey.area;
    if (sa.x1 > sa.x0 && sa.y1 > sa.y0) {
      r.survey_x0 = sa.x0;
      r.survey_y0 = sa.y0;
      r.survey_x1 = sa.x1;
      r.survey_y1 = sa.y1;
    }
    if (mf->survey.line_spacing_m > 0 || mf->survey.heading_deg != 0.0 || mf->survey.pattern != "lawnmower")
      std::fprintf(stderr, "airground-sim mission: %s: the simulated quadrotor flies an east-west lawnmower spaced by its overlap; "
                   "line_spacing_m / heading_deg / pattern are for the robot\n", o.mission_file.c_str());
  }
  if (o.web_port > 0) r.base_config = {"web.port=" + std::to_string(o.web_port)};

  // What the mission looks like as it runs.
  std::vector<std::vector<Sample>> samples(static_cast<std::size_t>(n));
  std::vector<std::vector<StateChange>> changes(static_cast<std::size_t>(n));
  std::vector<mission::MissionStatusMsg> status(static_cast<std::size_t>(n));
  std::vector<std::uint16_t> visits_seen(static_cast<std::size_t>(n), 0);
  std::vector<double> done_at(static_cast<std::size_t>(n), -1.0);
  std::vector<bool> killed(static_cast<std::size_t>(n), false);
  std::vector<Visit> visits;
  std::vector<Claim> last_claim(static_cast<std::size_t>(n));
  std::map<std::uint32_t, mission::RegionRecord> regions;  // newest record of every region id
  std::vector<double> traffic_t, traffic_kbps;
  std::uint64_t last_bytes = 0;
  double last_traffic_t = 0;
  const mapping::OrthoMapStage* ortho = nullptr;
  double next_status = o.status_period_s;
  std::vector<Sample> last_sample(static_cast<std::size_t>(n));

  r.sample = [&](const UgvSample& s) {
    Sample x;
    x.t = to_seconds(s.now);
    x.truth = s.truth;
    x.odom = s.odometry_in_map;
    static constexpr const char* kLoc[] = {"no-map", "converging", "tracking", "lost"};
    if (s.localization_received) x.loc = kLoc[static_cast<int>(s.localization->status) & 3];
    if (s.localization_received) {
      x.have_est = true;
      x.tracking = s.localization->status == LocalizationStatus::kTracking;
      x.err = std::hypot(s.localization->pose.x - s.truth_at_localization.x, s.localization->pose.y - s.truth_at_localization.y);
    }
    // Visits are read here, after the robot's own stages ran in this tick (its 5 Hz mission stage with
    // them), so the truth is the robot's pose when it marked the visit.
    const auto ui = static_cast<std::size_t>(s.ugv);
    if (const auto* ms = find_stage<const mission::MissionStage>(s.role)) {
      const mission::VisitedRecord& v = ms->manager().own_visited();
      for (std::uint16_t k = visits_seen[ui]; k < v.count; ++k) {
        Visit vis{x.t, s.ugv, v.entries[k].region_id, v.entries[k].x, v.entries[k].y};
        if (last_claim[ui].region == vis.region) {
          vis.have_goal = true;
          vis.goal_x = last_claim[ui].goal_x;
          vis.goal_y = last_claim[ui].goal_y;
        }
        vis.true_x = s.truth.x;
        vis.true_y = s.truth.y;
        vis.radius = ms->manager().params().visit_radius_m;
        visits.push_back(vis);
      }
      visits_seen[ui] = v.count;
    }
    killed[static_cast<std::size_t>(s.ugv)] = s.killed;
    last_sample[static_cast<std::size_t>(s.ugv)] = x;
    samples[static_cast<std::size_t>(s.ugv)].push_back(x);
  };
  r.observe = [&](TimeNs now, RoleInstance* uav, const std::vector<RoleInstance*>& ugvs, RoleInstance* base) {
    const double t = to_seconds(now);
    if (const auto* rs = find_stage<const mission::RegionsStage>(uav)) {
      const mission::RegionsMsg& m = rs->published();
      for (std::uint32_t k = 0; k < std::min<std::uint32_t>(m.count, static_cast<std::uint32_t>(m.regions.size())); ++k) regions[m.regions[k].id] = m.regions[k];
    }
    if (ortho == nullptr) ortho = find_stage<const mapping::OrthoMapStage>(uav);
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
      if (changes[i].empty() || changes[i].back().state != st.state || changes[i].back().region != st.region_id)
        changes[i].push_back(StateChange{t, st.state, st.region_id});
      status[i] = st;
      // Back at its start with nothing left; a new region can still send it out again.
      if (st.done && done_at[i] < 0) done_at[i] = t;
      if (!st.done) done_at[i] = -1;
      if (st.state == mission::ClaimState::kGoing && st.region_id != mission::kNoRegion) last_claim[i] = Claim{st.region_id, st.goal_x, st.goal_y};
    }
    if (o.during) o.during(t);
    if (o.status_period_s > 0 && t >= next_status) {
      next_status += o.status_period_s;
      const auto* rs = find_stage<const mission::RegionsStage>(uav);
      std::fprintf(stderr, "t=%.0f s: quadrotor: %zu regions, %llu map tiles in, %llu extractions\n", t, regions.size(),
                   rs ? static_cast<unsigned long long>(rs->counters().tiles_in) : 0ULL, rs ? static_cast<unsigned long long>(rs->counters().extractions) : 0ULL);
      for (std::size_t i = 0; i < ugvs.size(); ++i) {
        const Sample& x = last_sample[i];
        std::fprintf(stderr, "  ugv%zu %-10s region %-10d goal (%.0f, %.0f) at (%.0f, %.0f) loc %s err %.1f m sigma %.1f m visited %u failed %u regions %u%s\n", i + 1,
                     mission::to_string(status[i].state), status[i].region_id == mission::kNoRegion ? -1 : static_cast<int>(status[i].region_id), status[i].goal_x,
                     status[i].goal_y, x.truth.x, x.truth.y, x.loc, x.err, status[i].pose_sigma_m, status[i].visited_own,
                     status[i].failed_own, status[i].regions_known, killed[i] ? " (off)" : "");
      }
    }
    if (t - last_traffic_t >= 5.0) {
      traffic_t.push_back(t);
      traffic_kbps.push_back(static_cast<double>(bytes - last_bytes) * 8.0 / 1000.0 / std::max(1e-9, t - last_traffic_t));
      last_bytes = bytes;
      last_traffic_t = t;
    }
  };
  // The mission is over when the quadrotor has flown its survey (no region can appear any more) and
  // every robot still running is back at its start.
  r.stop_when = [&](TimeNs, bool survey_done) {
    if (!survey_done) return false;
    for (int i = 0; i < n; ++i)
      if (!killed[static_cast<std::size_t>(i)] && done_at[static_cast<std::size_t>(i)] < 0) return false;
    return true;
  };
  mapping::MapRaster raster;
  r.inspect = [&](const RunInspection& in) -> Status {
    if (const auto* om = find_stage<const mapping::OrthoMapStage>(in.uav)) raster = om->map().raster();
    return ok_status();
  };
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

  // Scoring.
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
  m.targets_total = static_cast<std::uint32_t>(targets.size());
  m.regions_found = static_cast<std::uint32_t>(regions.size());
  bool all_done = true;
  double last_done = 0;
  for (int i = 0; i < n; ++i) {
    const auto ui = static_cast<std::size_t>(i);
    if (killed[ui]) continue;
    if (done_at[ui] < 0) all_done = false;
    else last_done = std::max(last_done, done_at[ui]);
  }
  m.completed = all_done;
  m.mission_time_s = all_done ? last_done : sum.sim_s;
  // A visit is true when the robot's true position at the moment it marked it was within its visit radius
  // of the goal; a true visit to a region with no target within 10 m is a non-target visit, counted apart.
  std::vector<bool> target_hit(targets.size(), false);
  std::map<std::uint32_t, bool> region_visited;
  std::vector<VisitVerdict> verdict(visits.size(), VisitVerdict::kFalse);
  auto targets_near = [&](const mission::RegionRecord& rg) {
    std::vector<std::size_t> near;
    for (std::size_t ti = 0; ti < targets.size(); ++ti) {
      double dmin = std::hypot(targets[ti].x - static_cast<double>(rg.cx), targets[ti].y - static_cast<double>(rg.cy));
      for (const Pose2& c : targets[ti].car_poses) dmin = std::min(dmin, std::hypot(c.x - static_cast<double>(rg.cx), c.y - static_cast<double>(rg.cy)));
      if (dmin <= 10.0) near.push_back(ti);
    }
    return near;
  };
  for (std::size_t k = 0; k < visits.size(); ++k) {
    const Visit& v = visits[k];
    const auto it = regions.find(v.region);
    const double gx = v.have_goal ? v.goal_x : it != regions.end() ? static_cast<double>(it->second.goal_x) : v.est_x;
    const double gy = v.have_goal ? v.goal_y : it != regions.end() ? static_cast<double>(it->second.goal_y) : v.est_y;
    const std::vector<std::size_t> near = it != regions.end() ? targets_near(it->second) : std::vector<std::size_t>{};
    verdict[k] = judge_visit(v.true_x, v.true_y, gx, gy, v.radius, !near.empty());
    if (verdict[k] == VisitVerdict::kFalse) {
      ++m.false_visits;
      continue;
    }
    region_visited[v.region] = true;
    if (verdict[k] == VisitVerdict::kNonTarget) {
      ++m.non_target_visits;
      continue;
    }
    for (const std::size_t ti : near) target_hit[ti] = true;
  }
  m.regions_visited = static_cast<std::uint32_t>(region_visited.size());
  for (const bool h : target_hit) m.targets_visited += h ? 1U : 0U;
  LocErrorScore team_loc(kLocGoodRadiusM);
  double odom_sum = 0;
  std::size_t odom_n = 0;
  for (int i = 0; i < n; ++i) {
    const auto ui = static_cast<std::size_t>(i);
    const RobotSummary& rs = sum.ugvs.at(ui);
    MissionRobot mr;
    mr.name = rs.name;
    mr.distance_m = rs.distance_m;
    mr.collisions = rs.collisions;
    mr.killed_s = rs.killed_s;
    mr.done_s = done_at[ui];
    mr.visited = status[ui].visited_own;
    mr.failed = status[ui].failed_own;
    mr.final_state = mission::to_string(status[ui].state);
    m.takeovers += status[ui].takeovers;
    m.clashes_lost += status[ui].clashes_lost;
    std::vector<LocErrorSample> loc;
    double od = 0;
    for (const Sample& s : samples[ui]) {
      loc.push_back(LocErrorSample{s.have_est, s.tracking, s.err});
      od += std::hypot(s.odom.x - s.truth.x, s.odom.y - s.truth.y);
      if (mr.first_tracking_s < 0 && s.tracking) mr.first_tracking_s = s.t;
    }
    for (std::size_t k = 0; k < visits.size(); ++k) {
      if (visits[k].robot != i) continue;
      if (verdict[k] == VisitVerdict::kFalse) ++mr.false_visits;
      if (verdict[k] == VisitVerdict::kNonTarget) ++mr.non_target_visits;
    }
    LocErrorScore own(kLocGoodRadiusM);
    own.add_robot(loc);
    team_loc.add_robot(loc);
    mr.loc = own.stats();
    mr.loc_error_mean_m = mr.loc.mean_m;
    mr.loc_error_p95_m = mr.loc.p95_m;
    mr.odom_only_error_mean_m = samples[ui].empty() ? 0.0 : od / static_cast<double>(samples[ui].size());
    odom_sum += od;
    odom_n += samples[ui].size();
    m.collisions += rs.collisions;
    m.failed_goals += status[ui].failed_own;
    m.robots.push_back(mr);
  }
  m.loc = team_loc.stats();
  m.loc_error_mean_m = m.loc.mean_m;
  m.loc_error_p95_m = m.loc.p95_m;
  m.odom_only_error_mean_m = odom_n ? odom_sum / static_cast<double>(odom_n) : 0.0;
  if (!raster.cls.empty()) m.map_class_accuracy = class_accuracy(w, raster);

  // Files: maps, pictures, metrics, report.
  const fs::path out(o.out_dir);
  if (!raster.cls.empty())
    if (auto st = write_map_exports((out / "maps").string(), raster, w.header.datum); !st) return st.error();
  {  // the mission over the world: trails, regions, visits, targets
    cv::Mat bgr;
    cv::cvtColor(class_display_image(w.class_id), bgr, cv::COLOR_RGB2BGR);
    const double scale = std::min(1.0, 1600.0 / std::max(bgr.cols, bgr.rows));
    if (scale < 1.0) cv::resize(bgr, bgr, cv::Size(), scale, scale, cv::INTER_AREA);
    cv::Mat dim;
    cv::addWeighted(bgr, 0.55, cv::Mat(bgr.size(), bgr.type(), cv::Scalar(255, 255, 255)), 0.45, 0, dim);
    bgr = dim;
    auto px = [&](double x, double y) { return cv::Point(static_cast<int>(g.col_f(x) * scale), static_cast<int>(g.row_f(y) * scale)); };
    for (const auto& t : targets) {
      cv::drawMarker(bgr, px(t.x, t.y), cv::Scalar(0, 200, 255), cv::MARKER_TILTED_CROSS, 14, 2);
    }
    for (const auto& [id, rg] : regions) {
      cv::circle(bgr, px(rg.cx, rg.cy), 9, cv::Scalar(0, 140, 255), 1, cv::LINE_AA);
      cv::putText(bgr, std::to_string(id), px(rg.cx, rg.cy) + cv::Point(10, -6), cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(0, 80, 160), 1, cv::LINE_AA);
      if (rg.goal_valid) cv::drawMarker(bgr, px(rg.goal_x, rg.goal_y), region_visited.count(id) ? cv::Scalar(0, 170, 0) : cv::Scalar(0, 0, 220), cv::MARKER_DIAMOND, 10, 2);
    }
    for (int i = 0; i < n; ++i) {
      const auto& sm = samples[static_cast<std::size_t>(i)];
      const cv::Scalar c = series_colour(static_cast<std::size_t>(i));
      for (std::size_t k = 1; k < sm.size(); ++k) cv::line(bgr, px(sm[k - 1].truth.x, sm[k - 1].truth.y), px(sm[k].truth.x, sm[k].truth.y), c, 2, cv::LINE_AA);
      if (!sm.empty()) cv::circle(bgr, px(sm.back().truth.x, sm.back().truth.y), 5, c, cv::FILLED, cv::LINE_AA);
    }
    for (std::size_t k = 0; k < visits.size(); ++k)
      cv::drawMarker(bgr, px(visits[k].est_x, visits[k].est_y), verdict[k] == VisitVerdict::kFalse ? cv::Scalar(0, 0, 255)
                     : verdict[k] == VisitVerdict::kNonTarget ? cv::Scalar(200, 120, 0) : cv::Scalar(0, 120, 0), cv::MARKER_STAR, 12, 2);
    cv::imwrite((out / "mission_map.png").string(), bgr);
  }
  {
    std::vector<PlotSeries> err_series, odom_series;
    for (int i = 0; i < n; ++i) {
      PlotSeries s{"ugv" + std::to_string(i + 1), {}, {}, series_colour(static_cast<std::size_t>(i)), true};
      PlotSeries od{"ugv" + std::to_string(i + 1) + " odometry", {}, {}, series_colour(static_cast<std::size_t>(i)), false};
      for (const Sample& x : samples[static_cast<std::size_t>(i)]) {
        if (x.tracking) {
          s.x.push_back(x.t);
          s.y.push_back(x.err);
        }
        od.x.push_back(x.t);
        od.y.push_back(std::hypot(x.odom.x - x.truth.x, x.odom.y - x.truth.y));
      }
      err_series.push_back(std::move(s));
      odom_series.push_back(std::move(od));
    }
    PlotOptions po;
    po.title = "Ground robots: localization error while tracking (dots), 3 m line";
    po.x_label = "simulated time [s]";
    po.y_label = "error [m]";
    po.h_lines = {3.0};
    cv::imwrite((out / "pose_error.png").string(), line_plot(err_series, po));
    po.title = "Wheel odometry alone: error against the truth";
    po.h_lines = {};
    cv::imwrite((out / "odometry_error.png").string(), line_plot(odom_series, po));
    PlotOptions pt;
    pt.title = "Radio traffic (all robots' comms stages, sent)";
    pt.x_label = "simulated time [s]";
    pt.y_label = "kbit/s";
    cv::imwrite((out / "comms_traffic.png").string(), line_plot({PlotSeries{"team", traffic_t, traffic_kbps, series_colour(0), false}}, pt));
    std::vector<TimelineLane> lanes;
    for (int i = 0; i < n; ++i) {
      TimelineLane lane{"ugv" + std::to_string(i + 1), {}};
      const auto& ch = changes[static_cast<std::size_t>(i)];
      for (std::size_t k = 0; k < ch.size(); ++k) {
        const double t1 = k + 1 < ch.size() ? ch[k + 1].t : sum.sim_s;
        lane.spans.push_back(TimelineSpan{ch[k].t, t1, state_colour(ch[k].state), ch[k].region != mission::kNoRegion ? "R" + std::to_string(ch[k].region) : ""});
      }
      lanes.push_back(std::move(lane));
    }
    std::vector<std::pair<std::string, cv::Scalar>> legend;
    for (auto s : {mission::ClaimState::kIdle, mission::ClaimState::kGoing, mission::ClaimState::kReturning, mission::ClaimState::kDone,
                   mission::ClaimState::kFailedRetrying, mission::ClaimState::kStopped})
      legend.emplace_back(mission::to_string(s), state_colour(s));
    cv::imwrite((out / "claims_timeline.png").string(), timeline_plot(lanes, sum.sim_s, "Claims: each robot's state and claimed region", legend));
  }
  {
    std::ofstream v(out / "visits.csv");
    v << "t_s,robot,region,est_x_m,est_y_m,goal_x_m,goal_y_m,true_x_m,true_y_m,visit_radius_m,true_visit,verdict\n";
    for (std::size_t k = 0; k < visits.size(); ++k) {
      const auto it = regions.find(visits[k].region);
      const double gx = visits[k].have_goal ? visits[k].goal_x : it != regions.end() ? static_cast<double>(it->second.goal_x) : 0.0;
      const double gy = visits[k].have_goal ? visits[k].goal_y : it != regions.end() ? static_cast<double>(it->second.goal_y) : 0.0;
      v << visits[k].t << ",ugv" << visits[k].robot + 1 << "," << visits[k].region << "," << visits[k].est_x << "," << visits[k].est_y << "," << gx
        << "," << gy << "," << visits[k].true_x << "," << visits[k].true_y << "," << visits[k].radius << ","
        << (verdict[k] == VisitVerdict::kFalse ? 0 : 1) << "," << verdict_name(verdict[k]) << "\n";
    }
    std::ofstream rc(out / "regions.csv");
    rc << "region,cx_m,cy_m,goal_x_m,goal_y_m,cells,goal_valid,visited,target\n";
    for (const auto& [id, rg] : regions) {
      int tgt = -1;
      double best = 10.0;
      for (std::size_t ti = 0; ti < targets.size(); ++ti) {
        double dmin = std::hypot(targets[ti].x - static_cast<double>(rg.cx), targets[ti].y - static_cast<double>(rg.cy));
        for (const Pose2& c : targets[ti].car_poses) dmin = std::min(dmin, std::hypot(c.x - static_cast<double>(rg.cx), c.y - static_cast<double>(rg.cy)));
        if (dmin <= best) {
          best = dmin;
          tgt = targets[ti].id;
        }
      }
      rc << id << "," << rg.cx << "," << rg.cy << "," << rg.goal_x << "," << rg.goal_y << "," << rg.cells << "," << (rg.goal_valid ? 1 : 0) << ","
         << (region_visited.count(id) ? 1 : 0) << "," << tgt << "\n";
    }
    std::ofstream tc(out / "targets.csv");
    tc << "target,x_m,y_m,cars,visited\n";
    for (std::size_t ti = 0; ti < targets.size(); ++ti)
      tc << targets[ti].id << "," << targets[ti].x << "," << targets[ti].y << "," << targets[ti].cars << "," << (target_hit[ti] ? 1 : 0) << "\n";
  }
  std::ofstream j(out / "metrics.json");
  RunOptions oracle_list;
  oracle_list.oracles = o.oracles;
  j << "{\n  \"oracles\": " << oracle_list.oracles_json() << ",\n  \"targets_total\": " << m.targets_total << ",\n  \"targets_visited\": " << m.targets_visited
    << ",\n  \"regions_found\": " << m.regions_found << ",\n  \"regions_visited\": " << m.regions_visited
    << ",\n  \"mission_time_s\": " << m.mission_time_s << ",\n  \"completed\": " << (m.completed ? "true" : "false")
    << ",\n  \"time_cap_s\": " << m.time_cap_s << ",\n  \"survey_estimate_s\": " << m.survey_estimate_s
    << ",\n  \"loc_error_mean_m\": " << m.loc_error_mean_m << ",\n  \"loc_error_p95_m\": " << m.loc_error_p95_m
    << ",\n  \"loc_error_max_m\": " << m.loc.max_m << ",\n  \"loc_error_tracking_mean_m\": " << m.loc.tracking_mean_m
    << ",\n  \"loc_error_tracking_p95_m\": " << m.loc.tracking_p95_m << ",\n  \"loc_error_tracking_max_m\": " << m.loc.tracking_max_m
    << ",\n  \"tracking_fraction\": " << m.loc.tracking_fraction << ",\n  \"within_3m_fraction\": " << m.loc.within_fraction
    << ",\n  \"loc_samples_scored\": " << m.loc.samples
    << ",\n  \"odom_only_error_mean_m\": " << m.odom_only_error_mean_m << ",\n  \"collisions\": " << m.collisions
    << ",\n  \"failed_goals\": " << m.failed_goals << ",\n  \"false_visits\": " << m.false_visits
    << ",\n  \"non_target_visits\": " << m.non_target_visits << ",\n  \"scoring\": \"strict\""
    << ",\n  \"takeovers\": " << m.takeovers << ",\n  \"clashes_lost\": " << m.clashes_lost
    << ",\n  \"map_class_accuracy\": " << m.map_class_accuracy << ",\n  \"bytes_on_air\": " << m.bytes_on_air
    << ",\n  \"realtime_factor\": " << m.realtime_factor << ",\n  \"sim_s\": " << m.sim_s << ",\n  \"wall_s\": " << m.wall_s
    << ",\n  \"compute_time\": \"" << m.compute_time << "\",\n  \"stage_overruns\": " << m.stage_overruns
    << ",\n  \"stage_slips\": " << m.stage_slips << ",\n  \"stages\": [";
  for (std::size_t i = 0; i < m.stages.size(); ++i) {
    const auto& c = m.stages[i];
    j << (i ? ", " : "") << "{\"name\": \"" << c.name << "\", \"runs\": " << c.runs << ", \"overruns\": " << c.overruns
      << ", \"slips\": " << c.slips << ", \"exec_p99_ms\": " << c.exec_p99_ms << ", \"budget_ms\": " << c.budget_ms << "}";
  }
  j << "]"
    << ",\n  \"world\": " << nlohmann::json(o.world).dump()
    << ",\n  \"ugvs\": " << n << ",\n  \"seed\": " << o.seed << ",\n  \"comm_range_m\": " << o.comm_range_m << ",\n  \"robots\": [";
  for (std::size_t i = 0; i < m.robots.size(); ++i) {
    const MissionRobot& x = m.robots[i];
    j << (i ? "," : "") << "\n    {\"name\": \"" << x.name << "\", \"distance_m\": " << x.distance_m << ", \"collisions\": " << x.collisions
      << ", \"visited\": " << x.visited << ", \"failed\": " << x.failed << ", \"false_visits\": " << x.false_visits
      << ", \"non_target_visits\": " << x.non_target_visits
      << ", \"loc_error_mean_m\": " << x.loc_error_mean_m << ", \"loc_error_p95_m\": " << x.loc_error_p95_m
      << ", \"loc_error_max_m\": " << x.loc.max_m << ", \"loc_error_tracking_mean_m\": " << x.loc.tracking_mean_m
      << ", \"loc_error_tracking_p95_m\": " << x.loc.tracking_p95_m << ", \"tracking_fraction\": " << x.loc.tracking_fraction
      << ", \"within_3m_fraction\": " << x.loc.within_fraction
      << ", \"odom_only_error_mean_m\": " << x.odom_only_error_mean_m << ", \"first_tracking_s\": " << x.first_tracking_s
      << ", \"done_s\": " << x.done_s << ", \"killed_s\": " << x.killed_s << ", \"final_state\": \"" << x.final_state << "\"}";
  }
  j << "\n  ]\n}\n";
  std::ofstream md(out / "report.md");
  char line[1536];
  md << "# airground mission report\n\n" << oracle_list.oracles_line() << "\n\nWorld `" << o.world << "`, seed " << o.seed << ": 1 quadrotor at " << o.uav_altitude_m << " m, " << n
     << " ground robots (initial guesses up to " << o.init_error_m << " m off), radio range "
     << (o.comm_range_m > 0 ? std::to_string(static_cast<int>(o.comm_range_m)) + " m" : std::string("default")) << ". "
     << (m.completed ? "Every robot finished and returned to its start." : "The mission hit the time cap before every robot finished.")
     << " The survey was estimated at " << static_cast<int>(std::lround(m.survey_estimate_s)) << " s with its return; the cap was "
     << static_cast<int>(std::lround(m.time_cap_s)) << " s.\n\n";
  std::snprintf(line, sizeof line,
                "| figure | value |\n|---|---|\n| targets visited | **%u of %u** |\n| regions found / visited | %u / %u |\n| mission time | %.0f s |\n"
                "| localization error mean / p95 / max (every sample after the first good one) | %.2f / %.2f / %.2f m |\n"
                "| ... tracking samples only, mean / p95 | %.2f / %.2f m |\n| tracking / within 3 m (share of those samples) | %.1f %% / %.1f %% |\n"
                "| wheel odometry alone, mean error | %.1f m |\n| false visits / non-target visits | %u / %u |\n"
                "| failed goals | %u |\n| collisions | %llu |\n| quadrotor map class accuracy | %.3f |\n| radio payload on air | %.1f MB |\n"
                "| real-time factor | %.2fx (%.0f s simulated in %.0f s) |\n\n",
                m.targets_visited, m.targets_total, m.regions_found, m.regions_visited, m.mission_time_s, m.loc_error_mean_m, m.loc_error_p95_m,
                m.loc.max_m, m.loc.tracking_mean_m, m.loc.tracking_p95_m, 100 * m.loc.tracking_fraction, 100 * m.loc.within_fraction,
                m.odom_only_error_mean_m, m.false_visits, m.non_target_visits, m.failed_goals, static_cast<unsigned long long>(m.collisions), m.map_class_accuracy,
                static_cast<double>(m.bytes_on_air) / 1e6, m.realtime_factor, m.sim_s, m.wall_s);
  md << line;
  md << "Compute time: " << m.compute_time << " (docs/simulator.md): " << m.stage_overruns << " overruns and " << m.stage_slips
     << " slips of the robots' stages on their CPUs";
  if (m.stage_overruns + m.stage_slips > 0) {
    md << "; the stages that had any:\n\n| stage | runs | overruns | slips | exec p99 [ms] | budget [ms] |\n|---|---|---|---|---|---|\n";
    for (const auto& c : m.stages)
      if (c.overruns + c.slips > 0) {
        std::snprintf(line, sizeof line, "| %s | %llu | %llu | %llu | %.1f | %.1f |\n", c.name.c_str(), static_cast<unsigned long long>(c.runs),
                      static_cast<unsigned long long>(c.overruns), static_cast<unsigned long long>(c.slips), c.exec_p99_ms, c.budget_ms);
        md << line;
      }
    md << "\n";
  } else {
    md << ".\n\n";
  }
  md << "![mission](mission_map.png)\n\nTrails: true paths of the ground robots; orange circles: regions the quadrotor found "
     << "(diamonds: their goals, green once visited); stars: where a robot marked a visit (red: a false visit, its true position at that "
     << "moment was not within its visit radius of the goal; blue: a true visit to a region with no target near); yellow crosses: the "
     << "world's targets. Localization error: the robot's published pose against the truth at its stamp, every 0.2 s from its first "
     << "good sample (tracking, within 3 m) on, whether tracking or not.\n\n| robot | distance [m] | visited | failed | false / non-target visits | "
     << "loc error mean / p95 / max [m] | tracking / within 3 m | odometry-only mean [m] | first tracking [s] | done [s] | state |\n"
     << "|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const MissionRobot& x : m.robots) {
    std::snprintf(line, sizeof line, "| %s%s | %.0f | %u | %u | %u / %u | %.2f / %.2f / %.2f | %.1f %% / %.1f %% | %.1f | %.0f | %.0f | %s |\n", x.name.c_str(),
                  x.killed_s >= 0 ? " (powered off)" : "", x.distance_m, x.visited, x.failed, x.false_visits, x.non_target_visits, x.loc_error_mean_m,
                  x.loc_error_p95_m, x.loc.max_m, 100 * x.loc.tracking_fraction, 100 * x.loc.within_fraction, x.odom_only_error_mean_m,
                  x.first_tracking_s, x.done_s, x.final_state.c_str());
    md << line;
  }
  md << "\n![pose error](pose_error.png)\n\n![odometry error](odometry_error.png)\n\n![claims](claims_timeline.png)\n\n![traffic](comms_traffic.png)\n\n"
     << "Final maps of the quadrotor (`maps/`): map_rgb.png, map_elevation.png, map_class.png and the GeoTIFFs map_rgb.tif, map_elevation.tif, "
     << "map_class.tif (UTM of the datum).\n\n![semantic map](maps/map_class.png)\n\nFiles: metrics.json, visits.csv, summary.yaml (the runner's), "
     << "truth_*.csv, odom_*.csv, gps_uav.csv, camera/*.png.\n";
  if (!j || !md) return Error::make(ErrorCode::kIo, "cannot write the mission report in " + o.out_dir);
  return m;
}

}  // namespace ag::sim
