// Road routing (A* on a coarse drivable grid) and pure pursuit for the simulator's scripted robots.
#include "airground/sim/scripted_driver.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <queue>

#include "airground/messages/geometry.hpp"
#include "airground/platform/rng.hpp"

namespace ag::sim {

RoadRouter::RoadRouter(const World& world, double cell_m, double clearance_m) {
  const GridGeometry& g = world.grid();
  cv::Mat fine(g.height, g.width, CV_8UC1);
  for (int r = 0; r < g.height; ++r)
    for (int c = 0; c < g.width; ++c) {
      const ClassId k = world.class_at(c, r);
      fine.at<std::uint8_t>(r, c) = (k == ClassId::kRoad || k == ClassId::kDirt) ? 255 : 0;
    }
  // Keep away from non-drivable cells by the clearance, at the fine resolution.
  const int er = static_cast<int>(std::ceil(clearance_m / g.resolution));
  if (er > 0) cv::erode(fine, fine, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * er + 1, 2 * er + 1)));
  const double f = g.resolution / cell_m;
  geo_ = GridGeometry{cell_m, static_cast<std::int32_t>(std::floor(g.width * f)), static_cast<std::int32_t>(std::floor(g.height * f)),
                      g.origin_x, g.origin_y};
  cv::Mat coarse;
  cv::resize(fine, coarse, cv::Size(geo_.width, geo_.height), 0, 0, cv::INTER_AREA);
  free_ = coarse > 250;  // all (or nearly all) fine cells drivable
  free_ /= 255;
  // Keep only the largest connected network, so any two drivable points have a route between them.
  cv::Mat labels, stats, centroids;
  const int n = cv::connectedComponentsWithStats(free_, labels, stats, centroids, 8, CV_32S);
  int best = 0;
  for (int i = 1; i < n; ++i)
    if (best == 0 || stats.at<int>(i, cv::CC_STAT_AREA) > stats.at<int>(best, cv::CC_STAT_AREA)) best = i;
  free_ = labels == best;
  free_ /= 255;
  for (int r = 0; r < geo_.height; ++r)
    for (int c = 0; c < geo_.width; ++c)
      if (free_.at<std::uint8_t>(r, c) != 0) free_cells_.push_back(r * geo_.width + c);
}

bool RoadRouter::drivable(double x, double y) const noexcept { return free_cell(geo_.col(x), geo_.row(y)); }

bool RoadRouter::nearest_drivable(double x, double y, double radius_m, Eigen::Vector2d& out) const {
  const int c0 = geo_.col(x), r0 = geo_.row(y);
  const int rad = static_cast<int>(std::ceil(radius_m / geo_.resolution));
  double best = std::numeric_limits<double>::max();
  for (int dr = -rad; dr <= rad; ++dr)
    for (int dc = -rad; dc <= rad; ++dc) {
      if (!free_cell(c0 + dc, r0 + dr)) continue;
      const double d = dc * dc + dr * dr;
      if (d < best) {
        best = d;
        out = {geo_.x_of(c0 + dc), geo_.y_of(r0 + dr)};
      }
    }
  return best < std::numeric_limits<double>::max();
}

Eigen::Vector2d RoadRouter::pick_drivable(std::uint64_t key) const {
  if (free_cells_.empty()) return {0, 0};
  std::uint64_t state = key;
  const std::uint64_t z = splitmix64(state);  // one splitmix64 output: a hash of the key, not a stream
  const std::int32_t cell = free_cells_[z % free_cells_.size()];
  return {geo_.x_of(cell % geo_.width), geo_.y_of(cell / geo_.width)};
}

bool RoadRouter::line_free(int c0, int r0, int c1, int r1) const noexcept {
  const int n = std::max(std::abs(c1 - c0), std::abs(r1 - r0));
  for (int i = 0; i <= n; ++i) {
    const double t = n == 0 ? 0.0 : static_cast<double>(i) / n;
    if (!free_cell(static_cast<int>(std::lround(c0 + t * (c1 - c0))), static_cast<int>(std::lround(r0 + t * (r1 - r0))))) return false;
  }
  return true;
}

bool RoadRouter::route(double sx, double sy, double gx, double gy, std::vector<Eigen::Vector2d>& path) const {
  path.clear();
  Eigen::Vector2d s, g;
  if (!nearest_drivable(sx, sy, 5.0, s) || !nearest_drivable(gx, gy, 5.0, g)) return false;
  const int W = geo_.width;
  const int start = geo_.row(s.y()) * W + geo_.col(s.x());
  const int goal = geo_.row(g.y()) * W + geo_.col(g.x());
  std::vector<float> cost(static_cast<std::size_t>(W) * static_cast<std::size_t>(geo_.height), std::numeric_limits<float>::max());
  std::vector<std::int32_t> parent(cost.size(), -1);
  using Item = std::pair<float, std::int32_t>;
  std::priority_queue<Item, std::vector<Item>, std::greater<>> open;
  auto h = [&](int cell) {
    const double dc = cell % W - goal % W, dr = cell / W - goal / W;
    return static_cast<float>(std::sqrt(dc * dc + dr * dr));
  };
  cost[static_cast<std::size_t>(start)] = 0;
  open.emplace(h(start), start);
  constexpr int kDc[8] = {1, -1, 0, 0, 1, 1, -1, -1};
  constexpr int kDr[8] = {0, 0, 1, -1, 1, -1, 1, -1};
  while (!open.empty()) {
    const auto [f, cell] = open.top();
    open.pop();
    if (cell == goal) break;
    const float gc = cost[static_cast<std::size_t>(cell)];
    if (f - h(cell) > gc + 1e-3f) continue;  // stale entry
    const int c = cell % W, r = cell / W;
    for (int k = 0; k < 8; ++k) {
      const int nc = c + kDc[k], nr = r + kDr[k];
      if (!free_cell(nc, nr)) continue;
      if (k >= 4 && (!free_cell(c + kDc[k], r) || !free_cell(c, r + kDr[k]))) continue;  // no corner cutting
      const int n = nr * W + nc;
      const float nc_cost = gc + (k < 4 ? 1.0f : 1.41421356f);
      if (nc_cost < cost[static_cast<std::size_t>(n)]) {
        cost[static_cast<std::size_t>(n)] = nc_cost;
        parent[static_cast<std::size_t>(n)] = cell;
        open.emplace(nc_cost + h(n), n);
      }
    }
  }
  if (start != goal && parent[static_cast<std::size_t>(goal)] < 0) return false;
  std::vector<std::int32_t> cells;
  for (int c = goal; c != -1; c = parent[static_cast<std::size_t>(c)]) {
    cells.push_back(c);
    if (c == start) break;
  }
  std::reverse(cells.begin(), cells.end());
  // Shortcut: from each kept cell, jump to the farthest cell in straight line of sight.
  std::size_t i = 0;
  path.emplace_back(s);
  while (i + 1 < cells.size()) {
    std::size_t j = cells.size() - 1;
    while (j > i + 1 && !line_free(cells[i] % W, cells[i] / W, cells[j] % W, cells[j] / W)) --j;
    path.emplace_back(geo_.x_of(cells[j] % W), geo_.y_of(cells[j] / W));
    i = j;
  }
  return true;
}

void PurePursuit::command(const Pose2& pose, double& v, double& w) {
  v = w = 0;
  if (done()) return;
  const Eigen::Vector2d p(pose.x, pose.y);
  if (path_.size() == 1) path_.insert(path_.begin(), p);
  // Progress: the closest point on the next few segments (never going back).
  // Near-ties go to the later segment and the current one is never walked back: where the path doubles
  // back on itself (a dead end), the way out and the way back are equally close, and taking the way out
  // again would put the carrot behind the robot for ever (it spun in place at a dead end).
  double best = std::numeric_limits<double>::max();
  std::size_t best_seg = next_;
  double best_t = 0;
  for (std::size_t k = next_; k + 1 < path_.size() && k < next_ + 4; ++k) {
    const Eigen::Vector2d a = path_[k], d = path_[k + 1] - a;
    const double len2 = std::max(d.squaredNorm(), 1e-9);
    double tt = std::clamp((p - a).dot(d) / len2, 0.0, 1.0);
    if (k == next_) tt = std::max(tt, next_t_);
    const double dist = (a + tt * d - p).norm();
    if (dist <= best + 0.05) {
      best = std::min(best, dist);
      best_seg = k;
      best_t = tt;
    }
  }
  next_ = best_seg;
  next_t_ = best_t;
  // The carrot: lookahead metres further along the path from that point.
  Eigen::Vector2d target = path_.back();
  double left = p_.lookahead_m;
  Eigen::Vector2d from = path_[next_] + best_t * (path_[next_ + 1] - path_[next_]);
  for (std::size_t k = next_; k + 1 < path_.size(); ++k) {
    const Eigen::Vector2d to = path_[k + 1];
    const double seg = (to - from).norm();
    if (seg >= left) {
      target = from + (to - from) * (left / std::max(seg, 1e-9));
      break;
    }
    left -= seg;
    from = to;
  }
  const double to_goal = (path_.back() - p).norm();
  if (next_ + 2 >= path_.size() && to_goal < p_.goal_tolerance_m) {
    next_ = path_.size();
    return;
  }
  const double dist = std::max((target - p).norm(), 1e-3);
  const double heading_err = wrap_angle(std::atan2(target.y() - p.y(), target.x() - p.x()) - pose.yaw);
  // Curvature of the arc through the carrot; slow down for sharp turns and near the goal.
  const double curvature = 2.0 * std::sin(heading_err) / dist;
  v = p_.max_speed_mps * std::max(0.0, std::cos(heading_err));
  v = std::min(v, 0.8 * to_goal + 0.2);
  w = std::clamp(v * curvature, -p_.max_yaw_rate, p_.max_yaw_rate);
  if (std::abs(heading_err) > 0.8) {  // turn in place first
    v = 0;
    w = std::copysign(p_.max_yaw_rate, heading_err);
  }
}

}  // namespace ag::sim
