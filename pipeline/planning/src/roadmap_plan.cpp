// Roadmap queries: snapping the ends to free cells, the search over the graph (A*) and shortcutting.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "airground/planning/roadmap.hpp"

namespace ag::plan {

namespace {

double sq(double v) noexcept { return v * v; }

// Binary min-heap of node ids by key (cost so far + heuristic), over the planner's preallocated arrays.
struct SearchHeap {
  std::vector<std::uint32_t>& ids;
  std::vector<float>& keys;
  std::size_t n{0};

  void push(std::uint32_t node, float key) noexcept {
    if (n >= ids.size()) return;
    std::size_t i = n++;
    while (i > 0) {
      const std::size_t pi = (i - 1) / 2;
      if (keys[pi] <= key) break;
      ids[i] = ids[pi];
      keys[i] = keys[pi];
      i = pi;
    }
    ids[i] = node;
    keys[i] = key;
  }

  void pop(std::uint32_t& node, float& key) noexcept {
    node = ids[0];
    key = keys[0];
    const std::uint32_t ln = ids[--n];
    const float lk = keys[n];
    std::size_t i = 0;
    for (;;) {
      std::size_t ch = 2 * i + 1;
      if (ch >= n) break;
      if (ch + 1 < n && keys[ch + 1] < keys[ch]) ++ch;
      if (keys[ch] >= lk) break;
      ids[i] = ids[ch];
      keys[i] = keys[ch];
      i = ch;
    }
    ids[i] = ln;
    keys[i] = lk;
  }
};

// The length of a complete path; marks it planned.
void finish_path(PlannedPath& out) noexcept {
  out.length_m = 0;
  for (std::uint32_t i = 1; i < out.count; ++i)
    out.length_m += std::hypot(out.points[i].x - out.points[i - 1].x, out.points[i].y - out.points[i - 1].y);
  out.status = PlanStatus::kOk;
}

// Smallest clearance of the path's stretches from point a0 to point a1 [m]; 0 when none is free.
double min_clearance(const Roadmap& map, const PlannedPath& out, std::uint32_t a0, std::uint32_t a1) noexcept {
  double mcl = 1e30;
  for (std::uint32_t i = a0; i < a1; ++i) {
    double c = 0;
    if (map.line_free(out.points[i], out.points[i + 1], &c)) mcl = std::min(mcl, c);
  }
  return mcl < 1e29 ? mcl : 0.0;
}

}  // namespace

template <class Accept>
bool Roadmap::nearest_cell(std::int32_t pc, std::int32_t pr, double radius_m, Accept accept, std::int32_t& c, std::int32_t& r) const noexcept {
  const auto rad = static_cast<std::int32_t>(std::ceil(radius_m / p_.resolution_m));
  double best = 1e30;
  bool found = false;
  for (std::int32_t dy = -rad; dy <= rad; ++dy)
    for (std::int32_t dx = -rad; dx <= rad; ++dx) {
      const double d2 = dx * dx + dy * dy;
      if (d2 > sq(rad) || d2 >= best || !free_cell(pc + dx, pr + dy) || !accept(pc + dx, pr + dy)) continue;
      best = d2;
      c = pc + dx;
      r = pr + dy;
      found = true;
    }
  return found;
}

bool Roadmap::snap(Point2 p, double radius_m, std::int32_t& c, std::int32_t& r) const noexcept {
  const double res = p_.resolution_m;
  const auto pc = static_cast<std::int32_t>(std::floor((p.x - ox_) / res)), pr = static_cast<std::int32_t>(std::floor((p.y - oy_) / res));
  if (free_cell(pc, pr)) {
    c = pc;
    r = pr;
    return true;
  }
  return nearest_cell(pc, pr, radius_m, [](std::int32_t, std::int32_t) { return true; }, c, r);
}

bool Roadmap::escape(Point2 p, std::int32_t& c, std::int32_t& r) const noexcept {
  if (!(p_.start_escape_m > 0.0)) return false;
  const double res = p_.resolution_m;
  const double sx = (p.x - ox_) / res, sy = (p.y - oy_) / res;  // [cells]
  const auto pc = static_cast<std::int32_t>(std::floor(sx)), pr = static_cast<std::int32_t>(std::floor(sy));
  if (!escape_ground(pc, pr)) return false;
  // Every cell the line from p to the centre of (cc, cr) passes, sampled at a quarter cell.
  const auto over_ground = [&](std::int32_t cc, std::int32_t cr) {
    const double dx = cc + 0.5 - sx, dy = cr + 0.5 - sy;
    const int steps = static_cast<int>(std::ceil(4.0 * std::hypot(dx, dy)));
    for (int i = 1; i < steps; ++i) {
      const double f = static_cast<double>(i) / steps;
      if (!escape_ground(static_cast<std::int32_t>(std::floor(sx + f * dx)), static_cast<std::int32_t>(std::floor(sy + f * dy)))) return false;
    }
    return true;
  };
  return nearest_cell(pc, pr, p_.start_escape_m, over_ground, c, r);
}

std::uint32_t Roadmap::visible_nodes(double x, double y, std::uint32_t* out, std::uint32_t cap) const noexcept {
  const auto c = static_cast<std::int32_t>(std::floor(x)), r = static_cast<std::int32_t>(std::floor(y));
  std::uint32_t n = 0;
  for (std::uint32_t k = 0; k < node_end_ && n < cap; ++k)
    if (node_sees(k, c, r)) out[n++] = k;
  return n;
}
void Roadmap::plan(Point2 start, Point2 goal, PlannedPath& out, double snap_radius_m) noexcept {
  out.count = 0;
  out.length_m = out.cost = 0;
  out.expanded = 0;
  out.min_clearance_m = 0;
  out.start_escaped = false;
  const double res = p_.resolution_m;
  auto outside = [&](Point2 p) { return !inside(static_cast<std::int32_t>(std::floor((p.x - ox_) / res)), static_cast<std::int32_t>(std::floor((p.y - oy_) / res))); };
  if (outside(start)) {
    out.status = PlanStatus::kStartOutside;
    return;
  }
  if (outside(goal)) {
    out.status = PlanStatus::kGoalOutside;
    return;
  }
  std::int32_t sc = 0, sr = 0, gc = 0, gr = 0;
  if (!snap(start, snap_radius_m, sc, sr) && !(out.start_escaped = escape(start, sc, sr))) {
    out.status = PlanStatus::kStartBlocked;
    return;
  }
  if (!snap(goal, snap_radius_m, gc, gr)) {
    out.status = PlanStatus::kGoalBlocked;
    return;
  }
  // The snapped ends in cell coordinates: the exact point when its own cell is free, else the cell centre.
  const double sx0 = (start.x - ox_) / res, sy0 = (start.y - oy_) / res, gx0 = (goal.x - ox_) / res, gy0 = (goal.y - oy_) / res;
  const bool s_snapped = static_cast<std::int32_t>(std::floor(sx0)) != sc || static_cast<std::int32_t>(std::floor(sy0)) != sr;
  const bool g_snapped = static_cast<std::int32_t>(std::floor(gx0)) != gc || static_cast<std::int32_t>(std::floor(gy0)) != gr;
  const double sx = s_snapped ? sc + 0.5 : sx0, sy = s_snapped ? sr + 0.5 : sy0;
  const double gx = g_snapped ? gc + 0.5 : gx0, gy = g_snapped ? gr + 0.5 : gy0;
  // The graph runs between the cell centres of the (snapped) ends: a node that sees a cell sees its
  // centre; the exact ends join the path through their own cell (or the snap segment).
  const double scx = sc + 0.5, scy = sr + 0.5, gcx = gc + 0.5, gcy = gr + 0.5;

  auto push = [&](double cx, double cy) {
    if (out.count >= kMaxPathPoints) return false;
    out.points[out.count++] = Point2{ox_ + cx * res, oy_ + cy * res};
    return true;
  };

  // Straight line when it is free and not far.
  float mc = 0;
  std::uint32_t costly = 0;
  const double direct = std::hypot(gx - sx, gy - sy);
  if (direct <= 4.0 * vis_r_ && walk(sx, sy, gx, gy, &mc, &costly)) {
    push(sx0, sy0);
    if (s_snapped) push(sx, sy);
    push(gx, gy);
    if (g_snapped) push(gx0, gy0);
    out.cost = edge_cost(direct * res, (static_cast<double>(mc) - 0.5) * res, 0.0);
    out.min_clearance_m = (static_cast<double>(mc) - 0.5) * res;
    finish_path(out);
    return;
  }

  // Start and goal candidates through the visibility map.
  const auto cap = static_cast<std::uint32_t>(nodes_.size());
  const std::uint32_t v_start = cap, v_goal = cap + 1;
  ++search_stamp_;
  if (search_stamp_ == 0) {
    std::fill(stamp_.begin(), stamp_.end(), 0U);
    search_stamp_ = 1;
  }
  auto seen = [&](std::uint32_t n) { return stamp_[n] == search_stamp_; };
  auto set_g = [&](std::uint32_t n, float v, std::uint32_t par) {
    stamp_[n] = search_stamp_;
    g_[n] = v;
    parent_[n] = par;
  };
  SearchHeap heap{heap_, heap_key_};
  auto h = [&](std::uint32_t n) {
    return static_cast<float>(p_.lambda * res * std::hypot(nodes_[n].cx + 0.5 - gcx, nodes_[n].cy + 0.5 - gcy));
  };
  auto seg_cost = [&](double ax, double ay, double bx, double by, bool* okp) {
    float m = 0;
    std::uint32_t cst = 0;
    const bool ok = walk(ax, ay, bx, by, &m, &cst);
    *okp = ok;
    const double cells = std::max(1.0, std::fabs(bx - ax) + std::fabs(by - ay) + 1.0);
    return edge_cost(std::hypot(bx - ax, by - ay) * res, (static_cast<double>(m) - 0.5) * res, cst / cells);
  };

  set_g(v_start, 0.0F, v_start);
  const std::uint32_t ns = visible_nodes(scx, scy, cand_nodes_.data(), cap);
  for (std::uint32_t k = 0; k < ns; ++k) {
    const std::uint32_t n = cand_nodes_[k];
    bool ok = false;
    const double c = seg_cost(scx, scy, nodes_[n].cx + 0.5, nodes_[n].cy + 0.5, &ok);
    if (!ok) continue;
    set_g(n, static_cast<float>(c), v_start);
    heap.push(n, static_cast<float>(c) + h(n));
  }
  // Goal candidates: the nodes whose visibility covers the goal's cell (tested as they are expanded).
  const auto gcell_c = static_cast<std::int32_t>(std::floor(gx)), gcell_r = static_cast<std::int32_t>(std::floor(gy));
  bool reached = false;
  while (heap.n > 0) {
    std::uint32_t u = 0;
    float key = 0;
    heap.pop(u, key);
    if (u == v_goal) {
      reached = true;
      break;
    }
    if (key > g_[u] + h(u) + 1e-4F) continue;  // stale entry
    ++out.expanded;
    const Node& nu = nodes_[u];
    if (node_sees(u, gcell_c, gcell_r)) {
      bool ok = false;
      const double c = seg_cost(nu.cx + 0.5, nu.cy + 0.5, gcx, gcy, &ok);
      const float ng2 = g_[u] + static_cast<float>(c);
      if (ok && (!seen(v_goal) || ng2 < g_[v_goal])) {
        set_g(v_goal, ng2, u);
        heap.push(v_goal, ng2);
      }
    }
    for (std::uint16_t e = 0; e < nu.n_edges; ++e) {
      const Edge& ed = nu.edges[e];
      const float nv = g_[u] + ed.cost;
      if (seen(ed.to) && nv >= g_[ed.to]) continue;
      set_g(ed.to, nv, u);
      heap.push(ed.to, nv + h(ed.to));
    }
  }
  if (!reached) {
    out.status = PlanStatus::kNoRoute;
    return;
  }
  out.cost = g_[v_goal];
  // Nodes from the goal back to the start, then reversed into the path.
  std::uint32_t chain = 0;
  for (std::uint32_t n = parent_[v_goal]; n != v_start; n = parent_[n]) {
    if (chain >= kMaxPathPoints - 4) {
      out.status = PlanStatus::kTooLong;
      return;
    }
    cand_nodes_[chain++] = n;
  }
  push(sx0, sy0);
  push(scx, scy);
  for (std::uint32_t k = chain; k-- > 0;) push(nodes_[cand_nodes_[k]].cx + 0.5, nodes_[cand_nodes_[k]].cy + 0.5);
  push(gcx, gcy);
  push(gx0, gy0);
  shortcut(out);
  // Smallest clearance over the planned stretch (the snap segments excluded).
  const std::uint32_t a0 = s_snapped ? 1U : 0U, a1 = out.count - 1U - (g_snapped ? 1U : 0U);
  out.min_clearance_m = min_clearance(*this, out, a0, a1);
  finish_path(out);
}

void Roadmap::shortcut(PlannedPath& out) noexcept {
  if (out.count < 3) return;
  const double res = p_.resolution_m;
  // Dense points [cells] every ~shortcut_step_cells along the path, each with the clearance of the
  // stretch from its predecessor (-1: a snap segment, never cut).
  const double step = std::max(1.0, 1.0 / res);
  std::size_t n = 0;
  const std::size_t cap = dense_x_.size();
  for (std::uint32_t i = 0; i + 1 < out.count && n + 1 < cap; ++i) {
    const double ax = (out.points[i].x - ox_) / res, ay = (out.points[i].y - oy_) / res;
    const double bx = (out.points[i + 1].x - ox_) / res, by = (out.points[i + 1].y - oy_) / res;
    float m = 0;
    const float segc = walk(ax, ay, bx, by, &m, nullptr) ? m : -1.0F;
    const int pieces = segc < 0 ? 1 : std::max(1, static_cast<int>(std::ceil(std::hypot(bx - ax, by - ay) / step)));
    if (i == 0) {
      dense_x_[n] = ax;
      dense_y_[n] = ay;
      dense_c_[n++] = 0;
    }
    for (int k = 1; k <= pieces && n < cap; ++k) {
      const double t = static_cast<double>(k) / pieces;
      dense_x_[n] = ax + t * (bx - ax);
      dense_y_[n] = ay + t * (by - ay);
      dense_c_[n++] = segc;
    }
  }
  const auto want = static_cast<float>(p_.shortcut_clearance_m / res + 0.5);
  std::uint32_t w = 1;
  std::size_t i = 0;
  out.points[0] = Point2{ox_ + dense_x_[0] * res, oy_ + dense_y_[0] * res};
  while (i + 1 < n && w < kMaxPathPoints) {
    std::size_t best = i + 1;
    if (dense_c_[i + 1] >= 0) {
      float stretch = dense_c_[i + 1];
      std::uint32_t misses = 0;
      for (std::size_t j = i + 2; j < n && misses < 12; ++j) {
        if (dense_c_[j] < 0) break;
        stretch = std::min(stretch, dense_c_[j]);
        float m = 0;
        if (walk(dense_x_[i], dense_y_[i], dense_x_[j], dense_y_[j], &m, nullptr) && m >= std::min(want, stretch) - 1e-4F) {
          best = j;
          misses = 0;
        } else {
          ++misses;
        }
      }
    }
    out.points[w++] = Point2{ox_ + dense_x_[best] * res, oy_ + dense_y_[best] * res};
    i = best;
  }
  out.count = w;
}

}  // namespace ag::plan
