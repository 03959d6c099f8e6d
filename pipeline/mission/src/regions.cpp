// Regions of interest: opening, grouping by the merge distance, minimum size, stable ids, goals.
#include "airground/mission/regions.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace ag::mission {

namespace {
constexpr double kBig = 1e20;
}

RegionExtractor::RegionExtractor(const RegionParams& p, const ClassTable& classes, const TileExtent& extent)
    : p_(p), extent_(extent) {
  fw_ = w_ = extent.tiles_x * p.tile_cells;
  fh_ = h_ = extent.tiles_y * p.tile_cells;
  fox_ = ox_ = extent.tile_x0 * p.tile_cells * p.resolution_m;
  foy_ = oy_ = extent.tile_y0 * p.tile_cells * p.resolution_m;
  known_ = Box{0, 0, 0, 0};
  const std::size_t n = static_cast<std::size_t>(w_) * static_cast<std::size_t>(h_);
  store_cls_.assign(n, 255);
  store_prev_.assign(n, kNoRegionId);
  trav_lut_.assign(256, 0);
  for (int id = 0; id < 256; ++id)
    if (classes.valid_id(static_cast<std::uint8_t>(id)) &&
        classes.info(static_cast<ClassId>(id)).traversability <= p.max_level && id != p.vehicle_class)
      trav_lut_[static_cast<std::size_t>(id)] = 1;
  cls_.assign(n, 255);
  veh_.assign(n, 0);
  tmp_.assign(n, 0);
  reach_.assign(n, 0);
  dist_.assign(n, 0.0f);
  labels_.assign(n, -1);
  queue_.assign(n, 0);
  prev_id_.assign(n, kNoRegionId);
  tile_version_.assign(static_cast<std::size_t>(extent.tiles_x) * static_cast<std::size_t>(extent.tiles_y), 0);
  const std::size_t line = static_cast<std::size_t>(std::max(w_, h_)) + 1;
  envelope_.resize(line);
  const std::size_t cap = static_cast<std::size_t>(std::max(1, p.max_regions));
  groups_.assign(cap, Group{});
  order_.assign(cap, 0);
  regions_.assign(cap, Region{});
  prev_regions_.assign(cap, Region{});
  id_taken_scratch_.assign(cap, 0);
}

bool RegionExtractor::set_tile(std::int32_t tx, std::int32_t ty, std::uint64_t version, std::span<const std::uint8_t> cls) noexcept {
  const int tc = p_.tile_cells;
  if (cls.size() != static_cast<std::size_t>(tc) * static_cast<std::size_t>(tc) || tx < extent_.tile_x0 || ty < extent_.tile_y0 ||
      tx >= extent_.tile_x0 + extent_.tiles_x || ty >= extent_.tile_y0 + extent_.tiles_y) {
    ++stats_.tiles_rejected;
    return false;
  }
  const std::size_t ti = static_cast<std::size_t>(ty - extent_.tile_y0) * static_cast<std::size_t>(extent_.tiles_x) +
                         static_cast<std::size_t>(tx - extent_.tile_x0);
  if (version != 0 && version <= tile_version_[ti]) {
    ++stats_.tiles_rejected;
    return false;
  }
  tile_version_[ti] = version;
  const std::int32_t c0 = (tx - extent_.tile_x0) * tc, r0 = (ty - extent_.tile_y0) * tc;
  for (int r = 0; r < tc; ++r)
    std::copy_n(cls.data() + static_cast<std::size_t>(r) * static_cast<std::size_t>(tc), tc,
                store_cls_.data() + static_cast<std::size_t>(r0 + r) * static_cast<std::size_t>(fw_) + static_cast<std::size_t>(c0));
  const std::int32_t rx = tx - extent_.tile_x0, ry = ty - extent_.tile_y0;
  if (known_.tx1 <= known_.tx0) {
    known_ = Box{rx, ry, rx + 1, ry + 1};
  } else {
    known_.tx0 = std::min(known_.tx0, rx);
    known_.ty0 = std::min(known_.ty0, ry);
    known_.tx1 = std::max(known_.tx1, rx + 1);
    known_.ty1 = std::max(known_.ty1, ry + 1);
  }
  ++stats_.tiles_applied;
  changed_ = true;
  return true;
}

bool RegionExtractor::cell_of(double x, double y, std::int32_t& c, std::int32_t& r) const noexcept {
  if (!std::isfinite(x) || !std::isfinite(y)) return false;
  const double fc = std::floor((x - ox_) / p_.resolution_m), fr = std::floor((y - oy_) / p_.resolution_m);
  if (fc < 0 || fr < 0 || fc >= w_ || fr >= h_) return false;
  c = static_cast<std::int32_t>(fc);
  r = static_cast<std::int32_t>(fr);
  return true;
}

double RegionExtractor::clearance_at(double x, double y) const noexcept {
  std::int32_t c = 0, r = 0;
  if (!cell_of(x, y, c, r)) return 0.0;
  const std::size_t i = idx(c, r);
  if (!trav_lut_[cls_[i]]) return 0.0;
  const double border = (std::min({c, r, w_ - 1 - c, h_ - 1 - r}) + 0.5) * p_.resolution_m;
  return std::min(border, std::sqrt(static_cast<double>(dist_[i])) * p_.resolution_m - 0.5 * p_.resolution_m);
}

bool RegionExtractor::reachable_at(double x, double y) const noexcept {
  std::int32_t c = 0, r = 0;
  return cell_of(x, y, c, r) && reach_[idx(c, r)] == 2;
}

std::size_t RegionExtractor::memory_bytes() const noexcept {
  const std::size_t n = cls_.size();
  return n * (5 * sizeof(std::uint8_t) + sizeof(std::uint32_t) + sizeof(float) + 2 * sizeof(std::int32_t) + sizeof(std::uint32_t)) +
         groups_.size() * (sizeof(Group) + 2 * sizeof(Region) + sizeof(std::uint32_t) + 1);
}

// Opening with a (2k+1)^2 square: erosion then dilation, each as a row pass and a column pass.
void RegionExtractor::open_vehicle_mask() noexcept {
  const std::size_t n = static_cast<std::size_t>(w_) * static_cast<std::size_t>(h_);
  const std::uint8_t vc = p_.vehicle_class;
  for (std::size_t i = 0; i < n; ++i) veh_[i] = cls_[i] == vc ? 1 : 0;
  const int k = p_.open_radius_cells;
  if (k <= 0) return;
  const std::size_t w = static_cast<std::size_t>(w_);
  // along rows: dst[c] = AND / OR of src[c-k .. c+k] (outside the grid: not a vehicle)
  auto rows = [&](const std::uint8_t* src, std::uint8_t* dst, bool erode) {
    for (std::int32_t r = 0; r < h_; ++r) {
      const std::uint8_t* s = src + static_cast<std::size_t>(r) * w;
      std::uint8_t* d = dst + static_cast<std::size_t>(r) * w;
      for (std::int32_t c = 0; c < w_; ++c) {
        std::uint8_t v = erode ? 1 : 0;
        for (std::int32_t o = c - k; o <= c + k; ++o) {
          const std::uint8_t x = (o < 0 || o >= w_) ? 0 : s[o];
          v = erode ? static_cast<std::uint8_t>(v & x) : static_cast<std::uint8_t>(v | x);
        }
        d[c] = v;
      }
    }
  };
  // along columns, row by row: dst[r] = AND / OR of src[r-k .. r+k]
  auto cols = [&](const std::uint8_t* src, std::uint8_t* dst, bool erode) {
    for (std::int32_t r = 0; r < h_; ++r) {
      std::uint8_t* d = dst + static_cast<std::size_t>(r) * w;
      const bool clipped = r - k < 0 || r + k >= h_;
      if (erode && clipped) {
        std::fill(d, d + w, std::uint8_t{0});
        continue;
      }
      std::fill(d, d + w, static_cast<std::uint8_t>(erode ? 1 : 0));
      for (std::int32_t o = std::max(0, r - k); o <= std::min(h_ - 1, r + k); ++o) {
        const std::uint8_t* s = src + static_cast<std::size_t>(o) * w;
        if (erode)
          for (std::size_t c = 0; c < w; ++c) d[c] = static_cast<std::uint8_t>(d[c] & s[c]);
        else
          for (std::size_t c = 0; c < w; ++c) d[c] = static_cast<std::uint8_t>(d[c] | s[c]);
      }
    }
  };
  rows(veh_.data(), tmp_.data(), true);
  cols(tmp_.data(), veh_.data(), true);
  rows(veh_.data(), tmp_.data(), false);
  cols(tmp_.data(), veh_.data(), false);
}

// Exact squared Euclidean distance transform (Felzenszwalb & Huttenlocher), in cells: the column pass
// here, the row pass platform/distance_transform.hpp's.
void RegionExtractor::squared_distance(const std::uint8_t* feature) noexcept {
  // phase 1 (Meijster): the distance to the nearest feature in the same column, by a sweep north and a
  // sweep south over whole rows (contiguous, no strided access)
  float* g = dist_.data();
  const std::size_t w = static_cast<std::size_t>(w_);
  const float inf = 1e15f;
  for (std::size_t c = 0; c < w; ++c) g[c] = feature[c] ? 0.0f : inf;
  for (std::int32_t r = 1; r < h_; ++r) {
    float* row = g + static_cast<std::size_t>(r) * w;
    const float* prev = row - w;
    const std::uint8_t* f = feature + static_cast<std::size_t>(r) * w;
    for (std::size_t c = 0; c < w; ++c) row[c] = f[c] ? 0.0f : prev[c] + 1.0f;
  }
  for (std::int32_t r = h_ - 2; r >= 0; --r) {
    float* row = g + static_cast<std::size_t>(r) * w;
    const float* next = row + w;
    for (std::size_t c = 0; c < w; ++c) row[c] = std::min(row[c], next[c] + 1.0f);
  }
  const std::size_t n = static_cast<std::size_t>(w_) * static_cast<std::size_t>(h_);
  for (std::size_t i = 0; i < n; ++i) g[i] = g[i] >= 1e14f ? static_cast<float>(kBig) : g[i] * g[i];
  // rows
  for (std::int32_t r = 0; r < h_; ++r) {
    const float* row = g + static_cast<std::size_t>(r) * w;
    bool any = false;
    for (std::size_t c = 0; c < w; ++c) any = any || row[c] < 1e19f;
    if (!any) continue;  // no feature anywhere in this row's columns: stays kBig
    // Every cell is a parabola (kBig where its column has no feature); the row is read before it is written.
    dt::squared_distance_line(
        w_, [](std::int32_t) { return true; }, [&](std::int32_t c) { return static_cast<double>(row[c]); }, 0, w_, envelope_,
        [&](std::int32_t c, double d2) { dist_[idx(c, r)] = static_cast<float>(std::min(d2, 1e30)); });
  }
}

// reach_: 0 blocked, 1 traversable but in a small (enclosed) component, 2 reachable.
void RegionExtractor::reachable_components() noexcept {
  const std::size_t n = static_cast<std::size_t>(w_) * static_cast<std::size_t>(h_);
  for (std::size_t i = 0; i < n; ++i) reach_[i] = 0;
  std::size_t qend = 0, best_b = 0, best_e = 0;
  std::int32_t* q = queue_.data();
  for (std::int32_t r0 = 0; r0 < h_; ++r0)
    for (std::int32_t c0 = 0; c0 < w_; ++c0) {
      const std::size_t s = idx(c0, r0);
      if (reach_[s] != 0 || !trav_lut_[cls_[s]]) continue;
      const std::size_t b = qend;
      q[qend++] = static_cast<std::int32_t>(s);
      reach_[s] = 1;
      for (std::size_t h = b; h < qend; ++h) {
        const std::int32_t i = q[h];
        const std::int32_t c = i % w_, r = i / w_;
        const std::int32_t nb[4][2] = {{c - 1, r}, {c + 1, r}, {c, r - 1}, {c, r + 1}};
        for (const auto& x : nb) {
          if (x[0] < 0 || x[1] < 0 || x[0] >= w_ || x[1] >= h_) continue;
          const std::size_t j = idx(x[0], x[1]);
          if (reach_[j] != 0 || !trav_lut_[cls_[j]]) continue;
          reach_[j] = 1;
          q[qend++] = static_cast<std::int32_t>(j);
        }
      }
      if (qend - b > best_e - best_b) {
        best_b = b;
        best_e = qend;
      }
      if (qend - b >= static_cast<std::size_t>(std::max(1, p_.reachable_min_cells)))
        for (std::size_t h = b; h < qend; ++h) reach_[static_cast<std::size_t>(q[h])] = 2;
    }
  for (std::size_t h = best_b; h < best_e; ++h) reach_[static_cast<std::size_t>(q[h])] = 2;
}

// Groups: 4-connected components of tmp_ (the dilated vehicle mask); labels_ per cell, stats of the
// vehicle cells (veh_) per group.
std::uint32_t RegionExtractor::group_components() noexcept {
  const std::size_t n = static_cast<std::size_t>(w_) * static_cast<std::size_t>(h_);
  for (std::size_t i = 0; i < n; ++i) labels_[i] = -1;
  std::int32_t* q = queue_.data();
  std::uint32_t groups = 0;
  const std::uint32_t cap = static_cast<std::uint32_t>(groups_.size());
  for (std::int32_t r0 = 0; r0 < h_; ++r0)
    for (std::int32_t c0 = 0; c0 < w_; ++c0) {
      const std::size_t s = idx(c0, r0);
      if (labels_[s] != -1 || !tmp_[s]) continue;
      // a group beyond the capacity is labelled -2: visited, left out (counted)
      const std::int32_t lab = groups < cap ? static_cast<std::int32_t>(groups) : -2;
      Group g{};
      g.c0 = w_;
      g.r0 = h_;
      g.c1 = -1;
      g.r1 = -1;
      std::size_t qend = 0;
      q[qend++] = static_cast<std::int32_t>(s);
      labels_[s] = lab;
      for (std::size_t h = 0; h < qend; ++h) {
        const std::int32_t i = q[h];
        const std::int32_t c = i % w_, r = i / w_;
        if (veh_[static_cast<std::size_t>(i)]) {
          ++g.cells;
          g.sx += c;
          g.sy += r;
          g.c0 = std::min(g.c0, c);
          g.r0 = std::min(g.r0, r);
          g.c1 = std::max(g.c1, c);
          g.r1 = std::max(g.r1, r);
        }
        const std::int32_t nb[4][2] = {{c - 1, r}, {c + 1, r}, {c, r - 1}, {c, r + 1}};
        for (const auto& x : nb) {
          if (x[0] < 0 || x[1] < 0 || x[0] >= w_ || x[1] >= h_) continue;
          const std::size_t j = idx(x[0], x[1]);
          if (labels_[j] != -1 || !tmp_[j]) continue;
          labels_[j] = lab;
          q[qend++] = static_cast<std::int32_t>(j);
        }
      }
      if (lab >= 0) {
        groups_[static_cast<std::size_t>(lab)] = g;
        ++groups;
      } else {
        ++stats_.groups_over_capacity;
      }
    }
  return groups;
}

void RegionExtractor::find_goal(Region& reg) noexcept {
  const double res = p_.resolution_m;
  const std::int32_t rad = static_cast<std::int32_t>(std::ceil(p_.goal_search_radius_m / res));
  std::int32_t bc0 = 0, br0 = 0, bc1 = 0, br1 = 0;
  (void)cell_of(reg.x0 + 0.25 * res, reg.y0 + 0.25 * res, bc0, br0);
  (void)cell_of(reg.x1 - 0.25 * res, reg.y1 - 0.25 * res, bc1, br1);
  double best = -std::numeric_limits<double>::infinity();
  reg.goal_valid = false;
  for (std::int32_t r = std::max(0, br0 - rad); r <= std::min(h_ - 1, br1 + rad); ++r)
    for (std::int32_t c = std::max(0, bc0 - rad); c <= std::min(w_ - 1, bc1 + rad); ++c) {
      const std::size_t i = idx(c, r);
      if (reach_[i] != 2) continue;
      const double dc = c < bc0 ? bc0 - c : (c > bc1 ? c - bc1 : 0);
      const double dr = r < br0 ? br0 - r : (r > br1 ? r - br1 : 0);
      const double dist = std::sqrt(dc * dc + dr * dr) * res;
      if (dist > p_.goal_search_radius_m) continue;
      const double border = (std::min({c, r, w_ - 1 - c, h_ - 1 - r}) + 0.5) * res;
      const double clear = std::min(border, std::sqrt(static_cast<double>(dist_[i])) * res - 0.5 * res);
      if (clear < p_.min_goal_clearance_m) continue;
      const double score = std::min(clear, p_.goal_clearance_cap_m) - p_.goal_distance_weight * dist;
      if (score > best) {
        best = score;
        reg.goal_valid = true;
        reg.goal_x = ox_ + (c + 0.5) * res;
        reg.goal_y = oy_ + (r + 0.5) * res;
        reg.goal_clearance_m = clear;
      }
    }
}

std::size_t RegionExtractor::extract() noexcept {
  ++stats_.extractions;
  changed_ = false;
  const double res = p_.resolution_m;
  // 0. the working window: the tiles that hold data, copied out of the storage
  const int tc = p_.tile_cells;
  const Box win = known_.tx1 > known_.tx0 ? known_ : Box{0, 0, 1, 1};
  wc0_ = win.tx0 * tc;
  wr0_ = win.ty0 * tc;
  w_ = (win.tx1 - win.tx0) * tc;
  h_ = (win.ty1 - win.ty0) * tc;
  ox_ = fox_ + wc0_ * res;
  oy_ = foy_ + wr0_ * res;
  const std::size_t n = static_cast<std::size_t>(w_) * static_cast<std::size_t>(h_);
  for (std::int32_t r = 0; r < h_; ++r) {
    const std::size_t from = static_cast<std::size_t>(wr0_ + r) * static_cast<std::size_t>(fw_) + static_cast<std::size_t>(wc0_);
    std::copy_n(store_cls_.data() + from, w_, cls_.data() + idx(0, r));
    std::copy_n(store_prev_.data() + from, w_, prev_id_.data() + idx(0, r));
  }

  // 1. vehicle mask, opened
  open_vehicle_mask();
  bool any = false;
  for (std::size_t i = 0; i < n && !any; ++i) any = veh_[i] != 0;

  // 2. grouping: the closing's dilation by merge_distance / 2
  std::uint32_t groups = 0;
  if (any) {
    squared_distance(veh_.data());
    const double rc = 0.5 * p_.merge_distance_m / res;
    const float r2 = static_cast<float>(rc * rc + 1e-6);
    for (std::size_t i = 0; i < n; ++i) tmp_[i] = dist_[i] <= r2 ? 1 : 0;
    groups = group_components();
  } else {
    for (std::size_t i = 0; i < n; ++i) labels_[i] = -1;
  }

  // 3. minimum size
  stats_.groups_dropped_small = 0;
  std::uint32_t kept = 0;
  for (std::uint32_t g = 0; g < groups; ++g) {
    Group& gr = groups_[g];
    gr.keep = gr.cells >= static_cast<std::uint32_t>(std::max(1, p_.min_region_cells));
    gr.cand_id.fill(kNoRegionId);
    gr.cand_n.fill(0);
    if (gr.keep)
      order_[kept++] = g;
    else
      ++stats_.groups_dropped_small;
  }

  // 4. stable ids: overlap with the previous extraction's groups
  for (std::size_t i = 0; i < n; ++i) {
    const std::int32_t l = labels_[i];
    const std::uint32_t pid = prev_id_[i];
    if (l < 0 || pid == kNoRegionId || !groups_[static_cast<std::size_t>(l)].keep) continue;
    Group& g = groups_[static_cast<std::size_t>(l)];
    std::size_t slot = 4;
    for (std::size_t k = 0; k < 4; ++k)
      if (g.cand_id[k] == pid || g.cand_id[k] == kNoRegionId) {
        slot = k;
        break;
      }
    if (slot == 4) continue;  // more than four old groups overlap: the four first seen compete
    g.cand_id[slot] = pid;
    ++g.cand_n[slot];
  }
  std::sort(order_.begin(), order_.begin() + kept, [&](std::uint32_t a, std::uint32_t b) {
    return groups_[a].cells != groups_[b].cells ? groups_[a].cells > groups_[b].cells : a < b;
  });
  for (std::size_t k = 0; k < n_prev_; ++k) id_taken_scratch_[k] = 0;
  for (std::uint32_t k = 0; k < kept; ++k) {
    Group& g = groups_[order_[k]];
    g.id = kNoRegionId;
    std::uint32_t best_n = 0;
    std::size_t best_prev = 0;
    for (std::size_t s = 0; s < 4; ++s) {
      if (g.cand_id[s] == kNoRegionId || g.cand_n[s] <= best_n) continue;
      for (std::size_t pi = 0; pi < n_prev_; ++pi)
        if (prev_regions_[pi].id == g.cand_id[s] && !id_taken_scratch_[pi]) {
          best_n = g.cand_n[s];
          best_prev = pi;
          g.id = g.cand_id[s];
          break;
        }
    }
    if (g.id != kNoRegionId) {
      id_taken_scratch_[best_prev] = 1;
    } else {
      g.id = next_id_++;
      if (next_id_ == kNoRegionId) next_id_ = 1;
      ++stats_.ids_issued;
    }
  }
  for (std::size_t i = 0; i < n; ++i) {
    const std::int32_t l = labels_[i];
    prev_id_[i] = (l >= 0 && groups_[static_cast<std::size_t>(l)].keep) ? groups_[static_cast<std::size_t>(l)].id : kNoRegionId;
  }
  for (std::int32_t r = 0; r < h_; ++r)
    std::copy_n(prev_id_.data() + idx(0, r), w_,
                store_prev_.data() + static_cast<std::size_t>(wr0_ + r) * static_cast<std::size_t>(fw_) + static_cast<std::size_t>(wc0_));

  // 5. goals: clearance over the traversable cells, reachable components
  if (kept > 0) {
    for (std::size_t i = 0; i < n; ++i) tmp_[i] = trav_lut_[cls_[i]] ? 0 : 1;
    squared_distance(tmp_.data());
    reachable_components();
  }
  stats_.goals_missing = 0;
  std::size_t out = 0;
  for (std::uint32_t k = 0; k < kept; ++k) {
    const Group& g = groups_[order_[k]];
    Region& r = regions_[out++];
    r = Region{};
    r.id = g.id;
    r.cells = g.cells;
    r.cx = ox_ + (g.sx / g.cells + 0.5) * res;
    r.cy = oy_ + (g.sy / g.cells + 0.5) * res;
    r.x0 = ox_ + g.c0 * res;
    r.y0 = oy_ + g.r0 * res;
    r.x1 = ox_ + (g.c1 + 1) * res;
    r.y1 = oy_ + (g.r1 + 1) * res;
    find_goal(r);
    if (!r.goal_valid) ++stats_.goals_missing;
  }
  std::sort(regions_.begin(), regions_.begin() + static_cast<std::ptrdiff_t>(out), [](const Region& a, const Region& b) { return a.id < b.id; });

  // 6. version: grows when the set changed
  bool same = out == n_prev_;
  for (std::size_t k = 0; same && k < out; ++k) {
    const Region& a = regions_[k];
    const Region& b = prev_regions_[k];
    same = a.id == b.id && a.cells == b.cells && a.goal_valid == b.goal_valid && a.goal_x == b.goal_x && a.goal_y == b.goal_y;
  }
  if (!same || stats_.extractions == 1) ++version_;
  for (std::size_t k = 0; k < out; ++k) prev_regions_[k] = regions_[k];
  n_prev_ = out;
  n_regions_ = out;
  return out;
}

}  // namespace ag::mission
