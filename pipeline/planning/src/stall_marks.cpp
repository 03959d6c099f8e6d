// Stall marks: a robot standing on its route marks the ground ahead blocked.
#include "airground/planning/stall_marks.hpp"

#include <cmath>

#include "airground/platform/log.hpp"

namespace ag::plan {

bool StallMarks::observe(const Pose2& pose, Point2 goal, bool following, TimeNs now, Roadmap& map) noexcept {
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
  if (n_ == kMaxMarks) lift(0, map);
  const Point2 c{pose.x + p_.ahead_m * std::cos(pose.yaw), pose.y + p_.ahead_m * std::sin(pose.yaw)};
  marks_[n_++] = StallMark{c, now + from_seconds(p_.keep_s)};
  map.block_disc(c, p_.radius_m);
  if (p_.widen_radius_m > 0) map.widen_disc(c, p_.widen_radius_m);
  ++stalls_;
  if (static_cast<int>(p_.traversable) > static_cast<int>(map.params().max_level) && map.set_max_level(p_.traversable)) {
    map.rebuild();  // once: every tile changed
    widened_ = true;
    AG_LOG_WARN("planner", "the aerial map was wrong about where this robot can drive: planning through '%s' classes from now on (planner.stall_traversable)",
                p_.traversable == Traversability::kCostly ? "costly" : p_.traversable == Traversability::kRough ? "rough" : "free");
  }
  AG_LOG_INFO("planner", "standing on the route for %.0f s at (%.1f, %.1f): ground ahead at (%.1f, %.1f) marked blocked for %.0f s (%zu marks)",
              p_.stall_s, pose.x, pose.y, c.x, c.y, p_.keep_s, n_);
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
  map.unblock_disc(marks_[i].centre, p_.radius_m);
  if (p_.widen_radius_m > 0) map.unwiden_disc(marks_[i].centre, p_.widen_radius_m);
  for (std::size_t k = i + 1; k < n_; ++k) marks_[k - 1] = marks_[k];
  --n_;
}

}  // namespace ag::plan
