// Scoring shared by `mission` and `eval localization`: localization error over every sample after the first
// good one (not only the tracking ones), and a visit judged by the robot's true position when it marked it.
#pragma once

#include <cstddef>
#include <span>
#include <vector>

#include "airground/messages/geometry.hpp"
#include "airground/sim/generator.hpp"

namespace ag::sim {

// One sample of a robot's own pose estimate against the truth.
struct LocErrorSample {
  bool have_estimate{false};  // the robot had published a pose by then (err_m is meaningful)
  bool tracking{false};       // its localization said tracking (and, where the caller checks, was fresh)
  double err_m{-1};           // [m] |estimate - true pose at the estimate's stamp|
};

// A sample is good when it is tracking and its error is within the radius; a robot is scored from its first
// good sample on, whatever happens after (an excursion counts, it does not restart the statistics).
struct LocErrorStats {
  std::size_t samples{0};  // scored samples (from each robot's first good one on)
  double mean_m{-1}, p95_m{-1}, max_m{-1};                    // [m] over every scored sample with an estimate
  double tracking_mean_m{-1}, tracking_p95_m{-1}, tracking_max_m{-1};  // [m] over the scored tracking samples only
  double tracking_fraction{0};  // scored samples that were tracking
  double within_fraction{0};    // scored samples whose error was within the radius (tracking or not)
};

class LocErrorScore {
 public:
  explicit LocErrorScore(double good_radius_m) noexcept : radius_(good_radius_m) {}
  // Adds one robot's samples in time order; returns the index of its first good sample (size() if none).
  std::size_t add_robot(std::span<const LocErrorSample> samples);
  [[nodiscard]] LocErrorStats stats() const;

 private:
  double radius_;
  std::vector<double> all_, tracking_;
  std::size_t scored_{0}, tracking_n_{0}, within_n_{0};
};

// Nearest-rank percentile (q in [0, 1]); -1 for an empty set.
double percentile_nearest_rank(std::vector<double> v, double q);

enum class VisitVerdict {
  kTrue,       // the robot truly stood within the visit radius of the goal, and the region is a target
  kFalse,      // it did not (wherever its path went before or after)
  kNonTarget,  // it truly stood there, but no target is near the region: counted apart
};
[[nodiscard]] const char* verdict_name(VisitVerdict v) noexcept;
// true_x/true_y: the robot's true position at the moment it marked the visit.
[[nodiscard]] VisitVerdict judge_visit(double true_x, double true_y, double goal_x, double goal_y, double visit_radius_m,
                                       bool region_near_target) noexcept;

// The world's targets a mission is about: those with a car (or their centre) in `area`, the quadrotor's
// survey; the ids of the others (an imported map's cluster in the survey's border) go to `outside`.
[[nodiscard]] std::vector<TargetCluster> targets_in_area(std::span<const TargetCluster> all, const MapRect& area, std::vector<int>& outside);

}  // namespace ag::sim
