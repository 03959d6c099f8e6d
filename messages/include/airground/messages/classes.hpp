// The semantic class table: ids, names, colours, traversability and localization weights.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "airground/platform/result.hpp"

namespace ag {

// Class ids are part of the wire format (DESIGN.md §4).
enum class ClassId : std::uint8_t {
  kRoad = 0,
  kDirt = 1,
  kGrass = 2,
  kTree = 3,
  kBuilding = 4,
  kVehicle = 5,
  kWater = 6,
  kUnknown = 255,
};
inline constexpr std::size_t kNumKnownClasses = 7;  // ids 0..6 are contiguous

enum class Traversability : std::uint8_t { kFree = 0, kRough = 1, kCostly = 2, kBlocked = 3 };

struct Rgb {
  std::uint8_t r{0}, g{0}, b{0};
  friend bool operator==(const Rgb&, const Rgb&) = default;
};

struct ClassInfo {
  ClassId id{ClassId::kUnknown};
  std::string name;
  Rgb color;
  Traversability traversability{Traversability::kBlocked};
  double localization_weight{0.0};
};

class ClassTable {
 public:
  // The table of config/classes.yaml, compiled in (used when no file is given).
  static const ClassTable& builtin();
  // Loads and validates a classes.yaml; errors name the file and the entry.
  static Result<ClassTable> load_file(const std::string& path);
  static Result<ClassTable> load_string(std::string_view yaml, std::string_view origin);

  [[nodiscard]] const ClassInfo& info(ClassId id) const noexcept;
  [[nodiscard]] std::optional<ClassId> by_name(std::string_view name) const noexcept;
  [[nodiscard]] const std::vector<ClassInfo>& all() const noexcept { return classes_; }
  [[nodiscard]] bool valid_id(std::uint8_t raw) const noexcept;

 private:
  std::vector<ClassInfo> classes_;
  std::array<std::int16_t, 256> index_{};  // id -> position in classes_, -1 if absent
};

[[nodiscard]] constexpr std::uint8_t raw(ClassId c) noexcept { return static_cast<std::uint8_t>(c); }

}  // namespace ag
