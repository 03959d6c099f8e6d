// NMEA GGA and RMC.
#include "airground/drivers/gps/ublox/nmea.hpp"

#include <array>
#include <charconv>
#include <cmath>

namespace ag::ublox {

namespace {
int hexval(char c) noexcept {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  return -1;
}

std::string_view trim_eol(std::string_view s) noexcept {
  while (!s.empty() && (s.back() == '\r' || s.back() == '\n')) s.remove_suffix(1);
  return s;
}

// Splits the body (between '$' and '*') into comma fields.
struct Fields {
  std::array<std::string_view, 24> f{};
  std::size_t n{0};
};
bool split(std::string_view sentence, Fields& out) noexcept {
  sentence = trim_eol(sentence);
  if (!nmea_checksum_ok(sentence)) return false;
  const auto star = sentence.rfind('*');
  std::string_view body = sentence.substr(1, star - 1);
  out.n = 0;
  for (;;) {
    const auto c = body.find(',');
    if (out.n == out.f.size()) return false;
    out.f[out.n++] = body.substr(0, c);
    if (c == std::string_view::npos) break;
    body.remove_prefix(c + 1);
  }
  return true;
}

bool num(std::string_view s, double& v) noexcept {
  if (s.empty()) return false;
  const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
  return r.ec == std::errc{} && r.ptr == s.data() + s.size() && std::isfinite(v);
}
bool inum(std::string_view s, int& v) noexcept {
  if (s.empty()) return false;
  const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
  return r.ec == std::errc{} && r.ptr == s.data() + s.size();
}
// ddmm.mmmm / dddmm.mmmm with a hemisphere letter.
bool coord(std::string_view v, std::string_view hemi, int deg_digits, double& out) noexcept {
  if (v.size() < static_cast<std::size_t>(deg_digits) + 2 || hemi.size() != 1) return false;
  int d = 0;
  double m = 0;
  if (!inum(v.substr(0, static_cast<std::size_t>(deg_digits)), d) || !num(v.substr(static_cast<std::size_t>(deg_digits)), m)) return false;
  if (m < 0 || m >= 60 || d < 0 || d > (deg_digits == 2 ? 90 : 180)) return false;
  out = d + m / 60.0;
  if (hemi[0] == 'S' || hemi[0] == 'W') out = -out;
  else if (hemi[0] != 'N' && hemi[0] != 'E') return false;
  return true;
}
bool hms(std::string_view v, double& out) noexcept {
  int hh = 0, mm = 0;
  double ss = 0;
  if (v.size() < 6 || !inum(v.substr(0, 2), hh) || !inum(v.substr(2, 2), mm) || !num(v.substr(4), ss)) return false;
  if (hh > 23 || mm > 59 || ss < 0 || ss >= 61) return false;
  out = hh * 3600.0 + mm * 60.0 + ss;
  return true;
}
bool type_is(std::string_view f0, std::string_view t) noexcept { return f0.size() == 5 && f0.substr(2) == t; }
}  // namespace

std::uint8_t nmea_checksum(std::string_view body) noexcept {
  std::uint8_t x = 0;
  for (char c : body) x = static_cast<std::uint8_t>(x ^ static_cast<std::uint8_t>(c));
  return x;
}

bool nmea_checksum_ok(std::string_view s) noexcept {
  s = trim_eol(s);
  if (s.size() < 4 || s[0] != '$') return false;
  const auto star = s.rfind('*');
  if (star == std::string_view::npos || star + 3 != s.size()) return false;
  const int h = hexval(s[star + 1]), l = hexval(s[star + 2]);
  if (h < 0 || l < 0) return false;
  return nmea_checksum(s.substr(1, star - 1)) == static_cast<std::uint8_t>(h * 16 + l);
}

bool parse_gga(std::string_view s, GgaFix& o) noexcept {
  Fields f;
  if (!split(s, f) || f.n < 15 || !type_is(f.f[0], "GGA")) return false;
  GgaFix g;
  if (!inum(f.f[6], g.quality) || g.quality < 0 || g.quality > 9) return false;
  if (!f.f[1].empty() && !hms(f.f[1], g.utc_seconds_of_day)) return false;
  if (g.quality != 0) {
    if (!coord(f.f[2], f.f[3], 2, g.lat_deg) || !coord(f.f[4], f.f[5], 3, g.lon_deg)) return false;
    if (!f.f[9].empty() && !num(f.f[9], g.alt_msl_m)) return false;
  }
  if (!f.f[7].empty() && !inum(f.f[7], g.num_sv)) return false;
  if (!f.f[8].empty() && !num(f.f[8], g.hdop)) return false;
  if (!f.f[11].empty() && !num(f.f[11], g.geoid_sep_m)) return false;
  o = g;
  return true;
}

bool parse_rmc(std::string_view s, RmcFix& o) noexcept {
  Fields f;
  if (!split(s, f) || f.n < 10 || !type_is(f.f[0], "RMC")) return false;
  RmcFix r;
  if (f.f[2] != "A" && f.f[2] != "V") return false;
  r.valid = f.f[2] == "A";
  if (!f.f[1].empty() && !hms(f.f[1], r.utc_seconds_of_day)) return false;
  if (r.valid && (!coord(f.f[3], f.f[4], 2, r.lat_deg) || !coord(f.f[5], f.f[6], 3, r.lon_deg))) return false;
  double knots = 0;
  if (!f.f[7].empty() && !num(f.f[7], knots)) return false;
  r.speed_m_s = knots * 1852.0 / 3600.0;
  if (!f.f[8].empty() && !num(f.f[8], r.course_deg)) return false;
  if (f.f[9].size() == 6) {
    if (!inum(f.f[9].substr(0, 2), r.day) || !inum(f.f[9].substr(2, 2), r.month) || !inum(f.f[9].substr(4, 2), r.year)) return false;
    r.year += r.year < 80 ? 2000 : 1900;
  } else if (!f.f[9].empty()) {
    return false;
  }
  o = r;
  return true;
}

}  // namespace ag::ublox
