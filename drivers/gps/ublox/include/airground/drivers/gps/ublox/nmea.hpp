// NMEA 0183 fallback sentences: GGA (fix, position, altitude) and RMC (position, speed, course, date).
// A sentence is "$TTSSS,f1,...,fn*HH" with HH the XOR of the characters between '$' and '*'.
#pragma once

#include <cstdint>
#include <string_view>

namespace ag::ublox {

// True when the sentence (with or without CR/LF) has a '*HH' that matches its content.
[[nodiscard]] bool nmea_checksum_ok(std::string_view sentence) noexcept;
[[nodiscard]] std::uint8_t nmea_checksum(std::string_view body) noexcept;  // XOR of body (between $ and *)

struct GgaFix {
  double utc_seconds_of_day{0};
  double lat_deg{0}, lon_deg{0};
  int quality{0};          // 0 invalid, 1 GPS, 2 DGPS, 4 RTK fixed, 5 RTK float, 6 dead reckoning
  int num_sv{0};
  double hdop{0};
  double alt_msl_m{0}, geoid_sep_m{0};
};
struct RmcFix {
  double utc_seconds_of_day{0};
  bool valid{false};       // status A
  double lat_deg{0}, lon_deg{0};
  double speed_m_s{0}, course_deg{0};
  int day{0}, month{0}, year{0};
};

// Parse a checksummed sentence of any talker (GP, GN, GL...); false when it is another sentence type,
// the checksum is wrong or a field is malformed.
[[nodiscard]] bool parse_gga(std::string_view sentence, GgaFix& out) noexcept;
[[nodiscard]] bool parse_rmc(std::string_view sentence, RmcFix& out) noexcept;

}  // namespace ag::ublox
