// The particle filter's obstacle prior (ParticleFilterParams::obstacle_*): how far a particle lies from
// the nearest cell where the robot has room, searched cell by cell outward over a nearest-first table.
#include <algorithm>
#include <cmath>

#include "airground/localization/particle_filter.hpp"

namespace ag::loc {

void ParticleFilter::build_room_table() {
  for (int dr = -kRoomTableCells; dr <= kRoomTableCells; ++dr)
    for (int dc = -kRoomTableCells; dc <= kRoomTableCells; ++dc)
      if (dc * dc + dr * dr <= kRoomTableCells * kRoomTableCells)
        room_.push_back({static_cast<std::int16_t>(dc), static_cast<std::int16_t>(dr), dc * dc + dr * dr});
  std::stable_sort(room_.begin(), room_.end(), [](const RoomOffset& a, const RoomOffset& b) { return a.d2 < b.d2; });
}

double ParticleFilter::room_distance_m(const ClassDistanceFields& f, std::uint8_t obstacle_mask, double x, double y) const noexcept {
  const double res = f.resolution_m();
  const auto c0 = static_cast<std::int64_t>(std::floor((x - f.origin_x()) / res));
  const auto r0 = static_cast<std::int64_t>(std::floor((y - f.origin_y()) / res));
  const auto stride = static_cast<std::size_t>(f.stride());
  // The planner's clearance runs from a cell's centre to the nearest blocked cell's edge, the fields'
  // from centre to centre: half a cell more here (Roadmap's free_min_edt_).
  const int clear_q = static_cast<int>(std::ceil((p_.obstacle_clearance_m + 0.5 * res) / f.quantum_m() - 1e-9));
  const double reach = p_.obstacle_max_depth_m / res;
  const double reach2 = std::min(reach * reach, static_cast<double>(kRoomTableCells * kRoomTableCells));
  for (const RoomOffset& o : room_) {
    if (static_cast<double>(o.d2) > reach2) break;
    const std::int64_t c = c0 + o.dc, r = r0 + o.dr;
    const double d = std::sqrt(static_cast<double>(o.d2)) * res;
    if (c < 0 || r < 0 || c >= f.width() || r >= f.height()) return d;  // outside the fields: unknown
    const std::uint8_t* cell = f.cells() + static_cast<std::size_t>(r * f.width() + c) * stride;
    if (cell[stride - 1] == raw(ClassId::kUnknown)) return d;
    int clearance = 255;
    for (int k = 0; k < f.channels().count(); ++k)
      if ((obstacle_mask >> static_cast<unsigned>(k)) & 1U) clearance = std::min(clearance, static_cast<int>(cell[k]));
    if (clearance >= clear_q) return d;
  }
  return p_.obstacle_max_depth_m;
}

std::uint8_t ParticleFilter::room_channels(const ClassDistanceFields& f) const noexcept {
  if (p_.obstacle_penalty_per_m <= 0.0) return 0;
  const LocalizationChannels& ch = f.channels();
  const bool confirmed = est_.status == FilterStatus::kTracking && tracked_m_ >= p_.confirm_distance_m;
  if (p_.confirmed_room_obstacles_only && confirmed && ch.blocked_space_channels() != 0U) return ch.blocked_space_channels();
  return ch.obstacle_space_channels();
}

bool ParticleFilter::pose_blocked(const ClassDistanceFields& fields) const noexcept {
  if (est_.status == FilterStatus::kUninitialised) return false;
  const std::uint8_t mask = room_channels(fields);
  return mask != 0U && room_distance_m(fields, mask, est_.pose.x, est_.pose.y) > p_.obstacle_margin_m;
}

}  // namespace ag::loc
