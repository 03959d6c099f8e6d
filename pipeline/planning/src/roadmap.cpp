// Roadmap: fields (traversable, closed, clearance, free), node placement, edges, bridges, incremental
// updates and queries.
#include "airground/planning/roadmap.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace ag::plan {

namespace {
constexpr float kFar = 1e9F;
double sq(double v) noexcept { return v * v; }
}  // namespace

RoadmapParams load_roadmap_params(const SectionView& s, double resolution_m, int tile_cells) {
  RoadmapParams p;
  p.resolution_m = resolution_m;
  p.tile_cells = tile_cells;
  const std::string& t = s.text("traversable");
  p.max_level = t == "free" ? Traversability::kFree : t == "costly" ? Traversability::kCostly : Traversability::kRough;
  p.costly_factor = s.real("costly_factor");
  p.hole_fill_radius_cells = static_cast<int>(s.integer("hole_fill_radius_cells"));
  p.hole_fill_any_class = s.boolean("hole_fill_any_class");
  p.min_clearance_m = s.real("min_clearance_m");
  p.clearance_cap_m = s.real("clearance_cap_m");
  p.visibility_radius_m = s.real("visibility_radius_m");
  p.lambda = s.real("lambda");
  p.clearance_gain_m = s.real("clearance_gain_m");
  p.shortcut_clearance_m = s.real("shortcut_clearance_m");
  p.max_nodes = static_cast<int>(s.integer("max_nodes"));
  return p;
}

MapExtent extent_covering_area(double x0, double y0, double x1, double y1, double resolution_m, int tile_cells) noexcept {
  const double t = resolution_m * tile_cells;
  MapExtent e;
  e.tile_x0 = static_cast<std::int32_t>(std::floor(x0 / t));
  e.tile_y0 = static_cast<std::int32_t>(std::floor(y0 / t));
  e.tiles_x = static_cast<std::int32_t>(std::floor(x1 / t)) - e.tile_x0 + 1;
  e.tiles_y = static_cast<std::int32_t>(std::floor(y1 / t)) - e.tile_y0 + 1;
  return e;
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

Roadmap::Roadmap(const RoadmapParams& params, const ClassTable& classes, const MapExtent& extent) : p_(params), extent_(extent) {
  w_ = extent.tiles_x * p_.tile_cells;
  h_ = extent.tiles_y * p_.tile_cells;
  ox_ = extent.tile_x0 * p_.tile_cells * p_.resolution_m;
  oy_ = extent.tile_y0 * p_.tile_cells * p_.resolution_m;
  close_r_ = std::max(0, p_.hole_fill_radius_cells);
  cap_cells_ = static_cast<std::int32_t>(std::ceil(p_.clearance_cap_m / p_.resolution_m));
  vis_r_ = std::max(1, static_cast<std::int32_t>(std::floor(p_.visibility_radius_m / p_.resolution_m)));
  win_ = 2 * vis_r_ + 1;
  free_min_edt_ = static_cast<float>(p_.min_clearance_m / p_.resolution_m + 0.5);
  for (int i = 0; i < 256; ++i) {
    const auto id = static_cast<ClassId>(i);
    const bool known = classes.valid_id(static_cast<std::uint8_t>(i));
    const Traversability t = known ? classes.info(id).traversability : Traversability::kBlocked;
    std::uint8_t lv = 0;
    if (t != Traversability::kBlocked && static_cast<int>(t) <= static_cast<int>(p_.max_level))
      lv = t == Traversability::kCostly ? 2 : 1;
    level_[static_cast<std::size_t>(i)] = lv;
    fillable_[static_cast<std::size_t>(i)] = (p_.hole_fill_any_class || i == raw(ClassId::kUnknown)) ? 1 : 0;
  }
  const std::size_t n = static_cast<std::size_t>(w_) * static_cast<std::size_t>(h_);
  cls_.assign(n, raw(ClassId::kUnknown));
  trav_.assign(n, 0);
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
  env_v_.assign(static_cast<std::size_t>(w_ + 2 * m + 2), 0);
  env_z_.assign(static_cast<std::size_t>(w_ + 2 * m + 3), 0.0F);
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

std::size_t Roadmap::memory_bytes() const noexcept {
  return sizeof(*this) + cls_.size() * 6 + edt_.size() * sizeof(float) + cover_.size() * 2 + tile_version_.size() * 13 +
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
      const std::size_t k = idx(i * p_.tile_cells + c, j * p_.tile_cells + r);
      const std::uint8_t v = cls[static_cast<std::size_t>(r * p_.tile_cells + c)];
      cls_[k] = v;
      trav_[k] = level_[v] != 0 ? 1 : 0;
    }
  if (tile_dirty_[t] == 0) {
    tile_dirty_[t] = 1;
    dirty_[(dirty_head_ + n_dirty_) % dirty_.size()] = static_cast<std::uint32_t>(t);
    ++n_dirty_;
  }
  return true;
}

// ------------------------------------------------------------------------------------------ fields

void Roadmap::recompute_closed(Rect out) noexcept {
  out = clamp(out);
  if (close_r_ == 0) {
    for (std::int32_t y = out.y0; y < out.y1; ++y)
      for (std::int32_t x = out.x0; x < out.x1; ++x) closed_[idx(x, y)] = trav_[idx(x, y)];
    return;
  }
  const Rect d = clamp(out.grown(close_r_));
  for (std::int32_t y = d.y0; y < d.y1; ++y)
    for (std::int32_t x = d.x0; x < d.x1; ++x) {
      std::uint8_t any = 0;
      for (std::int32_t yy = std::max(0, y - close_r_); yy <= std::min(h_ - 1, y + close_r_) && any == 0; ++yy)
        for (std::int32_t xx = std::max(0, x - close_r_); xx <= std::min(w_ - 1, x + close_r_); ++xx)
          if (trav_[idx(xx, yy)] != 0) {
            any = 1;
            break;
          }
      dil_[idx(x, y)] = any;
    }
  for (std::int32_t y = out.y0; y < out.y1; ++y)
    for (std::int32_t x = out.x0; x < out.x1; ++x) {
      const std::size_t k = idx(x, y);
      if (trav_[k] != 0) {
        closed_[k] = 1;
        continue;
      }
      std::uint8_t all = fillable_[cls_[k]];
      for (std::int32_t yy = y - close_r_; yy <= y + close_r_ && all != 0; ++yy)
        for (std::int32_t xx = x - close_r_; xx <= x + close_r_; ++xx)
          if (!inside(xx, yy) || dil_[idx(xx, yy)] == 0) {
            all = 0;
            break;
          }
      closed_[k] = all;
    }
}

// Exact Euclidean distance to the nearest blocked cell centre (outside the extent is blocked), capped:
// column distances over the output rows, then Felzenszwalb-Huttenlocher lower envelopes along rows.
void Roadmap::recompute_clearance(Rect out) noexcept {
  out = clamp(out);
  if (out.x1 <= out.x0 || out.y1 <= out.y0) return;
  const std::int32_t m = cap_cells_ + 1;
  const std::int32_t ix0 = out.x0 - m, ix1 = out.x1 + m, iw = ix1 - ix0;
  const std::int32_t iy0 = out.y0 - m, iy1 = out.y1 + m;
  const std::int32_t far = m + 1;
  auto blocked = [&](std::int32_t x, std::int32_t y) { return !inside(x, y) || closed_[idx(x, y)] == 0; };
  // column pass: g[(y - out.y0) * iw + (x - ix0)] = vertical distance to a blocked cell, capped at far
  for (std::int32_t x = ix0; x < ix1; ++x) {
    std::int32_t last = iy0 - far;  // row of the last blocked cell seen going up
    for (std::int32_t y = iy0; y < out.y1; ++y) {
      if (blocked(x, y)) last = y;
      if (y >= out.y0) col_g_[static_cast<std::size_t>(y - out.y0) * static_cast<std::size_t>(iw) + static_cast<std::size_t>(x - ix0)] =
          static_cast<std::uint8_t>(std::min(far, y - last));
    }
    last = iy1 + far;
    for (std::int32_t y = iy1 - 1; y >= out.y0; --y) {
      if (blocked(x, y)) last = y;
      if (y < out.y1) {
        std::uint8_t& g = col_g_[static_cast<std::size_t>(y - out.y0) * static_cast<std::size_t>(iw) + static_cast<std::size_t>(x - ix0)];
        g = static_cast<std::uint8_t>(std::min<std::int32_t>(g, std::min(far, last - y)));
      }
    }
  }
  // row pass
  for (std::int32_t y = out.y0; y < out.y1; ++y) {
    const std::uint8_t* g = &col_g_[static_cast<std::size_t>(y - out.y0) * static_cast<std::size_t>(iw)];
    auto f = [&](std::int32_t q) { return static_cast<float>(g[q] * g[q]); };
    std::int32_t k = 0;
    env_v_[0] = 0;
    env_z_[0] = -kFar;
    env_z_[1] = kFar;
    for (std::int32_t q = 1; q < iw; ++q) {
      float s = 0;
      for (;;) {
        const std::int32_t v = env_v_[static_cast<std::size_t>(k)];
        s = ((f(q) + static_cast<float>(q * q)) - (f(v) + static_cast<float>(v * v))) / (2.0F * static_cast<float>(q - v));
        if (s <= env_z_[static_cast<std::size_t>(k)] && k > 0) {
          --k;
          continue;
        }
        break;
      }
      if (s <= env_z_[static_cast<std::size_t>(k)]) {  // k == 0
        env_v_[0] = q;
        env_z_[0] = -kFar;
        env_z_[1] = kFar;
        continue;
      }
      ++k;
      env_v_[static_cast<std::size_t>(k)] = q;
      env_z_[static_cast<std::size_t>(k)] = s;
      env_z_[static_cast<std::size_t>(k + 1)] = kFar;
    }
    k = 0;
    const auto cap = static_cast<float>(cap_cells_);
    for (std::int32_t q = out.x0 - ix0; q < out.x1 - ix0; ++q) {
      while (env_z_[static_cast<std::size_t>(k + 1)] < static_cast<float>(q)) ++k;
      const std::int32_t v = env_v_[static_cast<std::size_t>(k)];
      const float d2 = static_cast<float>((q - v) * (q - v)) + f(v);
      const std::size_t i = idx(q + ix0, y);
      const float d = closed_[i] == 0 ? 0.0F : std::min(cap, std::sqrt(d2));
      edt_[i] = d;
      free_[i] = (closed_[i] != 0 && d >= free_min_edt_ - 1e-4F) ? 1 : 0;
    }
  }
}

void Roadmap::recompute_fields(Rect changed) noexcept {
  const Rect q = clamp(changed.grown(2 * close_r_));
  recompute_closed(q);
  recompute_clearance(q.grown(cap_cells_ + 1));
}

// ------------------------------------------------------------------------------------------ lines

bool Roadmap::walk(double x0, double y0, double x1, double y1, float* min_clear, std::uint32_t* costly) const noexcept {
  std::int32_t c = static_cast<std::int32_t>(std::floor(x0)), r = static_cast<std::int32_t>(std::floor(y0));
  const std::int32_t ce = static_cast<std::int32_t>(std::floor(x1)), re = static_cast<std::int32_t>(std::floor(y1));
  const double dx = x1 - x0, dy = y1 - y0;
  const std::int32_t sx = dx > 0 ? 1 : -1, sy = dy > 0 ? 1 : -1;
  const double adx = std::fabs(dx), ady = std::fabs(dy);
  constexpr double kInf = std::numeric_limits<double>::infinity();
  double tmx = adx > 0 ? (sx > 0 ? (c + 1 - x0) : (x0 - c)) / adx : kInf;
  double tmy = ady > 0 ? (sy > 0 ? (r + 1 - y0) : (y0 - r)) / ady : kInf;
  const double tdx = adx > 0 ? 1.0 / adx : kInf, tdy = ady > 0 ? 1.0 / ady : kInf;
  float mc = kFar;
  std::uint32_t nc = 0;
  auto check = [&](std::int32_t cc, std::int32_t rr) {
    if (!inside(cc, rr)) return false;
    const std::size_t i = idx(cc, rr);
    if (free_[i] == 0) return false;
    mc = std::min(mc, edt_[i]);
    nc += level_[cls_[i]] == 2 ? 1U : 0U;
    return true;
  };
  if (!check(c, r)) return false;
  std::int32_t guard = std::abs(ce - c) + std::abs(re - r) + 2;
  while ((c != ce || r != re) && guard-- > 0) {
    const bool can_x = c != ce, can_y = r != re;
    if (can_x && can_y && std::fabs(tmx - tmy) < 1e-9) {
      if (!check(c + sx, r) || !check(c, r + sy)) return false;
      c += sx;
      r += sy;
      tmx += tdx;
      tmy += tdy;
    } else if (can_x && (!can_y || tmx < tmy)) {
      c += sx;
      tmx += tdx;
    } else {
      r += sy;
      tmy += tdy;
    }
    if (!check(c, r)) return false;
  }
  if (min_clear != nullptr) *min_clear = mc;
  if (costly != nullptr) *costly = nc;
  return true;
}

bool Roadmap::line_free(Point2 a, Point2 b, double* min_clearance_m) const noexcept {
  const double res = p_.resolution_m;
  float mc = 0;
  const bool ok = walk((a.x - ox_) / res, (a.y - oy_) / res, (b.x - ox_) / res, (b.y - oy_) / res, &mc, nullptr);
  if (ok && min_clearance_m != nullptr) *min_clearance_m = (static_cast<double>(mc) - 0.5) * res;
  return ok;
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

// ------------------------------------------------------------------------------------------ queries

bool Roadmap::snap(Point2 p, double radius_m, std::int32_t& c, std::int32_t& r) const noexcept {
  const double res = p_.resolution_m;
  const auto pc = static_cast<std::int32_t>(std::floor((p.x - ox_) / res)), pr = static_cast<std::int32_t>(std::floor((p.y - oy_) / res));
  if (free_cell(pc, pr)) {
    c = pc;
    r = pr;
    return true;
  }
  const auto rad = static_cast<std::int32_t>(std::ceil(radius_m / res));
  double best = 1e30;
  bool found = false;
  for (std::int32_t dy = -rad; dy <= rad; ++dy)
    for (std::int32_t dx = -rad; dx <= rad; ++dx) {
      const double d2 = dx * dx + dy * dy;
      if (d2 > sq(rad) || d2 >= best || !free_cell(pc + dx, pr + dy)) continue;
      best = d2;
      c = pc + dx;
      r = pr + dy;
      found = true;
    }
  return found;
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
  if (!snap(start, snap_radius_m, sc, sr)) {
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
  auto finish = [&]() {
    out.length_m = 0;
    for (std::uint32_t i = 1; i < out.count; ++i)
      out.length_m += std::hypot(out.points[i].x - out.points[i - 1].x, out.points[i].y - out.points[i - 1].y);
    out.status = PlanStatus::kOk;
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
    finish();
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
  std::size_t heap_n = 0;
  auto heap_push = [&](std::uint32_t n, float key) {
    if (heap_n >= heap_.size()) return;
    std::size_t i = heap_n++;
    while (i > 0) {
      const std::size_t pi = (i - 1) / 2;
      if (heap_key_[pi] <= key) break;
      heap_[i] = heap_[pi];
      heap_key_[i] = heap_key_[pi];
      i = pi;
    }
    heap_[i] = n;
    heap_key_[i] = key;
  };
  auto heap_pop = [&](std::uint32_t& n, float& key) {
    n = heap_[0];
    key = heap_key_[0];
    const std::uint32_t ln = heap_[--heap_n];
    const float lk = heap_key_[heap_n];
    std::size_t i = 0;
    for (;;) {
      std::size_t ch = 2 * i + 1;
      if (ch >= heap_n) break;
      if (ch + 1 < heap_n && heap_key_[ch + 1] < heap_key_[ch]) ++ch;
      if (heap_key_[ch] >= lk) break;
      heap_[i] = heap_[ch];
      heap_key_[i] = heap_key_[ch];
      i = ch;
    }
    heap_[i] = ln;
    heap_key_[i] = lk;
  };
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
    heap_push(n, static_cast<float>(c) + h(n));
  }
  // Goal candidates: the nodes whose visibility covers the goal's cell (tested as they are expanded).
  const auto gcell_c = static_cast<std::int32_t>(std::floor(gx)), gcell_r = static_cast<std::int32_t>(std::floor(gy));
  bool reached = false;
  while (heap_n > 0) {
    std::uint32_t u = 0;
    float key = 0;
    heap_pop(u, key);
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
        heap_push(v_goal, ng2);
      }
    }
    for (std::uint16_t e = 0; e < nu.n_edges; ++e) {
      const Edge& ed = nu.edges[e];
      const float nv = g_[u] + ed.cost;
      if (seen(ed.to) && nv >= g_[ed.to]) continue;
      set_g(ed.to, nv, u);
      heap_push(ed.to, nv + h(ed.to));
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
  double mcl = 1e30;
  const std::uint32_t a0 = s_snapped ? 1U : 0U, a1 = out.count - 1U - (g_snapped ? 1U : 0U);
  for (std::uint32_t i = a0; i < a1; ++i) {
    double c = 0;
    if (line_free(out.points[i], out.points[i + 1], &c)) mcl = std::min(mcl, c);
  }
  out.min_clearance_m = mcl < 1e29 ? mcl : 0.0;
  finish();
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
