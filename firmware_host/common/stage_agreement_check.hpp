// The start-up check that two stages of a role agree where one models the other: said as warnings (the
// role still runs, but worse), before any stage starts, naming the keys.
#pragma once

#include <string>
#include <vector>

#include "airground/platform/config.hpp"

namespace ag {

// - localization.pf_obstacle_traversable below planner.traversable (free < rough < costly < any), with
//   the obstacle prior on: the localizer's room is the planner's free space, so it would doubt poses on
//   routes the planner takes (docs/localization.md, "Obstacle prior");
// - planner.area_* reaching beyond localization.area_*: the planner could route the robot where the
//   localizer gives its particles no weight (docs/localization.md, "The localizer's area").
[[nodiscard]] std::vector<std::string> stage_agreement_warnings(const Config& c);

}  // namespace ag
