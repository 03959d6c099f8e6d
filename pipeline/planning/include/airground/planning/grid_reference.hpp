// The grid reference the planner is judged against (issue #6): the shortest 8-connected path through
// traversable cells that keep the robot's minimum clearance, and a checker of planned paths. Written
// independently of the roadmap: the clearance mask comes from stamping discs around blocked cells, not
// from a distance transform, so a bug in one does not hide in the other.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "airground/messages/classes.hpp"
#include "airground/planning/roadmap.hpp"

namespace ag::plan {

struct PathCheck {
  bool traversable{true};      // no sample on a non-traversable (or outside) cell
  bool clearance{true};        // no sample on a cell closer than min_clearance to a blocked cell
  double min_clearance_m{0};   // smallest clearance over the samples (snap segments excluded)
  double length_m{0};
  std::uint32_t bad_samples{0};
};

class GridReference {
 public:
  // cls: width x height class ids, row 0 south; (ox, oy) the south-west corner [m].
  GridReference(std::span<const std::uint8_t> cls, std::int32_t width, std::int32_t height, double resolution_m, double ox,
                double oy, const ClassTable& classes, Traversability max_level, double min_clearance_m);

  [[nodiscard]] bool traversable(std::int32_t c, std::int32_t r) const noexcept;
  [[nodiscard]] bool keeps_clearance(std::int32_t c, std::int32_t r) const noexcept;
  // [m] distance from the cell's centre to the nearest blocked cell's edge, up to cap_m (brute force).
  [[nodiscard]] double clearance_m(std::int32_t c, std::int32_t r, double cap_m = 10.0) const noexcept;
  // Length of the shortest 8-connected path [m] between the cells of a and b through cells that keep the
  // clearance (a diagonal step needs both side cells), or -1 when there is none.
  [[nodiscard]] double shortest_m(Point2 a, Point2 b) const;
  // Labels of the 8-connected components of the clearance-keeping cells (0 = not free).
  [[nodiscard]] const std::vector<std::uint32_t>& components() const;
  // Samples the path every 1/20 cell. skip_first/skip_last: the snap segments at the ends.
  [[nodiscard]] PathCheck check(std::span<const Point2> path, bool skip_first = false, bool skip_last = false) const;

  [[nodiscard]] std::int32_t width() const noexcept { return w_; }
  [[nodiscard]] std::int32_t height() const noexcept { return h_; }
  [[nodiscard]] std::int32_t col(double x) const noexcept;
  [[nodiscard]] std::int32_t row(double y) const noexcept;
  [[nodiscard]] double min_clearance_m() const noexcept { return min_clear_; }

 private:
  [[nodiscard]] std::size_t idx(std::int32_t c, std::int32_t r) const noexcept {
    return static_cast<std::size_t>(r) * static_cast<std::size_t>(w_) + static_cast<std::size_t>(c);
  }
  [[nodiscard]] bool in(std::int32_t c, std::int32_t r) const noexcept { return c >= 0 && r >= 0 && c < w_ && r < h_; }
  std::int32_t w_, h_;
  double res_, ox_, oy_, min_clear_;
  std::vector<std::uint8_t> trav_, keep_;
  mutable std::vector<std::uint32_t> comp_;
};

}  // namespace ag::plan
