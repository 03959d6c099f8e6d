// The mission targets a class map shows: its parked-car clusters, for a world imported from a user's
// map (world import), and a user's own targets file checked against the world it is for.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <string>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "airground/sim/generator.hpp"

namespace ag::sim {

namespace {

// One 8-connected group of vehicle cells taken for one car: its centre and long axis.
struct Blob {
  Pose2 pose;
  double area_m2{0};
};

std::vector<Blob> vehicle_blobs(const World& w, const DeriveTargetsOptions& o, DerivedTargets& out) {
  const GridGeometry& g = w.grid();
  const cv::Mat vehicle = w.class_id == raw(ClassId::kVehicle);
  cv::Mat labels, stats, centroids;
  const int n = cv::connectedComponentsWithStats(vehicle, labels, stats, centroids, 8, CV_32S);
  // Second moments per component, for the long axis.
  std::vector<double> sxx(static_cast<std::size_t>(n), 0.0), syy(static_cast<std::size_t>(n), 0.0), sxy(static_cast<std::size_t>(n), 0.0);
  for (int r = 0; r < labels.rows; ++r) {
    const auto* row = labels.ptr<std::int32_t>(r);
    for (int c = 0; c < labels.cols; ++c) {
      const int k = row[c];
      if (k == 0) continue;
      const auto uk = static_cast<std::size_t>(k);
      const double dx = c - centroids.at<double>(k, 0), dy = -(r - centroids.at<double>(k, 1));  // north up
      sxx[uk] += dx * dx;
      syy[uk] += dy * dy;
      sxy[uk] += dx * dy;
    }
  }
  const double cell_m2 = g.resolution * g.resolution;
  std::vector<Blob> blobs;
  for (int k = 1; k < n; ++k) {
    const double area = stats.at<std::int32_t>(k, cv::CC_STAT_AREA) * cell_m2;
    if (area < o.min_car_m2) {
      ++out.small_blobs;
      continue;
    }
    if (area > o.max_car_m2) ++out.large_blobs;  // touching cars, or a vehicle bigger than a car: one car still
    const auto uk = static_cast<std::size_t>(k);
    Blob b;
    b.area_m2 = area;
    b.pose.x = g.x_of(centroids.at<double>(k, 0));
    b.pose.y = g.y_of(centroids.at<double>(k, 1));
    b.pose.yaw = 0.5 * std::atan2(2.0 * sxy[uk], sxx[uk] - syy[uk]);
    blobs.push_back(b);
  }
  return blobs;
}

}  // namespace

DerivedTargets derive_targets(const World& w, const DeriveTargetsOptions& o) {
  DerivedTargets out;
  const std::vector<Blob> blobs = vehicle_blobs(w, o, out);
  // Single linkage: cars within link_m of each other, centre to centre, are one cluster.
  std::vector<std::size_t> parent(blobs.size());
  std::iota(parent.begin(), parent.end(), std::size_t{0});
  auto find = [&](std::size_t i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  };
  for (std::size_t i = 0; i < blobs.size(); ++i)
    for (std::size_t j = i + 1; j < blobs.size(); ++j)
      if (std::hypot(blobs[i].pose.x - blobs[j].pose.x, blobs[i].pose.y - blobs[j].pose.y) <= o.link_m) parent[find(i)] = find(j);
  std::vector<std::vector<std::size_t>> groups(blobs.size());
  for (std::size_t i = 0; i < blobs.size(); ++i) groups[find(i)].push_back(i);
  for (const std::vector<std::size_t>& members : groups) {
    if (members.empty()) continue;
    if (static_cast<int>(members.size()) < o.min_cars) {
      out.lone_cars += static_cast<int>(members.size());
      continue;
    }
    TargetCluster t;
    for (const std::size_t i : members) {
      t.car_poses.push_back(blobs[i].pose);
      t.x += blobs[i].pose.x;
      t.y += blobs[i].pose.y;
    }
    t.cars = static_cast<int>(members.size());
    t.x /= t.cars;
    t.y /= t.cars;
    out.targets.push_back(std::move(t));
  }
  // Ids 1..N from south-west to north-east (by x + y), so a re-import numbers them the same.
  std::sort(out.targets.begin(), out.targets.end(), [](const TargetCluster& a, const TargetCluster& b) {
    return a.x + a.y != b.x + b.y ? a.x + a.y < b.x + b.y : a.x < b.x;
  });
  for (std::size_t i = 0; i < out.targets.size(); ++i) {
    out.targets[i].id = static_cast<int>(i) + 1;
    out.cars += out.targets[i].cars;
  }
  return out;
}

Status check_targets_in_world(const TargetsFile& f, const World& w, const std::string& path) {
  const GridGeometry& g = w.grid();
  auto inside = [&](double x, double y) {
    return x >= g.origin_x && x <= g.origin_x + g.size_x() && y <= g.origin_y && y >= g.origin_y - g.size_y();
  };
  auto err = [&](const std::string& what) { return Error::make(ErrorCode::kConfig, "targets file " + path + ": " + what); };
  char buf[160];
  if (!inside(f.staging.x, f.staging.y)) {
    std::snprintf(buf, sizeof buf, "the staging pose (%.1f, %.1f) is outside the world", f.staging.x, f.staging.y);
    return err(buf);
  }
  const ClassInfo& at = ClassTable::builtin().info(w.class_at_xy(f.staging.x, f.staging.y));
  if (at.traversability == Traversability::kBlocked) {
    std::snprintf(buf, sizeof buf, "the staging pose (%.1f, %.1f) is on %s, where a ground robot cannot stand", f.staging.x,
                  f.staging.y, at.name.c_str());
    return err(buf);
  }
  for (const TargetCluster& t : f.targets)
    if (!inside(t.x, t.y)) {
      std::snprintf(buf, sizeof buf, "target %d at (%.1f, %.1f) is outside the world", t.id, t.x, t.y);
      return err(buf);
    }
  return ok_status();
}

}  // namespace ag::sim
