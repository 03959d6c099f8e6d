// Config loading: YAML through yaml-cpp, every value checked against its ParamSpec.
#include "airground/platform/config.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace ag {

std::string_view to_string(ParamType t) noexcept {
  switch (t) {
    case ParamType::kBool: return "bool";
    case ParamType::kInt: return "integer";
    case ParamType::kReal: return "number";
    case ParamType::kText: return "text";
  }
  return "?";
}

namespace {

std::string fmt_num(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.10g", v);
  return buf;
}

// Shortest text that reads back to the same double, so to_yaml() round-trips exactly.
std::string fmt_exact(double v) {
  char buf[64];
  const auto res = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, res.ptr);
}

// A YAML double-quoted scalar: quotes, backslashes and control characters escaped.
std::string yaml_quoted(std::string_view text) {
  std::string out = "\"";
  for (const char ch : text) {
    if (ch == '"' || ch == '\\') {
      out += '\\';
      out += ch;
    } else if (static_cast<unsigned char>(ch) < 0x20) {
      char esc[8];
      std::snprintf(esc, sizeof esc, "\\x%02x", static_cast<unsigned>(static_cast<unsigned char>(ch)));
      out += esc;
    } else {
      out += ch;
    }
  }
  return out + "\"";
}

std::string range_text(const ParamSpec& s) {
  switch (s.type) {
    case ParamType::kBool: return "true|false";
    case ParamType::kText: return s.choices.empty() ? std::string("any text") : std::string(s.choices);
    case ParamType::kInt:
    case ParamType::kReal: {
      std::string r = "[" + fmt_num(s.min) + ", " + fmt_num(s.max) + "]";
      if (!s.unit.empty()) r += " " + std::string(s.unit);
      return r;
    }
  }
  return {};
}

Config::Value default_of(const ParamSpec& s) {
  switch (s.type) {
    case ParamType::kBool: return s.default_num != 0.0;
    case ParamType::kInt: return static_cast<std::int64_t>(s.default_num);
    case ParamType::kReal: return s.default_num;
    case ParamType::kText: return std::string(s.default_text);
  }
  return 0.0;
}

bool in_choices(std::string_view choices, std::string_view v) {
  if (choices.empty()) return true;
  std::size_t start = 0;
  while (start <= choices.size()) {
    const std::size_t bar = choices.find('|', start);
    const std::string_view c = choices.substr(start, bar == std::string_view::npos ? std::string_view::npos : bar - start);
    if (c == v) return true;
    if (bar == std::string_view::npos) break;
    start = bar + 1;
  }
  return false;
}

Error config_error(std::string_view where, const std::string& what) {
  return Error::make(ErrorCode::kConfig, "config error: " + std::string(where) + ": " + what);
}

std::string known_keys(std::span<const ParamSection> schema, std::string_view section) {
  std::string out;
  for (const auto& sec : schema) {
    if (section.empty()) {
      out += (out.empty() ? "" : ", ") + std::string(sec.name);
    } else if (sec.name == section) {
      for (const auto& p : sec.params) out += (out.empty() ? "" : ", ") + std::string(p.key);
    }
  }
  return out;
}

}  // namespace

Config Config::defaults(std::span<const ParamSection> schema) {
  Config c;
  c.schema_.assign(schema.begin(), schema.end());
  for (const auto& sec : schema)
    for (const auto& p : sec.params) c.values_[std::string(sec.name) + "." + std::string(p.key)] = default_of(p);
  return c;
}

const ParamSpec* Config::find_spec(std::string_view full_key) const {
  const std::size_t dot = full_key.find('.');
  if (dot == std::string_view::npos) return nullptr;
  const std::string_view section = full_key.substr(0, dot);
  const std::string_view key = full_key.substr(dot + 1);
  for (const auto& sec : schema_)
    if (sec.name == section)
      for (const auto& p : sec.params)
        if (p.key == key) return &p;
  return nullptr;
}

Status Config::assign(std::string_view full_key, std::string_view raw, std::string_view where) {
  const ParamSpec* spec = find_spec(full_key);
  const std::string key(full_key);
  if (spec == nullptr) {
    const std::size_t dot = full_key.find('.');
    const std::string_view section = dot == std::string_view::npos ? full_key : full_key.substr(0, dot);
    std::string known = known_keys(schema_, section);
    if (known.empty()) return config_error(where, "unknown section '" + std::string(section) + "' (known sections: " + known_keys(schema_, {}) + ")");
    return config_error(where, "unknown key '" + key + "' (known keys in '" + std::string(section) + "': " + known + ")");
  }
  const std::string expect = "key '" + key + "' must be " + std::string(to_string(spec->type)) + " in " + range_text(*spec);
  switch (spec->type) {
    case ParamType::kBool:
      if (raw == "true" || raw == "True" || raw == "yes" || raw == "on") { values_[key] = true; return ok_status(); }
      if (raw == "false" || raw == "False" || raw == "no" || raw == "off") { values_[key] = false; return ok_status(); }
      return config_error(where, expect + ", got '" + std::string(raw) + "'");
    case ParamType::kInt: {
      std::int64_t v = 0;
      const auto [ptr, ec] = std::from_chars(raw.data(), raw.data() + raw.size(), v);
      if (ec != std::errc() || ptr != raw.data() + raw.size())
        return config_error(where, expect + ", got '" + std::string(raw) + "'");
      if (static_cast<double>(v) < spec->min || static_cast<double>(v) > spec->max)
        return config_error(where, "key '" + key + "' = " + std::string(raw) + " is out of range " + range_text(*spec));
      values_[key] = v;
      return ok_status();
    }
    case ParamType::kReal: {
      const std::string s(raw);
      char* end = nullptr;
      errno = 0;
      const double v = std::strtod(s.c_str(), &end);
      if (s.empty() || end != s.c_str() + s.size() || errno == ERANGE || !std::isfinite(v))
        return config_error(where, expect + ", got '" + s + "'");
      if (v < spec->min || v > spec->max)
        return config_error(where, "key '" + key + "' = " + s + " is out of range " + range_text(*spec));
      values_[key] = v;
      return ok_status();
    }
    case ParamType::kText:
      if (!in_choices(spec->choices, raw))
        return config_error(where, "key '" + key + "' = '" + std::string(raw) + "' is not one of " + range_text(*spec));
      values_[key] = std::string(raw);
      return ok_status();
  }
  return ok_status();
}

Result<Config> Config::load_string(std::span<const ParamSection> schema, std::string_view yaml,
                                   std::string_view origin) {
  Config c = defaults(schema);
  YAML::Node root;
  try {
    root = YAML::Load(std::string(yaml));
  } catch (const YAML::Exception& e) {
    return config_error(std::string(origin) + ":" + std::to_string(e.mark.line + 1) + ":" +
                            std::to_string(e.mark.column + 1),
                        "malformed YAML: " + e.msg);
  }
  if (root.IsNull()) return c;  // an empty file means all defaults
  if (!root.IsMap()) return config_error(origin, "the top level must be a mapping of sections");
  for (const auto& sec : root) {
    const std::string section = sec.first.as<std::string>();
    const std::string at_sec = std::string(origin) + ":" + std::to_string(sec.first.Mark().line + 1);
    if (std::none_of(schema.begin(), schema.end(), [&](const ParamSection& s) { return s.name == section; }))
      return config_error(at_sec, "unknown section '" + section + "' (known sections: " + known_keys(schema, {}) + ")");
    if (sec.second.IsNull()) continue;
    if (!sec.second.IsMap()) return config_error(at_sec, "section '" + section + "' must be a mapping of key: value");
    for (const auto& kv : sec.second) {
      const std::string key = kv.first.as<std::string>();
      const std::string where = std::string(origin) + ":" + std::to_string(kv.first.Mark().line + 1);
      if (!kv.second.IsScalar()) {
        if (c.find_spec(section + "." + key) == nullptr) {
          if (auto st = c.assign(section + "." + key, "", where); !st) return st.error();
        }
        return config_error(where, "key '" + section + "." + key + "' must be a single value, not a list or mapping");
      }
      if (auto st = c.assign(section + "." + key, kv.second.Scalar(), where); !st) return st.error();
    }
  }
  return c;
}

Result<Config> Config::load_file(std::span<const ParamSection> schema, const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error::make(ErrorCode::kConfig, "config error: " + path + ": cannot open (" + std::strerror(errno) + ")");
  std::ostringstream ss;
  ss << in.rdbuf();
  return load_string(schema, ss.str(), path);
}

Status Config::set(std::string_view assignment, std::string_view origin) {
  const std::size_t eq = assignment.find('=');
  if (eq == std::string_view::npos || eq == 0)
    return config_error(origin, "'" + std::string(assignment) + "' is not of the form section.key=value");
  return assign(assignment.substr(0, eq), assignment.substr(eq + 1), origin);
}

namespace {
[[noreturn]] void missing_key(std::string_view k, std::string_view type) {
  throw std::logic_error("config: no " + std::string(type) + " parameter '" + std::string(k) + "' in the schema");
}
}  // namespace

bool Config::has(std::string_view full_key) const { return values_.find(full_key) != values_.end(); }

bool Config::get_bool(std::string_view k) const {
  auto it = values_.find(k);
  if (it == values_.end() || !std::holds_alternative<bool>(it->second)) missing_key(k, "bool");
  return std::get<bool>(it->second);
}
std::int64_t Config::get_int(std::string_view k) const {
  auto it = values_.find(k);
  if (it == values_.end() || !std::holds_alternative<std::int64_t>(it->second)) missing_key(k, "integer");
  return std::get<std::int64_t>(it->second);
}
double Config::get_real(std::string_view k) const {
  auto it = values_.find(k);
  if (it == values_.end() || !std::holds_alternative<double>(it->second)) missing_key(k, "real");
  return std::get<double>(it->second);
}
const std::string& Config::get_text(std::string_view k) const {
  auto it = values_.find(k);
  if (it == values_.end() || !std::holds_alternative<std::string>(it->second)) missing_key(k, "text");
  return std::get<std::string>(it->second);
}

std::string Config::to_yaml() const {
  std::ostringstream o;
  for (const auto& sec : schema_) {
    if (!sec.help.empty()) o << "# " << sec.help << "\n";
    o << sec.name << ":\n";
    for (const auto& p : sec.params) {
      const std::string full = std::string(sec.name) + "." + std::string(p.key);
      const Value& v = values_.at(full);
      std::string val;
      if (std::holds_alternative<bool>(v)) val = std::get<bool>(v) ? "true" : "false";
      else if (std::holds_alternative<std::int64_t>(v)) val = std::to_string(std::get<std::int64_t>(v));
      else if (std::holds_alternative<double>(v)) val = fmt_exact(std::get<double>(v));
      else val = yaml_quoted(std::get<std::string>(v));
      std::string line = "  " + std::string(p.key) + ": " + val;
      if (line.size() < 36) line.resize(36, ' ');
      o << line << " # " << range_text(p);
      if (!p.help.empty()) o << " — " << p.help;
      o << "\n";
    }
  }
  return o.str();
}

}  // namespace ag
