// Class table loading and validation.
#include "airground/messages/classes.hpp"

#include <yaml-cpp/yaml.h>

#include <fstream>
#include <set>
#include <sstream>

namespace ag {

namespace {
constexpr const char* kBuiltinYaml = R"(classes:
  - {id: 0, name: road, color: [128, 64, 128], traversability: 0, localization_weight: 2.0}
  - {id: 1, name: dirt, color: [150, 120, 80], traversability: 1, localization_weight: 1.5}
  - {id: 2, name: grass, color: [110, 190, 60], traversability: 2, localization_weight: 0.75}
  - {id: 3, name: tree, color: [20, 100, 30], traversability: 3, localization_weight: 1.5}
  - {id: 4, name: building, color: [90, 90, 100], traversability: 3, localization_weight: 1.5}
  - {id: 5, name: vehicle, color: [230, 40, 40], traversability: 3, localization_weight: 0.5}
  - {id: 6, name: water, color: [40, 110, 210], traversability: 3, localization_weight: 0.0}
  - {id: 255, name: unknown, color: [0, 0, 0], traversability: 3, localization_weight: 0.0}
)";

Error err(std::string_view origin, int line, const std::string& what) {
  return Error::make(ErrorCode::kConfig, "class table " + std::string(origin) + (line > 0 ? ":" + std::to_string(line) : "") + ": " + what);
}
}  // namespace

const ClassTable& ClassTable::builtin() {
  static const ClassTable t = load_string(kBuiltinYaml, "<built-in>").value();
  return t;
}

Result<ClassTable> ClassTable::load_string(std::string_view yaml, std::string_view origin) {
  ClassTable t;
  t.index_.fill(-1);
  YAML::Node root;
  try {
    root = YAML::Load(std::string(yaml));
  } catch (const YAML::Exception& e) {
    return err(origin, e.mark.line + 1, "malformed YAML: " + e.msg);
  }
  if (!root.IsMap() || !root["classes"] || !root["classes"].IsSequence()) return err(origin, 0, "expected a 'classes:' list");
  std::set<std::string> names;
  for (const auto& n : root["classes"]) {
    const int line = n.Mark().line + 1;
    try {
      ClassInfo c;
      const int id = n["id"].as<int>();
      if (id < 0 || id > 255) return err(origin, line, "id " + std::to_string(id) + " outside 0..255");
      c.id = static_cast<ClassId>(id);
      c.name = n["name"].as<std::string>();
      const auto col = n["color"];
      if (!col.IsSequence() || col.size() != 3) return err(origin, line, "color must be [R, G, B]");
      for (int k = 0; k < 3; ++k) {
        const int v = col[static_cast<std::size_t>(k)].as<int>();
        if (v < 0 || v > 255) return err(origin, line, "color component outside 0..255");
      }
      c.color = Rgb{static_cast<std::uint8_t>(col[0].as<int>()), static_cast<std::uint8_t>(col[1].as<int>()),
                    static_cast<std::uint8_t>(col[2].as<int>())};
      const int tr = n["traversability"].as<int>();
      if (tr < 0 || tr > 3) return err(origin, line, "traversability must be 0..3");
      c.traversability = static_cast<Traversability>(tr);
      c.localization_weight = n["localization_weight"].as<double>();
      if (c.localization_weight < 0 || c.localization_weight > 10) return err(origin, line, "localization_weight must be in [0, 10]");
      if (t.index_[static_cast<std::size_t>(id)] >= 0) return err(origin, line, "duplicate id " + std::to_string(id));
      if (!names.insert(c.name).second) return err(origin, line, "duplicate name '" + c.name + "'");
      t.index_[static_cast<std::size_t>(id)] = static_cast<std::int16_t>(t.classes_.size());
      t.classes_.push_back(std::move(c));
    } catch (const YAML::Exception& e) {
      return err(origin, line, "entry needs id, name, color, traversability, localization_weight (" + e.msg + ")");
    }
  }
  if (t.index_[raw(ClassId::kUnknown)] < 0) return err(origin, 0, "the table must define id 255 (unknown)");
  return t;
}

Result<ClassTable> ClassTable::load_file(const std::string& path) {
  std::ifstream in(path);
  if (!in) return err(path, 0, "cannot open");
  std::ostringstream ss;
  ss << in.rdbuf();
  return load_string(ss.str(), path);
}

const ClassInfo& ClassTable::info(ClassId id) const noexcept {
  const auto i = index_[raw(id)];
  return classes_[static_cast<std::size_t>(i >= 0 ? i : index_[raw(ClassId::kUnknown)])];
}

std::optional<ClassId> ClassTable::by_name(std::string_view name) const noexcept {
  for (const auto& c : classes_)
    if (c.name == name) return c.id;
  return std::nullopt;
}

bool ClassTable::valid_id(std::uint8_t r) const noexcept { return index_[r] >= 0; }

}  // namespace ag
