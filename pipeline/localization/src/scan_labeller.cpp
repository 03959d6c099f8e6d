// Scan labelling: ground truth passing through, and the paper's geometric obstacle / ground split.
#include "airground/localization/scan_labeller.hpp"

#include <algorithm>
#include <cmath>

#include "airground/messages/geometry.hpp"

namespace ag::loc {

namespace {
// The ground may rise this much per metre between a column's last ground point and the next one seen
// (a road up a 5 % grade is still ground after a parked car hid part of it), up to kMaxTerrainRise.
constexpr double kTerrainGrade = 0.05;
constexpr double kMaxTerrainRise = 0.5;  // [m]
// A ground return becomes the column's ground reference only this much further out than the last one:
// the foot of a wall (rising in steps below min_step at close range) must not drag the reference up.
constexpr double kMinGroundAdvance = 0.15;  // [m]
}  // namespace

GeometricLabelParams load_geometric_label_params(const SectionView& s) {
  return load_params(s, kGeometricLabelFields);
}

GroundTruthLabeller::GroundTruthLabeller(const ClassTable& table) {
  map_.fill(255);
  for (const ClassInfo& c : table.all())
    if (c.id != ClassId::kUnknown) map_[raw(c.id)] = raw(c.id);
}

void GroundTruthLabeller::label(std::span<ScanPoint> points, int /*rings*/, int /*columns*/) noexcept {
  for (ScanPoint& p : points) p.cls = map_[p.cls];
}

GeometricLabeller::GeometricLabeller(const GeometricLabelParams& params, int max_rings, int max_columns)
    : p_(params), max_rings_(max_rings), max_columns_(max_columns),
      index_(static_cast<std::size_t>(max_rings) * static_cast<std::size_t>(max_columns), -1) {}

void GeometricLabeller::label(std::span<ScanPoint> points, int rings, int columns) noexcept {
  for (ScanPoint& p : points) p.cls = 255;
  if (rings <= 0 || columns <= 0 || rings > max_rings_ || columns > max_columns_) return;
  const auto cols = static_cast<std::size_t>(columns);
  const std::size_t n_pix = static_cast<std::size_t>(rings) * cols;
  std::fill_n(index_.begin(), n_pix, -1);
  for (std::size_t i = 0; i < points.size(); ++i) {
    const ScanPoint& p = points[i];
    if (p.ring >= rings || p.col >= columns || !(p.range > 0.0F) || static_cast<double>(p.range) > p_.max_range_m) continue;
    index_[p.ring * cols + p.col] = static_cast<std::int32_t>(i);
  }
  const double tan_slope = std::tan(p_.max_ground_slope_deg * kPi / 180.0);
  const auto ground = raw(kGroundLabel), obstacle = raw(kObstacleLabel);

  // Along each column, from the lowest beam up: gradient to the previous return and height above ground.
  for (std::size_t c = 0; c < cols; ++c) {
    double ground_z = -p_.sensor_height_m, ground_r = 0.0;
    double ground_z_before = ground_z, ground_r_before = ground_r;  // before the previous point, if it was ground
    double prev_z = ground_z, prev_r = 0.0;
    ScanPoint* prev = nullptr;
    for (int ring = rings - 1; ring >= 0; --ring) {
      const std::int32_t i = index_[static_cast<std::size_t>(ring) * cols + c];
      if (i < 0) continue;
      ScanPoint& p = points[static_cast<std::size_t>(i)];
      const double r = std::hypot(static_cast<double>(p.x), static_cast<double>(p.y));
      const double z = p.z;
      const double allowance = std::min(kMaxTerrainRise, kTerrainGrade * std::max(0.0, r - ground_r));
      // Tall above the column's ground, or rising steeply from it or from the previous return.
      const double dz_g = z - ground_z, dr_g = r - ground_r;
      bool is_obstacle = dz_g > p_.obstacle_height_m + allowance || (dz_g > p_.min_step_m && dz_g > tan_slope * dr_g);
      if (prev != nullptr) {
        const double dz = z - prev_z, dr = r - prev_r;
        const bool steep = dz > p_.min_step_m && dz > tan_slope * dr;
        is_obstacle = is_obstacle || steep;
        // The foot of a face: the previous return, taken for ground, starts the face if it stood above
        // the ground before it and this return rises straight from it.
        if (steep && prev->cls == ground && std::fabs(dr) < 0.5 && prev_z - ground_z_before > 0.5 * p_.min_step_m) {
          prev->cls = obstacle;
          ground_z = ground_z_before;
          ground_r = ground_r_before;
        }
      }
      if (!is_obstacle && dr_g >= kMinGroundAdvance) {
        ground_z_before = ground_z;
        ground_r_before = ground_r;
        ground_z = z;
        ground_r = r;
      }
      prev_z = z;
      prev_r = r;
      prev = &p;
      p.cls = is_obstacle ? obstacle : ground;
    }
  }

  // Flatness across the neighbouring columns: a ground return next to a steep step is an obstacle edge.
  for (int ring = 0; ring < rings; ++ring) {
    const std::size_t row = static_cast<std::size_t>(ring) * cols;
    for (std::size_t c = 0; c < cols; ++c) {
      const std::int32_t i = index_[row + c];
      if (i < 0) continue;
      ScanPoint& p = points[static_cast<std::size_t>(i)];
      if (p.cls != ground) continue;
      for (const std::size_t nc : {c == 0 ? cols - 1 : c - 1, c + 1 == cols ? 0 : c + 1}) {
        const std::int32_t j = index_[row + nc];
        if (j < 0) continue;
        const ScanPoint& q = points[static_cast<std::size_t>(j)];
        const double dz = static_cast<double>(q.z) - static_cast<double>(p.z);
        if (dz <= p_.max_roughness_m) continue;  // only a neighbour standing above makes p an edge
        const double dxy = std::hypot(static_cast<double>(q.x - p.x), static_cast<double>(q.y - p.y));
        if (dz > tan_slope * dxy && dxy < 2.0) {
          p.cls = obstacle;
          break;
        }
      }
    }
  }
}

}  // namespace ag::loc
