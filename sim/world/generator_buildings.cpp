// The generated world's buildings: houses and wings with pitched roofs, flat-roofed blocks with plant
// rooms, set along the frontages of the built-up blocks with their yards.
#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include "generator_town.hpp"

namespace ag::sim::generator {

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

}  // namespace ag::sim::generator
