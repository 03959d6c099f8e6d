// Where the robot could not go: a robot that follows a route but stands still marks the ground just
// ahead of it blocked in its own roadmap, and re-plans around it. The aerial map can be wrong at an
// edge the LiDAR cannot see either (ErfNet calls the metre of a pond's shore next to a track "road";
// water gives no return): without this the planner sends the robot into the same shore for ever
// (gen6 study, session 38: 63 collisions at one spot). nav2's costmaps learn from the robot's own
// sensors in the same way; a mark is lifted after keep_s, so a team-mate that stood in the way is no
// obstacle for ever. Within widen_radius_m of a mark the planner may also cross grass: the way round it.
// Optionally (stall_traversable: costly) it also plans over grass from its first mark
// on: where the map is wrong about a track it is often wrong both ways (gen6: the shore "road", the
// track "grass"); off by default, as grass fields cost the localizer its fix.
//
// Pure logic over a Roadmap; fixed capacity, no allocation after construction.
#pragma once

#include <array>
#include <cstdint>
#include <span>

#include "airground/messages/geometry.hpp"
#include "airground/platform/param_binding.hpp"
#include "airground/platform/time.hpp"
#include "airground/planning/roadmap.hpp"

namespace ag::plan {

struct StallParams {
  double stall_s{10.0};        // following a route and within move_m of one spot this long: stalled; 0 = off
  double move_m{0.3};          // [m]
  double goal_clear_m{3.0};    // [m] not within this of the goal (a robot at its goal stands by design)
  double ahead_m{1.0};         // [m] the mark's centre this far along the route from the robot (its footprint's edge)
  double radius_m{0.6};        // [m] the mark's radius
  // Standing again where a mark already is (its centre within radius_m of one): the way round it did not
  // get the robot moving (gen6, session 40: wedged at the pond's shore, 32 marks on one spot, the same
  // route each time), so the new mark is larger: radius_m more for every mark already there, up to this.
  double max_radius_m{1.8};
  double keep_s{600.0};        // [s] a mark is lifted after this
  // Around a mark the planner also goes over grass (costly, at costly_factor): where the aerial map is
  // wrong about a track it is often wrong both ways (gen6's pond: ErfNet calls the shore "road" and the
  // track beside it "grass"), and the way round the mark is then the real track. Only near the mark: grass
  // fields everywhere cost the localizer its fix (stall_traversable). 0 = off.
  double widen_radius_m{6.0};
  // From the first mark on, plan through classes up to this level (costly: grass): the way round may be
  // ground the map calls grass. Off by default (rough, the planner's own default): measured on gen6
  // (session 39) a lone robot routed over grass fields lost track there for good (5 of 13 targets).
  Traversability traversable{Traversability::kRough};
};
inline constexpr ParamField<StallParams> kStallFields[] = {
    field::real("stall_s", &StallParams::stall_s, 0.0, 600.0, "s",
                "following a route but within stall_move_m of one spot this long: the ground ahead is marked blocked and the route re-planned; 0 = off"),
    field::real("stall_move_m", &StallParams::move_m, 0.05, 5.0, "m", "... moving less than this counts as standing"),
    field::real("stall_goal_clear_m", &StallParams::goal_clear_m, 0.0, 50.0, "m", "... not within this of the goal"),
    field::real("stall_mark_ahead_m", &StallParams::ahead_m, 0.0, 5.0, "m", "the blocked mark's centre this far along the route from the robot (ahead of it without a route)"),
    field::real("stall_mark_radius_m", &StallParams::radius_m, 0.1, 5.0, "m", "the blocked mark's radius"),
    field::real("stall_mark_max_radius_m", &StallParams::max_radius_m, 0.1, 5.0, "m",
                "standing again at a marked spot: the new mark grows by stall_mark_radius_m per mark already there, up to this"),
    field::real("stall_mark_keep_s", &StallParams::keep_s, 1.0, 36000.0, "s", "a blocked mark is lifted after this"),
    field::real("stall_widen_radius_m", &StallParams::widen_radius_m, 0.0, 50.0, "m",
                "within this of a blocked mark the planner also goes over grass (costly classes, at costly_factor): the way round it; 0 = off"),
    field::choice<&StallParams::traversable>(
        "stall_traversable", "free|rough|costly", {Traversability::kFree, Traversability::kRough, Traversability::kCostly},
        "from the first blocked mark on, plan through classes up to this level (costly: also grass); the default rough = never wider (grass fields cost the localizer its fix)"),
};

struct StallMark {
  Point2 centre;
  double radius_m{0};
  TimeNs until{0};
};

// The point `dist` metres along the polyline `pts` from its point nearest `from` (the last point when it
// is shorter); `from` itself when `pts` has fewer than two points.
Point2 point_along(std::span<const Point2> pts, Point2 from, double dist) noexcept;

class StallMarks {
 public:
  static constexpr std::size_t kMaxMarks = 32;  // a full table lifts its oldest mark for a new one
  explicit StallMarks(const StallParams& p) : p_(p) {}

  // One pose (map frame). `following`: a route to a goal is being driven on a tracking pose; `route`: its
  // points (the mark goes ahead_m along it from the point nearest the robot: where it could not go; empty:
  // ahead_m along the robot's heading). Returns true when it marked the ground ahead blocked in `map`
  // (the caller re-plans once map.update() has run).
  bool observe(const Pose2& pose, Point2 goal, bool following, TimeNs now, Roadmap& map,
               std::span<const Point2> route = {}) noexcept;
  // Lifts marks past their keep_s; true when any was lifted.
  bool expire(TimeNs now, Roadmap& map) noexcept;
  // Lifts every mark (no route with them: a mark diverts a route, it never closes the last way); true
  // when there was one.
  bool lift_all(Roadmap& map) noexcept;

  [[nodiscard]] std::size_t count() const noexcept { return n_; }
  [[nodiscard]] const StallMark& mark(std::size_t i) const noexcept { return marks_[i]; }
  [[nodiscard]] std::uint64_t stalls() const noexcept { return stalls_; }
  [[nodiscard]] std::uint64_t lifted_for_route() const noexcept { return lifted_all_; }
  [[nodiscard]] bool widened() const noexcept { return widened_; }
  [[nodiscard]] const StallParams& params() const noexcept { return p_; }

 private:
  void lift(std::size_t i, Roadmap& map) noexcept;
  StallParams p_;
  std::array<StallMark, kMaxMarks> marks_{};
  std::size_t n_{0};
  bool anchored_{false};
  Point2 anchor_{};
  TimeNs since_{0};
  std::uint64_t stalls_{0}, lifted_all_{0};
  bool widened_{false};
};

}  // namespace ag::plan
