// The airground-sim command line's shared parts: parsed options and their checks, the command-table rows
// and the commands of the cli_*.cpp files.
#pragma once

#include <cstddef>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "airground/platform/result.hpp"
#include "airground/sim/compute_time.hpp"

namespace ag::sim::cli {

struct Args {
  std::vector<std::string> pos;
  std::map<std::string, std::vector<std::string>> opt;
  bool has(const std::string& k) const { return opt.count(k) != 0; }
  std::string get(const std::string& k, const std::string& def = "") const {
    auto it = opt.find(k);
    return it == opt.end() || it->second.empty() ? def : it->second.front();
  }
};

[[noreturn]] void usage_error(const std::string& msg);
// --record none|mcap of the evaluations and hil: whether they write DIR/recording.mcap.
bool record_mcap(const Args& a);
// Options take the following words up to the next "--" option; --pose takes several numbers.
Args parse(int argc, char** argv, int first);
// --oracle labels,vo: ground truth handed to the robots by name, an ablation; unknown names are an error.
std::vector<std::string> oracles_from(const Args& a);
double number(const Args& a, const std::string& k, double def);
std::vector<double> numbers(const Args& a, const std::string& k, std::size_t n);
std::string required(const Args& a, const std::string& k);
int fail(const Error& e);

// --compute-time model|measured|off and --target-cpu nuc|ryzen|xavier-nx (docs/simulator.md, "Compute time").
template <class O>
void compute_time_from(const Args& a, O& o) {
  if (a.has("compute-time")) {
    auto m = ag::sim::parse_compute_time(a.get("compute-time"));
    if (!m) usage_error("--compute-time: " + m.error().message);
    o.compute_time = m.value();
  }
  if (a.has("target-cpu")) {
    auto c = ag::sim::parse_target_cpu(a.get("target-cpu"));
    if (!c) usage_error("--target-cpu: " + c.error().message);
    o.target_cpu = c.value();
  }
}

// A command parsed here: its help is its contract, every option the help names (--x) is allowed and any
// other is an error naming it (exit 2), as the role binaries do.
struct Command {
  std::string_view name;  // "mission", "eval mapping", "world generate"
  const char* help;
  int (*handler)(const Args&);
};
// A command with its own parser (it checks its options itself, exit 2 on an unknown one).
struct OwnCommand {
  std::string_view name;
  int (*handler)(int argc, char** argv);
};

// The commands parsed here, by family, and the help texts that are their contracts.
int world_generate(const Args& a);  // cli_world.cpp
int world_import(const Args& a);
int world_show(const Args& a);
int render(const Args& a);
int scan(const Args& a);
extern const char kRunHelp[];  // cli_run.cpp
int run(const Args& a);
int write_model_configs(const Args& a);
extern const char kEvalMappingHelp[];  // cli_eval.cpp
extern const char kEvalLocalizationHelp[];
extern const char kEvalPlanningHelp[];
int eval_mapping_cmd(const Args& a);
int eval_localization_cmd(const Args& a);
int eval_planning_cmd(const Args& a);
extern const char kMissionHelp[];  // cli_mission.cpp
extern const char kHilHelp[];
int mission_cmd(const Args& a);
int hil_cmd(const Args& a);

}  // namespace ag::sim::cli

// Commands with their own parsers.
int segment_cmd(int argc, char** argv);      // segment.cpp
int vo_cmd(int argc, char** argv);           // vo.cpp
int eval_vo_cmd(int argc, char** argv);      // vo.cpp
int lidar_info_cmd(int argc, char** argv);   // lidar_info.cpp
int study_cmd(int argc, char** argv);        // study.cpp
int survey_plan_cmd(int argc, char** argv);  // survey_plan.cpp
