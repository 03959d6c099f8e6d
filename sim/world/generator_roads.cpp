// The generated world's roads: the grid with its gaps and curves, the blocks between them, the roads
// drawn with curbs, the staging pad and the tracks into the country.
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include "generator_town.hpp"

namespace ag::sim::generator {

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

}  // namespace ag::sim::generator
