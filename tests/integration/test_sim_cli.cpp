// airground-sim as a user runs it: every command's files, bad usage, corrupt worlds and configs.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "../mcap_reader/mcap_read.hpp"
#include "process.hpp"

namespace ag::test {
namespace {

namespace fs = std::filesystem;

std::string sim_bin() { return binary_dir() + "/sim/airground-sim"; }
std::string tmp(const std::string& name) { return (fs::path(::testing::TempDir()) / ("simcli-" + name)).string(); }

TEST(SimCli, HelpAndBadUsage) {
  const auto help = run({sim_bin(), "--help"});
  EXPECT_EQ(help.exit_code, 0);
  EXPECT_NE(help.out.find("world generate --seed S"), std::string::npos);
  EXPECT_NE(run({sim_bin(), "run", "--help"}).out.find("--duration"), std::string::npos);
  EXPECT_EQ(run({sim_bin()}).exit_code, 2);
  EXPECT_EQ(run({sim_bin(), "frobnicate"}).exit_code, 2);
  EXPECT_EQ(run({sim_bin(), "render", "--pose", "1", "2"}).exit_code, 2) << "--pose needs six numbers";
  EXPECT_EQ(run({sim_bin(), "run", "--duration", "abc"}).exit_code, 2);
  EXPECT_NE(run({sim_bin(), "mission", "--help"}).out.find("4x the survey's flying time"), std::string::npos);
  for (const char* bad : {"0", "-5"}) {  // 0 is the library's "from the survey", not a user's value
    const auto r = run({sim_bin(), "mission", "--max-duration", bad, "--out", tmp("bad_cap")});
    EXPECT_EQ(r.exit_code, 2) << bad;
    EXPECT_NE(r.err.find("--max-duration must be > 0"), std::string::npos) << r.err;
  }
}

TEST(SimCli, AnOptionTheCommandDoesNotHaveIsAnErrorNamingIt) {
  // A mistyped --ugvs would otherwise run the default team without a word.
  const auto typo = run({sim_bin(), "mission", "--ugv", "3", "--out", tmp("typo")});
  EXPECT_EQ(typo.exit_code, 2);
  EXPECT_NE(typo.err.find("unknown option '--ugv' for mission"), std::string::npos) << typo.err;
  EXPECT_FALSE(fs::exists(tmp("typo"))) << "nothing ran";
  // An option of another command is refused too: --duration is run's, mission has --max-duration.
  const auto other = run({sim_bin(), "mission", "--duration", "60", "--out", tmp("typo")});
  EXPECT_EQ(other.exit_code, 2);
  EXPECT_NE(other.err.find("'--duration'"), std::string::npos) << other.err;
  const auto eval = run({sim_bin(), "eval", "localization", "--init-eror", "4"});
  EXPECT_EQ(eval.exit_code, 2);
  EXPECT_NE(eval.err.find("for eval localization"), std::string::npos) << eval.err;
  // --target-cpu and --compute-time name their choices.
  const auto cpu = run({sim_bin(), "mission", "--target-cpu", "pi4", "--out", tmp("typo")});
  EXPECT_EQ(cpu.exit_code, 2);
  EXPECT_NE(cpu.err.find("nuc, ryzen, xavier-nx"), std::string::npos) << cpu.err;
  EXPECT_EQ(run({sim_bin(), "run", "--compute-time", "fast", "--out", tmp("typo")}).exit_code, 2);
  EXPECT_EQ(run({sim_bin(), "study", "--target-cpu", "pi4", "--out", tmp("typo")}).exit_code, 2);
  EXPECT_NE(run({sim_bin(), "mission", "--help"}).out.find("--target-cpu"), std::string::npos);
  // The guesses' sigma must be a positive number.
  const auto sigma = run({sim_bin(), "mission", "--init-sigma", "-3", "--out", tmp("typo")});
  EXPECT_EQ(sigma.exit_code, 2);
  EXPECT_NE(sigma.err.find("--init-sigma must be > 0"), std::string::npos) << sigma.err;
}

TEST(SimCli, GenerateShowRenderScanOnASmallWorld) {
  const std::string w = tmp("world");
  fs::remove_all(w);
  const auto gen = run({sim_bin(), "world", "generate", "--seed", "3", "--size", "200", "--targets", "4", "--out", w}, 120);
  ASSERT_EQ(gen.exit_code, 0) << gen.err;
  for (const char* f : {"world.yaml", "class.png", "albedo.png", "height.tif", "terrain.tif", "targets.yaml", "png/class.png", "png/hillshade.png"})
    EXPECT_TRUE(fs::exists(fs::path(w) / f)) << f;
  const auto show = run({sim_bin(), "world", "show", w, "--out", tmp("show")}, 60);
  EXPECT_EQ(show.exit_code, 0) << show.err;
  EXPECT_TRUE(fs::exists(fs::path(tmp("show")) / "albedo.png"));
  const auto render = run({sim_bin(), "render", "--world", w, "--pose", "0", "0", "40", "0", "0", "0.5", "--scale", "0.25", "--out", tmp("render")}, 60);
  ASSERT_EQ(render.exit_code, 0) << render.err;
  for (const char* f : {"rgb.png", "class.png", "depth_mm.png"}) EXPECT_TRUE(fs::exists(fs::path(tmp("render")) / f)) << f;
  const auto scan = run({sim_bin(), "scan", "--world", w, "--pose", "-60", "-60", "0.3", "--columns", "512", "--out", tmp("scan")}, 60);
  ASSERT_EQ(scan.exit_code, 0) << scan.err;
  std::ifstream ply(fs::path(tmp("scan")) / "scan.ply");
  std::string first;
  std::getline(ply, first);
  EXPECT_EQ(first, "ply");
}

// A user's own map is a whole mission: world import derives targets.yaml from the map's parked cars (or
// takes the user's file, checked against the world), and a mission on the imported world is scored.
TEST(SimCli, AnImportedMapIsAScoredMission) {
  const std::string gen = tmp("import-gen"), imp = tmp("import-world"), mine = tmp("import-mine"), m = tmp("import-mission");
  for (const std::string& d : {gen, imp, mine, m}) fs::remove_all(d);
  ASSERT_EQ(run({sim_bin(), "world", "generate", "--seed", "7", "--size", "200", "--targets", "6", "--out", gen}, 120).exit_code, 0);
  const std::string legend = tmp("import-legend.yaml");
  std::ofstream(legend) << "classes:\n  - {value: 0, class: road}\n  - {value: 1, class: dirt}\n  - {value: 2, class: grass}\n"
                           "  - {value: 3, class: tree}\n  - {value: 4, class: building}\n  - {value: 5, class: vehicle}\n"
                           "  - {value: 6, class: water}\n";
  const std::vector<std::string> base{sim_bin(), "world", "import", "--classes", gen + "/class.png", "--legend", legend, "--resolution", "0.25"};
  auto with = [&](std::vector<std::string> extra) {
    std::vector<std::string> v = base;
    v.insert(v.end(), extra.begin(), extra.end());
    return v;
  };
  const auto derived = run(with({"--out", imp}), 120);
  ASSERT_EQ(derived.exit_code, 0) << derived.err;
  EXPECT_NE(derived.out.find("6 targets derived from the vehicle class"), std::string::npos) << derived.out;
  EXPECT_TRUE(fs::exists(fs::path(imp) / "targets.yaml"));

  // The user's own file: its staging pose becomes the world's; a target outside the world is refused.
  const auto own = run(with({"--targets", gen + "/targets.yaml", "--out", mine}), 120);
  ASSERT_EQ(own.exit_code, 0) << own.err;
  EXPECT_NE(own.out.find("6 targets from " + gen + "/targets.yaml"), std::string::npos) << own.out;
  const std::string bad = tmp("import-bad-targets.yaml");
  std::ofstream(bad) << "format_version: 1\nstaging: {x: 0, y: 0, yaw: 0}\ntargets:\n  - id: 4\n    x: 500\n    y: 0\n    cars: 1\n"
                        "    car_poses:\n      - [500, 0, 0]\n";
  const auto refused = run(with({"--targets", bad, "--out", tmp("import-refused")}), 120);
  EXPECT_EQ(refused.exit_code, 1);
  EXPECT_NE(refused.err.find("target 4"), std::string::npos) << refused.err;
  EXPECT_EQ(run(with({"--target-link", "0", "--out", tmp("import-refused")}), 60).exit_code, 2);

  const auto mission = run({sim_bin(), "mission", "--world", imp, "--ugvs", "1", "--seed", "1", "--max-duration", "10", "--record", "none",
                            "--quiet", "--out", m},
                           300);
  ASSERT_EQ(mission.exit_code, 0) << mission.err;
  std::ifstream metrics(fs::path(m) / "metrics.json");
  std::stringstream ss;
  ss << metrics.rdbuf();
  // Every derived target is scored, or named as lying outside the surveyed area (the world less its 20 m
  // border: generated worlds put cars near their edges).
  auto number = [&](const std::string& key) {
    const std::size_t at = ss.str().find("\"" + key + "\": ");
    return at == std::string::npos ? -1 : std::stoi(ss.str().substr(at + key.size() + 4));
  };
  const int scored = number("targets_total"), outside = number("targets_outside_survey");
  EXPECT_EQ(scored + outside, 6) << ss.str().substr(0, 400);
  EXPECT_GE(scored, 4) << ss.str().substr(0, 400);
  EXPECT_EQ(outside > 0, mission.err.find("no car in the surveyed area") != std::string::npos) << mission.err;
  EXPECT_EQ(mission.err.find("targets are not scored"), std::string::npos) << mission.err;
}

TEST(SimCli, CorruptWorldIsAClearError) {
  const std::string w = tmp("corrupt");
  fs::remove_all(w);
  ASSERT_EQ(run({sim_bin(), "world", "generate", "--seed", "5", "--size", "200", "--targets", "2", "--out", w}, 120).exit_code, 0);
  fs::resize_file(fs::path(w) / "class.png", 100);
  const auto r = run({sim_bin(), "render", "--world", w, "--pose", "0", "0", "40", "0", "0", "0", "--out", tmp("r2")}, 60);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("class.png"), std::string::npos) << r.err;
}

TEST(SimCli, ModelConfigsRoundTripAndBadValuesAreRefused) {
  const std::string c = tmp("cfg");
  fs::remove_all(c);
  ASSERT_EQ(run({sim_bin(), "config", "--out", c}).exit_code, 0);
  const auto ok = run({sim_bin(), "run", "--ugvs", "1", "--duration", "1", "--camera-scale", "0.25", "--lidar-columns", "512",
                       "--record", "none", "--quiet", "--config-dir", c, "--out", tmp("run-ok")}, 120);
  EXPECT_EQ(ok.exit_code, 0) << ok.err;
  EXPECT_TRUE(fs::exists(fs::path(tmp("run-ok")) / "summary.json"));
  std::ofstream(fs::path(c) / "gps.yaml") << "gps:\n  sigma_m: -3\n";
  const auto bad = run({sim_bin(), "run", "--ugvs", "1", "--duration", "1", "--quiet", "--config-dir", c, "--out", tmp("run-bad")}, 120);
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_NE(bad.err.find("gps.sigma_m"), std::string::npos) << bad.err;
  EXPECT_NE(bad.err.find("gps.yaml"), std::string::npos) << bad.err;
}

TEST(SimCli, EvalLocalizationHelpAndAShortRun) {
  const auto help = run({sim_bin(), "eval", "localization", "--help"});
  EXPECT_EQ(help.exit_code, 0);
  for (const char* s : {"--init-error", "--map gt|online", "--route-km", "--labels", "--set", "--stand-still-s", "--yaw-drift-at-rest"})
    EXPECT_NE(help.out.find(s), std::string::npos) << s;
  EXPECT_EQ(run({sim_bin(), "eval", "localization", "--map", "satellite"}).exit_code, 2);
  EXPECT_EQ(run({sim_bin(), "eval", "localization", "--set", "novalue"}).exit_code, 2);
  EXPECT_EQ(run({sim_bin(), "eval", "localization", "--record", "csv"}).exit_code, 2);

  const std::string w = tmp("loc-world");
  fs::remove_all(w);
  ASSERT_EQ(run({sim_bin(), "world", "generate", "--seed", "4", "--size", "200", "--targets", "2", "--out", w}, 120).exit_code, 0);
  const std::string out = tmp("loc-eval");
  fs::remove_all(out);
  const auto r = run({sim_bin(), "eval", "localization", "--world", w, "--seed", "2", "--init-error", "16", "--map", "gt", "--route-km", "0.2",
                      "--max-duration", "20", "--lidar-columns", "512", "--threads", "2", "--quiet", "--out", out}, 300);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const char* f : {"metrics.json", "report.md", "samples.csv", "trajectory.png", "error.png"})
    EXPECT_TRUE(fs::exists(fs::path(out) / f)) << f;
  std::ifstream j(fs::path(out) / "metrics.json");
  std::stringstream ss;
  ss << j.rdbuf();
  const std::string metrics = ss.str();
  for (const char* k : {"\"converged\"", "\"convergence_time_s\"", "\"loc_error_mean_m\"", "\"loc_error_p95_m\"", "\"yaw_error_mean_deg\"",
                        "\"odom_only_error_mean_m\""})
    EXPECT_NE(metrics.find(k), std::string::npos) << k;
  // recording.mcap, read back by the official reader with the counts recording.json reports
  std::string why;
  const std::string script = mcap_reader_script(source_dir(), &why);
  ASSERT_FALSE(script.empty()) << why;
  const nlohmann::json rec = read_mcap(script, out + "/recording.mcap", {"--expect", out + "/recording.json"});
  EXPECT_TRUE(rec.value("ok", false)) << rec.dump().substr(0, 300);
  EXPECT_TRUE(rec.value("problems", nlohmann::json::array()).empty()) << rec["problems"].dump();
  EXPECT_GT(rec["counts"].value("/ugv1/truth", 0), 100);
  EXPECT_GT(rec["counts"].value("/ugv1/lidar/points", 0), 0);
  // An unknown ground-robot parameter is the user's error, named.
  const auto bad = run({sim_bin(), "eval", "localization", "--world", w, "--route-km", "0.1", "--max-duration", "2", "--lidar-columns", "512",
                        "--quiet", "--set", "nosuch.key=1", "--out", tmp("loc-bad")}, 120);
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_NE(bad.err.find("nosuch"), std::string::npos) << bad.err;
}

}  // namespace
}  // namespace ag::test
