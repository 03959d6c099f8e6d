// The global semantic planner's roadmap over the aerial class map (ALGORITHMS.md §3): traversable cells
// from the class table, small unknown holes closed, a truncated Euclidean clearance field, nodes placed
// at the largest clearance no node sees yet (visibility: a free straight line within R), edges between
// nodes whose visible regions overlap and that see each other, bridging nodes where they overlap but
// do not, edge weights lambda * length + a clearance penalty that FALLS with clearance (their code's
// sign, not the paper's typesetting). A changed map tile rebuilds only the region it can influence.
//
// Cells: width x height, row-major, row 0 at the SOUTH edge, cell (0, 0) at tile (tile_x0, tile_y0)'s
// south-west corner (the ortho-map's tile order, messages.hpp). A cell is "free" when it is traversable
// (after hole filling) and its clearance (distance from its centre to the nearest blocked cell's edge,
// cells outside the extent being blocked) is at least min_clearance_m. Cells whose centre lies outside the
// geofence (RoadmapParams::fence, the mission area less a margin) are blocked like an obstacle, so a route
// also keeps min_clearance_m inside the fence. Every line the planner returns crosses only free cells
// (conservative grid traversal: a line through a cell corner tests both cells).
//
// Memory is allocated in the constructor (nodes up to max_nodes); set_tile(), update(), rebuild() and
// plan() never allocate.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "airground/messages/classes.hpp"
#include "airground/messages/geometry.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/param_binding.hpp"
#include "airground/platform/distance_transform.hpp"

namespace ag::plan {

struct RoadmapParams {
  double resolution_m{0.5};         // [m] cell of the aerial map
  int tile_cells{64};               // [cells] tile edge of the aerial map
  Traversability max_level{Traversability::kRough};  // classes up to this level are traversable (road, dirt)
  double costly_factor{4.0};        // cost multiplier on cells of level kCostly when max_level allows them (grass)
  int hole_fill_radius_cells{1};    // morphological close radius for holes; 0 = off
  bool hole_fill_any_class{false};  // false: only unknown cells are filled (a seen obstacle stays one)
  double min_clearance_m{0.6};      // [m] half the robot's width plus a margin
  double clearance_cap_m{10.0};     // [m] the clearance field is truncated here
  double visibility_radius_m{10.0}; // [m] R (their later code: 10 m)
  double lambda{1.0};               // weight of length [1/m]
  double clearance_gain_m{0.5};     // penalty per metre = gain / (d + 0.01 m), capped at clearance_penalty_cap
  double clearance_penalty_cap{100.0};
  double shortcut_clearance_m{1.5}; // [m] a shortcut keeps min(this, what the replaced stretch kept)
  int max_nodes{16384};
  // A start with no free cell within the snap radius joins the nearest free cell within this [m] straight
  // across ground the planner only avoids (a costly class: grass), never across an obstacle, a blocked disc,
  // an unknown cell or the fence (0 = off). The planner's own stall marks widen the way round onto grass
  // (StallParams::widen_radius_m, 6 m), and once they expire or are lifted a robot still out there had no
  // route back: on gen6 one stood 2.5 m out on the grass by a parking lot, "no free cell near the start".
  double start_escape_m{6.0};
  MapRect fence{};  // cells centred outside it are blocked (the planner stage: its area_* less geofence_margin_m)
};

// The roadmap's parameters (section "planner"); resolution, tile size and the fence come from the stage.
inline constexpr ParamField<RoadmapParams> kRoadmapFields[] = {
    field::choice<&RoadmapParams::max_level>(
        "traversable", "free|rough|costly", {Traversability::kFree, Traversability::kRough, Traversability::kCostly},
        "highest traversability level planned through (classes.yaml: free = road, rough = +dirt, costly = +grass)"),
    field::real("costly_factor", &RoadmapParams::costly_factor, 1.0, 100.0, "", "cost multiplier on cells of a costly class (grass) when allowed"),
    field::integer("hole_fill_radius_cells", &RoadmapParams::hole_fill_radius_cells, 0, 5, "cells", "morphological close of the traversable mask; 0 = off"),
    field::boolean("hole_fill_any_class", &RoadmapParams::hole_fill_any_class, "close holes of any class (false: only unknown cells)"),
    field::real("min_clearance_m", &RoadmapParams::min_clearance_m, 0.0, 5.0, "m", "half the robot's width plus a margin: no path comes closer to an obstacle"),
    field::real("clearance_cap_m", &RoadmapParams::clearance_cap_m, 2.0, 30.0, "m", "the clearance field is truncated here"),
    field::real("visibility_radius_m", &RoadmapParams::visibility_radius_m, 2.0, 30.0, "m", "R: a node sees free cells on a free straight line within R"),
    field::real("lambda", &RoadmapParams::lambda, 0.01, 100.0, "1/m", "weight of an edge's length"),
    field::real("clearance_gain_m", &RoadmapParams::clearance_gain_m, 0.0, 100.0, "m", "clearance penalty per metre = gain / (d + 0.01 m): falls as clearance d grows"),
    field::real("shortcut_clearance_m", &RoadmapParams::shortcut_clearance_m, 0.0, 10.0, "m", "a shortcut keeps at least min(this, the clearance of the stretch it replaces)"),
    field::integer("max_nodes", &RoadmapParams::max_nodes, 64, 1 << 20, "nodes", "roadmap capacity (allocated at start)"),
    field::real("start_escape_m", &RoadmapParams::start_escape_m, 0.0, 20.0, "m",
                "a start off the free cells beyond the snap radius joins one within this, straight across grass (never an obstacle); 0 = off"),
};
RoadmapParams load_roadmap_params(const SectionView& s, double resolution_m, int tile_cells);


struct Point2 {
  double x{0}, y{0};  // [m] map frame
};

inline constexpr std::size_t kMaxPathPoints = 512;

// The point `dist` metres on along the polyline `pts` from `foot`, a point on the segment that ends at
// pts[next]; the polyline's last point when it is shorter (the local tracker's goal, a stall mark).
inline Point2 walk_along(std::span<const Point2> pts, std::size_t next, Point2 foot, double dist) noexcept {
  Point2 p = foot;
  for (std::size_t s = next; s < pts.size(); ++s) {
    const double l = std::hypot(pts[s].x - p.x, pts[s].y - p.y);
    if (l >= dist) {
      const double f = dist / std::max(l, 1e-9);
      return Point2{p.x + f * (pts[s].x - p.x), p.y + f * (pts[s].y - p.y)};
    }
    dist -= l;
    p = pts[s];
  }
  return p;
}

enum class PlanStatus : std::uint8_t {
  kOk = 0,
  kStartOutside = 1,   // start outside the map extent
  kGoalOutside = 2,
  kStartBlocked = 3,   // no free cell within snap_radius of the start
  kGoalBlocked = 4,
  kNoRoute = 5,        // start and goal are in different connected parts of the roadmap
  kTooLong = 6,        // more than kMaxPathPoints points
};
const char* to_string(PlanStatus s) noexcept;

// A planned route: points from start to goal, their count, cost and length.
struct PlannedPath {
  PlanStatus status{PlanStatus::kNoRoute};
  std::uint32_t count{0};
  std::array<Point2, kMaxPathPoints> points{};
  double length_m{0};
  double cost{0};
  double min_clearance_m{0};   // smallest clearance of the cells it crosses (after the snap segments)
  bool start_escaped{false};   // the start joined the free cells across grass (RoadmapParams::start_escape_m)
  std::uint32_t expanded{0};   // graph nodes the search closed
};

struct RoadmapStats {
  std::uint32_t nodes{0}, edges{0}, bridges{0};
  std::uint64_t visibility_computations{0};  // total since construction
  std::uint64_t full_builds{0}, tile_updates{0};
  std::uint64_t nodes_removed{0};            // by tile updates, total
  std::uint64_t edges_dropped_full{0};       // a node's edge list was full (counted, the edge is left out)
  std::uint64_t node_capacity_exhausted{0};  // a node could not be added (max_nodes)
};

class Roadmap {
 public:
  struct Edge {
    std::uint32_t to{0};
    float cost{0};
    float clearance_m{0};
  };
  static constexpr int kMaxEdges = 40;
  struct Node {
    std::int32_t cx{0}, cy{0};       // cell
    float clearance_m{0};
    bool alive{false};
    bool bridge{false};
    std::uint16_t n_edges{0};
    std::array<Edge, kMaxEdges> edges{};
  };

  Roadmap(const RoadmapParams& params, const ClassTable& classes, const TileExtent& extent);

  // Copies one tile (tile_cells^2 class ids, row 0 = south). False when outside the extent, of the wrong
  // size, or at the stored version. The roadmap around it is stale until update() or rebuild().
  bool set_tile(std::int32_t tx, std::int32_t ty, std::uint64_t version, std::span<const std::uint8_t> cls) noexcept;
  // Brings the roadmap up to date around up to max_tiles changed tiles (oldest first), each touching
  // only the region it can influence; returns the tiles done. With the default (all) and more than a
  // quarter of the tiles changed, one rebuild() instead.
  std::size_t update(std::size_t max_tiles = SIZE_MAX) noexcept;
  // Everything from the classes (clears the changed set).
  void rebuild() noexcept;
  [[nodiscard]] std::size_t pending_tiles() const noexcept { return n_dirty_; }
  // Blocks every cell whose centre lies within radius_m of `centre` [m, map frame] whatever its class
  // (what the robot found it cannot pass: the aerial map was wrong there), until unblock_disc() with the
  // same disc; blocks nest (a cell stays blocked while any disc covers it) and outlive set_tile(). The
  // roadmap around them is stale until update(). Returns the cells newly blocked.
  std::size_t block_disc(Point2 centre, double radius_m) noexcept;
  std::size_t unblock_disc(Point2 centre, double radius_m) noexcept;
  // Plans through costly classes (grass) on every cell whose centre lies within radius_m of `centre`,
  // whatever max_level, until unwiden_disc() with the same disc (nesting like blocks; a blocked cell stays
  // blocked): the way round a spot the robot found it cannot pass, where the map may call the real track
  // grass. The roadmap around it is stale until update(). Returns the cells newly widened.
  std::size_t widen_disc(Point2 centre, double radius_m) noexcept;
  std::size_t unwiden_disc(Point2 centre, double radius_m) noexcept;
  [[nodiscard]] bool widened_cell(std::int32_t c, std::int32_t r) const noexcept { return inside(c, r) && widen_[idx(c, r)] != 0; }
  [[nodiscard]] bool blocked_cell(std::int32_t c, std::int32_t r) const noexcept { return inside(c, r) && mark_[idx(c, r)] != 0; }
  // Plans through classes up to `level` from now on (every tile is stale until update() or rebuild()).
  // False when it already did.
  bool set_max_level(Traversability level) noexcept;
  [[nodiscard]] std::uint64_t tile_version(std::int32_t tx, std::int32_t ty) const noexcept;

  // Start to goal [m, map frame]. A start or goal on a cell that is not free snaps to the nearest free
  // cell within snap_radius_m (that first or last segment is exempt from the clearance rule).
  void plan(Point2 start, Point2 goal, PlannedPath& out, double snap_radius_m = 2.0) noexcept;

  // Grid access (cells as above).
  [[nodiscard]] std::int32_t width() const noexcept { return w_; }
  [[nodiscard]] std::int32_t height() const noexcept { return h_; }
  [[nodiscard]] double origin_x() const noexcept { return ox_; }  // [m] west edge
  [[nodiscard]] double origin_y() const noexcept { return oy_; }  // [m] south edge
  [[nodiscard]] double resolution_m() const noexcept { return p_.resolution_m; }
  [[nodiscard]] bool inside(std::int32_t c, std::int32_t r) const noexcept { return c >= 0 && r >= 0 && c < w_ && r < h_; }
  [[nodiscard]] bool in_fence(std::int32_t c, std::int32_t r) const noexcept { return c >= fence_.x0 && r >= fence_.y0 && c < fence_.x1 && r < fence_.y1; }
  [[nodiscard]] std::size_t idx(std::int32_t c, std::int32_t r) const noexcept {
    return static_cast<std::size_t>(r) * static_cast<std::size_t>(w_) + static_cast<std::size_t>(c);
  }
  [[nodiscard]] std::uint8_t class_at_cell(std::int32_t c, std::int32_t r) const noexcept { return inside(c, r) ? cls_[idx(c, r)] : 255; }
  [[nodiscard]] bool free_cell(std::int32_t c, std::int32_t r) const noexcept { return inside(c, r) && free_[idx(c, r)] != 0; }
  [[nodiscard]] bool traversable_cell(std::int32_t c, std::int32_t r) const noexcept { return inside(c, r) && closed_[idx(c, r)] != 0; }
  [[nodiscard]] double clearance_cell_m(std::int32_t c, std::int32_t r) const noexcept;
  [[nodiscard]] std::uint16_t coverage(std::int32_t c, std::int32_t r) const noexcept { return inside(c, r) ? cover_[idx(c, r)] : 0; }
  [[nodiscard]] double cell_x(double col) const noexcept { return ox_ + (col + 0.5) * p_.resolution_m; }
  [[nodiscard]] double cell_y(double row) const noexcept { return oy_ + (row + 0.5) * p_.resolution_m; }

  // Line test between two map-frame points: every crossed cell free; min clearance on it.
  [[nodiscard]] bool line_free(Point2 a, Point2 b, double* min_clearance_m = nullptr) const noexcept;

  [[nodiscard]] std::span<const Node> nodes() const noexcept { return {nodes_.data(), node_end_}; }
  [[nodiscard]] bool node_sees(std::uint32_t node, std::int32_t c, std::int32_t r) const noexcept;
  [[nodiscard]] const RoadmapStats& stats() const noexcept { return stats_; }
  [[nodiscard]] const RoadmapParams& params() const noexcept { return p_; }
  [[nodiscard]] const TileExtent& extent() const noexcept { return extent_; }
  [[nodiscard]] std::size_t memory_bytes() const noexcept;
  // Edge cost for a straight stretch of `length_m` whose smallest clearance is d and whose share of
  // costly cells is `costly_share`.
  [[nodiscard]] double edge_cost(double length_m, double d, double costly_share) const noexcept;

 private:
  struct Rect {
    std::int32_t x0{0}, y0{0}, x1{0}, y1{0};  // [x0, x1) x [y0, y1), cells
    [[nodiscard]] Rect grown(std::int32_t m) const noexcept { return {x0 - m, y0 - m, x1 + m, y1 + m}; }
  };
  [[nodiscard]] Rect clamp(Rect r) const noexcept;
  void recompute_fields(Rect changed) noexcept;           // trav, closed, clearance, free around `changed`
  void mark_tile_dirty(std::size_t t) noexcept;
  std::size_t change_disc(std::vector<std::uint8_t>& overlay, Point2 centre, double radius_m, int delta) noexcept;
  // A cell's traversable flag from its class, the fence and the overlays; whether it counts as costly.
  [[nodiscard]] std::uint8_t trav_of(std::int32_t c, std::int32_t r) const noexcept {
    const std::size_t k = idx(c, r);
    const bool by_class = level_[cls_[k]] != 0 || (widen_[k] != 0 && class_trav_[cls_[k]] == Traversability::kCostly);
    return by_class && in_fence(c, r) && mark_[k] == 0 ? 1 : 0;
  }
  [[nodiscard]] bool costly_cell(std::size_t k) const noexcept {
    return level_[cls_[k]] == 2 || (widen_[k] != 0 && class_trav_[cls_[k]] == Traversability::kCostly);
  }
  void recompute_closed(Rect out) noexcept;
  void recompute_clearance(Rect out) noexcept;
  void remove_node(std::uint32_t n) noexcept;
  std::int64_t add_node(std::int32_t c, std::int32_t r, bool bridge) noexcept;  // slot or -1
  void compute_visibility(std::uint32_t n) noexcept;      // bits + coverage
  void seed_nodes(Rect region) noexcept;                  // nodes at uncovered free cells, largest clearance first
  void connect_new_nodes() noexcept;                      // edges and bridges for new_nodes_
  bool add_edge(std::uint32_t a, std::uint32_t b, float cost, float clear) noexcept;
  [[nodiscard]] bool has_edge(std::uint32_t a, std::uint32_t b) const noexcept;
  [[nodiscard]] bool share_neighbour(std::uint32_t a, std::uint32_t b) const noexcept;
  [[nodiscard]] std::uint8_t* vis_bits(std::uint32_t n) noexcept { return vis_.data() + static_cast<std::size_t>(n) * vis_bytes_; }
  [[nodiscard]] const std::uint8_t* vis_bits(std::uint32_t n) const noexcept { return vis_.data() + static_cast<std::size_t>(n) * vis_bytes_; }
  // Line walk over cell coordinates (cell centres at +0.5): returns false at the first non-free cell.
  bool walk(double x0, double y0, double x1, double y1, float* min_clear, std::uint32_t* costly) const noexcept;
  bool snap(Point2 p, double radius_m, std::int32_t& c, std::int32_t& r) const noexcept;
  // The nearest free cell within radius_m of cell (pc, pr) that `accept(c, r)` also takes.
  template <class Accept>
  bool nearest_cell(std::int32_t pc, std::int32_t pr, double radius_m, Accept accept, std::int32_t& c, std::int32_t& r) const noexcept;
  // The nearest free cell within start_escape_m joined from p by a straight line over ground (escape_ground).
  bool escape(Point2 p, std::int32_t& c, std::int32_t& r) const noexcept;
  // A cell a robot may cross to reach the free cells: inside the fence, not in a blocked disc, of a class
  // up to costly (not an obstacle, not unknown).
  [[nodiscard]] bool escape_ground(std::int32_t c, std::int32_t r) const noexcept {
    if (!inside(c, r) || !in_fence(c, r)) return false;
    const std::size_t k = idx(c, r);
    return mark_[k] == 0 && static_cast<int>(class_trav_[cls_[k]]) <= static_cast<int>(Traversability::kCostly);
  }
  std::uint32_t visible_nodes(double x, double y, std::uint32_t* out, std::uint32_t cap) const noexcept;
  void shortcut(PlannedPath& out) noexcept;

  RoadmapParams p_;
  TileExtent extent_;
  std::int32_t w_{0}, h_{0};
  Rect fence_{};  // cells centred inside RoadmapParams::fence
  double ox_{0}, oy_{0};
  std::int32_t close_r_{0}, cap_cells_{0}, vis_r_{0}, win_{0};
  float free_min_edt_{0};  // [cells] EDT needed for a free cell
  void set_levels() noexcept;  // level_ from class_trav_ and p_.max_level
  std::array<Traversability, 256> class_trav_{};
  std::array<std::uint8_t, 256> level_{};  // class id -> 0 blocked, 1 traversable, 2 costly
  std::array<std::uint8_t, 256> fillable_{};
  std::vector<std::uint8_t> cls_, trav_, dil_, closed_, free_;
  std::vector<std::uint8_t> mark_;  // discs blocking the cell (block_disc); at most 255 over one cell
  std::vector<std::uint8_t> widen_;  // discs letting the planner through a costly class there (widen_disc)
  std::vector<float> edt_;        // [cells] distance to the nearest blocked cell centre, capped
  std::vector<std::uint16_t> cover_;
  std::vector<std::uint64_t> tile_version_;
  std::vector<std::uint8_t> tile_dirty_;
  std::vector<std::uint32_t> dirty_;
  std::size_t dirty_head_{0}, n_dirty_{0};
  // nodes
  std::vector<Node> nodes_;
  std::vector<std::uint8_t> vis_;
  std::size_t vis_bytes_{0};
  std::vector<std::uint32_t> free_slots_;
  std::size_t n_free_slots_{0};
  std::size_t node_end_{0};  // slots [0, node_end_) have been used
  std::vector<std::uint32_t> new_nodes_;
  std::size_t n_new_{0};
  std::vector<std::int16_t> disk_dx_, disk_dy_;  // window offsets within R, by distance
  // scratch
  std::vector<std::uint32_t> cand_, bucket_count_;
  std::vector<std::uint8_t> col_g_;  // column distances [cells], capped at the clearance cap + 1
  dt::EnvelopeScratch<float> envelope_;  // the clearance's row pass (platform/distance_transform.hpp)
  // search
  std::vector<float> g_;
  std::vector<std::uint32_t> parent_, stamp_, heap_;
  std::vector<float> heap_key_;
  std::uint32_t search_stamp_{0};
  std::vector<std::uint32_t> cand_nodes_;
  std::vector<std::uint64_t> pairs_;
  std::vector<double> dense_x_, dense_y_;  // shortcut scratch [cells]
  std::vector<float> dense_c_;  // node pairs that overlap without seeing each other
  RoadmapStats stats_;
};

}  // namespace ag::plan
