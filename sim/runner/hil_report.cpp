// The HIL run's results (each process's final stage timing, each ground robot's figures) and its report:
// hil.json, hil_report.md and the trajectories over the world's class map.
#include <algorithm>
#include <cstdio>
#include <fstream>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "airground/sim/runner.hpp"
#include "airground/sim/world_png.hpp"
#include "hil_run.hpp"
#include "roles.hpp"

namespace ag::sim::hil {
namespace {

// Each stage's budget in the role's table.
std::map<std::string, double> stage_budgets(const std::string& role) {
  std::map<std::string, double> b;
  const RoleDescription& d = role == "uav" ? uav_role() : role == "ugv" ? ugv_role() : base_role();
  for (const StageSpec& s : d.stages) b[std::string(s.name)] = s.budget_us;
  return b;
}

// The process's "final stage=..." log lines.
void read_stage_timing(const RoleProcess& c, std::vector<HilStageTiming>& timing) {
  const auto b = stage_budgets(c.role);
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
    timing.push_back(t);
  }
}

void write_json(const Run& run, const RunOptions& oracle_list) {
  const HilResult& res = run.res;
  json j;
  j["mission"] = run.opt.mission_file;
  j["oracles"] = oracle_list.oracles;
  j["world"] = run.opt.world;
  j["mission_done"] = res.mission_done;
  j["duration_s"] = res.duration_s;
  j["failure"] = run.failure;
  const double secs = std::max(1.0, res.duration_s);
  j["rates_hz"] = {{"lidar", static_cast<double>(res.lidar_revolutions) / secs}, {"camera", static_cast<double>(res.camera_frames) / secs}};
  j["traffic"] = {{"lidar_packets", res.lidar_packets}, {"lidar_revolutions", res.lidar_revolutions}, {"lidar_revolutions_skipped", res.lidar_revolutions_skipped},
                  {"camera_frames_skipped", res.camera_frames_skipped}, {"ubx_nav_pvt", res.ubx_messages}, {"camera_frames", res.camera_frames},
                  {"camera_frames_dropped", res.camera_frames_dropped}, {"vo_records", res.vo_records}, {"mavlink_frames", res.mavlink_frames}, {"arm_requests", res.arm_requests},
                  {"mavlink_bytes_in", res.mavlink_bytes_in}, {"can_commands_received", res.can_frames_in}};
  for (const HilRobot& r : res.robots)
    j["robots"].push_back({{"name", r.name}, {"exit_code", r.exit_code}, {"state", r.final_state}, {"distance_m", r.distance_m},
                           {"final_error_m", r.final_error_m}, {"mean_error_m", r.mean_error_m}, {"max_error_m", r.max_error_m}, {"collisions", r.collisions}});
  for (const HilStageTiming& t : res.timing)
    j["stage_timing"].push_back({{"robot", t.robot}, {"stage", t.stage}, {"runs", t.runs}, {"p50_us", t.p50_us}, {"p99_us", t.p99_us},
                                 {"max_us", t.max_us}, {"budget_us", t.budget_us}, {"overruns", t.overruns}});
  std::ofstream(run.out / "hil.json") << j.dump(2) << "\n";
}

void write_markdown(const Run& run, const RunOptions& oracle_list) {
  const HilResult& res = run.res;
  const std::string& failure = run.failure;
  std::ofstream md(run.out / "hil_report.md");
  md << "# HIL run: " << run.opt.mission_file << "\n\n" << oracle_list.oracles_line() << "\n\n"
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
}

// The ground robots' true (white) and estimated (red) trails over the world's class map.
void write_trajectories(const Run& run) {
  const GridGeometry& g = run.world.grid();
  cv::Mat img;
  cv::cvtColor(class_display_image(run.world.class_id), img, cv::COLOR_RGB2BGR);
  auto px = [&](const cv::Point2d& p) { return cv::Point(g.col(p.x), g.row(p.y)); };
  for (const auto& u : run.ugvs) {
    for (std::size_t k = 1; k < u->truth_trail.size(); ++k) cv::line(img, px(u->truth_trail[k - 1]), px(u->truth_trail[k]), cv::Scalar(255, 255, 255), 2);
    for (std::size_t k = 1; k < u->est_trail.size(); ++k) cv::line(img, px(u->est_trail[k - 1]), px(u->est_trail[k]), cv::Scalar(0, 0, 255), 1);
  }
  cv::imwrite((run.out / "trajectories.png").string(), img);
}

}  // namespace

std::string fixed(double v, int digits) {
  char b[64];
  std::snprintf(b, sizeof b, "%.*f", digits, v);
  return b;
}

void collect_results(Run& run) {
  for (const RoleProcess& c : run.children) {
    HilRobot r;
    r.name = c.name;
    r.exit_code = c.exit_code;
    read_stage_timing(c, run.res.timing);
    for (const auto& u : run.ugvs)
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
    run.res.robots.push_back(r);
  }
}

void write_report(const Run& run) {
  RunOptions oracle_list;
  oracle_list.oracles = run.opt.oracles;
  write_json(run, oracle_list);
  write_markdown(run, oracle_list);
  write_trajectories(run);
}

}  // namespace ag::sim::hil
