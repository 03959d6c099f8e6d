// UBX checksum, framing and NAV-PVT.
#include "airground/drivers/ublox/ubx.hpp"

#include <cstring>

namespace ag::ublox {

namespace {
template <typename T>
T le(const std::uint8_t* p) noexcept {
  T v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
}  // namespace

Fletcher8 ubx_checksum(std::uint8_t cls, std::uint8_t id, std::span<const std::uint8_t> payload) noexcept {
  Fletcher8 f;
  f.add(cls);
  f.add(id);
  f.add(static_cast<std::uint8_t>(payload.size() & 0xFF));
  f.add(static_cast<std::uint8_t>((payload.size() >> 8) & 0xFF));
  for (std::uint8_t x : payload) f.add(x);
  return f;
}

std::size_t ubx_encode(std::uint8_t cls, std::uint8_t id, std::span<const std::uint8_t> payload, std::span<std::uint8_t> out) noexcept {
  if (payload.size() > 0xFFFF || out.size() < payload.size() + 8) return 0;
  out[0] = kSync1;
  out[1] = kSync2;
  out[2] = cls;
  out[3] = id;
  out[4] = static_cast<std::uint8_t>(payload.size() & 0xFF);
  out[5] = static_cast<std::uint8_t>(payload.size() >> 8);
  if (!payload.empty()) std::memcpy(out.data() + 6, payload.data(), payload.size());
  const Fletcher8 f = ubx_checksum(cls, id, payload);
  out[6 + payload.size()] = f.a;
  out[7 + payload.size()] = f.b;
  return payload.size() + 8;
}

bool decode_nav_pvt(std::span<const std::uint8_t> payload, NavPvt& o) noexcept {
  if (payload.size() != kNavPvtLength) return false;
  const std::uint8_t* p = payload.data();
  if (p[20] > 5) return false;
  o.itow_ms = le<std::uint32_t>(p);
  o.year = le<std::uint16_t>(p + 4);
  o.month = p[6];
  o.day = p[7];
  o.hour = p[8];
  o.minute = p[9];
  o.second = p[10];
  o.valid_date = (p[11] & 0x01) != 0;
  o.valid_time = (p[11] & 0x02) != 0;
  o.fully_resolved = (p[11] & 0x04) != 0;
  o.t_acc_ns = le<std::uint32_t>(p + 12);
  o.nano = le<std::int32_t>(p + 16);
  o.fix_type = static_cast<FixType>(p[20]);
  o.gnss_fix_ok = (p[21] & 0x01) != 0;
  o.diff_soln = (p[21] & 0x02) != 0;
  const unsigned carr = (p[21] >> 6) & 0x03u;
  o.carrier = carr == 1 ? CarrierSolution::kFloat : carr == 2 ? CarrierSolution::kFixed : CarrierSolution::kNone;
  o.num_sv = p[23];
  o.lon_e7 = le<std::int32_t>(p + 24);
  o.lat_e7 = le<std::int32_t>(p + 28);
  o.lon_deg = static_cast<double>(o.lon_e7) * 1e-7;
  o.lat_deg = static_cast<double>(o.lat_e7) * 1e-7;
  o.height_m = static_cast<double>(le<std::int32_t>(p + 32)) * 1e-3;
  o.hmsl_m = static_cast<double>(le<std::int32_t>(p + 36)) * 1e-3;
  o.h_acc_m = static_cast<double>(le<std::uint32_t>(p + 40)) * 1e-3;
  o.v_acc_m = static_cast<double>(le<std::uint32_t>(p + 44)) * 1e-3;
  for (int i = 0; i < 3; ++i) o.vel_ned_m_s[i] = static_cast<double>(le<std::int32_t>(p + 48 + 4 * i)) * 1e-3;
  o.ground_speed_m_s = static_cast<double>(le<std::int32_t>(p + 60)) * 1e-3;
  o.heading_motion_deg = static_cast<double>(le<std::int32_t>(p + 64)) * 1e-5;
  o.s_acc_m_s = static_cast<double>(le<std::uint32_t>(p + 68)) * 1e-3;
  o.head_acc_deg = static_cast<double>(le<std::uint32_t>(p + 72)) * 1e-5;
  o.pdop = static_cast<double>(le<std::uint16_t>(p + 76)) * 0.01;
  return true;
}

}  // namespace ag::ublox
