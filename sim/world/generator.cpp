// The procedural world generator: lays out roads, water, parking, buildings, vegetation and target car
// clusters in metres, rasterises them into the world layers and paints the aerial colour.
// The layout's steps are in generator_terrain (ground, water), generator_roads (roads, blocks, staging,
// tracks), generator_cars (target clusters), generator_buildings, generator_vegetation and generator_paint.
#include "airground/sim/generator.hpp"

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "generator_town.hpp"

namespace ag::sim {

namespace generator {

double length_of(const std::vector<P2>& pts) {
  double l = 0;
  for (std::size_t i = 1; i < pts.size(); ++i) l += std::hypot(pts[i].x - pts[i - 1].x, pts[i].y - pts[i - 1].y);
  return l;
}

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

}  // namespace generator

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
    generator::ProceduralTown town(opt, layout == 0 ? opt.seed : derive_seed(opt.seed, 1000 + static_cast<std::uint64_t>(layout)), w);
    const auto built = town.build(clusters);
    if (built.ok()) break;
    if (layout + 1 == kLayouts) return built.error();
  }
  if (auto v = w.validate(); !v) return Error::make(ErrorCode::kInternal, "generator produced an invalid world: " + v.error().message);
  if (targets != nullptr) *targets = std::move(clusters);
  return w;
}

}  // namespace ag::sim
