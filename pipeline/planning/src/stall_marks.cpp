// Stall marks: a robot standing on its route marks the ground ahead blocked.
#include "airground/planning/stall_marks.hpp"

#include <algorithm>
#include <cmath>

#include "airground/platform/log.hpp"

namespace ag::plan {

Point2 point_along(std::span<const Point2> pts, Point2 from, double dist) noexcept {
  if (pts.size() < 2) return from;
  // the nearest point on the polyline: segment k, fraction u
  std::size_t best_k = 0;
  double best_u = 0, best_d2 = 1e300;
  for (std::size_t k = 0; k + 1 < pts.size(); ++k) {
    const double dx = pts[k + 1].x - pts[k].x, dy = pts[k + 1].y - pts[k].y, len2 = dx * dx + dy * dy;
    const double u = len2 > 0 ? std::clamp(((from.x - pts[k].x) * dx + (from.y - pts[k].y) * dy) / len2, 0.0, 1.0) : 0.0;
    const double ex = pts[k].x + u * dx - from.x, ey = pts[k].y + u * dy - from.y;
    if (ex * ex + ey * ey < best_d2) {
      best_d2 = ex * ex + ey * ey;
      best_k = k;
      best_u = u;
    }
  }
  const Point2 foot{pts[best_k].x + best_u * (pts[best_k + 1].x - pts[best_k].x), pts[best_k].y + best_u * (pts[best_k + 1].y - pts[best_k].y)};
  return walk_along(pts, best_k + 1, foot, dist);
}

bool StallMarks::observe(const Pose2& pose, Point2 goal, bool following, TimeNs now, Roadmap& map, std::span<const Point2> route) noexcept {
  const bool near_goal = std::hypot(goal.x - pose.x, goal.y - pose.y) <= p_.goal_clear_m;
  if (!(p_.stall_s > 0) || !following || near_goal || !std::isfinite(pose.x) || !std::isfinite(pose.y)) {
    anchored_ = false;
    return false;
  }
  if (!anchored_ || std::hypot(pose.x - anchor_.x, pose.y - anchor_.y) > p_.move_m) {
    anchored_ = true;
    anchor_ = Point2{pose.x, pose.y};
    since_ = now;
    return false;
  }
  if (now - since_ < from_seconds(p_.stall_s)) return false;
  since_ = now;  // the next mark only after standing as long again
  const Point2 c = route.size() >= 2 ? point_along(route, Point2{pose.x, pose.y}, p_.ahead_m)
                                     : Point2{pose.x + p_.ahead_m * std::cos(pose.yaw), pose.y + p_.ahead_m * std::sin(pose.yaw)};
  std::size_t here = 0;  // marks already on this spot
  for (std::size_t i = 0; i < n_; ++i) here += std::hypot(marks_[i].centre.x - c.x, marks_[i].centre.y - c.y) <= p_.radius_m ? 1U : 0U;
  const double radius = std::min(std::max(p_.radius_m, p_.max_radius_m), p_.radius_m * static_cast<double>(here + 1));
  if (n_ == kMaxMarks) lift(0, map);
  marks_[n_++] = StallMark{c, radius, now + from_seconds(p_.keep_s)};
  map.block_disc(c, radius);
  if (p_.widen_radius_m > 0) map.widen_disc(c, p_.widen_radius_m);
  ++stalls_;
  if (static_cast<int>(p_.traversable) > static_cast<int>(map.params().max_level) && map.set_max_level(p_.traversable)) {
    map.rebuild();  // once: every tile changed
    widened_ = true;
    AG_LOG_WARN("planner", "the aerial map was wrong about where this robot can drive: planning through '%s' classes from now on (planner.stall_traversable)",
                p_.traversable == Traversability::kCostly ? "costly" : p_.traversable == Traversability::kRough ? "rough" : "free");
  }
  AG_LOG_INFO("planner", "standing on the route for %.0f s at (%.1f, %.1f): ground ahead at (%.1f, %.1f) marked blocked (radius %.1f m) for %.0f s (%zu marks)",
              p_.stall_s, pose.x, pose.y, c.x, c.y, radius, p_.keep_s, n_);
  return true;
}

bool StallMarks::expire(TimeNs now, Roadmap& map) noexcept {
  bool any = false;
  while (n_ > 0 && marks_[0].until <= now) {  // marks are in time order: the oldest first
    lift(0, map);
    any = true;
  }
  return any;
}

bool StallMarks::lift_all(Roadmap& map) noexcept {
  if (n_ == 0) return false;
  AG_LOG_INFO("planner", "no route with %zu blocked mark(s): lifted (a mark diverts a route, it never closes the last way)", n_);
  while (n_ > 0) lift(n_ - 1, map);
  ++lifted_all_;
  return true;
}

void StallMarks::lift(std::size_t i, Roadmap& map) noexcept {
  map.unblock_disc(marks_[i].centre, marks_[i].radius_m);
  if (p_.widen_radius_m > 0) map.unwiden_disc(marks_[i].centre, p_.widen_radius_m);
  for (std::size_t k = i + 1; k < n_; ++k) marks_[k - 1] = marks_[k];
  --n_;
}

}  // namespace ag::plan
