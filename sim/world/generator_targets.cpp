// targets.yaml (the mission's car clusters and the staging pose) and the built-in default world.
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include "airground/sim/generator.hpp"

namespace ag::sim {

namespace {

std::string number(double v) {
  char buf[64];
  const auto res = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, res.ptr);
}

struct DefaultScene {
  World world;
  std::vector<TargetCluster> targets;
};

const DefaultScene& default_scene() {
  static const DefaultScene scene = [] {
    GeneratorOptions o;
    o.seed = 42;
    o.size_m = 400;
    o.resolution = 0.25;
    o.targets = 13;
    DefaultScene s;
    auto w = generate_world(o, &s.targets);
    if (!w) {  // a fixed seed either always works or never does: the tests catch it
      std::fprintf(stderr, "default world: %s\n", w.error().message.c_str());
      std::abort();
    }
    s.world = std::move(w.value());
    s.world.header.name = "default";
    return s;
  }();
  return scene;
}

Error targets_error(ErrorCode code, const std::string& path, const std::string& what) {
  return Error::make(code, "targets file " + path + ": " + what);
}

}  // namespace

const World& default_world() { return default_scene().world; }
const std::vector<TargetCluster>& default_targets() { return default_scene().targets; }

Status save_targets(const std::vector<TargetCluster>& targets, const Pose2& staging, const std::string& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  const std::string path = (std::filesystem::path(dir) / "targets.yaml").string();
  std::ostringstream y;
  y << "# Mission targets of an airground world: clusters of parked cars (class vehicle) and the staging\n"
       "# pose the ground robots start from. Map frame (local ENU): [m], yaw [rad] from east, CCW.\n";
  y << "format_version: 1\n";
  y << "staging: {x: " << number(staging.x) << ", y: " << number(staging.y) << ", yaw: " << number(staging.yaw) << "}\n";
  y << "targets:\n";
  if (targets.empty()) y << "  []\n";
  for (const TargetCluster& t : targets) {
    y << "  - id: " << t.id << "\n";
    y << "    x: " << number(t.x) << "\n";
    y << "    y: " << number(t.y) << "\n";
    y << "    cars: " << t.cars << "\n";
    y << "    car_poses:  # [x, y, yaw]\n";
    for (const Pose2& p : t.car_poses) y << "      - [" << number(p.x) << ", " << number(p.y) << ", " << number(p.yaw) << "]\n";
  }
  const std::string text = y.str();
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) return targets_error(ErrorCode::kIo, path, "cannot create");
  out << text;
  out.close();
  if (!out) return targets_error(ErrorCode::kIo, path, "write failed");
  return ok_status();
}

Result<TargetsFile> load_targets(const std::string& dir) {
  return load_targets_file((std::filesystem::path(dir) / "targets.yaml").string());
}

Result<TargetsFile> load_targets_file(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) return targets_error(ErrorCode::kIo, path, "missing (no such file)");
  std::ifstream in(path, std::ios::binary);
  if (!in) return targets_error(ErrorCode::kIo, path, "cannot open");
  std::string text;
  in.seekg(0, std::ios::end);
  text.resize(static_cast<std::size_t>(std::max<std::streamoff>(in.tellg(), 0)));
  in.seekg(0);
  in.read(text.data(), static_cast<std::streamsize>(text.size()));
  if (!in) return targets_error(ErrorCode::kIo, path, "read error");
  TargetsFile out;
  try {
    const YAML::Node root = YAML::Load(text);
    if (!root.IsMap()) return targets_error(ErrorCode::kMalformed, path, "expected a map (empty or truncated file?)");
    if (!root["format_version"] || root["format_version"].as<int>() != 1) {
      return targets_error(ErrorCode::kMalformed, path, "format_version must be 1");
    }
    const YAML::Node st = root["staging"];
    if (!st || !st.IsMap()) return targets_error(ErrorCode::kMalformed, path, "missing 'staging: {x, y, yaw}'");
    out.staging = Pose2{st["x"].as<double>(), st["y"].as<double>(), st["yaw"].as<double>()};
    const YAML::Node list = root["targets"];
    if (!list || !list.IsSequence()) return targets_error(ErrorCode::kMalformed, path, "missing 'targets:' list");
    std::set<int> ids;
    for (const YAML::Node& n : list) {
      const std::string line = "line " + std::to_string(n.Mark().line + 1) + ": ";
      TargetCluster t;
      t.id = n["id"].as<int>();
      t.x = n["x"].as<double>();
      t.y = n["y"].as<double>();
      t.cars = n["cars"].as<int>();
      const YAML::Node poses = n["car_poses"];
      if (!poses || !poses.IsSequence()) return targets_error(ErrorCode::kMalformed, path, line + "missing car_poses list");
      for (const YAML::Node& p : poses) {
        if (!p.IsSequence() || p.size() != 3) return targets_error(ErrorCode::kMalformed, path, line + "a car pose must be [x, y, yaw]");
        t.car_poses.push_back(Pose2{p[0].as<double>(), p[1].as<double>(), p[2].as<double>()});
      }
      if (t.cars < 1 || static_cast<std::size_t>(t.cars) != t.car_poses.size()) {
        return targets_error(ErrorCode::kMalformed, path, line + "cars (" + std::to_string(t.cars) + ") must equal the number of car_poses (" +
                                                              std::to_string(t.car_poses.size()) + ") and be at least 1");
      }
      if (!ids.insert(t.id).second) return targets_error(ErrorCode::kMalformed, path, line + "duplicate target id " + std::to_string(t.id));
      for (const Pose2& p : t.car_poses) {
        if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.yaw)) {
          return targets_error(ErrorCode::kMalformed, path, line + "car pose is not finite");
        }
      }
      out.targets.push_back(std::move(t));
    }
  } catch (const YAML::Exception& e) {
    return targets_error(ErrorCode::kMalformed, path, "line " + std::to_string(e.mark.line + 1) + ": " + e.msg);
  }
  return out;
}

}  // namespace ag::sim
