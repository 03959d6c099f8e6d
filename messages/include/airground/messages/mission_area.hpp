// The mission area: the map-frame rectangle a robot works in. The localizer's distance fields, the
// planner's roadmap and the regions stage's class grid are sized from it, each stage reading the same four
// rows (area_x0_m .. area_y1_m) in its own section; the simulator and HIL set all three from the world.
#pragma once

#include <array>
#include <string>
#include <string_view>

#include "airground/messages/geometry.hpp"
#include "airground/platform/param_binding.hpp"
#include "airground/platform/result.hpp"

namespace ag {

struct MissionArea {
  double area_x0_m{-500.0}, area_y0_m{-500.0}, area_x1_m{500.0}, area_y1_m{500.0};  // [m] map frame
  [[nodiscard]] MapRect rect() const noexcept { return {area_x0_m, area_y0_m, area_x1_m, area_y1_m}; }
};

// The four rows; `west_help` is the first row's help, saying what the stage covers with the area.
constexpr std::array<ParamField<MissionArea>, 4> mission_area_fields(std::string_view west_help) {
  return {field::real("area_x0_m", &MissionArea::area_x0_m, -1e6, 1e6, "m", west_help),
          field::real("area_y0_m", &MissionArea::area_y0_m, -1e6, 1e6, "m", "mission area: south edge"),
          field::real("area_x1_m", &MissionArea::area_x1_m, -1e6, 1e6, "m", "mission area: east edge"),
          field::real("area_y1_m", &MissionArea::area_y1_m, -1e6, 1e6, "m", "mission area: north edge")};
}

// The area read from section `s`, or a configuration error naming the stage when it is not a rectangle
// (east of its west edge and north of its south edge).
template <std::size_t N>
[[nodiscard]] Result<MissionArea> load_mission_area(const SectionView& s, const std::array<ParamField<MissionArea>, N>& fields,
                                                    std::string_view stage) {
  MissionArea a{};
  load_params(s, std::span<const ParamField<MissionArea>>(fields), a);
  if (!(a.area_x1_m > a.area_x0_m) || !(a.area_y1_m > a.area_y0_m))
    return Error::make(ErrorCode::kConfig, "config error: " + std::string(stage) +
                                               ".area_x1_m/area_y1_m must be east/north of area_x0_m/area_y0_m");
  return a;
}

}  // namespace ag
