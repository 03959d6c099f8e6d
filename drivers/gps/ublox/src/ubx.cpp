// UBX checksum, framing and NAV-PVT.
#include "airground/drivers/gps/ublox/ubx.hpp"

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
  o.valid_raw = p[11];
  o.flags_raw = p[21];
  o.flags2_raw = p[22];
  o.flags3_raw = le<std::uint16_t>(p + 78);
  o.height_mm = le<std::int32_t>(p + 32);
  o.hmsl_mm = le<std::int32_t>(p + 36);
  o.h_acc_mm = le<std::uint32_t>(p + 40);
  o.v_acc_mm = le<std::uint32_t>(p + 44);
  for (int i = 0; i < 3; ++i) o.vel_ned_mm_s[i] = le<std::int32_t>(p + 48 + 4 * i);
  o.ground_speed_mm_s = le<std::int32_t>(p + 60);
  o.heading_motion_e5 = le<std::int32_t>(p + 64);
  o.s_acc_mm_s = le<std::uint32_t>(p + 68);
  o.head_acc_e5 = le<std::uint32_t>(p + 72);
  o.pdop_e2 = le<std::uint16_t>(p + 76);
  o.head_veh_e5 = le<std::int32_t>(p + 84);
  o.mag_dec_e2 = le<std::int16_t>(p + 88);
  o.mag_acc_e2 = le<std::uint16_t>(p + 90);
  return true;
}

namespace {
template <typename T>
void put(std::uint8_t* p, T v) noexcept {
  std::memcpy(p, &v, sizeof v);
}
}  // namespace

void encode_nav_pvt(const NavPvt& o, std::span<std::uint8_t, kNavPvtLength> out) noexcept {
  std::uint8_t* p = out.data();
  std::memset(p, 0, kNavPvtLength);
  put(p, o.itow_ms);
  put(p + 4, o.year);
  p[6] = o.month;
  p[7] = o.day;
  p[8] = o.hour;
  p[9] = o.minute;
  p[10] = o.second;
  p[11] = o.valid_raw;
  put(p + 12, o.t_acc_ns);
  put(p + 16, o.nano);
  p[20] = static_cast<std::uint8_t>(o.fix_type);
  p[21] = o.flags_raw;
  p[22] = o.flags2_raw;
  p[23] = o.num_sv;
  put(p + 24, o.lon_e7);
  put(p + 28, o.lat_e7);
  put(p + 32, o.height_mm);
  put(p + 36, o.hmsl_mm);
  put(p + 40, o.h_acc_mm);
  put(p + 44, o.v_acc_mm);
  for (int i = 0; i < 3; ++i) put(p + 48 + 4 * i, o.vel_ned_mm_s[i]);
  put(p + 60, o.ground_speed_mm_s);
  put(p + 64, o.heading_motion_e5);
  put(p + 68, o.s_acc_mm_s);
  put(p + 72, o.head_acc_e5);
  put(p + 76, o.pdop_e2);
  put(p + 78, o.flags3_raw);
  put(p + 84, o.head_veh_e5);
  put(p + 88, o.mag_dec_e2);
  put(p + 90, o.mag_acc_e2);
}

}  // namespace ag::ublox
