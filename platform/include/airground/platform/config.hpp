// Typed parameters with defaults, ranges and units, loaded from YAML and validated at start-up.
#pragma once

#include <cstdint>
#include <map>
#include <span>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include "airground/platform/result.hpp"

namespace ag {

enum class ParamType { kBool, kInt, kReal, kText };

// One parameter, declared once in constexpr tables beside the code that reads it (PX4-style).
struct ParamSpec {
  std::string_view key;       // relative to its section, e.g. "period_s"
  ParamType type{ParamType::kReal};
  double default_num{0};      // bool (0/1), int and real defaults
  std::string_view default_text{};
  double min{0};
  double max{0};
  std::string_view unit{};    // "s", "Hz", "m", "count", ... ("" for unitless)
  std::string_view help{};
  std::string_view choices{};  // text parameters: allowed values separated by '|', empty = any

  static constexpr ParamSpec real(std::string_view k, double def, double lo, double hi, std::string_view unit,
                                  std::string_view help) {
    return ParamSpec{k, ParamType::kReal, def, {}, lo, hi, unit, help, {}};
  }
  static constexpr ParamSpec integer(std::string_view k, std::int64_t def, std::int64_t lo, std::int64_t hi,
                                     std::string_view unit, std::string_view help) {
    return ParamSpec{k, ParamType::kInt, static_cast<double>(def), {}, static_cast<double>(lo),
                     static_cast<double>(hi), unit, help, {}};
  }
  static constexpr ParamSpec boolean(std::string_view k, bool def, std::string_view help) {
    return ParamSpec{k, ParamType::kBool, def ? 1.0 : 0.0, {}, 0, 1, {}, help, {}};
  }
  static constexpr ParamSpec text(std::string_view k, std::string_view def, std::string_view choices,
                                  std::string_view help) {
    return ParamSpec{k, ParamType::kText, 0, def, 0, 0, {}, help, choices};
  }
};

// A section of the schema: a YAML mapping ("scheduler", "status", a stage name) and its parameters.
struct ParamSection {
  std::string_view name;
  std::span<const ParamSpec> params;
  std::string_view help{};
};

class Config {
 public:
  using Value = std::variant<bool, std::int64_t, double, std::string>;

  // Every parameter at its default.
  static Config defaults(std::span<const ParamSection> schema);
  // Defaults overlaid with a YAML file; any unknown key, wrong type, out-of-range value or malformed
  // YAML is an ErrorCode::kConfig error naming the file, the key (and line) and the allowed range.
  static Result<Config> load_file(std::span<const ParamSection> schema, const std::string& path);
  static Result<Config> load_string(std::span<const ParamSection> schema, std::string_view yaml,
                                    std::string_view origin);
  // "section.key=value" from the command line, validated the same way.
  Status set(std::string_view assignment, std::string_view origin = "--set");

  [[nodiscard]] bool get_bool(std::string_view full_key) const;
  [[nodiscard]] std::int64_t get_int(std::string_view full_key) const;
  [[nodiscard]] double get_real(std::string_view full_key) const;
  [[nodiscard]] const std::string& get_text(std::string_view full_key) const;
  [[nodiscard]] bool has(std::string_view full_key) const;

  // The effective parameters as commented YAML (units, ranges, help) that load_file() reads back.
  [[nodiscard]] std::string to_yaml() const;
  [[nodiscard]] std::span<const ParamSection> schema() const noexcept { return schema_; }

 private:
  const ParamSpec* find_spec(std::string_view full_key) const;
  Status assign(std::string_view full_key, std::string_view raw, std::string_view where);

  std::vector<ParamSection> schema_;  // owned: Config::defaults(role_schema(role)) is safe
  std::map<std::string, Value, std::less<>> values_;
};

// Reads one section's parameters for a stage: ctx.params("status").real("period_s").
class SectionView {
 public:
  SectionView(const Config& c, std::string_view section) : cfg_(c), section_(section) {}
  [[nodiscard]] bool boolean(std::string_view k) const { return cfg_.get_bool(full(k)); }
  [[nodiscard]] std::int64_t integer(std::string_view k) const { return cfg_.get_int(full(k)); }
  [[nodiscard]] double real(std::string_view k) const { return cfg_.get_real(full(k)); }
  [[nodiscard]] const std::string& text(std::string_view k) const { return cfg_.get_text(full(k)); }

 private:
  [[nodiscard]] std::string full(std::string_view k) const { return std::string(section_) + "." + std::string(k); }
  const Config& cfg_;
  std::string section_;
};

std::string_view to_string(ParamType t) noexcept;

}  // namespace ag
