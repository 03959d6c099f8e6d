// The procedural world generator: a seeded town-and-country scene with roads, tracks, buildings, trees,
// water and parked-car clusters that are the mission targets.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "airground/messages/geometry.hpp"
#include "airground/platform/result.hpp"
#include "airground/sim/world.hpp"

namespace ag::sim {

struct GeneratorOptions {
  std::uint64_t seed{1};
  double size_m{400};       // side of the square world [m], 200..1000 is the tested range (100..2000 accepted)
  double resolution{0.25};  // [m/cell]
  int targets{13};          // clusters of parked cars (0..64)
  Datum datum;
};

// A mission target: a group of 2-8 parked cars (a row in a parking lot or along a road side).
struct TargetCluster {
  int id{0};
  double x{0}, y{0};  // [m] map frame: mean of the car centres
  int cars{0};
  std::vector<Pose2> car_poses;  // [m, m, rad] car centres, yaw along the car's length
};

// What the generator lays out: deterministic for a seed (its own PRNG, no std:: distributions), the
// map-frame origin at the world's centre, every road connected, and every vehicle cell belonging to
// exactly one target cluster. Clusters are at least 20 m apart car to car (15 m in worlds under 300 m)
// and 25 m from the staging pad. The staging pose (header.staging) is the centre of a 24 m paved pad
// beside the westernmost north-south road, in the south-west block, yaw 0 (facing the road to the east).
Result<World> generate_world(const GeneratorOptions& options, std::vector<TargetCluster>* targets = nullptr);

// The built-in default world: 400 m square, seed 42, 0.25 m/cell, 13 targets, default datum; generated
// once per process.
const World& default_world();
const std::vector<TargetCluster>& default_targets();

// targets.yaml in a world directory: the clusters and the staging pose, for missions and scoring.
Status save_targets(const std::vector<TargetCluster>& targets, const Pose2& staging, const std::string& dir);
struct TargetsFile {
  Pose2 staging;
  std::vector<TargetCluster> targets;
};
Result<TargetsFile> load_targets(const std::string& dir);
// A targets file anywhere (load_targets reads DIR/targets.yaml with this).
Result<TargetsFile> load_targets_file(const std::string& path);

// The targets a class map shows, for a world imported from a user's map: every 8-connected group of
// vehicle cells of at least min_car_m2 is one car (its centre; yaw along its long axis; cars that touch
// are one car); cars within link_m of each other, centre to centre, are one cluster, and a cluster of at
// least min_cars is a target. Ids 1..N from south-west to north-east. The generator's clusters are at
// least 15 m apart car to car, and its cars at most 11.3 m apart within one (across a lot's aisle):
// link_m 12 separates them.
struct DeriveTargetsOptions {
  double link_m{12.0};
  double min_car_m2{1.5};   // smaller groups are labelling noise
  double max_car_m2{20.0};  // larger groups are counted (touching cars, trucks), still one car each
  int min_cars{1};
};
struct DerivedTargets {
  std::vector<TargetCluster> targets;
  int cars{0};         // in the targets
  int small_blobs{0};  // vehicle groups under min_car_m2, dropped
  int large_blobs{0};  // vehicle groups over max_car_m2
  int lone_cars{0};    // in clusters of fewer than min_cars, dropped
};
DerivedTargets derive_targets(const World& w, const DeriveTargetsOptions& options = {});
// A user's targets file for world w: its staging pose inside the world on ground a robot can stand on,
// every target inside the world; the error names the file and the target.
Status check_targets_in_world(const TargetsFile& f, const World& w, const std::string& path);

}  // namespace ag::sim
