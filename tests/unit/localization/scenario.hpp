// Drives a SemanticLocalizer along a route of a synthetic world: noisy odometry in, ray-cast scans
// (labelled by the labeller under test) when the filter wants one, the fused pose's error out.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <span>
#include <vector>

#include "airground/localization/semantic_localizer.hpp"
#include "synthetic_world.hpp"

namespace ag::loc::test {

struct ScenarioResult {
  bool converged{false};
  double convergence_time_s{-1};    // [s] from the start to the first tracking sample
  double convergence_distance_m{-1};
  double mean_err_m{0}, p95_err_m{0}, max_err_m{0};  // fused pose, tracking samples after convergence
  double yaw_mean_deg{0};
  double odom_mean_err_m{0};        // odometry alone (aligned at the start), same samples
  std::size_t tracking_samples{0}, lost_samples{0}, samples_after_convergence{0};
  std::uint64_t updates{0};
  std::uint32_t recoveries{0};
  std::vector<double> err;          // fused position error of every sample [m] (-1 before convergence)
  std::vector<LocalizationStatus> status;
};

// odom[k] is the odometry's cumulative pose at truth[k]; labeller labels the ray-cast scans in place.
// `scan_truth` (optional) is where the scans are taken from (default: truth).
inline ScenarioResult run_scenario(SemanticLocalizer& loc, const SyntheticWorld& w, const ClassDistanceFields& fields,
                                   std::span<const TruthSample> truth, std::span<const Pose2> odom, ScanLabeller& labeller,
                                   const LidarModel& lidar, std::uint64_t seed) {
  ScenarioResult res;
  std::vector<ScanPoint> scan;
  scan.reserve(static_cast<std::size_t>(lidar.rings * lidar.columns));
  std::vector<double> after, yaw_after, odom_after;
  double dist = 0.0;
  const Pose2 odom_origin = truth[0].pose;
  for (std::size_t k = 0; k < truth.size(); ++k) {
    if (k > 0) dist += std::hypot(truth[k].pose.x - truth[k - 1].pose.x, truth[k].pose.y - truth[k - 1].pose.y);
    loc.on_odometry(odom[k], truth[k].stamp);
    if (loc.wants_scan(fields)) {
      ray_cast(w, truth[k].pose, lidar, seed * 100003ULL + k, scan);
      labeller.label(scan, lidar.rings, lidar.columns);
      loc.on_scan(scan, fields, truth[k].stamp);
    }
    const FusedPoseSample s = loc.pose();
    res.status.push_back(s.status);
    if (s.status == LocalizationStatus::kTracking && !res.converged) {
      res.converged = true;
      res.convergence_time_s = to_seconds(truth[k].stamp - truth[0].stamp);
      res.convergence_distance_m = dist;
    }
    const double e = std::hypot(s.pose.x - truth[k].pose.x, s.pose.y - truth[k].pose.y);
    res.err.push_back(res.converged ? e : -1.0);
    if (!res.converged) continue;
    ++res.samples_after_convergence;
    if (s.status == LocalizationStatus::kLost) ++res.lost_samples;
    if (s.status != LocalizationStatus::kTracking) continue;
    ++res.tracking_samples;
    after.push_back(e);
    yaw_after.push_back(std::fabs(wrap_angle(s.pose.yaw - truth[k].pose.yaw)) * 180.0 / kPi);
    const Pose2 o = compose(odom_origin, odom[k]);
    odom_after.push_back(std::hypot(o.x - truth[k].pose.x, o.y - truth[k].pose.y));
  }
  res.updates = loc.filter().estimate().updates;
  res.recoveries = loc.filter().estimate().recoveries;
  if (!after.empty()) {
    double sum = 0, ysum = 0, osum = 0;
    for (std::size_t i = 0; i < after.size(); ++i) {
      sum += after[i];
      ysum += yaw_after[i];
      osum += odom_after[i];
    }
    const auto n = static_cast<double>(after.size());
    res.mean_err_m = sum / n;
    res.yaw_mean_deg = ysum / n;
    res.odom_mean_err_m = osum / n;
    res.max_err_m = *std::max_element(after.begin(), after.end());
    std::vector<double> sorted = after;
    std::sort(sorted.begin(), sorted.end());
    res.p95_err_m = sorted[static_cast<std::size_t>(0.95 * (n - 1))];
  }
  return res;
}

inline void print(const char* what, const ScenarioResult& r) {
  std::printf("%s: converged %d after %.1f s (%.0f m), error after: mean %.2f m, p95 %.2f m, max %.2f m, yaw %.2f deg; "
              "odometry alone %.2f m; updates %llu, recoveries %u, lost samples %zu\n",
              what, r.converged ? 1 : 0, r.convergence_time_s, r.convergence_distance_m, r.mean_err_m, r.p95_err_m,
              r.max_err_m, r.yaw_mean_deg, r.odom_mean_err_m, static_cast<unsigned long long>(r.updates), r.recoveries,
              r.lost_samples);
}

// A route that snakes along the east-west roads (rows) of the world, turning onto north-south roads.
inline std::vector<std::pair<int, int>> snake_route(const SyntheticWorld& w, int rows, int first_row = 0) {
  std::vector<std::pair<int, int>> r;
  const int nx = static_cast<int>(w.road_x.size());
  for (int j = first_row; j < first_row + rows && j < static_cast<int>(w.road_y.size()); ++j) {
    const bool east = (j - first_row) % 2 == 0;
    r.emplace_back(east ? 0 : nx - 1, j);
    r.emplace_back(east ? nx - 1 : 0, j);
  }
  return r;
}

}  // namespace ag::loc::test
