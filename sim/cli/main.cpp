// airground-sim: the command table and main(); the commands are in cli_*.cpp and in the tools' own files.
#include <cctype>
#include <cstdio>
#include <set>
#include <string>
#include <string_view>

#include "cli.hpp"

using namespace ag::sim::cli;

namespace {

constexpr const char* kUsage =
    "airground-sim — the world our robots live in when there is no field\n\n"
    "Usage:\n"
    "  airground-sim world generate --seed S [--size METRES] [--targets N] [--resolution M] --out DIR\n"
    "  airground-sim world import --classes RASTER.png --legend LEGEND.yaml --resolution METRES_PER_PIXEL\n"
    "                             --out DIR [--elevation RASTER.tif] [--color IMAGE.png] [--name NAME]\n"
    "                             [--datum LAT,LON,HEIGHT]   (--px-per-m P instead of --resolution)\n"
    "                             [--targets FILE.yaml | --target-link METRES]   (the mission's targets: your file,\n"
    "                             or the map's parked-car clusters, cars within 12 m of each other one cluster)\n"
    "  airground-sim world show DIR --out DIR\n"
    "  airground-sim render --world W --pose X Y Z ROLL PITCH YAW --out DIR [--scale 0.5] [--config camera.yaml]\n"
    "  airground-sim scan --world W --pose X Y YAW --out DIR [--columns 512|1024|2048] [--height 0.6]\n"
    "  airground-sim run --world W --ugvs N --seed S --duration T --out DIR [options]\n"
    "  airground-sim eval mapping --world W --seed S --out DIR [options]   (see eval mapping --help)\n"
    "  airground-sim eval vo --world W --seed S --out DIR [options]   (the quadrotor's visual odometry; eval vo --help)\n"
    "  airground-sim vo --images DIR --camera CAMERA.yaml --out DIR   (visual odometry over your own images)\n"
    "  airground-sim eval localization --world W --seed S --init-error 16 --map gt|online --out DIR [options]\n"
    "                                  (see eval localization --help)\n"
    "  airground-sim eval planning --world W --seed S --pairs 20 --out DIR   (see eval planning --help)\n"
    "  airground-sim mission --world W --ugvs N --seed S [--comm-range METRES] [--mission FILE.yaml] --out DIR\n"
    "  airground-sim hil --world W --mission FILE.yaml --out DIR   (the real role binaries over the wire protocols)\n"
    "                        (a whole team mission and its report; see mission --help)\n"
    "  airground-sim study --ugvs 1,2,3,5,10 --comm-range 50,150,1000 --seeds K --out DIR   (a grid of missions;\n"
    "                        --slurm SDIR writes it as a Slurm job array)\n"
    "  airground-sim survey-plan --world W --out FILE.plan   (the quadrotor's survey as a QGroundControl plan)\n"
    "  airground-sim segment --weights FILE --image IMAGE.png --out DIR [--threads N]   (ErfNet: logits.npy,\n"
    "                        classes.png; see segment --help)\n"
    "  airground-sim lidar-info --pcap FILE --metadata FILE [--out DIR]   (an Ouster capture: sensor, profile,\n"
    "                        frames, errors; the first frame as PNGs and PLY; see lidar-info --help)\n"
    "  airground-sim config --out DIR   (every simulator model's parameters with units and ranges, as\n"
    "                                    YAML files that 'run --config-dir DIR' reads back)\n\n"
    "--world W is a world directory or 'default' (the built-in 400 m world, seed 42).\n"
    "Angles in radians, positions in metres in the world's map frame (x east, y north, origin at the centre).\n"
    "'airground-sim COMMAND --help' shows a command's options. Exit status: 0 ok, 1 failed, 2 bad usage.\n";

// The command table; kUsage is the help of the commands without one of their own.
constexpr Command kCommands[] = {
    {"run", kRunHelp, &run},
    {"mission", kMissionHelp, &mission_cmd},
    {"hil", kHilHelp, &hil_cmd},
    {"eval mapping", kEvalMappingHelp, &eval_mapping_cmd},
    {"eval localization", kEvalLocalizationHelp, &eval_localization_cmd},
    {"eval planning", kEvalPlanningHelp, &eval_planning_cmd},
    {"world generate", kUsage, &world_generate},
    {"world import", kUsage, &world_import},
    {"world show", kUsage, &world_show},
    {"render", kUsage, &render},
    {"scan", kUsage, &scan},
    {"config", kUsage, &write_model_configs},
};
constexpr OwnCommand kOwnCommands[] = {
    {"eval vo", &eval_vo_cmd},  {"vo", &vo_cmd},        {"segment", &segment_cmd}, {"lidar-info", &lidar_info_cmd},
    {"study", &study_cmd},      {"survey-plan", &survey_plan_cmd},
};

// The options a help text names: every "--word" in it.
std::set<std::string> named_options(std::string_view help) {
  std::set<std::string> out;
  for (std::size_t i = help.find("--"); i != std::string_view::npos; i = help.find("--", i + 2)) {
    std::size_t e = i + 2;
    while (e < help.size() && (std::islower(static_cast<unsigned char>(help[e])) != 0 || std::isdigit(static_cast<unsigned char>(help[e])) != 0 ||
                               (help[e] == '-' && e > i + 2)))
      ++e;
    if (e > i + 2) out.emplace(help.substr(i + 2, e - i - 2));
  }
  return out;
}

void check_options(const Args& a, const Command& c) {
  const std::set<std::string> allowed = named_options(c.help);
  for (const auto& [k, v] : a.opt)
    if (allowed.count(k) == 0) usage_error("unknown option '--" + k + "' for " + std::string(c.name) + " (see airground-sim " + std::string(c.name) + " --help)");
}

// argv[1] [argv[2]] against the command names: the two-word name first ("eval mapping" before "eval").
template <class C, std::size_t N>
const C* find_command(const C (&table)[N], int argc, char** argv, int& words) {
  const std::string one = argc > 1 ? argv[1] : "";
  const std::string two = argc > 2 ? one + " " + argv[2] : "";
  for (const C& c : table)
    if (!two.empty() && c.name == two) {
      words = 2;
      return &c;
    }
  for (const C& c : table)
    if (c.name == one) {
      words = 1;
      return &c;
    }
  return nullptr;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || std::string(argv[1]) == "--help" || std::string(argv[1]) == "-h") {
    std::fputs(kUsage, argc < 2 ? stderr : stdout);
    return argc < 2 ? 2 : 0;
  }
  if (std::string(argv[1]) == "--version") {
    std::printf("airground-sim 0.1.0\n");
    return 0;
  }
  const bool help = [&] {
    for (int i = 1; i < argc; ++i)
      if (std::string(argv[i]) == "--help" || std::string(argv[i]) == "-h") return true;
    return false;
  }();
  try {
    int words = 0;
    if (const OwnCommand* c = find_command(kOwnCommands, argc, argv, words)) return c->handler(argc, argv);
    if (const Command* c = find_command(kCommands, argc, argv, words)) {
      if (help) {
        std::fputs(c->help, stdout);
        return 0;
      }
      const Args a = parse(argc, argv, 1 + words);
      check_options(a, *c);
      return c->handler(a);
    }
    if (help) {
      std::fputs(kUsage, stdout);
      return 0;
    }
    const std::string cmd = argv[1];
    if (cmd == "world") usage_error(argc < 3 ? "world needs generate, import or show" : "unknown world command '" + std::string(argv[2]) + "'");
    if (cmd == "eval") usage_error("eval needs 'mapping', 'vo', 'localization' or 'planning'");
    usage_error("unknown command '" + cmd + "'");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "airground-sim: %s\n", e.what());
    return 1;
  }
}
