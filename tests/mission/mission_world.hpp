// Test helper: the mission tests' world, the generator's 200 m world of seed 7 with three parked-car
// clusters, saved with its targets.yaml into `dir`; an empty string, or what failed.
#pragma once

#include <string>
#include <vector>

#include "airground/sim/generator.hpp"

namespace ag::sim::test {

inline std::string save_mission_world(const std::string& dir) {
  GeneratorOptions g;
  g.seed = 7;
  g.size_m = 200;
  g.targets = 3;
  std::vector<TargetCluster> targets;
  auto w = generate_world(g, &targets);
  if (!w.ok()) return w.error().message;
  if (auto s = save_world(w.value(), dir); !s.ok()) return s.error().message;
  if (auto s = save_targets(targets, w.value().header.staging, dir); !s.ok()) return s.error().message;
  return {};
}

}  // namespace ag::sim::test
