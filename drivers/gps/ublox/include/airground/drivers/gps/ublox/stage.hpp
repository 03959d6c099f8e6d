// The u-blox stage: the quadrotor's GNSS. Every step it reads what the receiver sent (serial port on
// the robot, a replay file on the desk), cuts it into UBX and NMEA, and publishes each NAV-PVT fix as a
// "gps" message in the map frame (local ENU around the mission datum, WGS-84). NMEA GGA is the fallback
// while no NAV-PVT has been seen (a receiver left in its NMEA default).
#pragma once

#include <memory>
#include <span>
#include <string>
#include <vector>

#include "airground/messages/channels.hpp"
#include "airground/messages/messages.hpp"
#include "airground/drivers/gps/ublox/byte_source.hpp"
#include "airground/drivers/gps/ublox/stream_parser.hpp"
#include "airground/platform/param_binding.hpp"
#include "airground/platform/stage.hpp"

namespace ag::ublox {

// WGS-84 geodetic to local east/north/up around a datum (exact: through ECEF).
class LocalEnu {
 public:
  LocalEnu(double lat0_deg, double lon0_deg, double h0_m) noexcept;
  void forward(double lat_deg, double lon_deg, double h_m, double& e, double& n, double& u) const noexcept;

 private:
  double x0_, y0_, z0_, sl_, cl_, so_, co_;
};

struct UbloxSettings {
  std::string source{"serial"};
  std::string device{"/dev/ttyACM0"};
  int baud{115200};
  std::string replay;
  double datum_lat_deg{0.0};
  double datum_lon_deg{0.0};
  double datum_height_m{0.0};
  int max_bytes_per_step{4096};
  std::string gps_channel{chan::kGps.name};
};
inline constexpr ParamField<UbloxSettings> kUbloxStageFields[] = {
    field::text("source", &UbloxSettings::source, "serial", "serial|replay|sim|none", "bytes from the receiver (serial port), a recording (replay), the simulator's receiver, or no receiver"),
    field::text("device", &UbloxSettings::device, "/dev/ttyACM0", "", "serial device of the receiver"),
    field::integer("baud", &UbloxSettings::baud, 9600, 921600, "Bd", "serial speed"),
    field::text("replay", &UbloxSettings::replay, "", "", "recorded stream to replay when source is replay"),
    field::real("datum_lat_deg", &UbloxSettings::datum_lat_deg, -90.0, 90.0, "deg", "mission datum latitude (the map frame's origin)"),
    field::real("datum_lon_deg", &UbloxSettings::datum_lon_deg, -180.0, 180.0, "deg", "mission datum longitude"),
    field::real("datum_height_m", &UbloxSettings::datum_height_m, -1000.0, 10000.0, "m", "mission datum height above the WGS-84 ellipsoid"),
    field::integer("max_bytes_per_step", &UbloxSettings::max_bytes_per_step, 64, 65536, "B", "bytes read per step (115200 Bd is 11.5 kB/s)"),
    field::text("gps_channel", &UbloxSettings::gps_channel, chan::kGps.name, "", "ring channel the fixes are published on"),
};
inline constexpr auto kUbloxStageParams = param_specs(kUbloxStageFields);

struct UbloxStageCounters {
  std::uint64_t nav_pvt{0}, gga{0};
  std::uint64_t fixes_published{0};
  std::uint64_t read_errors{0};
  std::uint64_t ring_full{0};
  std::uint64_t device_errors{0};  // no device or recording: the stage publishes nothing
  std::uint64_t bytes{0};          // read from the receiver
  std::uint64_t silence_warnings{0};  // "no fix for a few seconds" warnings logged
};

class UbloxStage final : public Stage {
 public:
  static constexpr std::span<const ParamSpec> kParams{kUbloxStageParams};
  static std::unique_ptr<Stage> make() { return std::make_unique<UbloxStage>(); }

  Status init(StageContext& ctx) override;
  void step(TimeNs now) noexcept override;

  [[nodiscard]] const UbloxStageCounters& counters() const noexcept { return c_; }
  [[nodiscard]] const StreamCounters& stream_counters() const noexcept { return parser_.counters(); }
  [[nodiscard]] const GpsMsg& last_fix() const noexcept { return last_; }
  [[nodiscard]] bool active() const noexcept { return source_ != nullptr; }

 private:
  void publish(TimeNs now, std::uint8_t fix_type, double lat, double lon, double h, double hacc, double vacc) noexcept;
  void warn_silence(TimeNs now) noexcept;
  std::unique_ptr<ByteSource> source_;
  std::unique_ptr<LocalEnu> enu_;
  StreamParser parser_;
  std::vector<std::uint8_t> buf_;
  RingWriter<GpsMsg, kGpsRing> out_;
  int max_bytes_{4096};
  bool seen_pvt_{false};
  GpsMsg last_{};
  UbloxStageCounters c_;
  UbloxStageCounters at_last_fix_;
  StreamCounters stream_at_last_fix_;
  DeviceCounters own_device_;
  DeviceCounters* device_{&own_device_};
  DeviceSilence silence_;
  std::string device_name_;  // for the warning (init-time string)
};

}  // namespace ag::ublox
