// The procedural world generator: lays out roads, water, parking, buildings, vegetation and target car
// clusters in metres, rasterises them into the world layers and paints the aerial colour.
#include "airground/sim/generator.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "airground/core/geometry.hpp"
#include "airground/platform/rng.hpp"
#include "airground/sim/world_texture.hpp"

namespace ag::sim {

namespace {

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

double length_of(const std::vector<P2>& pts) {
  double l = 0;
  for (std::size_t i = 1; i < pts.size(); ++i) l += std::hypot(pts[i].x - pts[i - 1].x, pts[i].y - pts[i - 1].y);
  return l;
}

// Point and unit tangent at arc length s along a polyline.
std::pair<P2, P2> along(const std::vector<P2>& pts, double s) {
  for (std::size_t i = 1; i < pts.size(); ++i) {
    const P2 d = pts[i] - pts[i - 1];
    const double l = std::hypot(d.x, d.y);
    if (s <= l || i + 1 == pts.size()) {
      const P2 t = l > 0 ? d * (1.0 / l) : P2(1, 0);
      return {pts[i - 1] + t * std::min(s, l), t};
    }
    s -= l;
  }
  return {pts.front(), P2(1, 0)};
}

std::vector<P2> offset_polyline(const std::vector<P2>& pts, double offset) {
  std::vector<P2> out;
  out.reserve(pts.size());
  for (std::size_t i = 0; i < pts.size(); ++i) {
    const P2 d = pts[std::min(i + 1, pts.size() - 1)] - pts[i == 0 ? 0 : i - 1];
    const double l = std::max(std::hypot(d.x, d.y), 1e-9);
    out.emplace_back(pts[i].x - d.y / l * offset, pts[i].y + d.x / l * offset);
  }
  return out;
}

std::vector<P2> bezier(P2 p0, P2 p1, P2 p2, P2 p3, double step) {
  const double approx = cv::norm(p1 - p0) + cv::norm(p2 - p1) + cv::norm(p3 - p2);
  const int n = std::max(8, static_cast<int>(approx / step));
  std::vector<P2> pts;
  for (int i = 0; i <= n; ++i) {
    const double t = static_cast<double>(i) / n, u = 1 - t;
    pts.push_back(p0 * (u * u * u) + p1 * (3 * u * u * t) + p2 * (3 * u * t * t) + p3 * (t * t * t));
  }
  return pts;
}

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

// ---------------------------------------------------------------------------------------------------

void ProceduralTown::make_terrain() {
  Rng rng(derive_seed(seed_, kTerrain));
  constexpr double kCoarse = 4.0;  // [m] terrain lattice, smoothed up to the grid by cubic interpolation
  const int n = static_cast<int>(std::ceil(g_.size_x() / kCoarse)) + 1;
  cv::Mat coarse = fractal_noise(cv::Size(n, n), 160.0 / kCoarse, 3, rng.next_u64());
  const double amplitude = 2.0 + g_.size_x() / 300.0;
  const double tilt_dir = rng.uniform(0, 2 * kPi), tilt = rng.uniform(0.002, 0.006);
  for (int r = 0; r < n; ++r) {
    for (int c = 0; c < n; ++c) {
      const double x = -half_ + c * kCoarse, y = half_ - r * kCoarse;
      coarse.at<float>(r, c) = static_cast<float>(amplitude * 0.5 * static_cast<double>(coarse.at<float>(r, c)) +
                                                  tilt * (x * std::cos(tilt_dir) + y * std::sin(tilt_dir)));
    }
  }
  cv::resize(coarse, w_.terrain, cv::Size(g_.width, g_.height), 0, 0, cv::INTER_CUBIC);
  // Cubic pieces leave a faint 4 m lattice in the slopes (visible in any hillshade); a 1.5 m blur removes it.
  const double sigma = 1.5 / g_.resolution;
  cv::GaussianBlur(w_.terrain, w_.terrain, cv::Size(0, 0), sigma, sigma, cv::BORDER_REPLICATE);
  // The datum is the ground at the map origin.
  const float at_origin = w_.terrain.at<float>(g_.height / 2, g_.width / 2);
  w_.terrain -= static_cast<double>(at_origin);
}

void ProceduralTown::plan_roads() {
  Rng rng(derive_seed(seed_, kRoads));
  const double s = g_.size_x();
  const auto grid_lines = [&](std::vector<double>& pos, std::vector<double>& width) {
    double p = -half_ + rng.uniform(40.0, std::min(80.0, 0.3 * s));
    while (p < half_ - 35.0) {
      pos.push_back(p);
      width.push_back(rng.uniform(6.0, 10.0));
      p += rng.uniform(90.0, 140.0);
    }
  };
  grid_lines(ns_x_, ns_w_);
  grid_lines(ew_y_, ew_w_);
  const double far = half_ + 20.0;  // roads run off the map edge
  for (std::size_t i = 0; i < ns_x_.size(); ++i) {
    roads_.push_back(Road{{{ns_x_[i], -far}, {ns_x_[i], far}}, ns_w_[i], rng.bernoulli(0.3)});
  }
  // East-west roads run between the north-south ones; some stretches are left out (T-junctions), but one
  // road always crosses the whole map so every north-south road is reached.
  const std::size_t full = ew_y_.empty() ? 0 : static_cast<std::size_t>(rng.below(ew_y_.size()));
  ew_segment_.assign(ew_y_.size(), std::vector<bool>(ns_x_.size() + 1, true));
  for (std::size_t j = 0; j < ew_y_.size(); ++j) {
    const bool yellow = rng.bernoulli(0.3);
    for (std::size_t k = 0; k <= ns_x_.size(); ++k) {
      const bool edge_stub = k == 0 || k == ns_x_.size();
      if (j != full && rng.bernoulli(edge_stub ? 0.35 : 0.2)) {
        ew_segment_[j][k] = false;
        continue;
      }
      const double xa = k == 0 ? -far : ns_x_[k - 1], xb = k == ns_x_.size() ? far : ns_x_[k];
      roads_.push_back(Road{{{xa, ew_y_[j]}, {xb, ew_y_[j]}}, ew_w_[j], yellow});
    }
  }
  // Curved roads join two points on different straight roads, sweeping across the blocks between.
  const int curves = std::max(1, static_cast<int>(std::lround(s / 300.0)));
  const std::size_t straight = roads_.size();
  for (int k = 0; k < curves && straight >= 2; ++k) {
    for (int attempt = 0; attempt < 50; ++attempt) {
      const auto ra = static_cast<std::size_t>(rng.below(straight)), rb = static_cast<std::size_t>(rng.below(straight));
      if (ra == rb) continue;
      const auto& A = roads_[ra].centre;
      const auto& B = roads_[rb].centre;
      const P2 a = A[0] + (A[1] - A[0]) * rng.uniform(0.15, 0.85);
      const P2 b = B[0] + (B[1] - B[0]) * rng.uniform(0.15, 0.85);
      const double d = cv::norm(b - a);
      if (!inside(a, 15) || !inside(b, 15) || d < 90.0 || d > 260.0) continue;
      const P2 dir = (b - a) * (1.0 / d), normal(-dir.y, dir.x);
      const double bend = rng.uniform(0.25, 0.45) * d * (rng.bernoulli(0.5) ? 1 : -1);
      const P2 c1 = a + dir * (d * 0.3) + normal * bend;
      const P2 c2 = a + dir * (d * 0.7) + normal * (bend * rng.uniform(-0.6, 1.0));
      roads_.push_back(Road{bezier(a, c1, c2, b, 2.0), rng.uniform(6.0, 8.0), false});
      break;
    }
  }
}

void ProceduralTown::make_blocks() {
  Rng rng(derive_seed(seed_, kBlocks));
  const std::size_t nx = ns_x_.size(), ny = ew_y_.size();
  for (std::size_t j = 0; j <= ny; ++j) {
    for (std::size_t i = 0; i <= nx; ++i) {
      Block b;
      b.x0 = i == 0 ? -half_ : ns_x_[i - 1] + ns_w_[i - 1] / 2;
      b.x1 = i == nx ? half_ : ns_x_[i] - ns_w_[i] / 2;
      b.y0 = j == 0 ? -half_ : ew_y_[j - 1] + ew_w_[j - 1] / 2;
      b.y1 = j == ny ? half_ : ew_y_[j] - ew_w_[j] / 2;
      if (b.w() < 12.0 || b.h() < 12.0) continue;
      if (i > 0) b.sides.push_back(Frontage{{b.x0, b.y0}, {b.x0, b.y1}, {1, 0}});
      if (i < nx) b.sides.push_back(Frontage{{b.x1, b.y0}, {b.x1, b.y1}, {-1, 0}});
      if (j > 0 && ew_segment_[j - 1][i]) b.sides.push_back(Frontage{{b.x0, b.y0}, {b.x1, b.y0}, {0, 1}});
      if (j < ny && ew_segment_[j][i]) b.sides.push_back(Frontage{{b.x0, b.y1}, {b.x1, b.y1}, {0, -1}});
      // Town in the middle, countryside towards the edges.
      const double d = std::min(1.0, cv::norm(b.centre()) / (half_ * 1.2));
      const std::array<double, 4> weight{0.62 * (1.0 - 0.6 * d), 0.18, 0.1 + 0.25 * d, 0.1 + 0.25 * d};
      double pick = rng.uniform(0, weight[0] + weight[1] + weight[2] + weight[3]);
      std::size_t k = 0;
      while (k < 3 && pick >= weight[k]) pick -= weight[k++];
      b.land = static_cast<Land>(k);
      blocks_.push_back(b);
    }
  }
  if (blocks_.empty()) return;
  // At least one built-up block: the one nearest the centre.
  const auto central = std::min_element(blocks_.begin(), blocks_.end(), [](const Block& a, const Block& b) {
    return cv::norm(a.centre()) < cv::norm(b.centre());
  });
  central->land = Land::kUrban;
}

void ProceduralTown::make_water() {
  Rng rng(derive_seed(seed_, kWater));
  // Ponds: in the largest blocks that are not built up and not the staging block (south-west corner);
  // one per 500 m of world side.
  std::vector<std::pair<double, std::size_t>> candidates;
  for (std::size_t i = 0; i < blocks_.size(); ++i) {
    const Block& b = blocks_[i];
    if (b.x0 <= -half_ + 1 && b.y0 <= -half_ + 1 && blocks_.size() > 1) continue;
    // Built-up blocks only when nothing else is left: the town keeps its buildings.
    candidates.emplace_back(-std::min(b.w(), b.h()) * (b.land == Land::kUrban ? 0.01 : 1.0), i);
  }
  std::sort(candidates.begin(), candidates.end());
  const std::size_t ponds = std::min(candidates.size(), static_cast<std::size_t>(1 + g_.size_x() / 500.0));
  cv::Mat pond(g_.height, g_.width, CV_8UC1);
  for (std::size_t k = 0; k < ponds; ++k) {
    const std::size_t bi = candidates[k].second;
    pond_blocks_.push_back(bi);
    Block& pb = blocks_[bi];
    if (pb.land == Land::kUrban) pb.land = Land::kPark;
    const double radius = std::clamp(std::min(pb.w(), pb.h()) / 2 - 9.0, 5.0, rng.uniform(13.0, 24.0));
    const P2 centre = pb.centre() + P2(rng.uniform(-0.1, 0.1) * pb.w(), rng.uniform(-0.1, 0.1) * pb.h());
    const std::array<double, 3> phase{rng.uniform(0, 2 * kPi), rng.uniform(0, 2 * kPi), rng.uniform(0, 2 * kPi)};
    std::vector<cv::Point> shore;
    for (int v = 0; v < 96; ++v) {
      const double a = 2 * kPi * v / 96.0;
      const double rr = radius * (1 + 0.18 * std::sin(2 * a + phase[0]) + 0.1 * std::sin(3 * a + phase[1]) + 0.05 * std::sin(5 * a + phase[2]));
      shore.push_back(fixed(centre + P2(rr * std::cos(a), rr * std::sin(a))));
    }
    pond.setTo(cv::Scalar(0));
    cv::fillPoly(pond, std::vector<std::vector<cv::Point>>{shore}, cv::Scalar(255), cv::LINE_8, kShift);
    // The pond surface is level (the lowest ground under it) and the banks ease into it over 8 m.
    const auto bank = static_cast<float>(8.0 / g_.resolution);
    const int margin = static_cast<int>(bank) + 2;
    const cv::Rect around = (cv::boundingRect(pond) + cv::Point(-margin, -margin) + cv::Size(2 * margin, 2 * margin)) &
                            cv::Rect(0, 0, g_.width, g_.height);
    double lowest = 0;
    cv::minMaxLoc(w_.terrain(around), &lowest, nullptr, nullptr, nullptr, pond(around));
    const auto level = static_cast<float>(lowest - 0.1);
    cv::Mat from_shore;
    cv::distanceTransform(~pond(around), from_shore, cv::DIST_L2, cv::DIST_MASK_5);
    for (int r = 0; r < around.height; ++r) {
      const auto* d = from_shore.ptr<float>(r);
      auto* t = w_.terrain.ptr<float>(r + around.y) + around.x;
      for (int c = 0; c < around.width; ++c) {
        if (d[c] >= bank) continue;
        const float e = d[c] / bank, ease = e * e * (3.0F - 2.0F * e);
        t[c] = level + (t[c] - level) * ease;
      }
    }
    w_.class_id.setTo(cv::Scalar(raw(ClassId::kWater)), pond);
  }

  // A stream in larger worlds: from the north edge towards the east edge, away from the staging corner.
  if (g_.size_x() < 300.0) return;
  P2 p(rng.uniform(-0.1, 0.3) * g_.size_x(), half_ + 5);
  const P2 target(half_ + 30, rng.uniform(-0.35, 0.05) * g_.size_x());
  std::vector<P2> line{p};
  double heading = std::atan2(target.y - p.y, target.x - p.x);
  const double meander = rng.uniform(0, 2 * kPi);
  for (int step = 0; step < 2000 && inside(p, -10); ++step) {
    const double to_target = std::atan2(target.y - p.y, target.x - p.x);
    heading = to_target + 0.7 * std::sin(step * 0.045 + meander) + 0.15 * rng.gaussian();
    p += P2(std::cos(heading), std::sin(heading)) * 2.0;
    line.push_back(p);
  }
  cv::Mat stream(g_.height, g_.width, CV_8UC1, cv::Scalar(0));
  draw_polyline(stream, line, rng.uniform(3.0, 5.0), 255);
  w_.class_id.setTo(cv::Scalar(raw(ClassId::kWater)), stream);
}

void ProceduralTown::draw_roads() {
  cv::Mat full(g_.height, g_.width, CV_8UC1, cv::Scalar(0));
  cv::Mat lanes(g_.height, g_.width, CV_8UC1, cv::Scalar(0));
  cv::Mat overlap(g_.height, g_.width, CV_8UC1, cv::Scalar(255));  // 0 where two roads meet (distance transform input)
  for (const Road& road : roads_) {
    // Drawn in its own bounding box first to find where it crosses roads drawn before it.
    const auto [roi, own] = polyline_mask(road.centre, road.width);
    cv::Mat full_roi = full(roi), overlap_roi = overlap(roi);
    overlap_roi.setTo(cv::Scalar(0), own & full_roi);
    full_roi |= own;
    draw_polyline(lanes, road.centre, road.width - 2 * kCurbWidth, 255);
  }
  cv::distanceTransform(overlap, junction_dist_, cv::DIST_L2, cv::DIST_MASK_3);
  junction_dist_ *= g_.resolution;
  w_.class_id.setTo(cv::Scalar(raw(ClassId::kRoad)), full);
  w_.height.setTo(cv::Scalar(0), full);
  cv::Mat curb = full & ~lanes;
  w_.height.setTo(cv::Scalar(static_cast<double>(kCurbHeight)), curb);
}

void ProceduralTown::make_staging() {
  // In the south-west block, against the first north-south road, half-way up the block.
  const double road_x = ns_x_.empty() ? -half_ + 60 : ns_x_[0], road_w = ns_w_.empty() ? 7.0 : ns_w_[0];
  const double south = -half_, north = ew_y_.empty() ? half_ : ew_y_[0] - ew_w_[0] / 2;
  const double cy = std::clamp((south + north) / 2, south + kStagingPad / 2 + 4, north - kStagingPad / 2 - 4);
  const double kerb = road_x - road_w / 2;
  // Overlap the kerb so the pad opens onto the carriageway without a curb step.
  staging_ = Box{{kerb - kStagingPad / 2 + kCurbWidth + 0.1, cy}, kStagingPad / 2 + kCurbWidth / 2, kStagingPad / 2, 0.0};
  if (staging_.c.x - staging_.half_len < -half_ + 2) staging_.c.x = -half_ + 2 + staging_.half_len;
  const double reach = staging_.reach(0);
  for_cells(staging_.c.x - reach, staging_.c.y - reach, staging_.c.x + reach, staging_.c.y + reach, [&](int c, int r, double x, double y) {
    if (staging_.contains(x, y)) set(c, r, ClassId::kRoad, 0.0F);
  });
  w_.header.staging = Pose2{staging_.c.x - kCurbWidth / 2, staging_.c.y, 0.0};
}

bool ProceduralTown::cars_clear_of_others(const std::vector<Pose2>& cars) const {
  for (const Pose2& p : cars) {
    if (std::hypot(p.x - w_.header.staging.x, p.y - w_.header.staging.y) < kStagingClearance) return false;
    const double spacing = g_.size_x() < 300.0 ? kClusterSpacingSmall : kClusterSpacing;
    for (const Pose2& q : cars_) {
      if (std::hypot(p.x - q.x, p.y - q.y) < spacing) return false;
    }
  }
  return true;
}

void ProceduralTown::draw_car(const Pose2& p) {
  const Box car{{p.x, p.y}, kCarLength / 2, kCarWidth / 2, p.yaw};
  const double reach = car.reach(0);
  for_cells(p.x - reach, p.y - reach, p.x + reach, p.y + reach, [&](int c, int r, double x, double y) {
    if (car.contains(x, y)) set(c, r, ClassId::kVehicle, kCarHeight);
  });
}

bool ProceduralTown::try_lot_cluster(Rng& rng, int max_cars, TargetCluster& out) {
  std::vector<std::pair<std::size_t, std::size_t>> frontages;
  for (std::size_t i = 0; i < blocks_.size(); ++i) {
    for (std::size_t k = 0; k < blocks_[i].sides.size(); ++k) frontages.emplace_back(i, k);
  }
  if (frontages.empty()) return false;
  const auto [bi, si] = frontages[static_cast<std::size_t>(rng.below(frontages.size()))];
  const Block& b = blocks_[bi];
  const Frontage& f = b.sides[si];
  const bool two_rows = rng.bernoulli(0.6);
  const int bays = static_cast<int>(6 + rng.below(7));
  const double len = bays * kBayWidth + 2 * kLotEntrance;
  const double depth = two_rows ? 2 * kBayDepth + kAisle : kBayDepth + kAisle;
  const double side_len = cv::norm(f.b - f.a);
  const double depth_room = std::fabs(f.inward.x) > 0.5 ? b.w() : b.h();
  if (side_len < len + 16.0 || depth_room < depth + 6.0) return false;
  const P2 along_dir = (f.b - f.a) * (1.0 / side_len);
  const double t = rng.uniform(8.0 + len / 2, side_len - 8.0 - len / 2);
  const double overlap = kCurbWidth + 0.1;  // into the road: a curb cut along the lot's front
  const P2 centre = f.a + along_dir * t + f.inward * (depth / 2 - overlap / 2);
  const double yaw = std::atan2(along_dir.y, along_dir.x);
  const Box lot{centre, len / 2, depth / 2 + overlap / 2, yaw};
  // From 0.5 m behind the kerb the ground must be free grass, with room around the lot.
  const double near = 2.0, far_side = depth + 0.5;
  const Box behind{f.a + along_dir * t + f.inward * ((near + far_side) / 2), len / 2, (far_side - near) / 2, yaw};
  if (!box_free(behind, 1.5)) return false;
  // Bays: row 0 at the road side of the aisle (single-row lots have only the far row), listed as a
  // snake (row 0 forwards, row 1 backwards) so consecutive slots are neighbours, also across the aisle.
  std::vector<Pose2> slots;
  const double facing = std::atan2(f.inward.y, f.inward.x);
  for (int row = two_rows ? 0 : 1; row < 2; ++row) {
    const double d = row == 0 ? kBayDepth / 2 : depth - kBayDepth / 2;
    for (int i = 0; i < bays; ++i) {
      const int k = row == 0 ? i : bays - 1 - i;
      const P2 c = f.a + along_dir * (t - len / 2 + kLotEntrance + (k + 0.5) * kBayWidth) + f.inward * d;
      slots.push_back(Pose2{c.x, c.y, facing});
    }
  }
  const int n = static_cast<int>(2 + rng.below(static_cast<std::uint64_t>(max_cars - 1)));
  std::vector<Pose2> cars;
  // From a random bay onwards, then back from just before it: never a jump along the lot.
  const auto first = static_cast<std::size_t>(rng.below(slots.size()));
  std::vector<std::size_t> order;
  for (std::size_t i = first; i < slots.size(); ++i) order.push_back(i);
  for (std::size_t i = first; i-- > 0;) order.push_back(i);
  bool skipped = false;  // at most one empty bay in a row: the cars stay one group
  for (std::size_t v = 0; v < order.size() && static_cast<int>(cars.size()) < n; ++v) {
    const bool turn_back = v > 0 && order[v] + 1 == first;
    const bool skip = v > 0 && !turn_back && !skipped && rng.bernoulli(0.2);
    skipped = skip;
    if (skip) continue;
    Pose2 p = slots[order[v]];
    p.yaw = wrap_angle(p.yaw + (rng.bernoulli(0.75) ? 0.0 : kPi) + rng.uniform(-0.04, 0.04));  // nose in or out
    const P2 jitter = along_dir * rng.uniform(-0.15, 0.15);
    p.x += jitter.x, p.y += jitter.y;
    cars.push_back(p);
  }
  if (static_cast<int>(cars.size()) < 2 || !cars_clear_of_others(cars)) return false;
  // Commit: the lot surface, bay outlines for the paint, the cars.
  const double reach = lot.reach(0);
  for_cells(centre.x - reach, centre.y - reach, centre.x + reach, centre.y + reach, [&](int c, int r, double x, double y) {
    if (lot.contains(x, y) && cls(c, r) != raw(ClassId::kWater)) set(c, r, ClassId::kRoad, 0.0F);
  });
  lots_.push_back(lot);
  for (const Pose2& s : slots) bays_.push_back(Box{{s.x, s.y}, kBayDepth / 2, kBayWidth / 2, facing});
  out.car_poses = cars;
  return true;
}

bool ProceduralTown::try_roadside_cluster(Rng& rng, int max_cars, TargetCluster& out) {
  const Road& road = roads_[static_cast<std::size_t>(rng.below(roads_.size()))];
  const double len = length_of(road.centre);
  const double side = rng.bernoulli(0.5) ? 1.0 : -1.0;
  const double offset = side * (road.width / 2 - kCurbWidth - 0.3 - kCarWidth / 2);
  const int n = static_cast<int>(2 + rng.below(static_cast<std::uint64_t>(max_cars - 1)));
  const double spacing = rng.uniform(5.8, 6.8);
  const double extent = (n - 1) * spacing;
  const double t0 = rng.uniform(0, std::max(len - extent, 1.0));
  std::vector<Pose2> cars;
  for (int k = 0; k < n; ++k) {
    const auto [p, dir] = along(road.centre, t0 + k * spacing + rng.uniform(-0.3, 0.3));
    const P2 c = p + P2(-dir.y, dir.x) * offset;
    const double yaw = std::atan2(dir.y, dir.x) + (side > 0 ? kPi : 0.0);  // parked with the traffic on its side
    cars.push_back(Pose2{c.x, c.y, wrap_angle(yaw + rng.uniform(-0.03, 0.03))});
  }
  for (const Pose2& p : cars) {
    const Box car{{p.x, p.y}, kCarLength / 2, kCarWidth / 2, p.yaw};
    if (!inside({p.x, p.y}, 4.0)) return false;
    bool ok = true;
    const double reach = car.reach(0.3);
    for_cells(p.x - reach, p.y - reach, p.x + reach, p.y + reach, [&](int c, int r, double x, double y) {
      if (ok && car.contains(x, y, 0.2) &&
          (cls(c, r) != raw(ClassId::kRoad) || w_.height.at<float>(r, c) > 0.05F || junction_dist_.at<float>(r, c) < 7.0F)) {
        ok = false;
      }
    });
    if (!ok) return false;
    for (const Box& lot : lots_) {
      if (lot.contains(p.x, p.y, 6.0)) return false;  // keep lot entrances clear
    }
  }
  if (!cars_clear_of_others(cars)) return false;
  out.car_poses = cars;
  return true;
}

Status ProceduralTown::make_targets(std::vector<TargetCluster>& targets) {
  Rng rng(derive_seed(seed_, kTargets));
  for (int t = 0; t < opt_.targets; ++t) {
    TargetCluster cl;
    bool placed = false;
    const bool lot_first = t % 2 == 0;
    for (int attempt = 0; attempt < 1200 && !placed; ++attempt) {
      const bool lot = (attempt % 4 == 3) ? !lot_first : lot_first;
      const int max_cars = attempt < 600 ? 8 : 3;  // a crowded map still has room for small groups
      placed = lot ? try_lot_cluster(rng, max_cars, cl) : try_roadside_cluster(rng, max_cars, cl);
    }
    if (!placed) {
      return Error::make(ErrorCode::kInvalidArgument, "generator: could place only " + std::to_string(t) + " of " +
                                                          std::to_string(opt_.targets) + " target clusters in a " +
                                                          std::to_string(static_cast<int>(g_.size_x())) + " m world; use fewer targets or a larger world");
    }
    cl.id = t;
    cl.cars = static_cast<int>(cl.car_poses.size());
    for (const Pose2& p : cl.car_poses) {
      cl.x += p.x / cl.cars;
      cl.y += p.y / cl.cars;
      cars_.push_back(p);
      draw_car(p);
    }
    targets.push_back(std::move(cl));
  }
  return ok_status();
}

void ProceduralTown::track_from(Rng& rng, P2 start, double heading, double max_len, double width) {
  std::vector<P2> line{start};
  P2 p = start;
  const double wander = rng.uniform(0.02, 0.06);
  double turn = 0;
  for (double s = 0; s < max_len; s += 2.0) {
    turn = 0.85 * turn + wander * rng.gaussian();
    heading += turn;
    p += P2(std::cos(heading), std::sin(heading)) * 2.0;
    if (!inside(p, 2)) break;
    line.push_back(p);
    const int c = g_.col(p.x), r = g_.row(p.y);
    const std::uint8_t k = cls(c, r);
    if (s > 10.0 && (k == raw(ClassId::kRoad) || k == raw(ClassId::kWater))) break;  // reached a road or the water
  }
  if (line.size() < 5) return;
  const auto [roi, own] = polyline_mask(line, width);
  for (int r = 0; r < roi.height; ++r) {
    for (int c = 0; c < roi.width; ++c) {
      if (own.at<std::uint8_t>(r, c) == 0) continue;
      const int cc = c + roi.x, rr = r + roi.y;
      const std::uint8_t k = cls(cc, rr);
      if (k == raw(ClassId::kGrass)) set(cc, rr, ClassId::kDirt, 0.0F);
      if (k == raw(ClassId::kRoad)) w_.height.at<float>(rr, cc) = 0.0F;  // the track drops the curb where it joins
    }
  }
}

void ProceduralTown::make_tracks() {
  Rng rng(derive_seed(seed_, kTracks));
  // A gravel track from the staging pad into the country to the west or south.
  track_from(rng, P2(staging_.c.x - staging_.half_len + 1, staging_.c.y + rng.uniform(-6, 6)), kPi + rng.uniform(-0.5, 0.5),
             g_.size_x() * 0.5, rng.uniform(3.0, 4.0));
  for (std::size_t i = 0; i < blocks_.size(); ++i) {
    const Block& b = blocks_[i];
    if (b.land == Land::kUrban || b.sides.empty()) continue;
    const bool pond = std::find(pond_blocks_.begin(), pond_blocks_.end(), i) != pond_blocks_.end();
    const double p = b.land == Land::kWood ? 0.8 : (pond ? 1.0 : 0.55);
    if (!rng.bernoulli(p)) continue;
    const Frontage& f = b.sides[static_cast<std::size_t>(rng.below(b.sides.size()))];
    const P2 start = f.a + (f.b - f.a) * rng.uniform(0.25, 0.75) - f.inward * (kCurbWidth + 0.2);
    const double heading = std::atan2(f.inward.y, f.inward.x) + rng.uniform(-0.4, 0.4);
    const double width = b.land == Land::kPark ? rng.uniform(2.0, 2.8) : rng.uniform(3.0, 4.5);
    track_from(rng, start, heading, std::max(b.w(), b.h()) * 1.4, width);
  }
}

bool ProceduralTown::place_building(Rng& rng, const std::vector<BuildingPart>& parts) {
  for (const BuildingPart& p : parts) {
    if (!box_free(p.box, 1.5)) return false;
  }
  const float base = w_.terrain.at<float>(std::clamp(g_.row(parts[0].box.c.y), 0, g_.height - 1),
                                          std::clamp(g_.col(parts[0].box.c.x), 0, g_.width - 1));
  for (const BuildingPart& p : parts) {
    const double reach = p.box.reach(0);
    for_cells(p.box.c.x - reach, p.box.c.y - reach, p.box.c.x + reach, p.box.c.y + reach, [&](int c, int r, double x, double y) {
      if (!p.box.contains(x, y)) return;
      double roof = p.eave;
      if (p.roof == Roof::kGable) {
        const P2 l = p.box.to_local(x, y);
        roof += p.rise * (1.0 - std::fabs(l.y) / p.box.half_wid);  // the ridge runs along the part's length
      }
      // Roofs are level in absolute height: the building stands on the ground at its first part's centre.
      const float h = std::clamp(static_cast<float>(roof) + base - w_.terrain.at<float>(r, c), kMinBuilding, kMaxBuilding);
      const bool mine = cls(c, r) == raw(ClassId::kBuilding);
      set(c, r, ClassId::kBuilding, mine ? std::max(h, w_.height.at<float>(r, c)) : h);
    });
    if (p.roof == Roof::kGable) {
      gables_.push_back(p);
      gables_.back().base = base;
    }
  }
  // Plant rooms and vents on flat roofs.
  for (const BuildingPart& p : parts) {
    if (p.roof != Roof::kFlat || p.box.half_len < 4 || p.box.half_wid < 4) continue;
    const int units = static_cast<int>(rng.below(4));
    for (int u = 0; u < units; ++u) {
      const double hl = rng.uniform(0.8, 2.2), hw = rng.uniform(0.8, 1.8);
      const P2 l(rng.uniform(-p.box.half_len + hl + 1, p.box.half_len - hl - 1), rng.uniform(-p.box.half_wid + hw + 1, p.box.half_wid - hw - 1));
      const double cs = std::cos(p.box.yaw), sn = std::sin(p.box.yaw);
      const Box unit{p.box.c + P2(l.x * cs - l.y * sn, l.x * sn + l.y * cs), hl, hw, p.box.yaw};
      const float extra = static_cast<float>(rng.uniform(1.0, 2.5));
      const double reach = unit.reach(0);
      for_cells(unit.c.x - reach, unit.c.y - reach, unit.c.x + reach, unit.c.y + reach, [&](int c, int r, double x, double y) {
        if (unit.contains(x, y) && cls(c, r) == raw(ClassId::kBuilding)) {
          w_.height.at<float>(r, c) = std::min(w_.height.at<float>(r, c) + extra, kMaxBuilding);
        }
      });
    }
  }
  return true;
}

bool ProceduralTown::place_tree(P2 c0, double radius, double top, bool among_trees) {
  if (!inside(c0, radius + 0.5)) return false;
  const double margin = 0.6, reach = radius + margin;
  bool ok = true;
  for_cells(c0.x - reach, c0.y - reach, c0.x + reach, c0.y + reach, [&](int c, int r, double x, double y) {
    if (!ok || std::hypot(x - c0.x, y - c0.y) > reach) return;
    const std::uint8_t k = cls(c, r);
    if (k != raw(ClassId::kGrass) && !(among_trees && k == raw(ClassId::kTree))) ok = false;
  });
  if (!ok) return false;
  for_cells(c0.x - radius, c0.y - radius, c0.x + radius, c0.y + radius, [&](int c, int r, double x, double y) {
    const double d = std::hypot(x - c0.x, y - c0.y) / radius;
    if (d > 1.0) return;
    const float h = static_cast<float>(top * (1.0 - 0.38 * d * d));  // a domed crown
    const bool tree = cls(c, r) == raw(ClassId::kTree);
    set(c, r, ClassId::kTree, tree ? std::max(h, w_.height.at<float>(r, c)) : h);
  });
  return true;
}

void ProceduralTown::place_hedge(const std::vector<P2>& line, double width, double h) {
  const auto [roi, own] = polyline_mask(line, width);
  for (int r = 0; r < roi.height; ++r) {
    for (int c = 0; c < roi.width; ++c) {
      const int cc = c + roi.x, rr = r + roi.y;
      if (own.at<std::uint8_t>(r, c) != 0 && cls(cc, rr) == raw(ClassId::kGrass)) set(cc, rr, ClassId::kTree, static_cast<float>(h));
    }
  }
}

void ProceduralTown::urban_block(Rng& rng, const Block& b) {
  const bool dense = rng.bernoulli(0.35);
  for (const Frontage& f : b.sides) {
    const double side_len = cv::norm(f.b - f.a);
    const P2 dir = (f.b - f.a) * (1.0 / side_len);
    const double yaw = std::atan2(dir.y, dir.x);
    const double depth_room = (std::fabs(f.inward.x) > 0.5 ? b.w() : b.h()) / 2;
    double s = rng.uniform(3.0, 8.0);
    while (s < side_len - 10.0) {
      const double parcel = dense ? rng.uniform(20.0, 36.0) : rng.uniform(14.0, 26.0);
      const double setback = dense ? rng.uniform(2.0, 5.0) : rng.uniform(3.0, 7.0);
      const double width = std::min(parcel - rng.uniform(3.0, 6.0), side_len - s - 3.0);
      const double depth = std::min(dense ? rng.uniform(12.0, 18.0) : rng.uniform(8.0, 13.0), depth_room - setback - 3.0);
      if (width < 6.0 || depth < 6.0) break;
      const P2 front_mid = f.a + dir * (s + width / 2);
      std::vector<BuildingPart> parts;
      BuildingPart main;
      main.box = Box{front_mid + f.inward * (setback + depth / 2), width / 2, depth / 2, yaw};
      const bool tower = dense && rng.bernoulli(0.35);
      if (dense) {
        main.roof = Roof::kFlat;
        main.eave = tower ? rng.uniform(16.0, 29.0) : rng.uniform(9.0, 16.0);
      } else {
        main.roof = Roof::kGable;
        main.eave = rng.uniform(5.0, 7.5);
        main.rise = rng.uniform(2.0, 4.5);
        if (main.box.half_wid > main.box.half_len) {  // the ridge follows the longer side
          std::swap(main.box.half_len, main.box.half_wid);
          main.box.yaw += kPi / 2;
        }
      }
      parts.push_back(main);
      if (rng.bernoulli(0.3)) {  // an L-shaped wing reaching back at one end
        BuildingPart wing = main;
        const double ww = width * rng.uniform(0.35, 0.5), extra = rng.uniform(4.0, 9.0);
        const double end = rng.bernoulli(0.5) ? 1.0 : -1.0;
        const P2 wc = front_mid + dir * (end * (width - ww) / 2) + f.inward * (setback + (depth + extra) / 2);
        wing.box = Box{wc, (depth + extra) / 2, ww / 2, std::atan2(f.inward.y, f.inward.x)};
        if (wing.roof == Roof::kGable) wing.rise = std::min(main.rise, ww * 0.4);
        if (setback + depth + extra < depth_room - 2.0) parts.push_back(wing);
      }
      const bool built = place_building(rng, parts);
      // Back yard: a hedge on the back boundary and a few trees.
      const double back = std::min(setback + depth + rng.uniform(6.0, 12.0), depth_room - 1.5);
      if (rng.bernoulli(0.4) && built) {
        place_hedge({front_mid - dir * (parcel / 2) + f.inward * back, front_mid + dir * (parcel / 2) + f.inward * back},
                    rng.uniform(1.0, 1.6), rng.uniform(1.2, 2.2));
      }
      const int yard_trees = static_cast<int>(rng.below(dense ? 2 : 4));
      for (int k = 0; k < yard_trees; ++k) {
        const P2 c = front_mid + dir * rng.uniform(-parcel / 2, parcel / 2) + f.inward * rng.uniform(setback + depth + 2, back + 2);
        place_tree(c, rng.uniform(1.8, 3.5), rng.uniform(6.0, 13.0), true);
      }
      s += parcel;
    }
  }
  // Large blocks get apartment slabs or a hall in the middle.
  if (b.w() > 70 && b.h() > 70) {
    const int n = static_cast<int>(1 + rng.below(3));
    for (int k = 0; k < n; ++k) {
      BuildingPart slab;
      const bool hall = rng.bernoulli(0.3);
      slab.box = Box{b.centre() + P2(rng.uniform(-0.2, 0.2) * b.w(), rng.uniform(-0.2, 0.2) * b.h()),
                     rng.uniform(12.0, hall ? 24.0 : 22.0), rng.uniform(6.0, hall ? 14.0 : 9.0), rng.bernoulli(0.5) ? 0.0 : kPi / 2};
      slab.roof = Roof::kFlat;
      slab.eave = hall ? rng.uniform(6.0, 10.0) : rng.uniform(12.0, 28.0);
      place_building(rng, {slab});
    }
  }
  for (int k = 0; k < static_cast<int>(b.w() * b.h() / 600.0); ++k) {
    place_tree(P2(rng.uniform(b.x0, b.x1), rng.uniform(b.y0, b.y1)), rng.uniform(2.0, 3.8), rng.uniform(7.0, 15.0), true);
  }
}

void ProceduralTown::park_block(Rng& rng, const Block& b) {
  const double area = b.w() * b.h();
  const int groves = 1 + static_cast<int>(area / 3000.0);
  for (int k = 0; k < groves; ++k) {
    const P2 c(rng.uniform(b.x0 + 8, b.x1 - 8), rng.uniform(b.y0 + 8, b.y1 - 8));
    const double spread = rng.uniform(7.0, 18.0);
    const int n = static_cast<int>(5 + rng.below(16));
    for (int t = 0; t < n; ++t) {
      const double a = rng.uniform(0, 2 * kPi), d = spread * std::sqrt(rng.uniform());
      place_tree(c + P2(d * std::cos(a), d * std::sin(a)), rng.uniform(2.2, 4.5), rng.uniform(8.0, 17.0), true);
    }
  }
  for (int k = 0; k < static_cast<int>(area / 500.0); ++k) {
    place_tree(P2(rng.uniform(b.x0, b.x1), rng.uniform(b.y0, b.y1)), rng.uniform(2.0, 4.0), rng.uniform(6.0, 15.0), false);
  }
  for (const Frontage& f : b.sides) {
    if (!rng.bernoulli(0.35)) continue;
    const P2 in = f.inward * 2.5, dir = (f.b - f.a) * (1.0 / cv::norm(f.b - f.a));
    place_hedge({f.a + in + dir * 3.0, f.b + in - dir * 3.0}, rng.uniform(1.0, 1.5), rng.uniform(1.3, 2.3));
  }
}

void ProceduralTown::wood_block(Rng& rng, const Block& b) {
  std::vector<std::pair<P2, double>> clearings;
  for (int k = 0; k < 1 + static_cast<int>(rng.below(3)); ++k) {
    clearings.emplace_back(P2(rng.uniform(b.x0, b.x1), rng.uniform(b.y0, b.y1)), rng.uniform(6.0, 14.0));
  }
  const int attempts = static_cast<int>(b.w() * b.h() / 14.0);
  for (int k = 0; k < attempts; ++k) {
    const P2 c(rng.uniform(b.x0 + 1, b.x1 - 1), rng.uniform(b.y0 + 1, b.y1 - 1));
    bool in_clearing = false;
    for (const auto& [cc, rr] : clearings) in_clearing = in_clearing || cv::norm(c - cc) < rr;
    if (!in_clearing) place_tree(c, rng.uniform(2.2, 4.6), rng.uniform(9.0, 19.0), true);
  }
}

void ProceduralTown::field_block(Rng& rng, const Block& b) {
  for (const Frontage& f : b.sides) {
    if (!rng.bernoulli(0.6)) continue;
    const P2 in = f.inward * 2.0, dir = (f.b - f.a) * (1.0 / cv::norm(f.b - f.a));
    const std::vector<P2> line{f.a + in + dir * 2.0, f.b + in - dir * 2.0};
    place_hedge(line, rng.uniform(1.2, 1.8), rng.uniform(1.4, 2.5));
    const double len = cv::norm(line[1] - line[0]);
    for (double s = rng.uniform(5, 25); s < len; s += rng.uniform(15, 40)) {  // standards along the hedge
      place_tree(along(line, s).first + f.inward * 1.0, rng.uniform(2.5, 4.5), rng.uniform(8.0, 16.0), true);
    }
  }
  for (int k = 0; k < static_cast<int>(rng.below(4)); ++k) {
    place_tree(P2(rng.uniform(b.x0, b.x1), rng.uniform(b.y0, b.y1)), rng.uniform(3.0, 5.0), rng.uniform(9.0, 18.0), false);
  }
}

void ProceduralTown::fill_blocks() {
  Rng rng(derive_seed(seed_, kBlocks) ^ 0x5A5AULL);
  for (const Block& b : blocks_) {
    switch (b.land) {
      case Land::kUrban: urban_block(rng, b); break;
      case Land::kPark: park_block(rng, b); break;
      case Land::kWood: wood_block(rng, b); break;
      case Land::kField: field_block(rng, b); break;
    }
  }
}

void ProceduralTown::street_trees() {
  Rng rng(derive_seed(seed_, kStreetTrees));
  for (const Road& road : roads_) {
    if (!rng.bernoulli(0.45)) continue;
    const double len = length_of(road.centre);
    for (const double side : {-1.0, 1.0}) {
      if (!rng.bernoulli(0.7)) continue;
      const double spacing = rng.uniform(9.0, 14.0), radius = rng.uniform(1.8, 2.8), top = rng.uniform(7.0, 12.0);
      for (double s = rng.uniform(0, spacing); s < len; s += spacing) {
        const auto [p, t] = along(road.centre, s);
        const P2 n(-t.y, t.x);
        place_tree(p + n * (side * (road.width / 2 + 1.2 + radius)), radius * rng.uniform(0.9, 1.1), top * rng.uniform(0.9, 1.1), false);
      }
    }
  }
}

void ProceduralTown::finish_heights() {
  // Leafy, uneven crowns and hedges: LiDAR and stereo see rough vegetation, not smooth domes.
  const cv::Mat leaves = value_noise(cv::Size(g_.width, g_.height), std::max(0.8 / g_.resolution, 1.5), derive_seed(seed_, kPaint) ^ 0x1EAFULL);
  for (int r = 0; r < g_.height; ++r) {
    const auto* k = w_.class_id.ptr<std::uint8_t>(r);
    const auto* n = leaves.ptr<float>(r);
    auto* h = w_.height.ptr<float>(r);
    for (int c = 0; c < g_.width; ++c) {
      if (k[c] == raw(ClassId::kTree)) h[c] = std::max(h[c] + 0.35F * n[c], 0.5F);
    }
  }
}

// ---- paint ----

void ProceduralTown::paint() {
  w_.albedo = paint_albedo(w_.class_id, w_.height, g_.resolution, derive_seed(seed_, kPaint));
  Rng rng(derive_seed(seed_, kMarkings));
  cv::Mat lane_white(g_.height, g_.width, CV_8UC1, cv::Scalar(0));
  cv::Mat lane_yellow(g_.height, g_.width, CV_8UC1, cv::Scalar(0));
  cv::Mat paint_white(g_.height, g_.width, CV_8UC1, cv::Scalar(0));  // crossings and bays: also inside junctions
  cv::Mat paint_yellow(g_.height, g_.width, CV_8UC1, cv::Scalar(0));
  const double line_w = std::max(0.15, g_.resolution * 0.7);
  const auto dashed = [&](cv::Mat& m, const std::vector<P2>& line, double dash, double gap) {
    const double len = length_of(line);
    for (double s = rng.uniform(0, dash + gap); s + dash < len; s += dash + gap) {
      std::vector<P2> piece;
      for (double u = s; u <= s + dash + 1e-9; u += 0.5) piece.push_back(along(line, u).first);
      draw_polyline(m, piece, line_w, 255, cv::LINE_AA);
    }
  };
  for (const Road& road : roads_) {
    if (road.width >= 6.5) dashed(road.yellow_centre ? lane_yellow : lane_white, road.centre, 3.0, 5.0);
    if (road.width >= 7.5) {
      const double edge = road.width / 2 - kCurbWidth - 0.35;
      draw_polyline(lane_white, offset_polyline(road.centre, edge), line_w, 255, cv::LINE_AA);
      draw_polyline(lane_white, offset_polyline(road.centre, -edge), line_w, 255, cv::LINE_AA);
    }
  }
  // Zebra crossings on some arms of the grid junctions.
  for (std::size_t j = 0; j < ew_y_.size(); ++j) {
    for (std::size_t i = 0; i < ns_x_.size(); ++i) {
      const bool west = ew_segment_[j][i], east = ew_segment_[j][i + 1];
      if (!west && !east) continue;
      const auto zebra = [&](P2 centre, double yaw, double road_w) {  // stripes run along the road
        const double usable = road_w / 2 - kCurbWidth - 0.4;
        for (double v = -usable + 0.25; v <= usable - 0.25; v += 1.0) {
          const P2 off(-std::sin(yaw) * v, std::cos(yaw) * v);
          fill_box(paint_white, Box{centre + off, 1.5, 0.25, yaw}, 255, cv::LINE_AA);
        }
      };
      const P2 x(ns_x_[i], ew_y_[j]);
      for (const double dir : {-1.0, 1.0}) {  // arms of the north-south road
        if (rng.bernoulli(0.35)) zebra(x + P2(0, dir * (ew_w_[j] / 2 + 2.5)), kPi / 2, ns_w_[i]);
      }
      if (west && rng.bernoulli(0.35)) zebra(x - P2(ns_w_[i] / 2 + 2.5, 0), 0.0, ew_w_[j]);
      if (east && rng.bernoulli(0.35)) zebra(x + P2(ns_w_[i] / 2 + 2.5, 0), 0.0, ew_w_[j]);
    }
  }
  // Parking bays: the lines between them.
  for (const Box& bay : bays_) {
    const double cs = std::cos(bay.yaw), sn = std::sin(bay.yaw);
    for (const double side : {-1.0, 1.0}) {
      const P2 v(-sn * bay.half_wid * side, cs * bay.half_wid * side), u(cs * bay.half_len, sn * bay.half_len);
      draw_polyline(paint_white, {bay.c + v - u, bay.c + v + u}, line_w, 255, cv::LINE_AA);
    }
  }
  // The staging pad: a yellow border and cross, easy to find from the air.
  {
    const Box pad{staging_.c - P2(kCurbWidth / 2, 0), kStagingPad / 2 - 0.8, kStagingPad / 2 - 0.8, 0};
    const P2 a = pad.c + P2(-pad.half_len, -pad.half_wid), b = pad.c + P2(pad.half_len, -pad.half_wid);
    const P2 c = pad.c + P2(pad.half_len, pad.half_wid), d = pad.c + P2(-pad.half_len, pad.half_wid);
    draw_polyline(paint_yellow, {a, b, c, d, a}, 0.4, 255, cv::LINE_AA);
    draw_polyline(paint_yellow, {a + (c - a) * 0.3, a + (c - a) * 0.7}, 0.4, 255, cv::LINE_AA);
    draw_polyline(paint_yellow, {b + (d - b) * 0.3, b + (d - b) * 0.7}, 0.4, 255, cv::LINE_AA);
  }
  const cv::Mat wear = value_noise(cv::Size(g_.width, g_.height), std::max(0.7 / g_.resolution, 1.5), derive_seed(seed_, kMarkings));
  for (int r = 0; r < g_.height; ++r) {
    const auto* k = w_.class_id.ptr<std::uint8_t>(r);
    const auto* h = w_.height.ptr<float>(r);
    const auto* jd = junction_dist_.ptr<float>(r);
    const auto* lw = lane_white.ptr<std::uint8_t>(r);
    const auto* ly = lane_yellow.ptr<std::uint8_t>(r);
    const auto* pw = paint_white.ptr<std::uint8_t>(r);
    const auto* py = paint_yellow.ptr<std::uint8_t>(r);
    const auto* wr = wear.ptr<float>(r);
    auto* o = w_.albedo.ptr<cv::Vec3b>(r);
    for (int c = 0; c < g_.width; ++c) {
      if (k[c] != raw(ClassId::kRoad) || h[c] > 0.05F) continue;
      const bool lanes_here = jd[c] > 1.5F;
      const float white = std::max(lanes_here ? lw[c] / 255.0F : 0.0F, pw[c] / 255.0F);
      const float yellow = std::max(lanes_here ? ly[c] / 255.0F : 0.0F, py[c] / 255.0F);
      const float fade = 0.72F + 0.2F * wr[c];  // worn paint
      const auto blend = [&](float alpha, float R, float G, float B) {
        if (alpha <= 0.0F) return;
        const float a = alpha * fade;
        o[c] = cv::Vec3b(static_cast<std::uint8_t>(o[c][0] + (R - o[c][0]) * a), static_cast<std::uint8_t>(o[c][1] + (G - o[c][1]) * a),
                         static_cast<std::uint8_t>(o[c][2] + (B - o[c][2]) * a));
      };
      blend(white, 236.0F, 236.0F, 230.0F);
      blend(yellow, 232.0F, 190.0F, 40.0F);
    }
  }
  // Car glass: windscreen and rear window darker than the paint.
  for (const Pose2& p : cars_) {
    const Box car{{p.x, p.y}, kCarLength / 2, kCarWidth / 2, p.yaw};
    const double reach = car.reach(0);
    for_cells(p.x - reach, p.y - reach, p.x + reach, p.y + reach, [&](int c, int r, double x, double y) {
      if (!car.contains(x, y) || cls(c, r) != raw(ClassId::kVehicle)) return;
      const P2 l = car.to_local(x, y);
      const bool windscreen = l.x > 0.35 && l.x < 1.15 && std::fabs(l.y) < 0.72;
      const bool rear = l.x < -1.15 && l.x > -1.75 && std::fabs(l.y) < 0.7;
      if (windscreen || rear) w_.albedo.at<cv::Vec3b>(r, c) = cv::Vec3b(38, 44, 54);
    });
  }
  // Ridge lines on pitched roofs.
  for (const BuildingPart& p : gables_) {
    const double reach = p.box.reach(0);
    for_cells(p.box.c.x - reach, p.box.c.y - reach, p.box.c.x + reach, p.box.c.y + reach, [&](int c, int r, double x, double y) {
      if (!p.box.contains(x, y, -0.3) || cls(c, r) != raw(ClassId::kBuilding)) return;
      // Only where this part's roof is the top surface: a wing's ridge stops where it meets the main roof.
      const double ridge = p.eave + p.rise + static_cast<double>(p.base - w_.terrain.at<float>(r, c));
      if (static_cast<double>(w_.height.at<float>(r, c)) > ridge + 0.05) return;
      if (std::fabs(p.box.to_local(x, y).y) < std::max(0.15, g_.resolution * 0.6)) {
        cv::Vec3b& v = w_.albedo.at<cv::Vec3b>(r, c);
        for (int ch = 0; ch < 3; ++ch) v[ch] = static_cast<std::uint8_t>(std::min(255, v[ch] + 26));
      }
    });
  }
}

Status ProceduralTown::build(std::vector<TargetCluster>& targets) {
  w_.class_id = cv::Mat(g_.height, g_.width, CV_8UC1, cv::Scalar(raw(ClassId::kGrass)));
  w_.height = cv::Mat(g_.height, g_.width, CV_32FC1, cv::Scalar(0));
  make_terrain();
  plan_roads();
  make_blocks();
  make_water();
  draw_roads();
  make_staging();
  if (auto s = make_targets(targets); !s) return s;
  make_tracks();
  fill_blocks();
  street_trees();
  finish_heights();
  paint();
  return ok_status();
}

}  // namespace

Result<World> generate_world(const GeneratorOptions& opt, std::vector<TargetCluster>* targets) {
  const auto bad = [](const std::string& m) { return Error::make(ErrorCode::kInvalidArgument, "generator: " + m); };
  if (!(opt.size_m >= 100.0 && opt.size_m <= 2000.0)) return bad("size_m must be in [100, 2000] m");
  if (!(opt.resolution >= 0.05 && opt.resolution <= 2.0)) return bad("resolution must be in [0.05, 2] m/cell");
  if (opt.size_m / opt.resolution > 10000.0) return bad("size_m / resolution must be at most 10000 cells per side");
  if (opt.targets < 0 || opt.targets > 64) return bad("targets must be in [0, 64]");
  World w;
  w.header.name = "procedural-s" + std::to_string(opt.seed) + "-" + std::to_string(static_cast<int>(std::lround(opt.size_m))) + "m";
  w.header.source = "generator";
  w.header.seed = opt.seed;
  w.header.datum = opt.datum;
  w.header.grid.resolution = opt.resolution;
  w.header.grid.width = static_cast<std::int32_t>(std::lround(opt.size_m / opt.resolution));
  w.header.grid.height = w.header.grid.width;
  w.header.grid.origin_x = -w.header.grid.width * opt.resolution / 2;
  w.header.grid.origin_y = w.header.grid.height * opt.resolution / 2;
  std::vector<TargetCluster> clusters;
  // A layout with no room left for every target cluster is redrawn from a derived seed: still one world per seed.
  constexpr int kLayouts = 6;
  for (int layout = 0;; ++layout) {
    clusters.clear();
    ProceduralTown town(opt, layout == 0 ? opt.seed : derive_seed(opt.seed, 1000 + static_cast<std::uint64_t>(layout)), w);
    const auto built = town.build(clusters);
    if (built.ok()) break;
    if (layout + 1 == kLayouts) return built.error();
  }
  if (auto v = w.validate(); !v) return Error::make(ErrorCode::kInternal, "generator produced an invalid world: " + v.error().message);
  if (targets != nullptr) *targets = std::move(clusters);
  return w;
}

}  // namespace ag::sim
