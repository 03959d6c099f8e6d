// The generated world's ground: rolling terrain with a slight tilt, ponds levelled into it and a stream.
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <utility>
#include <vector>

#include "airground/sim/world_texture.hpp"
#include "generator_town.hpp"

namespace ag::sim::generator {

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

}  // namespace ag::sim::generator
