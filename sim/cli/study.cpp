// airground-sim study: the paper's grid of team missions, run as parallel 'airground-sim mission'
// processes on this machine or written as a Slurm job array (--slurm), then merged into a table and plots.
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "airground/sim/eval_mission.hpp"

namespace fs = std::filesystem;

namespace {

constexpr const char* kStudyHelp =
    "airground-sim study — the paper's simulation study: a grid of team missions over team size, radio\n"
    "range and seed, run as parallel 'airground-sim mission' processes (or as a Slurm job array), then a\n"
    "table and plots.\n\n"
    "Usage: airground-sim study --ugvs 1,2,3,5,10 --comm-range 50,150,1000 --seeds K --out DIR [options]\n\n"
    "Writes DIR/runs/u<N>_r<R>_s<S>/ (each mission's report), DIR/study.csv (one row per mission),\n"
    "DIR/study.md (the table and the summary: targets reached in every run, false visits, localization\n"
    "error, mission time by team size and range), DIR/mission_time.png, DIR/pose_error.png, DIR/targets.png.\n"
    "A mission whose folder already has metrics.json is not run again (resume an interrupted study).\n"
    "Defaults: --ugvs 1,2,3 --comm-range 150 --seeds 1 --out study --jobs (cores / 2, at least 1).\n\n"
    "Options:\n"
    "  --world W              (default)\n"
    "  --worlds W1,W2,...     several worlds (default, or world directories, e.g. made by 'world generate'):\n"
    "                         the grid on each, in DIR/runs/<world>_u<N>_r<R>_s<S>/; study.md adds a table by world\n"
    "  --first-seed S         seeds S .. S+K-1 (1)\n"
    "  --jobs J               missions at once (each gets cores / J sensor threads); with --slurm the job\n"
    "                         array's limit of tasks at once (none unless given)\n"
    "  --max-duration T       per mission (as mission: 4x the survey's flying time, >= 1800 s)\n"
    "  --altitude A           quadrotor altitude (40 m; the paper flew 60 m)\n"
    "  --lidar-columns C      (1024)\n"
    "  --set SECTION.KEY=VALUE  passed to every mission (repeatable)\n"
    "  --set-uav SECTION.KEY=VALUE  passed to every mission (repeatable)\n"
    "  --oracle labels,vo     ablation passed to every mission; study.csv and study.md list each mission's oracles\n"
    "  --compute-time MODE    passed to every mission: model (default), measured or off (docs/simulator.md)\n"
    "  --target-cpu CPU       passed to every mission: nuc|ryzen|xavier-nx (default: the paper's computers)\n"
    "  --uav-cache DIR|none   the quadrotor cache every mission shares (DIR/uav_cache): the first mission of a\n"
    "                         world, seed and altitude records its quadrotor's mapping, later ones replay it\n"
    "                         (same results, without the camera, VO, ErfNet and mapping); none: all live\n"
    "  --uav-cache-build EXE  passed to every mission: replay the recordings the airground-sim EXE made\n"
    "  --report-only          run nothing: write the table and plots from the missions already done\n"
    "                         (also while another study process is still running into DIR)\n"
    "  --slurm SDIR           run nothing here: write SDIR/study.sbatch, a Slurm job array with one task per\n"
    "                         mission (task N runs the local study's mission N, same command line, into the same\n"
    "                         DIR/runs/<name>/ folder, and skips it when it has metrics.json: resubmit to\n"
    "                         resume); 'sbatch SDIR/study.sbatch', then --report-only merges the missions\n"
    "  --cpus-per-task C      with --slurm: each task's CPUs, given to the mission as --threads (2)\n";

[[noreturn]] void usage(const std::string& msg) {
  std::fprintf(stderr, "airground-sim study: %s (see airground-sim study --help)\n", msg.c_str());
  std::exit(2);
}

struct Options {
  std::map<std::string, std::vector<std::string>> opt;
  [[nodiscard]] bool has(const std::string& k) const { return opt.count(k) != 0; }
  [[nodiscard]] std::string get(const std::string& k, const std::string& def = "") const {
    auto it = opt.find(k);
    return it == opt.end() || it->second.empty() ? def : it->second.back();
  }
};

// --key value pairs; flags take no value; an option that is neither is an error naming it.
Options parse(int argc, char** argv) {
  static const std::set<std::string> valued = {"world", "worlds", "ugvs", "comm-range", "seeds", "first-seed", "out", "jobs", "max-duration", "altitude",
                                               "lidar-columns", "set", "set-uav", "oracle", "slurm", "cpus-per-task",
                                               "compute-time", "target-cpu", "uav-cache", "uav-cache-build"};
  Options o;
  for (int i = 2; i < argc; ++i) {
    const std::string s = argv[i];
    if (s.rfind("--", 0) != 0) usage("unexpected argument '" + s + "'");
    const std::string k = s.substr(2);
    if (k == "report-only") {
      o.opt[k];
      continue;
    }
    if (!valued.count(k)) usage("unknown option '--" + k + "'");
    if (i + 1 >= argc) usage("--" + k + " needs a value");
    o.opt[k].push_back(argv[++i]);
  }
  return o;
}

double number(const Options& o, const std::string& k, double def) {
  if (!o.has(k)) return def;
  const std::string v = o.get(k);
  char* end = nullptr;
  const double d = std::strtod(v.c_str(), &end);
  if (v.empty() || *end != '\0' || !std::isfinite(d)) usage("--" + k + " needs a number, got '" + v + "'");
  return d;
}

// A comma-separated list of numbers (repeated options add to it); an empty list is an error.
std::vector<double> number_list(const Options& o, const std::string& k, const std::string& def) {
  std::string v = o.has(k) ? "" : def;
  if (o.has(k))
    for (const auto& p : o.opt.at(k)) v += (v.empty() ? "" : ",") + p;
  std::vector<double> out;
  std::size_t i = 0;
  while (i <= v.size()) {
    const std::size_t j = std::min(v.find(',', i), v.size());
    const std::string tok = v.substr(i, j - i);
    if (!tok.empty()) {
      char* end = nullptr;
      const double d = std::strtod(tok.c_str(), &end);
      if (*end != '\0' || !std::isfinite(d)) usage("--" + k + ": '" + tok + "' is not a number");
      out.push_back(d);
    }
    i = j + 1;
  }
  if (out.empty()) usage("--" + k + " needs at least one value");
  return out;
}

// --oracle labels,vo: checked here so that an unknown name stops the study, not every mission.
void check_oracles(const Options& o) {
  if (!o.has("oracle")) return;
  for (const std::string& v : o.opt.at("oracle")) {
    std::size_t b = 0;
    while (b <= v.size()) {
      const std::size_t e = std::min(v.find(',', b), v.size());
      const std::string name = v.substr(b, e - b);
      if (name != "vo" && name != "labels") usage("--oracle: unknown oracle '" + name + "' (known: labels, vo)");
      b = e + 1;
    }
  }
}

// One mission of the grid: its team size, radio range, seed and output folder.
struct Cell {
  int ugvs;
  double range;
  int seed;
  std::string dir;
  std::string world;  // as the mission takes it: "default" or an absolute directory
};

// --world W or --worlds W1,W2,...: each as the mission takes it, with the folder tag its runs get ("" for
// a single world, so a one-world study keeps its folder names).
std::vector<std::pair<std::string, std::string>> world_list(const Options& o) {
  if (o.has("world") && o.has("worlds")) usage("--world and --worlds: give one of them");
  std::vector<std::string> names;
  const std::string v = o.has("worlds") ? o.get("worlds") : o.get("world", "default");
  for (std::size_t b = 0; b <= v.size();) {
    const std::size_t e = std::min(v.find(',', b), v.size());
    if (e > b) names.push_back(v.substr(b, e - b));
    b = e + 1;
  }
  if (names.empty()) usage("--worlds needs at least one world");
  std::vector<std::pair<std::string, std::string>> out;
  std::set<std::string> tags;
  for (std::size_t i = 0; i < names.size(); ++i) {
    std::string world = names[i];
    if (world != "default") {
      if (!fs::is_directory(world)) usage("--worlds: '" + world + "' is not a world directory (or 'default')");
      world = fs::absolute(world).lexically_normal().string();  // a task may start in another folder
    }
    std::string tag;
    if (names.size() > 1) {
      for (char ch : fs::path(world).filename().string()) tag += std::isalnum(static_cast<unsigned char>(ch)) != 0 ? ch : '-';
      if (tag.empty() || tags.count(tag) != 0) tag += std::to_string(i + 1);
      tags.insert(tag);
    }
    out.emplace_back(world, tag);
  }
  return out;
}

// The grid in the order both the local run and the Slurm array number it: team size, range, seed.
std::vector<Cell> make_grid(const Options& o, const std::string& out, std::size_t& sizes, std::size_t& ranges, int& seeds) {
  const auto ugvs = number_list(o, "ugvs", "1,2,3");
  const auto range_list = number_list(o, "comm-range", "150");
  seeds = static_cast<int>(number(o, "seeds", 1));
  const int first_seed = static_cast<int>(number(o, "first-seed", 1));
  if (seeds < 1) usage("--seeds must be >= 1");
  for (double u : ugvs)
    if (u < 1 || u > 32 || u != std::floor(u)) usage("--ugvs: team sizes 1..32");
  for (double r : range_list)
    if (r < 0) usage("--comm-range: ranges must be >= 0");
  std::vector<Cell> grid;
  for (const auto& [world, tag] : world_list(o))
    for (double u : ugvs)
      for (double r : range_list)
        for (int k = 0; k < seeds; ++k) {
          char d[128];
          std::snprintf(d, sizeof d, "u%d_r%.0f_s%d", static_cast<int>(u), r, first_seed + k);
          const std::string name = tag.empty() ? std::string(d) : tag + "_" + d;
          grid.push_back(Cell{static_cast<int>(u), r, first_seed + k, (fs::path(out) / "runs" / name).string(), world});
        }
  sizes = ugvs.size();
  ranges = range_list.size();
  return grid;
}

// The mission's command line (without the program), the same for a local process and a Slurm task.
std::vector<std::string> mission_args(const Options& o, const Cell& c, const std::string& dir, const std::string& threads) {
  std::vector<std::string> args = {"mission", "--world", c.world, "--ugvs", std::to_string(c.ugvs), "--seed", std::to_string(c.seed),
                                   "--comm-range", std::to_string(c.range), "--out", dir, "--threads", threads, "--quiet",
                                   "--record", "none", "--altitude", o.get("altitude", "40"),
                                   "--lidar-columns", o.get("lidar-columns", "1024")};
  if (o.has("max-duration")) {
    args.emplace_back("--max-duration");
    args.push_back(o.get("max-duration"));
  }
  const std::string cache = o.get("uav-cache", (fs::absolute(fs::path(o.get("out", "study"))) / "uav_cache").string());
  if (cache != "none") {
    args.emplace_back("--uav-cache");
    args.push_back(cache);
  }
  if (o.has("uav-cache-build")) {
    args.emplace_back("--uav-cache-build");
    args.push_back(fs::absolute(o.get("uav-cache-build")).string());
  }
  for (const char* key : {"set", "set-uav", "oracle", "compute-time", "target-cpu"})
    if (o.has(key))
      for (const auto& s : o.opt.at(key)) {
        args.push_back(std::string("--") + key);
        args.push_back(s);
      }
  return args;
}

// A word for bash, single-quoted unless it is plain.
std::string shell_word(const std::string& s) {
  const bool plain = !s.empty() && std::all_of(s.begin(), s.end(), [](char ch) {
    return std::isalnum(static_cast<unsigned char>(ch)) != 0 || std::string_view("/._,:=+-@%").find(ch) != std::string_view::npos;
  });
  if (plain) return s;
  std::string q = "'";
  for (char ch : s) q += ch == '\'' ? std::string("'\\''") : std::string(1, ch);
  return q + "'";
}

// Writes SDIR/study.sbatch: task N of the array runs grid[N] into its folder unless it is done already.
int write_slurm_array(const Options& o, const std::vector<Cell>& grid, const std::string& out) {
  const fs::path sdir = fs::absolute(o.get("slurm"));
  const int cpus = static_cast<int>(number(o, "cpus-per-task", 2));
  if (cpus < 1 || cpus > 1024) usage("--cpus-per-task must be in 1..1024");
  std::error_code ec;
  const fs::path self = fs::canonical("/proc/self/exe", ec);
  if (ec) {
    std::fprintf(stderr, "airground-sim study: cannot resolve this program's path (/proc/self/exe): %s\n", ec.message().c_str());
    return 1;
  }
  fs::create_directories(sdir / "logs", ec);
  if (ec) {
    std::fprintf(stderr, "airground-sim study: --slurm: cannot create %s: %s\n", (sdir / "logs").c_str(), ec.message().c_str());
    return 1;
  }
  const fs::path out_abs = fs::absolute(out).lexically_normal();
  std::string s = "#!/bin/bash\n";
  s += "# airground-sim study as a Slurm job array, written by 'airground-sim study --slurm': task N runs the\n"
       "# study's mission N into its own folder " + out_abs.string() + "/runs/<name>/ (its mission.log there) and\n"
       "# skips a mission whose folder has metrics.json, so resubmitting resumes. When the array is done:\n"
       "#   " + self.string() + " study --report-only --out " + shell_word(out_abs.string()) + "\n";
  s += "#SBATCH --job-name=airground-study\n";
  s += "#SBATCH --array=0-" + std::to_string(grid.size() - 1) + (o.has("jobs") ? "%" + std::to_string(static_cast<int>(number(o, "jobs", 1))) : "") + "\n";
  s += "#SBATCH --ntasks=1\n#SBATCH --cpus-per-task=" + std::to_string(cpus) + "\n";
  s += "#SBATCH --output=" + (sdir / "logs").string() + "/task_%a.out\n";
  s += "set -euo pipefail\n";
  s += "task=${SLURM_ARRAY_TASK_ID:?this script is a Slurm job array: submit it with sbatch}\n";
  s += "threads=${SLURM_CPUS_PER_TASK:-" + std::to_string(cpus) + "}\n";
  s += "case $task in\n";
  for (std::size_t i = 0; i < grid.size(); ++i) {
    const std::string dir = (out_abs / "runs" / fs::path(grid[i].dir).filename()).string();
    s += "  " + std::to_string(i) + ") dir=" + shell_word(dir) + "\n     set -- " + shell_word(self.string());
    for (const std::string& a : mission_args(o, grid[i], dir, "@THREADS@")) s += " " + (a == "@THREADS@" ? std::string("\"$threads\"") : shell_word(a));
    s += " ;;\n";
  }
  s += "  *) echo \"study.sbatch: no mission $task (0.." + std::to_string(grid.size() - 1) + ")\" >&2; exit 2 ;;\nesac\n";
  s += "if [ -f \"$dir/metrics.json\" ]; then echo \"task $task: $dir has metrics.json, not run again\"; exit 0; fi\n";
  s += "mkdir -p \"$dir\"\n";
  s += "echo \"task $task on $(hostname): $dir ($threads threads)\"\n";
  s += "\"$@\" > \"$dir/mission.log\" 2>&1 || { status=$?; echo \"task $task: mission FAILED (exit $status), see $dir/mission.log\" >&2; exit $status; }\n";
  s += "echo \"task $task: done\"\n";
  const fs::path script = sdir / "study.sbatch";
  {
    std::ofstream f(script);
    f << s;
    if (!f) {
      std::fprintf(stderr, "airground-sim study: --slurm: cannot write %s\n", script.c_str());
      return 1;
    }
  }
  fs::permissions(script, fs::perms::owner_exec | fs::perms::group_exec | fs::perms::others_exec, fs::perm_options::add, ec);
  std::printf("study: %zu missions as a Slurm job array (%d CPUs per task): %s\n  submit: sbatch %s\n  merge:  %s study --report-only --out %s\n",
              grid.size(), cpus, script.c_str(), shell_word(script.string()).c_str(), self.c_str(), shell_word(out_abs.string()).c_str());
  return 0;
}

// Runs the grid here, `jobs` missions at once, skipping those already done.
void run_local(const Options& o, std::vector<Cell>& grid, int jobs, int threads) {
  struct Job {
    Cell* cell;
    pid_t pid{0};
    bool done{false};
  };
  std::vector<Job> queue;
  for (Cell& c : grid) queue.push_back(Job{&c});
  std::size_t next = 0, running = 0, finished = 0;
  const auto t0 = std::chrono::steady_clock::now();
  auto launch = [&](Job& j) {
    std::vector<std::string> args = mission_args(o, *j.cell, j.cell->dir, std::to_string(threads));
    args.insert(args.begin(), "/proc/self/exe");
    std::filesystem::create_directories(j.cell->dir);
    const pid_t pid = fork();
    if (pid == 0) {
      const std::string log = j.cell->dir + "/mission.log";
      if (std::freopen(log.c_str(), "w", stdout) == nullptr || std::freopen(log.c_str(), "a", stderr) == nullptr) _exit(127);
      std::vector<char*> argv;
      for (auto& s : args) argv.push_back(s.data());
      argv.push_back(nullptr);
      execv("/proc/self/exe", argv.data());
      _exit(127);
    }
    j.pid = pid;
    ++running;
  };
  for (;;) {
    while (running < static_cast<std::size_t>(jobs) && next < queue.size()) {
      Job& j = queue[next++];
      if (fs::exists(j.cell->dir + "/metrics.json")) {
        j.done = true;
        ++finished;
        continue;
      }
      launch(j);
    }
    if (running == 0) break;
    int st = 0;
    const pid_t pid = waitpid(-1, &st, 0);
    if (pid <= 0) break;
    for (auto& j : queue)
      if (j.pid == pid && !j.done) {
        j.done = true;
        --running;
        ++finished;
        const double el = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        std::fprintf(stderr, "[%zu/%zu] %s %s (%.0f s elapsed)\n", finished, queue.size(), j.cell->dir.c_str(),
                     WIFEXITED(st) && WEXITSTATUS(st) == 0 ? "done" : "FAILED (see its mission.log)", el);
      }
  }
}

}  // namespace

int study_cmd(int argc, char** argv) {
  for (int i = 2; i < argc; ++i)
    if (std::string(argv[i]) == "--help" || std::string(argv[i]) == "-h") {
      std::fputs(kStudyHelp, stdout);
      return 0;
    }
  const Options o = parse(argc, argv);
  check_oracles(o);
  if (o.has("compute-time"))
    if (auto m = ag::sim::parse_compute_time(o.get("compute-time")); !m) usage("--compute-time: " + m.error().message);
  if (o.has("target-cpu"))
    if (auto c = ag::sim::parse_target_cpu(o.get("target-cpu")); !c) usage("--target-cpu: " + c.error().message);
  if (o.has("slurm") && o.has("report-only")) usage("--slurm writes the job array and --report-only merges its results: one at a time");
  if (o.has("cpus-per-task") && !o.has("slurm")) usage("--cpus-per-task is for --slurm (a local study uses --jobs)");
  if (o.has("slurm") && o.get("slurm").empty()) usage("--slurm needs a folder");
  const std::string out = o.get("out", "study");
  std::size_t sizes = 0, ranges = 0;
  int seeds = 0;
  std::vector<Cell> grid = make_grid(o, out, sizes, ranges, seeds);
  const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  const int jobs = static_cast<int>(number(o, "jobs", std::max(1, cores / 2)));
  if (jobs < 1) usage("--jobs must be >= 1");
  std::error_code ec;
  fs::create_directories(fs::path(out) / "runs", ec);
  if (ec) {
    std::fprintf(stderr, "airground-sim study: cannot create %s: %s\n", (fs::path(out) / "runs").c_str(), ec.message().c_str());
    return 1;
  }
  if (o.has("slurm")) return write_slurm_array(o, grid, out);
  if (!o.has("report-only")) {
    std::fprintf(stderr, "study: %zu missions (%zu team sizes x %zu ranges x %d seeds), %d at once -> %s\n", grid.size(), sizes, ranges, seeds, jobs,
                 out.c_str());
    run_local(o, grid, jobs, std::max(1, cores / jobs));
  }
  auto s = ag::sim::summarise_study(out);
  if (!s) {
    std::fprintf(stderr, "airground-sim: %s\n", s.error().message.c_str());
    return 1;
  }
  std::printf("%s", s.value().c_str());
  return 0;
}
