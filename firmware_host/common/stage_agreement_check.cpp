// The start-up check that a role's stages agree (see stage_agreement_check.hpp).
#include "stage_agreement_check.hpp"

#include <array>
#include <cstdio>
#include <string_view>

namespace ag {

namespace {
// The level's rank (free 0 .. any 3), -1 for a key the role does not have or a value it does not know.
int level(const Config& c, std::string_view key) {
  if (!c.has(key)) return -1;
  constexpr std::array<std::string_view, 4> kLevels{"free", "rough", "costly", "any"};
  for (std::size_t i = 0; i < kLevels.size(); ++i)
    if (c.get_text(key) == kLevels[i]) return static_cast<int>(i);
  return -1;
}
}  // namespace

std::vector<std::string> stage_agreement_warnings(const Config& c) {
  std::vector<std::string> w;
  const int room = level(c, "localization.pf_obstacle_traversable");
  const int route = level(c, "planner.traversable");
  const bool prior = c.has("localization.pf_obstacle_penalty_per_m") && c.get_real("localization.pf_obstacle_penalty_per_m") > 0.0;
  if (prior && room >= 0 && route >= 0 && room < route)
    w.emplace_back("localization.pf_obstacle_traversable: " + c.get_text("localization.pf_obstacle_traversable") +
                   " is narrower than planner.traversable: " + c.get_text("planner.traversable") +
                   ": the localizer's obstacle prior would doubt poses on routes the planner takes; set it to the planner's level "
                   "(docs/localization.md, \"Obstacle prior\")");
  constexpr std::array<std::string_view, 4> kEdges{"area_x0_m", "area_y0_m", "area_x1_m", "area_y1_m"};
  std::string beyond;
  for (std::size_t i = 0; i < kEdges.size(); ++i) {
    const std::string loc = "localization." + std::string(kEdges[i]), plan = "planner." + std::string(kEdges[i]);
    if (!c.has(loc) || !c.has(plan)) continue;
    const double l = c.get_real(loc), p = c.get_real(plan);
    if (i < 2 ? p >= l : p <= l) continue;  // the west and south edges may not lie lower, the east and north not higher
    char edge[160];
    std::snprintf(edge, sizeof edge, "%s%s %.1f beyond %s %.1f", beyond.empty() ? "" : ", ", plan.c_str(), p, loc.c_str(), l);
    beyond += edge;
  }
  if (!beyond.empty())
    w.emplace_back("the planner's area reaches beyond the localizer's (" + beyond +
                   "): it could route the robot where the localizer gives its particles no weight; set planner.area_* within "
                   "localization.area_* (docs/localization.md)");
  return w;
}

}  // namespace ag
