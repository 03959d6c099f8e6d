// Grid reference: disc-stamped clearance mask, 8-connected Dijkstra, path checker.
#include "airground/planning/grid_reference.hpp"

#include <algorithm>
#include <cmath>
#include <functional>
#include <queue>

namespace ag::plan {

GridReference::GridReference(std::span<const std::uint8_t> cls, std::int32_t width, std::int32_t height, double resolution_m,
                             double ox, double oy, const ClassTable& classes, Traversability max_level, double min_clearance_m)
    : w_(width), h_(height), res_(resolution_m), ox_(ox), oy_(oy), min_clear_(min_clearance_m) {
  const std::size_t n = static_cast<std::size_t>(w_) * static_cast<std::size_t>(h_);
  trav_.assign(n, 0);
  for (std::size_t i = 0; i < n && i < cls.size(); ++i) {
    const std::uint8_t id = cls[i];
    const Traversability t = classes.valid_id(id) ? classes.info(static_cast<ClassId>(id)).traversability : Traversability::kBlocked;
    trav_[i] = (t != Traversability::kBlocked && static_cast<int>(t) <= static_cast<int>(max_level)) ? 1 : 0;
  }
  keep_ = trav_;
  // A cell keeps the clearance when no blocked cell centre (outside counts as blocked) is nearer than
  // rho = clearance / resolution + 1/2 cells: stamp that open disc around every blocked cell next to a free one.
  const double rho = min_clearance_m / resolution_m + 0.5;
  const auto rad = static_cast<std::int32_t>(std::ceil(rho));
  auto stamp = [&](std::int32_t bc, std::int32_t br) {
    for (std::int32_t dy = -rad; dy <= rad; ++dy)
      for (std::int32_t dx = -rad; dx <= rad; ++dx)
        if (static_cast<double>(dx * dx + dy * dy) < rho * rho - 1e-6 && in(bc + dx, br + dy)) keep_[idx(bc + dx, br + dy)] = 0;
  };
  for (std::int32_t r = -1; r <= h_; ++r)
    for (std::int32_t c = -1; c <= w_; ++c) {
      const bool blocked = !in(c, r) || trav_[idx(c, r)] == 0;
      if (!blocked) continue;
      bool edge = false;
      for (std::int32_t dy = -1; dy <= 1 && !edge; ++dy)
        for (std::int32_t dx = -1; dx <= 1; ++dx)
          if (in(c + dx, r + dy) && trav_[idx(c + dx, r + dy)] != 0) {
            edge = true;
            break;
          }
      if (edge) stamp(c, r);
    }
}

bool GridReference::traversable(std::int32_t c, std::int32_t r) const noexcept { return in(c, r) && trav_[idx(c, r)] != 0; }
bool GridReference::keeps_clearance(std::int32_t c, std::int32_t r) const noexcept { return in(c, r) && keep_[idx(c, r)] != 0; }
std::int32_t GridReference::col(double x) const noexcept { return static_cast<std::int32_t>(std::floor((x - ox_) / res_)); }
std::int32_t GridReference::row(double y) const noexcept { return static_cast<std::int32_t>(std::floor((y - oy_) / res_)); }

double GridReference::clearance_m(std::int32_t c, std::int32_t r, double cap_m) const noexcept {
  if (!traversable(c, r)) return -0.5 * res_;
  const auto rad = static_cast<std::int32_t>(std::ceil(cap_m / res_)) + 1;
  double best2 = 1e30;
  for (std::int32_t dy = -rad; dy <= rad; ++dy)
    for (std::int32_t dx = -rad; dx <= rad; ++dx) {
      const double d2 = static_cast<double>(dx * dx + dy * dy);
      if (d2 >= best2) continue;
      if (!in(c + dx, r + dy) || trav_[idx(c + dx, r + dy)] == 0) best2 = d2;
    }
  return std::min(cap_m, (std::sqrt(best2) - 0.5) * res_);
}

double GridReference::shortest_m(Point2 a, Point2 b) const {
  const std::int32_t ac = col(a.x), ar = row(a.y), bc = col(b.x), br = row(b.y);
  if (!keeps_clearance(ac, ar) || !keeps_clearance(bc, br)) return -1.0;
  const std::size_t n = static_cast<std::size_t>(w_) * static_cast<std::size_t>(h_);
  std::vector<double> dist(n, 1e300);
  using Item = std::pair<double, std::uint32_t>;
  std::priority_queue<Item, std::vector<Item>, std::greater<>> q;
  const std::size_t s = idx(ac, ar), t = idx(bc, br);
  dist[s] = 0;
  q.emplace(0.0, static_cast<std::uint32_t>(s));
  constexpr std::int32_t kDx[8] = {1, -1, 0, 0, 1, 1, -1, -1}, kDy[8] = {0, 0, 1, -1, 1, -1, 1, -1};
  while (!q.empty()) {
    const auto [d, i] = q.top();
    q.pop();
    if (d > dist[i]) continue;
    if (i == t) return d * res_;
    const auto c = static_cast<std::int32_t>(i % static_cast<std::uint32_t>(w_)), r = static_cast<std::int32_t>(i / static_cast<std::uint32_t>(w_));
    for (int k = 0; k < 8; ++k) {
      const std::int32_t nc = c + kDx[k], nr = r + kDy[k];
      if (!keeps_clearance(nc, nr)) continue;
      if (k >= 4 && (!keeps_clearance(c + kDx[k], r) || !keeps_clearance(c, r + kDy[k]))) continue;
      const double nd = d + (k >= 4 ? std::sqrt(2.0) : 1.0);
      const std::size_t j = idx(nc, nr);
      if (nd < dist[j]) {
        dist[j] = nd;
        q.emplace(nd, static_cast<std::uint32_t>(j));
      }
    }
  }
  return -1.0;
}

const std::vector<std::uint32_t>& GridReference::components() const {
  if (!comp_.empty()) return comp_;
  comp_.assign(keep_.size(), 0);
  std::uint32_t label = 0;
  std::vector<std::uint32_t> stack;
  for (std::size_t s = 0; s < keep_.size(); ++s) {
    if (keep_[s] == 0 || comp_[s] != 0) continue;
    ++label;
    comp_[s] = label;
    stack.assign(1, static_cast<std::uint32_t>(s));
    while (!stack.empty()) {
      const std::uint32_t i = stack.back();
      stack.pop_back();
      const auto c = static_cast<std::int32_t>(i % static_cast<std::uint32_t>(w_)), r = static_cast<std::int32_t>(i / static_cast<std::uint32_t>(w_));
      for (std::int32_t dy = -1; dy <= 1; ++dy)
        for (std::int32_t dx = -1; dx <= 1; ++dx) {
          if ((dx == 0 && dy == 0) || !keeps_clearance(c + dx, r + dy)) continue;
          if (dx != 0 && dy != 0 && (!keeps_clearance(c + dx, r) || !keeps_clearance(c, r + dy))) continue;
          const std::size_t j = idx(c + dx, r + dy);
          if (comp_[j] == 0) {
            comp_[j] = label;
            stack.push_back(static_cast<std::uint32_t>(j));
          }
        }
    }
  }
  return comp_;
}

PathCheck GridReference::check(std::span<const Point2> path, bool skip_first, bool skip_last) const {
  PathCheck pc;
  pc.min_clearance_m = 1e30;
  for (std::size_t i = 0; i + 1 < path.size(); ++i) {
    const double len = std::hypot(path[i + 1].x - path[i].x, path[i + 1].y - path[i].y);
    pc.length_m += len;
    if ((skip_first && i == 0) || (skip_last && i + 2 == path.size())) continue;
    const int steps = std::max(1, static_cast<int>(std::ceil(len / res_ * 20.0)));
    std::int32_t lc = -1 << 30, lr = -1 << 30;
    for (int s = 0; s <= steps; ++s) {
      const double t = static_cast<double>(s) / steps;
      const std::int32_t c = col(path[i].x + t * (path[i + 1].x - path[i].x)), r = row(path[i].y + t * (path[i + 1].y - path[i].y));
      if (c == lc && r == lr) continue;
      lc = c;
      lr = r;
      const bool tr = traversable(c, r), kc = keeps_clearance(c, r);
      if (!tr) pc.traversable = false;
      if (!kc) pc.clearance = false;
      if (!tr || !kc) ++pc.bad_samples;
      pc.min_clearance_m = std::min(pc.min_clearance_m, clearance_m(c, r));
    }
  }
  if (pc.min_clearance_m > 1e29) pc.min_clearance_m = 0;
  return pc;
}

}  // namespace ag::plan
