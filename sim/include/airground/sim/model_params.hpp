// Loading one simulator model's parameters from a YAML mapping, checked against its ParamSpec table.
#pragma once

#include <yaml-cpp/yaml.h>

#include <span>
#include <string>
#include <string_view>

#include "airground/platform/config.hpp"
#include "airground/platform/result.hpp"

namespace ag::sim {

// `node` is the model's own mapping (key: scalar); null or undefined means all defaults. `schema` holds
// exactly one section. Unknown keys, wrong types and
// out-of-range values are ErrorCode::kConfig errors naming origin:line, the key and the allowed range.
inline Result<Config> load_model_params(std::span<const ParamSection> schema, const YAML::Node& node,
                                        std::string_view origin) {
  Config c = Config::defaults(schema);
  if (!node.IsDefined() || node.IsNull()) return c;
  const std::string section(schema.front().name);
  if (!node.IsMap())
    return Error::make(ErrorCode::kConfig, "config error: " + std::string(origin) + ": '" + section +
                                               "' must be a mapping of key: value");
  for (const auto& kv : node) {
    const std::string key = kv.first.Scalar();
    const std::string where = std::string(origin) + ":" + std::to_string(kv.first.Mark().line + 1);
    if (!kv.second.IsScalar()) {
      // An unknown key is reported as unknown before its shape.
      if (auto st = c.set(section + "." + key + "=", where); !st && st.error().message.find("unknown") != std::string::npos)
        return st.error();
      return Error::make(ErrorCode::kConfig, "config error: " + where + ": key '" + section + "." + key +
                                                 "' must be a single value, not a list or mapping");
    }
    if (auto st = c.set(section + "." + key + "=" + kv.second.Scalar(), where); !st) return st.error();
  }
  return c;
}

// The same from YAML text whose top level is the model's mapping.
inline Result<Config> load_model_params(std::span<const ParamSection> schema, std::string_view yaml,
                                        std::string_view origin) {
  YAML::Node node;
  try {
    node = YAML::Load(std::string(yaml));
  } catch (const YAML::Exception& e) {
    return Error::make(ErrorCode::kConfig, "config error: " + std::string(origin) + ":" +
                                               std::to_string(e.mark.line + 1) + ": malformed YAML: " + e.msg);
  }
  return load_model_params(schema, node, origin);
}

// A model file's mapping: its keys at the top level, or under one key named after the model's section
// (as `airground-sim config --out` writes it). Both the runner and `eval mapping` read files this way.
inline YAML::Node model_mapping(const YAML::Node& root, std::string_view section) {
  const std::string sec(section);
  if (root.IsMap() && root.size() == 1 && root[sec]) return root[sec];
  return root;
}

inline Error model_config_error(std::string_view origin, const std::string& what) {
  return Error::make(ErrorCode::kConfig, "config error: " + std::string(origin) + ": " + what);
}

}  // namespace ag::sim
