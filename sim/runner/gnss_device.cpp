// The simulated u-blox receiver's NAV-PVT.
#include "gnss_device.hpp"

#include <cmath>

namespace ag::sim {

std::size_t encode_nav_pvt_message(TimeNs now, const GpsFix& fix, NavPvtBytes& out) noexcept {
  ublox::NavPvt p;
  p.itow_ms = static_cast<std::uint32_t>((now / kNsPerMs) % (7 * 24 * 3600 * 1000LL));
  p.fix_type = fix.fix_type == GpsFixType::kNoFix ? ublox::FixType::kNone : ublox::FixType::k3D;
  p.flags_raw = fix.fix_type == GpsFixType::kNoFix ? 0 : 1;  // gnssFixOK
  p.valid_raw = 0x07;
  p.num_sv = 14;
  p.lat_e7 = static_cast<std::int32_t>(std::lround(fix.lat_deg * 1e7));
  p.lon_e7 = static_cast<std::int32_t>(std::lround(fix.lon_deg * 1e7));
  p.height_mm = static_cast<std::int32_t>(std::lround(fix.height_m * 1e3));
  p.hmsl_mm = p.height_mm;
  p.h_acc_mm = static_cast<std::uint32_t>(std::lround(fix.h_accuracy_m * 1e3));
  p.v_acc_mm = static_cast<std::uint32_t>(std::lround(fix.v_accuracy_m * 1e3));
  p.vel_ned_mm_s[0] = static_cast<std::int32_t>(std::lround(fix.vel_north_mps * 1e3));
  p.vel_ned_mm_s[1] = static_cast<std::int32_t>(std::lround(fix.vel_east_mps * 1e3));
  p.vel_ned_mm_s[2] = static_cast<std::int32_t>(std::lround(-fix.vel_up_mps * 1e3));
  p.pdop_e2 = 120;
  std::array<std::uint8_t, ublox::kNavPvtLength> payload{};
  ublox::encode_nav_pvt(p, payload);
  return ublox::ubx_encode(ublox::kClassNav, ublox::kIdNavPvt, payload, out);
}

}  // namespace ag::sim
