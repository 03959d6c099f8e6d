// The study's table and plots from the missions' metrics.json files.
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include "airground/sim/eval_mission.hpp"
#include "airground/sim/plot.hpp"

namespace ag::sim {

namespace {
namespace fs = std::filesystem;

struct Row {
  std::string name;
  int ugvs{0};
  double range{0};
  int seed{0};
  double targets_total{0}, targets_visited{0}, mission_time_s{0}, loc_mean{-1}, loc_p95{-1}, odom_mean{0};
  double false_visits{0}, failed_goals{0}, collisions{0}, bytes{0}, rtf{0};
  double repeat_visits{-1};                // visits of a region someone had visited already; -1: unknown
  double first_visit_s{-1}, last_visit_s{-1};  // from visits.csv; -1: none or no file
  bool completed{false};
  std::string world{"?"};    // the mission's --world ("?": a metrics.json from before it was recorded)
  std::string oracles{"?"};  // the ground truth the robots got, "+"-joined; "none" in field mode; "?" not recorded
};

// The first and last visit times of a run's visits.csv (t_s in the first column). A line that does not
// start with a number is reported by file and line and skipped.
void read_visit_times(const fs::path& file, Row& r) {
  std::ifstream in(file);
  if (!in) return;
  std::string line;
  for (int n = 1; std::getline(in, line); ++n) {
    if (n == 1 || line.empty()) continue;  // the header
    char* end = nullptr;
    const double t = std::strtod(line.c_str(), &end);
    if (end == line.c_str() || *end != ',' || !std::isfinite(t)) {
      std::fprintf(stderr, "study: %s:%d: no visit time in the first column, line skipped\n", file.c_str(), n);
      continue;
    }
    if (r.first_visit_s < 0 || t < r.first_visit_s) r.first_visit_s = t;
    r.last_visit_s = std::max(r.last_visit_s, t);
  }
}

// Mean of `field` over the runs of one team size and range that have it (>= 0); NaN if none.
template <typename F>
double mean_of(const std::vector<Row>& rows, int ugvs, double range, F field) {
  double sum = 0;
  int n = 0;
  for (const Row& r : rows)
    if (r.ugvs == ugvs && r.range == range && field(r) >= 0) {
      sum += field(r);
      ++n;
    }
  return n > 0 ? sum / n : std::nan("");
}
// One run's row from its metrics.json (and visits.csv).
Row read_row(const fs::path& run, const nlohmann::json& j) {
  Row r;
  r.name = run.filename().string();
  auto num = [&](const char* k, double def) { return j.contains(k) && j[k].is_number() ? j[k].get<double>() : def; };
  r.ugvs = static_cast<int>(num("ugvs", 0));
  r.range = num("comm_range_m", 0);
  r.seed = static_cast<int>(num("seed", 0));
  r.targets_total = num("targets_total", 0);
  r.targets_visited = num("targets_visited", 0);
  r.mission_time_s = num("mission_time_s", 0);
  r.loc_mean = num("loc_error_mean_m", -1);
  r.loc_p95 = num("loc_error_p95_m", -1);
  r.odom_mean = num("odom_only_error_mean_m", 0);
  r.false_visits = num("false_visits", 0);
  r.failed_goals = num("failed_goals", 0);
  r.collisions = num("collisions", 0);
  r.bytes = num("bytes_on_air", 0);
  r.rtf = num("realtime_factor", 0);
  r.completed = j.contains("completed") && j["completed"].is_boolean() && j["completed"].get<bool>();
  if (j.contains("robots") && j["robots"].is_array() && j.contains("regions_visited") && j["regions_visited"].is_number()) {
    double visits = 0;
    for (const auto& robot : j["robots"])
      if (robot.is_object() && robot.contains("visited") && robot["visited"].is_number()) visits += robot["visited"].get<double>();
    r.repeat_visits = std::max(0.0, visits - j["regions_visited"].get<double>());
  }
  if (j.contains("oracles") && j["oracles"].is_array()) {
    r.oracles.clear();
    for (const auto& o : j["oracles"])
      if (o.is_string()) r.oracles += (r.oracles.empty() ? "" : "+") + o.get<std::string>();
    if (r.oracles.empty()) r.oracles = "none";
  }
  if (j.contains("world") && j["world"].is_string()) r.world = j["world"].get<std::string>();
  read_visit_times(run / "visits.csv", r);
  return r;
}

// Every run of DIR/runs with a metrics.json, by range, team size and seed.
Result<std::vector<Row>> read_rows(const std::string& dir) {
  std::vector<Row> rows;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(fs::path(dir) / "runs", ec)) {
    const fs::path mj = e.path() / "metrics.json";
    if (!fs::exists(mj)) continue;
    std::ifstream f(mj);
    nlohmann::json j = nlohmann::json::parse(f, nullptr, false);
    if (j.is_discarded() || !j.is_object()) {
      std::fprintf(stderr, "study: %s: not valid JSON, skipped\n", mj.c_str());
      continue;
    }
    rows.push_back(read_row(e.path(), j));
  }
  if (ec) return Error::make(ErrorCode::kIo, "cannot list " + (fs::path(dir) / "runs").string() + ": " + ec.message());
  std::sort(rows.begin(), rows.end(), [](const Row& a, const Row& b) {
    return std::tie(a.range, a.ugvs, a.seed) < std::tie(b.range, b.ugvs, b.seed);
  });
  return rows;
}

// study.csv; false when it could not be written.
bool write_study_csv(const fs::path& out, const std::vector<Row>& rows) {
  std::ofstream csv(out / "study.csv");
  csv << "run,ugvs,comm_range_m,seed,oracles,world,targets_total,targets_visited,completed,mission_time_s,loc_error_mean_m,loc_error_p95_m,"
         "odom_only_error_mean_m,false_visits,failed_goals,collisions,bytes_on_air,realtime_factor,repeat_visits,first_visit_s,"
         "last_visit_s\n";
  for (const Row& r : rows)
    csv << r.name << "," << r.ugvs << "," << r.range << "," << r.seed << "," << r.oracles << "," << r.world << "," << r.targets_total << "," << r.targets_visited << ","
        << (r.completed ? 1 : 0) << "," << r.mission_time_s << "," << r.loc_mean << "," << r.loc_p95 << "," << r.odom_mean << ","
        << r.false_visits << "," << r.failed_goals << "," << r.collisions << "," << r.bytes << "," << r.rtf << "," << r.repeat_visits
        << "," << r.first_visit_s << "," << r.last_visit_s << "\n";
  return static_cast<bool>(csv);
}

// Mission time by team size, one series per range: the sum over the seeds and the runs.
using ByRange = std::map<double, std::map<int, std::pair<double, int>>>;

ByRange mission_time_by_range(const std::vector<Row>& rows) {
  ByRange by_range;
  for (const Row& r : rows) {
    auto& cell = by_range[r.range][r.ugvs];
    cell.first += r.mission_time_s;
    cell.second += 1;
  }
  return by_range;
}

// mission_time.png, pose_error.png and targets.png: one series per range.
void write_study_plots(const fs::path& out, const std::vector<Row>& rows, const ByRange& by_range) {
  std::vector<PlotSeries> time_series, err_series, tgt_series;
  std::size_t k = 0;
  for (const auto& [range, m] : by_range) {
    PlotSeries s{"range " + std::to_string(static_cast<int>(range)) + " m", {}, {}, series_colour(k), false};
    for (const auto& [u, c] : m) {
      s.x.push_back(u);
      s.y.push_back(c.first / c.second);
    }
    time_series.push_back(s);
    PlotSeries e{"range " + std::to_string(static_cast<int>(range)) + " m", {}, {}, series_colour(k), true};
    PlotSeries t{e.name, {}, {}, series_colour(k), true};
    for (const Row& r : rows)
      if (r.range == range) {
        e.x.push_back(r.ugvs + 0.08 * static_cast<double>(k));
        e.y.push_back(r.loc_mean);
        t.x.push_back(r.ugvs + 0.08 * static_cast<double>(k));
        t.y.push_back(r.targets_visited);
      }
    err_series.push_back(e);
    tgt_series.push_back(t);
    ++k;
  }
  PlotOptions po;
  po.title = "Mission time by team size (mean over seeds)";
  po.x_label = "ground robots";
  po.y_label = "mission time [s]";
  cv::imwrite((out / "mission_time.png").string(), line_plot(time_series, po));
  po.title = "Localization error after convergence (mean per mission), 1.5 m line";
  po.y_label = "error [m]";
  po.h_lines = {1.5};
  cv::imwrite((out / "pose_error.png").string(), line_plot(err_series, po));
  po.title = "Targets reached per mission";
  po.y_label = "targets";
  po.h_lines = {rows.empty() ? 0.0 : rows.front().targets_total};
  cv::imwrite((out / "targets.png").string(), line_plot(tgt_series, po));
}

// The first lines say whether any ground truth reached the robots (field mode) and in which runs.
void write_oracles(std::ostringstream& md, const std::vector<Row>& rows) {
  std::map<std::string, std::vector<std::string>> by_oracles;
  for (const Row& r : rows) by_oracles[r.oracles].push_back(r.name);
  if (by_oracles.empty() || (by_oracles.size() == 1 && by_oracles.begin()->first == "none")) {
    md << "Field mode: no ground truth reached a robot in any mission (oracles: none).\n\n";
    return;
  }
  md << "ABLATION in some or all missions: ground truth handed to the robots by name; those figures are not field-mode figures.\n\n";
  for (const auto& [names, runs] : by_oracles) {
    md << "- oracles " << (names == "?" ? "not recorded (a metrics.json from before field mode)" : names) << ": " << runs.size() << " mission"
       << (runs.size() == 1 ? "" : "s") << " (";
    for (std::size_t i = 0; i < runs.size(); ++i) md << (i ? ", " : "") << runs[i];
    md << ")\n";
  }
  md << "\n";
}

// By world, when the study ran on several: the goals per world (every target in 25 of 26, no false
// visit), with targets_by_world.png.
void write_by_world(std::ostringstream& md, const fs::path& out, const std::vector<Row>& rows) {
  std::map<std::string, std::vector<const Row*>> by_world;
  for (const Row& r : rows) by_world[r.world].push_back(&r);
  if (by_world.size() <= 1) return;
  char line[512];
  md << "\n\nBy world:\n\n| world | missions | all targets reached | targets reached / total | no false visit | loc error mean (mean over missions) [m] | mission time mean [s] |\n"
     << "|---|---|---|---|---|---|---|\n";
  std::vector<PlotSeries> world_series;
  std::size_t wk = 0;
  for (const auto& [world, wr] : by_world) {
    std::size_t all = 0, clean = 0, ln = 0;
    double reached = 0, total = 0, loc = 0, time = 0;
    PlotSeries ws{fs::path(world).filename().string(), {}, {}, series_colour(wk), true};
    for (const Row* r : wr) {
      all += r->targets_total > 0 && r->targets_visited >= r->targets_total ? 1 : 0;
      clean += r->false_visits == 0 ? 1 : 0;
      reached += r->targets_visited;
      total += r->targets_total;
      time += r->mission_time_s;
      if (r->loc_mean >= 0) {
        loc += r->loc_mean;
        ++ln;
      }
      ws.x.push_back(r->ugvs + 0.08 * static_cast<double>(wk));
      ws.y.push_back(r->targets_total > 0 ? r->targets_visited / r->targets_total : 0.0);
    }
    world_series.push_back(ws);
    ++wk;
    std::snprintf(line, sizeof line, "| %s | %zu | %zu | %.0f / %.0f | %zu | %s | %.0f |\n", world.c_str(), wr.size(), all, reached, total, clean,
                  ln > 0 ? std::to_string(loc / static_cast<double>(ln)).substr(0, 4).c_str() : "–", time / static_cast<double>(wr.size()));
    md << line;
  }
  PlotOptions wpo;
  wpo.title = "Share of targets reached per mission, by world";
  wpo.x_label = "ground robots";
  wpo.y_label = "targets reached / total";
  wpo.h_lines = {1.0};
  cv::imwrite((out / "targets_by_world.png").string(), line_plot(world_series, wpo));
  md << "\n![targets by world](targets_by_world.png)\n";
}

// Mission time by team size and range (mean over the seeds done), the paper's main figure as a table, and
// the same grid for the visits: when the first region was reached, and how many visits went to a region
// someone had reached already (their news had not reached the robot).
void write_grids(std::ostringstream& md, const std::vector<Row>& rows, const ByRange& by_range) {
  char line[512];
  std::set<int> sizes;
  for (const Row& r : rows) sizes.insert(r.ugvs);
  // A grid's title and header: one column per range.
  const auto grid_header = [&](const char* title) {
    md << "\n" << title << "\n\n| robots |";
    for (const auto& [range, m] : by_range) md << " range " << static_cast<int>(range) << " m |";
    md << "\n|---|";
    for (std::size_t i = 0; i < by_range.size(); ++i) md << "---|";
    md << "\n";
  };
  md << "\n";
  grid_header("Mission time [s] by team size (mean over seeds; runs in brackets; `cap`: a run hit the time cap):");
  for (const int u : sizes) {
    md << "| " << u << " |";
    for (const auto& [range, m] : by_range) {
      const auto it = m.find(u);
      bool cap = false;
      for (const Row& r : rows)
        if (r.ugvs == u && r.range == range && !r.completed) cap = true;
      if (it == m.end()) md << " – |";
      else {
        std::snprintf(line, sizeof line, " %.0f (%d)%s |", it->second.first / it->second.second, it->second.second, cap ? " cap" : "");
        md << line;
      }
    }
    md << "\n";
  }
  const auto grid = [&](const char* title, auto field, int decimals) {
    grid_header(title);
    for (const int u : sizes) {
      md << "| " << u << " |";
      for (const auto& [range, m] : by_range) {
        const double v = mean_of(rows, u, range, field);
        if (std::isnan(v)) md << " – |";
        else {
          std::snprintf(line, sizeof line, " %.*f |", decimals, v);
          md << line;
        }
      }
      md << "\n";
    }
  };
  grid("First visit [s] by team size (mean over seeds, from each run's visits.csv):", [](const Row& r) { return r.first_visit_s; }, 0);
  grid("Repeat visits by team size (visits to a region another robot had visited already; mean over seeds):",
       [](const Row& r) { return r.repeat_visits; }, 1);
}

// The table of every run.
void write_run_table(std::ostringstream& md, const std::vector<Row>& rows) {
  char line[512];
  md << "\n![mission time](mission_time.png)\n\n![pose error](pose_error.png)\n\n![targets](targets.png)\n\n"
     << "| run | robots | range [m] | seed | targets | done | mission time [s] | loc error mean / p95 [m] | odometry only [m] | false visits | repeat visits | first / last visit [s] | failed goals | collisions | MB on air | RTF |\n"
     << "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const Row& r : rows) {
    char repeat[32] = "–", visits[48] = "–";
    if (r.repeat_visits >= 0) std::snprintf(repeat, sizeof repeat, "%.0f", r.repeat_visits);
    if (r.first_visit_s >= 0) std::snprintf(visits, sizeof visits, "%.0f / %.0f", r.first_visit_s, r.last_visit_s);
    std::snprintf(line, sizeof line, "| %s | %d | %.0f | %d | %.0f / %.0f | %s | %.0f | %.2f / %.2f | %.1f | %.0f | %s | %s | %.0f | %.0f | %.1f | %.2f |\n",
                  r.name.c_str(), r.ugvs, r.range, r.seed, r.targets_visited, r.targets_total, r.completed ? "yes" : "cap", r.mission_time_s,
                  r.loc_mean, r.loc_p95, r.odom_mean, r.false_visits, repeat, visits, r.failed_goals, r.collisions, r.bytes / 1e6, r.rtf);
    md << line;
  }
}

}  // namespace

Result<std::string> summarise_study(const std::string& dir) {
  auto read = read_rows(dir);
  if (!read) return read.error();
  const std::vector<Row>& rows = read.value();
  const fs::path out(dir);
  const bool csv_ok = write_study_csv(out, rows);
  // Summary figures.
  std::size_t all_reached = 0, zero_false = 0;
  double loc_sum = 0, loc_max = 0, odom_sum = 0;
  std::size_t loc_n = 0;
  for (const Row& r : rows) {
    if (r.targets_total > 0 && r.targets_visited >= r.targets_total) ++all_reached;
    if (r.false_visits == 0) ++zero_false;
    if (r.loc_mean >= 0) {
      loc_sum += r.loc_mean;
      loc_max = std::max(loc_max, r.loc_mean);
      ++loc_n;
    }
    odom_sum += r.odom_mean;
  }
  const ByRange by_range = mission_time_by_range(rows);
  write_study_plots(out, rows, by_range);

  std::ostringstream md;
  char line[512];
  md << "# airground study\n\n";
  write_oracles(md, rows);
  md << rows.size() << " missions. All targets reached in " << all_reached << " of " << rows.size()
     << "; no false visit in " << zero_false << " of " << rows.size() << ".";
  if (loc_n > 0) {
    std::snprintf(line, sizeof line, " Localization error after convergence: mean %.2f m over the missions (worst mission %.2f m); wheel odometry alone %.1f m.",
                  loc_sum / static_cast<double>(loc_n), loc_max, odom_sum / static_cast<double>(rows.size()));
    md << line;
  }
  write_by_world(md, out, rows);
  write_grids(md, rows, by_range);
  write_run_table(md, rows);
  std::ofstream f(out / "study.md");
  f << md.str();
  if (!f || !csv_ok) return Error::make(ErrorCode::kIo, "cannot write the study files in " + dir);
  std::snprintf(line, sizeof line, "study: %zu missions, all targets in %zu, no false visit in %zu; table %s/study.md\n", rows.size(), all_reached, zero_false, dir.c_str());
  return std::string(line);
}

}  // namespace ag::sim
