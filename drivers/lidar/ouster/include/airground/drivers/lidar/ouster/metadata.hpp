// Ouster sensor metadata (the sensor's JSON, as `get_metadata` / the SDK write it): beam angles, lidar
// mode, packet layout, beam-origin offset and the lidar-to-sensor transform. Four layouts are read:
// the legacy flat file (FW 1.x-2.1), the flat FW 2.x file (the same keys plus data_format.udp_profile_lidar),
// the reduced config (angles and mode only: the rest takes the OS-1 defaults the Ouster SDK uses) and the
// nested FW 2.2+/3.x file (sensor_info, beam_intrinsics, lidar_data_format, config_params...).
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "airground/platform/result.hpp"

namespace ag::ouster {

inline constexpr int kMaxColumnsPerPacketSupported = 16;  // what the sensors send (1, 2, 4, 8, 16)

enum class UdpProfile : std::uint8_t {
  kLegacy = 0,                   // FW <= 2.1: per-column frame id and encoder count, 12 B pixels
  kRng19Rfl8Sig16Nir16 = 1,      // FW 2.2+ single return: 32 B packet header and footer, 12 B pixels
  kRng19Rfl8Sig16Nir16Dual = 2,  // FW 2.2+ dual return: 16 B pixels, both returns
  kRng15Rfl8Nir8 = 3,            // FW 2.2+ low data rate: 4 B pixels, range in units of 8 mm
};
inline constexpr UdpProfile kSupportedProfiles[] = {UdpProfile::kLegacy, UdpProfile::kRng19Rfl8Sig16Nir16,
                                                    UdpProfile::kRng19Rfl8Sig16Nir16Dual, UdpProfile::kRng15Rfl8Nir8};
const char* to_string(UdpProfile p) noexcept;
// The error (kConfig) names the text and every supported profile.
Result<UdpProfile> parse_udp_profile(std::string_view text);
[[nodiscard]] constexpr bool has_second_return(UdpProfile p) noexcept { return p == UdpProfile::kRng19Rfl8Sig16Nir16Dual; }

struct LidarMode {
  int columns{1024};       // columns per frame (512, 1024, 2048, 4096)
  int frequency_hz{10};    // frames per second (10, 20; 5 for 4096)
};
// "1024x10" -> {1024, 10}; the error names the text.
Result<LidarMode> parse_lidar_mode(std::string_view text);

using Mat4 = std::array<double, 16>;  // row-major homogeneous transform, translation in mm
inline constexpr Mat4 kIdentity4{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
// The SDK's default for OS-1 when the file has none: 180 deg about z, 36.18 mm up.
inline constexpr Mat4 kDefaultLidarToSensor{-1, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1, 36.18, 0, 0, 0, 1};
inline constexpr double kDefaultOs1BeamOriginMm = 12.163;

struct SensorInfo {
  std::string prod_line;             // "OS-1-64", "" when the file has none
  std::string firmware;              // "v2.1.2"
  LidarMode mode;
  UdpProfile profile{UdpProfile::kLegacy};
  int pixels_per_column{64};         // beams
  int columns_per_packet{16};
  int column_window_first{0}, column_window_last{1023};  // columns the sensor sends (wraps when first > last)
  [[nodiscard]] int columns_in_window() const noexcept {
    return column_window_first <= column_window_last ? column_window_last - column_window_first + 1
                                                     : mode.columns - column_window_first + column_window_last + 1;
  }
  std::vector<double> beam_altitude_deg;  // one per beam, top first
  std::vector<double> beam_azimuth_deg;
  std::vector<int> pixel_shift_by_row;    // destagger offsets (empty when unknown)
  double lidar_origin_to_beam_origin_mm{kDefaultOs1BeamOriginMm};
  Mat4 beam_to_lidar{};                   // filled from the beam-origin offset when the file has none
  Mat4 lidar_to_sensor{kDefaultLidarToSensor};
  Mat4 imu_to_sensor{kIdentity4};
  std::string layout;                     // which metadata layout the file had: legacy, flat-2.x, reduced, nested
  std::uint16_t udp_port_lidar{7502}, udp_port_imu{7503};
};

// Parses and validates (beam counts, mode, window, port ranges); `origin` names the file in errors.
Result<SensorInfo> parse_metadata(std::string_view json_text, std::string_view origin);
Result<SensorInfo> read_metadata_file(const std::string& path);

}  // namespace ag::ouster
