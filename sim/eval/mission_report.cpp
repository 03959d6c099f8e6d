// A team mission's report folder: the final maps, the mission over the world, plots, tables, metrics.json, report.md.
#include <nlohmann/json.hpp>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "airground/sim/map_export.hpp"
#include "airground/sim/plot.hpp"
#include "airground/sim/world_png.hpp"
#include "mission_log.hpp"

namespace ag::sim::mission_eval {

namespace {

namespace fs = std::filesystem;

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

// The mission over the world: trails, regions, visits, targets.
void write_mission_map(const fs::path& out, const World& w, const std::vector<TargetCluster>& targets, const MissionLog& log,
                       const VisitJudgement& judged) {
  const GridGeometry& g = w.grid();
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
  for (const auto& [id, rg] : log.regions) {
    cv::circle(bgr, px(rg.cx, rg.cy), 9, cv::Scalar(0, 140, 255), 1, cv::LINE_AA);
    cv::putText(bgr, std::to_string(id), px(rg.cx, rg.cy) + cv::Point(10, -6), cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(0, 80, 160), 1, cv::LINE_AA);
    if (rg.goal_valid)
      cv::drawMarker(bgr, px(rg.goal_x, rg.goal_y), judged.region_visited.count(id) ? cv::Scalar(0, 170, 0) : cv::Scalar(0, 0, 220), cv::MARKER_DIAMOND, 10, 2);
  }
  for (std::size_t i = 0; i < log.samples.size(); ++i) {
    const auto& sm = log.samples[i];
    const cv::Scalar c = series_colour(i);
    for (std::size_t k = 1; k < sm.size(); ++k) cv::line(bgr, px(sm[k - 1].truth.x, sm[k - 1].truth.y), px(sm[k].truth.x, sm[k].truth.y), c, 2, cv::LINE_AA);
    if (!sm.empty()) cv::circle(bgr, px(sm.back().truth.x, sm.back().truth.y), 5, c, cv::FILLED, cv::LINE_AA);
  }
  const auto& visits = log.visits;
  const auto& verdict = judged.verdict;
  for (std::size_t k = 0; k < visits.size(); ++k)
    cv::drawMarker(bgr, px(visits[k].est_x, visits[k].est_y), verdict[k] == VisitVerdict::kFalse ? cv::Scalar(0, 0, 255)
                   : verdict[k] == VisitVerdict::kNonTarget ? cv::Scalar(200, 120, 0) : cv::Scalar(0, 120, 0), cv::MARKER_STAR, 12, 2);
  cv::imwrite((out / "mission_map.png").string(), bgr);
}

// Localization and odometry errors, radio traffic and the claims timeline.
void write_mission_plots(const fs::path& out, const MissionLog& log, double sim_s) {
  const std::size_t n = log.samples.size();
  std::vector<PlotSeries> err_series, odom_series;
  for (std::size_t i = 0; i < n; ++i) {
    PlotSeries s{"ugv" + std::to_string(i + 1), {}, {}, series_colour(i), true};
    PlotSeries od{"ugv" + std::to_string(i + 1) + " odometry", {}, {}, series_colour(i), false};
    for (const Sample& x : log.samples[i]) {
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
  cv::imwrite((out / "comms_traffic.png").string(), line_plot({PlotSeries{"team", log.traffic_t, log.traffic_kbps, series_colour(0), false}}, pt));
  std::vector<TimelineLane> lanes;
  for (std::size_t i = 0; i < n; ++i) {
    TimelineLane lane{"ugv" + std::to_string(i + 1), {}};
    const auto& ch = log.changes[i];
    for (std::size_t k = 0; k < ch.size(); ++k) {
      const double t1 = k + 1 < ch.size() ? ch[k + 1].t : sim_s;
      lane.spans.push_back(TimelineSpan{ch[k].t, t1, state_colour(ch[k].state), ch[k].region != mission::kNoRegion ? "R" + std::to_string(ch[k].region) : ""});
    }
    lanes.push_back(std::move(lane));
  }
  std::vector<std::pair<std::string, cv::Scalar>> legend;
  for (auto s : {mission::ClaimState::kIdle, mission::ClaimState::kGoing, mission::ClaimState::kReturning, mission::ClaimState::kDone,
                 mission::ClaimState::kFailedRetrying, mission::ClaimState::kStopped})
    legend.emplace_back(mission::to_string(s), state_colour(s));
  cv::imwrite((out / "claims_timeline.png").string(), timeline_plot(lanes, sim_s, "Claims: each robot's state and claimed region", legend));
}

// visits.csv, regions.csv and targets.csv.
void write_mission_tables(const fs::path& out, const std::vector<TargetCluster>& targets, const MissionLog& log, const VisitJudgement& judged) {
  const auto& visits = log.visits;
  const auto& regions = log.regions;
  std::ofstream v(out / "visits.csv");
  v << "t_s,robot,region,est_x_m,est_y_m,goal_x_m,goal_y_m,true_x_m,true_y_m,visit_radius_m,true_visit,verdict\n";
  for (std::size_t k = 0; k < visits.size(); ++k) {
    const auto it = regions.find(visits[k].region);
    const double gx = visits[k].have_goal ? visits[k].goal_x : it != regions.end() ? static_cast<double>(it->second.goal_x) : 0.0;
    const double gy = visits[k].have_goal ? visits[k].goal_y : it != regions.end() ? static_cast<double>(it->second.goal_y) : 0.0;
    v << visits[k].t << ",ugv" << visits[k].robot + 1 << "," << visits[k].region << "," << visits[k].est_x << "," << visits[k].est_y << "," << gx
      << "," << gy << "," << visits[k].true_x << "," << visits[k].true_y << "," << visits[k].radius << ","
      << (judged.verdict[k] == VisitVerdict::kFalse ? 0 : 1) << "," << verdict_name(judged.verdict[k]) << "\n";
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
       << (judged.region_visited.count(id) ? 1 : 0) << "," << tgt << "\n";
  }
  std::ofstream tc(out / "targets.csv");
  tc << "target,x_m,y_m,cars,visited\n";
  for (std::size_t ti = 0; ti < targets.size(); ++ti)
    tc << targets[ti].id << "," << targets[ti].x << "," << targets[ti].y << "," << targets[ti].cars << "," << (judged.target_hit[ti] ? 1 : 0) << "\n";
}

// metrics.json; false when it could not be written.
bool write_mission_metrics(const fs::path& out, const MissionOptions& o, const MissionMetrics& m) {
  std::ofstream j(out / "metrics.json");
  RunOptions oracle_list;  // the run's options this report names (its oracles, the guesses' sigma)
  oracle_list.oracles = o.oracles;
  oracle_list.init_error_m = o.init_error_m;
  oracle_list.init_error_uniform = true;
  oracle_list.init_sigma_m = o.init_sigma_m;
  j << "{\n  \"oracles\": " << oracle_list.oracles_json() << ",\n  \"targets_total\": " << m.targets_total << ",\n  \"targets_visited\": " << m.targets_visited
    << ",\n  \"targets_outside_survey\": " << m.targets_outside_survey
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
    << ",\n  \"uav\": {\"mode\": \"" << m.uav_replay.mode << "\", \"recording\": " << nlohmann::json(m.uav_replay.file).dump()
    << (m.uav_replay.build.empty() ? std::string() : ", \"recorded_by\": " + nlohmann::json(m.uav_replay.build).dump())
    << ", \"recording_end_s\": " << m.uav_replay.recording_end_s << ", \"last_output_s\": " << m.uav_replay.last_output_s
    << ", \"beyond_end_s\": " << m.uav_replay.beyond_end_s << "}"
    << ",\n  \"world\": " << nlohmann::json(o.world).dump()
    << ",\n  \"ugvs\": " << o.ugvs << ",\n  \"seed\": " << o.seed << ",\n  \"comm_range_m\": " << o.comm_range_m << ",\n  \"robots\": [";
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
  return static_cast<bool>(j);
}

// report.md (replacing the runner's); false when it could not be written.
bool write_mission_report(const fs::path& out, const MissionOptions& o, const MissionMetrics& m) {
  RunOptions oracle_list;  // the run's options this report names (its oracles, the guesses' sigma)
  oracle_list.oracles = o.oracles;
  oracle_list.init_error_m = o.init_error_m;
  oracle_list.init_error_uniform = true;
  oracle_list.init_sigma_m = o.init_sigma_m;
  std::ofstream md(out / "report.md");
  char line[1536];
  md << "# airground mission report\n\n" << oracle_list.oracles_line() << "\n\nWorld `" << o.world << "`, seed " << o.seed << ": 1 quadrotor at " << o.uav_altitude_m << " m, " << o.ugvs
     << " ground robots (initial guesses up to " << o.init_error_m << " m off, given with sigma "
     << initial_sigma_m(oracle_list) << " m), radio range "
     << (o.comm_range_m > 0 ? std::to_string(static_cast<int>(o.comm_range_m)) + " m" : std::string("default")) << ". "
     << (m.completed ? "Every robot finished and returned to its start." : "The mission hit the time cap before every robot finished.")
     << " The survey was estimated at " << static_cast<int>(std::lround(m.survey_estimate_s)) << " s with its return; the cap was "
     << static_cast<int>(std::lround(m.time_cap_s)) << " s.\n\n";
  if (!m.outside_survey_ids.empty()) {
    md << "Not scored: the world's target" << (m.outside_survey_ids.size() > 1 ? "s " : " ");
    for (std::size_t i = 0; i < m.outside_survey_ids.size(); ++i) md << (i > 0 ? ", " : "") << m.outside_survey_ids[i];
    md << (m.outside_survey_ids.size() > 1 ? " have" : " has") << " no car in the area the quadrotor surveys, so "
       << (m.outside_survey_ids.size() > 1 ? "they are" : "it is") << " not part of the mission.\n\n";
  }
  if (m.uav_replay.mode == "replayed")
    md << "The quadrotor's mapping was replayed from `" << m.uav_replay.file << "` (recorded live with the same key"
       << (m.uav_replay.build.empty() ? std::string() : " by the build `" + m.uav_replay.build + "`") << "; its comms stage and flight ran live"
       << (m.uav_replay.beyond_end_s > 0 ? ", and this mission ran " + std::to_string(static_cast<int>(m.uav_replay.beyond_end_s)) + " s past the recording's end" : std::string())
       << ").\n\n";
  else if (m.uav_replay.mode == "recorded")
    md << "The quadrotor's mapping ran live and was recorded into `" << m.uav_replay.file << "` for later missions.\n\n";
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
  return static_cast<bool>(md);
}

}  // namespace

Status write_mission_files(const MissionOptions& o, const World& w, const std::vector<TargetCluster>& targets, const MissionLog& log,
                           const VisitJudgement& judged, const MissionMetrics& m) {
  const fs::path out(o.out_dir);
  if (!log.raster.cls.empty())
    if (auto st = write_map_exports((out / "maps").string(), log.raster, w.header.datum); !st) return st.error();
  write_mission_map(out, w, targets, log, judged);
  write_mission_plots(out, log, m.sim_s);
  write_mission_tables(out, targets, log, judged);
  const bool metrics_ok = write_mission_metrics(out, o, m);
  const bool report_ok = write_mission_report(out, o, m);
  if (!metrics_ok || !report_ok) return Error::make(ErrorCode::kIo, "cannot write the mission report in " + o.out_dir);
  return ok_status();
}

}  // namespace ag::sim::mission_eval
