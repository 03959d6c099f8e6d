// Localization error statistics from the first good sample on, and visit verdicts from the true pose at the visit.
#include "airground/sim/eval_scoring.hpp"

#include <algorithm>
#include <cmath>

namespace ag::sim {

double percentile_nearest_rank(std::vector<double> v, double q) {
  if (v.empty()) return -1;
  std::sort(v.begin(), v.end());
  const double rank = std::ceil(std::clamp(q, 0.0, 1.0) * static_cast<double>(v.size()));
  const std::size_t k = rank < 1 ? 0 : std::min(v.size() - 1, static_cast<std::size_t>(rank) - 1);
  return v[k];
}

std::size_t LocErrorScore::add_robot(std::span<const LocErrorSample> samples) {
  std::size_t first = samples.size();
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const LocErrorSample& s = samples[i];
    const bool good = s.have_estimate && s.tracking && s.err_m >= 0 && s.err_m <= radius_;
    if (first == samples.size() && !good) continue;
    if (first == samples.size()) first = i;
    ++scored_;
    if (s.tracking) ++tracking_n_;
    if (!s.have_estimate || s.err_m < 0) continue;  // no pose to score: neither tracking error nor within
    all_.push_back(s.err_m);
    if (s.tracking) tracking_.push_back(s.err_m);
    if (s.err_m <= radius_) ++within_n_;
  }
  return first;
}

LocErrorStats LocErrorScore::stats() const {
  LocErrorStats r;
  r.samples = scored_;
  auto fill = [](const std::vector<double>& v, double& mean, double& p95, double& mx) {
    if (v.empty()) return;
    double s = 0;
    for (const double e : v) s += e;
    mean = s / static_cast<double>(v.size());
    p95 = percentile_nearest_rank(v, 0.95);
    mx = *std::max_element(v.begin(), v.end());
  };
  fill(all_, r.mean_m, r.p95_m, r.max_m);
  fill(tracking_, r.tracking_mean_m, r.tracking_p95_m, r.tracking_max_m);
  if (scored_ > 0) {
    r.tracking_fraction = static_cast<double>(tracking_n_) / static_cast<double>(scored_);
    r.within_fraction = static_cast<double>(within_n_) / static_cast<double>(scored_);
  }
  return r;
}

const char* verdict_name(VisitVerdict v) noexcept {
  switch (v) {
    case VisitVerdict::kTrue: return "true";
    case VisitVerdict::kFalse: return "false";
    case VisitVerdict::kNonTarget: return "non_target";
  }
  return "?";
}

VisitVerdict judge_visit(double true_x, double true_y, double goal_x, double goal_y, double visit_radius_m, bool region_near_target) noexcept {
  if (!(std::hypot(true_x - goal_x, true_y - goal_y) <= visit_radius_m)) return VisitVerdict::kFalse;
  return region_near_target ? VisitVerdict::kTrue : VisitVerdict::kNonTarget;
}

std::vector<TargetCluster> targets_in_area(std::span<const TargetCluster> all, const MapRect& area, std::vector<int>& outside) {
  std::vector<TargetCluster> in;
  for (const TargetCluster& t : all) {
    bool inside = area.contains(t.x, t.y);
    for (const Pose2& c : t.car_poses) inside = inside || area.contains(c.x, c.y);
    if (inside) in.push_back(t);
    else outside.push_back(t.id);
  }
  return in;
}

}  // namespace ag::sim
