// The routes the simulator drives its scripted ground robots on (without their own planner and drive).
#include <algorithm>
#include <cmath>

#include "airground/platform/log.hpp"
#include "team.hpp"

namespace ag::sim::lockstep {

Pose2 Ugv::truth_at(TimeNs t) const noexcept {
  if (history_n == 0) return vehicle.pose();
  const std::size_t n = std::min(history_n, kHistory);
  auto at = [&](std::size_t back) -> const std::pair<TimeNs, Pose2>& { return history[(history_n - 1 - back) % kHistory]; };
  if (t >= at(0).first) return at(0).second;
  for (std::size_t k = 1; k < n; ++k) {
    const auto& a = at(k);
    if (a.first > t) continue;
    const auto& b = at(k - 1);
    const double w = static_cast<double>(t - a.first) / static_cast<double>(std::max<TimeNs>(1, b.first - a.first));
    return Pose2{a.second.x + w * (b.second.x - a.second.x), a.second.y + w * (b.second.y - a.second.y),
                 wrap_angle(a.second.yaw + w * wrap_angle(b.second.yaw - a.second.yaw))};
  }
  return at(n - 1).second;
}

Pose3 lidar_pose(const Ugv& u, double mount) {
  Pose3 p = u.vehicle.pose3();
  p.z += mount;
  return p;
}

void new_leg(Team& t, Ugv& u, TimeNs now) {
  std::vector<Eigen::Vector2d> path;
  u.on_route = false;
  for (int attempt = 0; attempt < 20; ++attempt) {
    const std::uint64_t key = t.opt.seed * std::uint64_t{1000003} + static_cast<std::uint64_t>(u.node) * std::uint64_t{10007} + u.leg++;
    const Eigen::Vector2d goal = t.router->pick_drivable(key);
    const Pose2& p = u.vehicle.pose();
    const double d = (goal - Eigen::Vector2d(p.x, p.y)).norm();
    if (d < 20.0 || (d > 150.0 && attempt < 15)) continue;  // legs of 20-150 m, like an errand across the block
    if (t.router->route(p.x, p.y, goal.x(), goal.y(), path) && path.size() >= 2) {
      u.pursuit.set_path(std::move(path));
      u.on_route = true;
      return;
    }
  }
  u.pursuit.set_path({});
  u.retry_at = now + 2 * kNsPerS;  // stay put and try again later rather than search every tick
  AG_LOG_WARN("sim", "%s: no road route from (%.1f, %.1f); retrying in 2 s", u.name.c_str(), u.vehicle.pose().x, u.vehicle.pose().y);
}

// A route with a vertex at least every `step` metres: pure pursuit looks for its progress on the next
// few segments only, so on a route that comes back along the same road (out and back) long segments
// would let it mistake the way back for the way out.
std::vector<Eigen::Vector2d> densify(const std::vector<Eigen::Vector2d>& route, double step) {
  std::vector<Eigen::Vector2d> out;
  if (route.empty()) return out;
  out.push_back(route.front());
  for (std::size_t i = 1; i < route.size(); ++i) {
    const Eigen::Vector2d a = route[i - 1], d = route[i] - a;
    const int n = std::max(1, static_cast<int>(std::ceil(d.norm() / step)));
    for (int k = 1; k <= n; ++k) out.push_back(a + d * (static_cast<double>(k) / n));
  }
  return out;
}

// A scripted robot that hit something: route from here back onto its route a vertex ahead, then on.
void rejoin_route(Team& t, Ugv& u, TimeNs now) {
  const Pose2& p = u.vehicle.pose();
  const std::size_t k = std::min(u.route_progress + 1, u.route.size() - 1);
  std::vector<Eigen::Vector2d> path;
  if (!t.router->route(p.x, p.y, u.route[k].x(), u.route[k].y(), path) || path.empty()) path.assign(1, Eigen::Vector2d(p.x, p.y));
  path = densify(path, 1.0);
  path.insert(path.end(), u.route.begin() + static_cast<std::ptrdiff_t>(k) + 1, u.route.end());
  u.route.assign(path.begin(), path.end());
  u.route_progress = 0;
  u.pursuit.set_path(std::move(path));
  (void)now;
}

}  // namespace ag::sim::lockstep
