// The generated world's vegetation: trees and hedges, the blocks' land use (parks, woods, fields) and the
// street trees, with rough crowns.
#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include "airground/sim/world_texture.hpp"
#include "generator_town.hpp"

namespace ag::sim::generator {

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

}  // namespace ag::sim::generator
