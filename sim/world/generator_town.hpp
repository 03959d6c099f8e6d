// The procedural world generator's layout in progress (private to sim/world/generator*.cpp): its parts
// in metres, the drawing primitives that rasterise them and the town that lays them out step by step.
#pragma once

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

#include "airground/messages/geometry.hpp"
#include "airground/platform/rng.hpp"
#include "airground/sim/generator.hpp"

namespace ag::sim::generator {

using P2 = cv::Point2d;

constexpr double kCurbWidth = 0.5;   // [m] raised strip along each road edge
constexpr float kCurbHeight = 0.15F;  // [m]
constexpr double kCarLength = 4.5, kCarWidth = 1.8;  // [m]
constexpr float kCarHeight = 1.5F;    // [m]
constexpr double kBayWidth = 2.5, kBayDepth = 5.0, kAisle = 6.0, kLotEntrance = 3.5;  // parking lot layout [m]
constexpr double kStagingPad = 24.0;  // [m] side of the staging pad
// [m] minimum distance between cars of different target clusters: 20 m, down to 15 m in small worlds
// so that a dozen clusters still fit in 200 m (within a cluster neighbouring cars are at most 11.3 m apart).
constexpr double kClusterSpacing = 20.0, kClusterSpacingSmall = 15.0;
constexpr double kStagingClearance = 25.0;  // [m] from the staging pose to any target car
constexpr int kShift = 4;             // OpenCV drawing: coordinates in 1/16 cell
constexpr float kMinBuilding = 5.0F, kMaxBuilding = 30.0F;

// Sub-streams of the seed, one per part of the layout, so changing how one part draws does not move the others.
enum Stream : std::uint64_t { kTerrain = 1, kRoads, kWater, kTargets, kTracks, kBlocks, kStreetTrees, kPaint, kMarkings };

struct Road {
  std::vector<P2> centre;  // [m] map frame
  double width{7};         // [m] kerb to kerb
  bool yellow_centre{false};
};

// An oriented rectangle in the map frame: centre, half extents along and across `yaw`.
struct Box {
  P2 c;
  double half_len{0}, half_wid{0}, yaw{0};

  [[nodiscard]] P2 to_local(double x, double y) const noexcept {
    const double dx = x - c.x, dy = y - c.y, cs = std::cos(yaw), sn = std::sin(yaw);
    return {dx * cs + dy * sn, -dx * sn + dy * cs};
  }
  [[nodiscard]] bool contains(double x, double y, double margin = 0.0) const noexcept {
    const P2 l = to_local(x, y);
    return std::fabs(l.x) <= half_len + margin && std::fabs(l.y) <= half_wid + margin;
  }
  [[nodiscard]] double reach(double margin) const noexcept { return std::hypot(half_len, half_wid) + margin; }
};

enum class Roof { kFlat, kGable };

struct BuildingPart {
  Box box;
  Roof roof{Roof::kFlat};
  double eave{6}, rise{0};  // [m] wall height, extra height of the ridge above the eaves
  float base{0};            // [m] terrain the building stands on (set when placed)
};

// A straight road side that a block faces: the kerb line from a to b, `inward` pointing into the block.
struct Frontage {
  P2 a, b;
  P2 inward;
};

enum class Land { kUrban, kPark, kWood, kField };

struct Block {
  double x0{0}, x1{0}, y0{0}, y1{0};  // [m] kerb to kerb
  Land land{Land::kField};
  std::vector<Frontage> sides;
  [[nodiscard]] double w() const noexcept { return x1 - x0; }
  [[nodiscard]] double h() const noexcept { return y1 - y0; }
  [[nodiscard]] P2 centre() const noexcept { return {(x0 + x1) / 2, (y0 + y1) / 2}; }
};

double length_of(const std::vector<P2>& pts);
// Point and unit tangent at arc length s along a polyline.
std::pair<P2, P2> along(const std::vector<P2>& pts, double s);
std::vector<P2> offset_polyline(const std::vector<P2>& pts, double offset);
std::vector<P2> bezier(P2 p0, P2 p1, P2 p2, P2 p3, double step);

// The world under construction with the drawing primitives that work in metres.
class ProceduralTown {
 public:
  ProceduralTown(const GeneratorOptions& opt, std::uint64_t layout_seed, World& w)
      : opt_(opt), seed_(layout_seed), w_(w), g_(w.header.grid), half_(g_.size_x() / 2) {}

  Status build(std::vector<TargetCluster>& targets);

 private:
  // ---- coordinates ----
  [[nodiscard]] cv::Point fixed(P2 p) const {
    return {static_cast<int>(std::lround((g_.col_f(p.x) - 0.5) * (1 << kShift))),
            static_cast<int>(std::lround((g_.row_f(p.y) - 0.5) * (1 << kShift)))};
  }
  [[nodiscard]] int cells(double metres) const { return std::max(1, static_cast<int>(std::lround(metres / g_.resolution))); }
  [[nodiscard]] bool inside(P2 p, double margin = 0) const {
    return std::fabs(p.x) <= half_ - margin && std::fabs(p.y) <= half_ - margin;
  }
  // Calls f(col, row, x, y) for each cell whose centre lies in [x0, x1] x [y0, y1] [m].
  template <typename F>
  void for_cells(double x0, double y0, double x1, double y1, F&& f) const {
    const int c0 = std::max(0, static_cast<int>(std::ceil((x0 - g_.origin_x) / g_.resolution - 0.5)));
    const int c1 = std::min(g_.width - 1, static_cast<int>(std::floor((x1 - g_.origin_x) / g_.resolution - 0.5)));
    const int r0 = std::max(0, static_cast<int>(std::ceil((g_.origin_y - y1) / g_.resolution - 0.5)));
    const int r1 = std::min(g_.height - 1, static_cast<int>(std::floor((g_.origin_y - y0) / g_.resolution - 0.5)));
    for (int r = r0; r <= r1; ++r) {
      const double y = g_.y_of(r);
      for (int c = c0; c <= c1; ++c) f(c, r, g_.x_of(c), y);
    }
  }
  void draw_polyline(cv::Mat& m, const std::vector<P2>& pts, double width_m, int value, int line_type = cv::LINE_8) const {
    std::vector<cv::Point> px;
    px.reserve(pts.size());
    for (const P2& p : pts) px.push_back(fixed(p));
    cv::polylines(m, px, false, cv::Scalar(value), cells(width_m), line_type, kShift);
  }
  void fill_box(cv::Mat& m, const Box& b, int value, int line_type = cv::LINE_8) const {
    const double cs = std::cos(b.yaw), sn = std::sin(b.yaw);
    const P2 u(cs * b.half_len, sn * b.half_len), v(-sn * b.half_wid, cs * b.half_wid);
    const std::array<cv::Point, 4> poly{fixed(b.c + u + v), fixed(b.c - u + v), fixed(b.c - u - v), fixed(b.c + u - v)};
    cv::fillConvexPoly(m, poly.data(), 4, cv::Scalar(value), line_type, kShift);
  }
  // A thick polyline drawn into a mask covering only its own bounding box (in cells).
  std::pair<cv::Rect, cv::Mat> polyline_mask(const std::vector<P2>& pts, double width_m) const {
    double x0 = 1e18, y0 = 1e18, x1 = -1e18, y1 = -1e18;
    for (const P2& p : pts) x0 = std::min(x0, p.x), x1 = std::max(x1, p.x), y0 = std::min(y0, p.y), y1 = std::max(y1, p.y);
    const double m = width_m + g_.resolution;
    const int c0 = std::clamp(g_.col(x0 - m), 0, g_.width - 1), c1 = std::clamp(g_.col(x1 + m), 0, g_.width - 1);
    const int r0 = std::clamp(g_.row(y1 + m), 0, g_.height - 1), r1 = std::clamp(g_.row(y0 - m), 0, g_.height - 1);
    const cv::Rect roi(c0, r0, c1 - c0 + 1, r1 - r0 + 1);
    cv::Mat own(roi.size(), CV_8UC1, cv::Scalar(0));
    std::vector<cv::Point> px;
    px.reserve(pts.size());
    for (const P2& p : pts) px.push_back(fixed(p) - cv::Point(c0 << kShift, r0 << kShift));
    cv::polylines(own, px, false, cv::Scalar(255), cells(width_m), cv::LINE_8, kShift);
    return {roi, own};
  }
  [[nodiscard]] std::uint8_t cls(int c, int r) const { return w_.class_id.at<std::uint8_t>(r, c); }
  void set(int c, int r, ClassId k, float h) {
    w_.class_id.at<std::uint8_t>(r, c) = raw(k);
    w_.height.at<float>(r, c) = h;
  }
  // True when every cell within `margin` of the box is grass (nothing placed there yet).
  [[nodiscard]] bool box_free(const Box& b, double margin) const {
    bool free = inside(b.c, 2.0);
    const double reach = b.reach(margin);
    if (free) {
      for_cells(b.c.x - reach, b.c.y - reach, b.c.x + reach, b.c.y + reach, [&](int c, int r, double x, double y) {
        if (free && b.contains(x, y, margin) && cls(c, r) != raw(ClassId::kGrass)) free = false;
      });
    }
    return free;
  }

  // ---- layout steps ----
  void make_terrain();
  void plan_roads();
  void make_blocks();
  void make_water();
  void draw_roads();
  void make_staging();
  Status make_targets(std::vector<TargetCluster>& targets);
  bool try_lot_cluster(Rng& rng, int max_cars, TargetCluster& out);
  bool try_roadside_cluster(Rng& rng, int max_cars, TargetCluster& out);
  [[nodiscard]] bool cars_clear_of_others(const std::vector<Pose2>& cars) const;
  void draw_car(const Pose2& p);
  void make_tracks();
  void track_from(Rng& rng, P2 start, double heading, double max_len, double width);
  void fill_blocks();
  void urban_block(Rng& rng, const Block& b);
  void park_block(Rng& rng, const Block& b);
  void wood_block(Rng& rng, const Block& b);
  void field_block(Rng& rng, const Block& b);
  bool place_building(Rng& rng, const std::vector<BuildingPart>& parts);
  bool place_tree(P2 c, double radius, double top, bool among_trees);
  void place_hedge(const std::vector<P2>& line, double width, double h);
  void street_trees();
  void finish_heights();
  void paint();

  const GeneratorOptions& opt_;
  std::uint64_t seed_;
  World& w_;
  const GridGeometry& g_;
  double half_;  // [m] half the world side

  std::vector<Road> roads_;
  std::vector<double> ns_x_, ns_w_;  // north-south roads: centre x, width
  std::vector<double> ew_y_, ew_w_;  // east-west roads: centre y, width
  std::vector<std::vector<bool>> ew_segment_;  // [ew road][gap k]: present between ns road k-1 and k
  std::vector<Block> blocks_;
  cv::Mat junction_dist_;  // [m] distance to where two roads overlap
  std::vector<Box> lots_;
  std::vector<Box> bays_;  // painted bay outlines
  std::vector<Pose2> cars_;
  std::vector<BuildingPart> gables_;
  Box staging_;
  std::vector<std::size_t> pond_blocks_;
};

}  // namespace ag::sim::generator
