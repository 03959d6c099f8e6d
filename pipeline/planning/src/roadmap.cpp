// Roadmap: construction, tiles, node placement, edges, bridges and incremental updates. The fields and
// line walks are in roadmap_fields.cpp, the queries in roadmap_plan.cpp.
#include "airground/planning/roadmap.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace ag::plan {

namespace {
double sq(double v) noexcept { return v * v; }
}  // namespace

RoadmapParams load_roadmap_params(const SectionView& s, double resolution_m, int tile_cells) {
  RoadmapParams p = load_params(s, kRoadmapFields);
  p.resolution_m = resolution_m;
  p.tile_cells = tile_cells;
  return p;
}

const char* to_string(PlanStatus s) noexcept {
  switch (s) {
    case PlanStatus::kOk: return "ok";
    case PlanStatus::kStartOutside: return "start outside the map";
    case PlanStatus::kGoalOutside: return "goal outside the map";
    case PlanStatus::kStartBlocked: return "no free cell near the start";
    case PlanStatus::kGoalBlocked: return "no free cell near the goal";
    case PlanStatus::kNoRoute: return "no route";
    case PlanStatus::kTooLong: return "route has too many points";
  }
  return "?";
}

Roadmap::Roadmap(const RoadmapParams& params, const ClassTable& classes, const TileExtent& extent) : p_(params), extent_(extent) {
  w_ = extent.tiles_x * p_.tile_cells;
  h_ = extent.tiles_y * p_.tile_cells;
  ox_ = extent.tile_x0 * p_.tile_cells * p_.resolution_m;
  oy_ = extent.tile_y0 * p_.tile_cells * p_.resolution_m;
  close_r_ = std::max(0, p_.hole_fill_radius_cells);
  cap_cells_ = static_cast<std::int32_t>(std::ceil(p_.clearance_cap_m / p_.resolution_m));
  vis_r_ = std::max(1, static_cast<std::int32_t>(std::floor(p_.visibility_radius_m / p_.resolution_m)));
  win_ = 2 * vis_r_ + 1;
  free_min_edt_ = static_cast<float>(p_.min_clearance_m / p_.resolution_m + 0.5);
  // A cell's centre is at origin + (index + 0.5) * resolution: the first and one-past-last index inside.
  auto first = [&](double v, double o, std::int32_t n) {
    return static_cast<std::int32_t>(std::clamp(std::ceil((v - o) / p_.resolution_m - 0.5), 0.0, static_cast<double>(n)));
  };
  auto end = [&](double v, double o, std::int32_t n) {
    return static_cast<std::int32_t>(std::clamp(std::floor((v - o) / p_.resolution_m - 0.5) + 1.0, 0.0, static_cast<double>(n)));
  };
  fence_ = {first(p_.fence.x0, ox_, w_), first(p_.fence.y0, oy_, h_), end(p_.fence.x1, ox_, w_), end(p_.fence.y1, oy_, h_)};
  for (int i = 0; i < 256; ++i) {
    const bool known = classes.valid_id(static_cast<std::uint8_t>(i));
    class_trav_[static_cast<std::size_t>(i)] = known ? classes.info(static_cast<ClassId>(i)).traversability : Traversability::kBlocked;
    fillable_[static_cast<std::size_t>(i)] = (p_.hole_fill_any_class || i == raw(ClassId::kUnknown)) ? 1 : 0;
  }
  set_levels();
  const std::size_t n = static_cast<std::size_t>(w_) * static_cast<std::size_t>(h_);
  cls_.assign(n, raw(ClassId::kUnknown));
  trav_.assign(n, 0);
  mark_.assign(n, 0);
  widen_.assign(n, 0);
  dil_.assign(n, 0);
  closed_.assign(n, 0);
  free_.assign(n, 0);
  edt_.assign(n, 0.0F);
  cover_.assign(n, 0);
  const std::size_t tiles = static_cast<std::size_t>(extent.tiles_x) * static_cast<std::size_t>(extent.tiles_y);
  tile_version_.assign(tiles, 0);
  tile_dirty_.assign(tiles, 0);
  dirty_.assign(tiles, 0);
  const auto cap = static_cast<std::size_t>(std::max(p_.max_nodes, 64));
  nodes_.assign(cap, Node{});
  vis_bytes_ = (static_cast<std::size_t>(win_) * static_cast<std::size_t>(win_) + 7) / 8;
  vis_.assign(cap * vis_bytes_, 0);
  free_slots_.assign(cap, 0);
  new_nodes_.assign(cap, 0);
  for (std::int32_t dy = -vis_r_; dy <= vis_r_; ++dy)
    for (std::int32_t dx = -vis_r_; dx <= vis_r_; ++dx)
      if (dx * dx + dy * dy <= vis_r_ * vis_r_) {
        disk_dx_.push_back(static_cast<std::int16_t>(dx));
        disk_dy_.push_back(static_cast<std::int16_t>(dy));
      }
  cand_.assign(n, 0);
  bucket_count_.assign(static_cast<std::size_t>(4 * (cap_cells_ + 2) + 2), 0);
  const std::int32_t m = cap_cells_ + 1;
  col_g_.assign(static_cast<std::size_t>(h_) * static_cast<std::size_t>(w_ + 2 * m + 2), 0);
  envelope_.resize(static_cast<std::size_t>(w_ + 2 * m + 2));
  g_.assign(cap + 2, 0.0F);
  parent_.assign(cap + 2, 0);
  stamp_.assign(cap + 2, 0);
  heap_.assign(cap * static_cast<std::size_t>(kMaxEdges) + 2 * cap + 16, 0);
  heap_key_.assign(heap_.size(), 0.0F);
  cand_nodes_.assign(cap, 0);
  pairs_.assign(cap * 8, 0);
  dense_x_.assign(8192, 0.0);
  dense_y_.assign(8192, 0.0);
  dense_c_.assign(8192, 0.0F);
}

void Roadmap::set_levels() noexcept {
  for (std::size_t i = 0; i < 256; ++i) {
    const Traversability t = class_trav_[i];
    std::uint8_t lv = 0;
    if (t != Traversability::kBlocked && static_cast<int>(t) <= static_cast<int>(p_.max_level)) lv = t == Traversability::kCostly ? 2 : 1;
    level_[i] = lv;
  }
}

bool Roadmap::set_max_level(Traversability level) noexcept {
  if (level == p_.max_level) return false;
  p_.max_level = level;
  set_levels();
  for (std::int32_t r = 0; r < h_; ++r)
    for (std::int32_t c = 0; c < w_; ++c) trav_[idx(c, r)] = trav_of(c, r);
  for (std::size_t t = 0; t < tile_dirty_.size(); ++t) mark_tile_dirty(t);
  return true;
}

std::size_t Roadmap::memory_bytes() const noexcept {
  return sizeof(*this) + cls_.size() * 8 + edt_.size() * sizeof(float) + cover_.size() * 2 + tile_version_.size() * 13 +
         nodes_.size() * sizeof(Node) + vis_.size() + (free_slots_.size() + new_nodes_.size() + cand_nodes_.size()) * 4 +
         cand_.size() * 4 + col_g_.size() + (g_.size() + parent_.size() + stamp_.size()) * 4 + heap_.size() * 8 +
         pairs_.size() * 8;
}

double Roadmap::clearance_cell_m(std::int32_t c, std::int32_t r) const noexcept {
  if (!inside(c, r)) return -0.5 * p_.resolution_m;
  return (static_cast<double>(edt_[idx(c, r)]) - 0.5) * p_.resolution_m;
}

double Roadmap::edge_cost(double length_m, double d, double costly_share) const noexcept {
  const double pen = std::min(p_.clearance_gain_m / (std::max(d, 0.0) + 0.01), p_.clearance_penalty_cap);
  return length_m * (p_.lambda + pen) * (1.0 + costly_share * (p_.costly_factor - 1.0));
}

Roadmap::Rect Roadmap::clamp(Rect r) const noexcept {
  return {std::max(r.x0, 0), std::max(r.y0, 0), std::min(r.x1, w_), std::min(r.y1, h_)};
}

std::uint64_t Roadmap::tile_version(std::int32_t tx, std::int32_t ty) const noexcept {
  const std::int32_t i = tx - extent_.tile_x0, j = ty - extent_.tile_y0;
  if (i < 0 || j < 0 || i >= extent_.tiles_x || j >= extent_.tiles_y) return 0;
  return tile_version_[static_cast<std::size_t>(j) * static_cast<std::size_t>(extent_.tiles_x) + static_cast<std::size_t>(i)];
}

bool Roadmap::set_tile(std::int32_t tx, std::int32_t ty, std::uint64_t version, std::span<const std::uint8_t> cls) noexcept {
  const std::int32_t i = tx - extent_.tile_x0, j = ty - extent_.tile_y0;
  if (i < 0 || j < 0 || i >= extent_.tiles_x || j >= extent_.tiles_y) return false;
  if (cls.size() != static_cast<std::size_t>(p_.tile_cells) * static_cast<std::size_t>(p_.tile_cells)) return false;
  const std::size_t t = static_cast<std::size_t>(j) * static_cast<std::size_t>(extent_.tiles_x) + static_cast<std::size_t>(i);
  if (tile_version_[t] == version) return false;
  tile_version_[t] = version;
  for (int r = 0; r < p_.tile_cells; ++r)
    for (int c = 0; c < p_.tile_cells; ++c) {
      const std::int32_t cx = i * p_.tile_cells + c, cy = j * p_.tile_cells + r;
      const std::size_t k = idx(cx, cy);
      const std::uint8_t v = cls[static_cast<std::size_t>(r * p_.tile_cells + c)];
      cls_[k] = v;
      trav_[k] = trav_of(cx, cy);
    }
  mark_tile_dirty(t);
  return true;
}

void Roadmap::mark_tile_dirty(std::size_t t) noexcept {
  if (tile_dirty_[t] != 0) return;
  tile_dirty_[t] = 1;
  dirty_[(dirty_head_ + n_dirty_) % dirty_.size()] = static_cast<std::uint32_t>(t);
  ++n_dirty_;
}

std::size_t Roadmap::block_disc(Point2 centre, double radius_m) noexcept { return change_disc(mark_, centre, radius_m, +1); }
std::size_t Roadmap::unblock_disc(Point2 centre, double radius_m) noexcept { return change_disc(mark_, centre, radius_m, -1); }
std::size_t Roadmap::widen_disc(Point2 centre, double radius_m) noexcept { return change_disc(widen_, centre, radius_m, +1); }
std::size_t Roadmap::unwiden_disc(Point2 centre, double radius_m) noexcept { return change_disc(widen_, centre, radius_m, -1); }

std::size_t Roadmap::change_disc(std::vector<std::uint8_t>& overlay, Point2 centre, double radius_m, int delta) noexcept {
  if (!std::isfinite(centre.x) || !std::isfinite(centre.y) || !(radius_m >= 0)) return 0;
  const double res = p_.resolution_m, fc = (centre.x - ox_) / res - 0.5, fr = (centre.y - oy_) / res - 0.5, rc = radius_m / res;
  const Rect box = clamp(Rect{static_cast<std::int32_t>(std::floor(fc - rc)), static_cast<std::int32_t>(std::floor(fr - rc)),
                              static_cast<std::int32_t>(std::ceil(fc + rc)) + 1, static_cast<std::int32_t>(std::ceil(fr + rc)) + 1});
  std::size_t changed = 0;
  for (std::int32_t r = box.y0; r < box.y1; ++r)
    for (std::int32_t c = box.x0; c < box.x1; ++c) {
      if ((c - fc) * (c - fc) + (r - fr) * (r - fr) > rc * rc) continue;
      const std::size_t k = idx(c, r);
      const std::uint8_t before = overlay[k];
      if (delta > 0 && before < 255) ++overlay[k];
      if (delta < 0 && before > 0) --overlay[k];
      if ((before == 0) == (overlay[k] == 0)) continue;
      trav_[k] = trav_of(c, r);
      if (overlay[k] != 0) ++changed;
      const auto t = static_cast<std::size_t>(r / p_.tile_cells) * static_cast<std::size_t>(extent_.tiles_x) + static_cast<std::size_t>(c / p_.tile_cells);
      mark_tile_dirty(t);
    }
  return delta > 0 ? changed : 0;
}

// ------------------------------------------------------------------------------------------ nodes

bool Roadmap::node_sees(std::uint32_t n, std::int32_t c, std::int32_t r) const noexcept {
  if (n >= node_end_ || !nodes_[n].alive) return false;
  const std::int32_t dx = c - nodes_[n].cx, dy = r - nodes_[n].cy;
  if (dx < -vis_r_ || dx > vis_r_ || dy < -vis_r_ || dy > vis_r_) return false;
  const auto bit = static_cast<std::size_t>((dy + vis_r_) * win_ + (dx + vis_r_));
  return (vis_bits(n)[bit >> 3] >> (bit & 7) & 1) != 0;
}

std::int64_t Roadmap::add_node(std::int32_t c, std::int32_t r, bool bridge) noexcept {
  std::uint32_t n = 0;
  if (n_free_slots_ > 0) {
    n = free_slots_[--n_free_slots_];
  } else if (node_end_ < nodes_.size()) {
    n = static_cast<std::uint32_t>(node_end_++);
  } else {
    ++stats_.node_capacity_exhausted;
    return -1;
  }
  Node& nd = nodes_[n];
  nd.cx = c;
  nd.cy = r;
  nd.clearance_m = static_cast<float>(clearance_cell_m(c, r));
  nd.alive = true;
  nd.bridge = bridge;
  nd.n_edges = 0;
  compute_visibility(n);
  ++stats_.nodes;
  if (bridge) ++stats_.bridges;
  if (n_new_ < new_nodes_.size()) new_nodes_[n_new_++] = n;
  return n;
}

void Roadmap::compute_visibility(std::uint32_t n) noexcept {
  ++stats_.visibility_computations;
  std::uint8_t* bits = vis_bits(n);
  std::fill(bits, bits + vis_bytes_, std::uint8_t{0});
  const Node& nd = nodes_[n];
  const double x0 = nd.cx + 0.5, y0 = nd.cy + 0.5;
  for (std::size_t k = 0; k < disk_dx_.size(); ++k) {
    const std::int32_t c = nd.cx + disk_dx_[k], r = nd.cy + disk_dy_[k];
    if (!inside(c, r) || free_[idx(c, r)] == 0) continue;
    if (!walk(x0, y0, c + 0.5, r + 0.5, nullptr, nullptr)) continue;
    const auto bit = static_cast<std::size_t>((disk_dy_[k] + vis_r_) * win_ + (disk_dx_[k] + vis_r_));
    bits[bit >> 3] = static_cast<std::uint8_t>(bits[bit >> 3] | (1U << (bit & 7)));
    std::uint16_t& cv = cover_[idx(c, r)];
    if (cv < 0xFFFF) ++cv;
  }
}

void Roadmap::remove_node(std::uint32_t n) noexcept {
  Node& nd = nodes_[n];
  if (!nd.alive) return;
  for (std::uint16_t e = 0; e < nd.n_edges; ++e) {
    Node& o = nodes_[nd.edges[e].to];
    for (std::uint16_t k = 0; k < o.n_edges; ++k)
      if (o.edges[k].to == n) {
        o.edges[k] = o.edges[--o.n_edges];
        break;
      }
    --stats_.edges;
  }
  nd.n_edges = 0;
  const std::uint8_t* bits = vis_bits(n);
  for (std::int32_t dy = -vis_r_; dy <= vis_r_; ++dy)
    for (std::int32_t dx = -vis_r_; dx <= vis_r_; ++dx) {
      const auto bit = static_cast<std::size_t>((dy + vis_r_) * win_ + (dx + vis_r_));
      if ((bits[bit >> 3] >> (bit & 7) & 1) == 0) continue;
      std::uint16_t& cv = cover_[idx(nd.cx + dx, nd.cy + dy)];
      if (cv > 0) --cv;
    }
  nd.alive = false;
  if (nd.bridge) --stats_.bridges;
  --stats_.nodes;
  ++stats_.nodes_removed;
  free_slots_[n_free_slots_++] = n;
}

void Roadmap::seed_nodes(Rect region) noexcept {
  region = clamp(region);
  const std::size_t nb = bucket_count_.size();
  std::fill(bucket_count_.begin(), bucket_count_.end(), 0U);
  std::uint32_t* sorted = cand_.data();
  auto key_of = [&](std::size_t i) { return std::min(nb - 1, static_cast<std::size_t>(edt_[i] * 4.0F)); };
  // Two passes over the region (count, then place): descending clearance, cell order within a key.
  std::size_t n = 0;
  for (std::int32_t y = region.y0; y < region.y1; ++y)
    for (std::int32_t x = region.x0; x < region.x1; ++x) {
      const std::size_t i = idx(x, y);
      if (free_[i] == 0 || cover_[i] != 0) continue;
      ++bucket_count_[key_of(i)];
      ++n;
    }
  std::uint32_t pos = 0;
  for (std::size_t b = nb; b-- > 0;) {
    const std::uint32_t cnt = bucket_count_[b];
    bucket_count_[b] = pos;
    pos += cnt;
  }
  for (std::int32_t y = region.y0; y < region.y1; ++y)
    for (std::int32_t x = region.x0; x < region.x1; ++x) {
      const std::size_t i = idx(x, y);
      if (free_[i] == 0 || cover_[i] != 0) continue;
      sorted[bucket_count_[key_of(i)]++] = static_cast<std::uint32_t>(i);
    }
  for (std::size_t k = 0; k < n; ++k) {
    const std::uint32_t i = sorted[k];
    if (cover_[i] != 0) continue;
    const auto c = static_cast<std::int32_t>(i % static_cast<std::uint32_t>(w_)), r = static_cast<std::int32_t>(i / static_cast<std::uint32_t>(w_));
    if (add_node(c, r, false) < 0) return;
  }
}

bool Roadmap::has_edge(std::uint32_t a, std::uint32_t b) const noexcept {
  const Node& na = nodes_[a];
  for (std::uint16_t e = 0; e < na.n_edges; ++e)
    if (na.edges[e].to == b) return true;
  return false;
}

bool Roadmap::share_neighbour(std::uint32_t a, std::uint32_t b) const noexcept {
  const Node& na = nodes_[a];
  for (std::uint16_t e = 0; e < na.n_edges; ++e)
    if (has_edge(na.edges[e].to, b)) return true;
  return false;
}

bool Roadmap::add_edge(std::uint32_t a, std::uint32_t b, float cost, float clear) noexcept {
  Node& na = nodes_[a];
  Node& nb = nodes_[b];
  if (na.n_edges >= kMaxEdges || nb.n_edges >= kMaxEdges) {
    ++stats_.edges_dropped_full;
    return false;
  }
  na.edges[na.n_edges++] = Edge{b, cost, clear};
  nb.edges[nb.n_edges++] = Edge{a, cost, clear};
  ++stats_.edges;
  return true;
}

void Roadmap::connect_new_nodes() noexcept {
  const auto reach2 = sq(2.0 * vis_r_ + 1.0);
  std::size_t n_pairs = 0;
  const double res = p_.resolution_m;
  auto try_connect = [&](std::uint32_t a, bool allow_pairs) {
    const Node& na = nodes_[a];
    for (std::uint32_t b = 0; b < node_end_; ++b) {
      const Node& nb = nodes_[b];
      if (b == a || !nb.alive) continue;
      const double dx = nb.cx - na.cx, dy = nb.cy - na.cy;
      const double d2 = dx * dx + dy * dy;
      if (d2 > reach2 || has_edge(a, b)) continue;
      float mc = 0;
      std::uint32_t costly = 0;
      // Visible regions overlap: scan the intersection of the two windows.
      bool overlap = false;
      if (d2 <= sq(vis_r_)) {
        overlap = node_sees(b, na.cx, na.cy) || node_sees(a, nb.cx, nb.cy);
      }
      if (!overlap) {
        const std::int32_t x0 = std::max(na.cx, nb.cx) - vis_r_, x1 = std::min(na.cx, nb.cx) + vis_r_;
        const std::int32_t y0 = std::max(na.cy, nb.cy) - vis_r_, y1 = std::min(na.cy, nb.cy) + vis_r_;
        for (std::int32_t y = y0; y <= y1 && !overlap; ++y)
          for (std::int32_t x = x0; x <= x1; ++x)
            if (node_sees(a, x, y) && node_sees(b, x, y)) {
              overlap = true;
              break;
            }
      }
      if (!overlap) continue;
      if (walk(na.cx + 0.5, na.cy + 0.5, nb.cx + 0.5, nb.cy + 0.5, &mc, &costly)) {
        const double len = std::sqrt(d2) * res;
        const double cells = std::max(1.0, std::fabs(dx) + std::fabs(dy) + 1.0);
        const double cost = edge_cost(len, (static_cast<double>(mc) - 0.5) * res, costly / cells);
        (void)add_edge(a, b, static_cast<float>(cost), static_cast<float>((static_cast<double>(mc) - 0.5) * res));
      } else if (allow_pairs) {
        if (n_pairs < pairs_.size()) pairs_[n_pairs++] = (static_cast<std::uint64_t>(a) << 32) | b;
        else ++stats_.edges_dropped_full;
      }
    }
  };
  for (std::size_t k = 0; k < n_new_; ++k) try_connect(new_nodes_[k], true);
  // Bridges: overlapping but not seeing each other, and not already joined through a common neighbour.
  for (std::size_t k = 0; k < n_pairs; ++k) {
    const auto a = static_cast<std::uint32_t>(pairs_[k] >> 32), b = static_cast<std::uint32_t>(pairs_[k] & 0xFFFFFFFFU);
    if (!nodes_[a].alive || !nodes_[b].alive || has_edge(a, b) || share_neighbour(a, b)) continue;
    const Node& na = nodes_[a];
    const Node& nb = nodes_[b];
    const std::int32_t x0 = std::max(na.cx, nb.cx) - vis_r_, x1 = std::min(na.cx, nb.cx) + vis_r_;
    const std::int32_t y0 = std::max(na.cy, nb.cy) - vis_r_, y1 = std::min(na.cy, nb.cy) + vis_r_;
    float best = -1.0F;
    std::int32_t bx = 0, by = 0;
    for (std::int32_t y = y0; y <= y1; ++y)
      for (std::int32_t x = x0; x <= x1; ++x)
        if (node_sees(a, x, y) && node_sees(b, x, y) && edt_[idx(x, y)] > best) {
          best = edt_[idx(x, y)];
          bx = x;
          by = y;
        }
    if (best < 0) continue;
    const std::size_t before = n_new_;
    const std::int64_t nn = add_node(bx, by, true);
    if (nn < 0) break;
    for (std::size_t j = before; j < n_new_; ++j) try_connect(new_nodes_[j], false);
  }
  n_new_ = 0;
}

// ------------------------------------------------------------------------------------------ build

void Roadmap::rebuild() noexcept {
  for (std::size_t t = 0; t < tile_dirty_.size(); ++t) tile_dirty_[t] = 0;
  n_dirty_ = 0;
  dirty_head_ = 0;
  recompute_closed(Rect{0, 0, w_, h_});
  recompute_clearance(Rect{0, 0, w_, h_});
  std::fill(cover_.begin(), cover_.end(), std::uint16_t{0});
  for (std::size_t n = 0; n < node_end_; ++n) nodes_[n] = Node{};
  node_end_ = 0;
  n_free_slots_ = 0;
  n_new_ = 0;
  stats_.nodes = stats_.edges = stats_.bridges = 0;
  seed_nodes(Rect{0, 0, w_, h_});
  connect_new_nodes();
  ++stats_.full_builds;
}

std::size_t Roadmap::update(std::size_t max_tiles) noexcept {
  if (n_dirty_ == 0) return 0;
  // Most of the map changed (the first load) and the caller wants it all now: one full build is cheaper
  // than tile by tile. A caller with a budget (the stage) passes a count and gets bounded steps.
  if (max_tiles == SIZE_MAX && n_dirty_ * 4 > tile_dirty_.size()) {
    const std::size_t n = n_dirty_;
    rebuild();
    return n;
  }
  std::size_t done = 0;
  while (n_dirty_ > 0 && done < max_tiles) {
    const std::uint32_t t = dirty_[dirty_head_];
    dirty_head_ = (dirty_head_ + 1) % dirty_.size();
    --n_dirty_;
    tile_dirty_[t] = 0;
    const auto tx = static_cast<std::int32_t>(t % static_cast<std::uint32_t>(extent_.tiles_x));
    const auto ty = static_cast<std::int32_t>(t / static_cast<std::uint32_t>(extent_.tiles_x));
    const Rect tile{tx * p_.tile_cells, ty * p_.tile_cells, (tx + 1) * p_.tile_cells, (ty + 1) * p_.tile_cells};
    recompute_fields(tile);
    const Rect changed = clamp(tile.grown(2 * close_r_ + cap_cells_ + 1));
    const Rect affected = changed.grown(vis_r_);
    for (std::uint32_t n = 0; n < node_end_; ++n) {
      const Node& nd = nodes_[n];
      if (nd.alive && nd.cx >= affected.x0 && nd.cx < affected.x1 && nd.cy >= affected.y0 && nd.cy < affected.y1) remove_node(n);
    }
    n_new_ = 0;
    seed_nodes(changed.grown(2 * vis_r_));
    connect_new_nodes();
    ++stats_.tile_updates;
    ++done;
  }
  return done;
}

}  // namespace ag::plan
