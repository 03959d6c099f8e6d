// The generated world's target car clusters: groups parked in a new lot or along a road, apart from
// each other and from the staging pad.
#include <algorithm>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "generator_town.hpp"

namespace ag::sim::generator {

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

}  // namespace ag::sim::generator
