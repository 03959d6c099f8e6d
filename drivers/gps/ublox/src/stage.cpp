// The u-blox stage: bytes to fixes to "gps".
#include "airground/drivers/gps/ublox/stage.hpp"

#include "airground/messages/channels.hpp"
#include "airground/platform/log.hpp"

#include <cmath>
#include <string>

#include "airground/drivers/gps/ublox/nmea.hpp"
#include "airground/drivers/gps/ublox/ubx.hpp"

namespace ag::ublox {

namespace {
constexpr double kA = 6378137.0, kF = 1.0 / 298.257223563, kE2 = kF * (2.0 - kF);
constexpr double kDeg = 3.14159265358979323846 / 180.0;
void ecef(double lat_deg, double lon_deg, double h, double& x, double& y, double& z) noexcept {
  const double sl = std::sin(lat_deg * kDeg), cl = std::cos(lat_deg * kDeg);
  const double n = kA / std::sqrt(1.0 - kE2 * sl * sl);
  x = (n + h) * cl * std::cos(lon_deg * kDeg);
  y = (n + h) * cl * std::sin(lon_deg * kDeg);
  z = (n * (1.0 - kE2) + h) * sl;
}
}  // namespace

LocalEnu::LocalEnu(double lat0, double lon0, double h0) noexcept
    : sl_(std::sin(lat0 * kDeg)), cl_(std::cos(lat0 * kDeg)), so_(std::sin(lon0 * kDeg)), co_(std::cos(lon0 * kDeg)) {
  ecef(lat0, lon0, h0, x0_, y0_, z0_);
}

void LocalEnu::forward(double lat, double lon, double h, double& e, double& n, double& u) const noexcept {
  double x, y, z;
  ecef(lat, lon, h, x, y, z);
  const double dx = x - x0_, dy = y - y0_, dz = z - z0_;
  e = -so_ * dx + co_ * dy;
  n = -sl_ * co_ * dx - sl_ * so_ * dy + cl_ * dz;
  u = cl_ * co_ * dx + cl_ * so_ * dy + sl_ * dz;
}

// A receiver that is absent (no device, a recording missing) does not stop the robot: the stage logs
// why, counts it and publishes nothing (the pose graph then holds its priors), like the base stage.
Status UbloxStage::init(StageContext& ctx) {
  const UbloxSettings cfg = load_params(ctx.params(), kUbloxStageFields);
  const std::string where = std::string(ctx.stage_name) + ".";
  auto w = ctx.channels.ring_writer(chan::kGps.with_name(cfg.gps_channel));
  if (!w) return w.error();
  out_ = w.value();
  const std::string& src = cfg.source;
  if (src != "serial" && src != "replay" && src != "sim" && src != "none")
    return Error::make(ErrorCode::kConfig, "config error: " + where + "source must be serial, replay, sim or none, got '" + src + "'");
  enu_ = std::make_unique<LocalEnu>(cfg.datum_lat_deg, cfg.datum_lon_deg, cfg.datum_height_m);
  max_bytes_ = cfg.max_bytes_per_step;
  buf_.assign(1024, 0);
  if (src == "none") return ok_status();
  if (ctx.device != nullptr) device_ = ctx.device;
  device_->describe("fixes", {"bad_checksum", "malformed", "garbage_bytes", "read"});
  device_name_ = src == "replay" ? cfg.replay : src == "sim" ? std::string("the simulator's receiver") : cfg.device;
  auto absent = [&](const std::string& why) {
    ++c_.device_errors;
    AG_LOG_ERROR("gps", "%s; no fixes from this receiver (the robot keeps running)", why.c_str());
    return ok_status();
  };
  if (src == "sim") {
    SimSerialLink* link = find_sim_gps(ctx.instance);
    if (link == nullptr)
      return Error::make(ErrorCode::kConfig, "config error: " + where + "source is sim but the simulator gave robot '" +
                                                 std::string(ctx.instance) + "' no receiver");
    source_ = link->open_source();
  } else if (src == "replay") {
    auto r = ReplayFile::open(cfg.replay, 1024);
    if (!r) return absent(where + "replay: " + r.error().message);
    source_ = std::move(r).value();
  } else {
    auto s = SerialPort::open(cfg.device, cfg.baud);
    if (!s) return absent(where + "device: " + s.error().message);
    source_ = std::move(s).value();
  }
  return ok_status();
}

void UbloxStage::publish(TimeNs now, std::uint8_t fix_type, double lat, double lon, double h, double hacc, double vacc) noexcept {
  GpsMsg m;
  m.stamp = now;  // the receiver's time is GPS time, not this clock: the arrival time stands in
  m.published = now;
  m.fix_type = fix_type;
  enu_->forward(lat, lon, h, m.east_m, m.north_m, m.up_m);
  m.h_accuracy_m = hacc;
  m.v_accuracy_m = vacc;
  last_ = m;
  ++c_.fixes_published;
  device_->unit_received(fix_type != 0, now);  // complete: a usable fix; incomplete: the receiver has none
  at_last_fix_ = c_;
  stream_at_last_fix_ = parser_.counters();
  if (out_.push(m) != 0) ++c_.ring_full;
}

void UbloxStage::step(TimeNs now) noexcept {
  if (!source_) return;
  for (int total = 0; total < max_bytes_;) {
    const long n = source_->read(buf_);
    if (n < 0) {
      if (!source_->at_end()) ++c_.read_errors;
      break;
    }
    if (n == 0) break;
    total += static_cast<int>(n);
    c_.bytes += static_cast<std::uint64_t>(n);
    device_->received_bytes(static_cast<std::uint64_t>(n));
    std::span<const std::uint8_t> in(buf_.data(), static_cast<std::size_t>(n));
    while (!in.empty()) {
      StreamMessage m;
      in = in.subspan(parser_.feed(in, m));
      if (m.kind == StreamMessage::Kind::kUbx && m.cls == kClassNav && m.id == kIdNavPvt) {
        NavPvt p;
        if (!decode_nav_pvt(m.payload, p)) continue;
        ++c_.nav_pvt;
        seen_pvt_ = true;
        const bool usable = p.gnss_fix_ok && (p.fix_type == FixType::k2D || p.fix_type == FixType::k3D || p.fix_type == FixType::kGnssDeadReckoning);
        publish(now, usable ? static_cast<std::uint8_t>(p.fix_type == FixType::kGnssDeadReckoning ? 3 : static_cast<int>(p.fix_type)) : 0,
                p.lat_deg, p.lon_deg, p.height_m, p.h_acc_m, p.v_acc_m);
      } else if (m.kind == StreamMessage::Kind::kNmea && !seen_pvt_) {
        GgaFix g;
        if (!parse_gga(m.sentence, g)) continue;
        ++c_.gga;
        // GGA has no accuracies: HDOP times a 2.5 m single-point error (a coarse, documented guess).
        publish(now, g.quality == 0 ? 0 : 3, g.lat_deg, g.lon_deg, g.alt_msl_m + g.geoid_sep_m, g.hdop * 2.5, g.hdop * 5.0);
      }
    }
  }
  const StreamCounters& sc = parser_.counters();
  device_->error_total(0, sc.ubx_bad_checksum + sc.nmea_bad_checksum);
  device_->error_total(1, sc.ubx_oversize + sc.nmea_malformed);
  device_->error_total(2, sc.garbage_bytes);
  device_->error_total(3, c_.read_errors);
  if (!source_->at_end() && silence_.check(*device_, now)) warn_silence(now);
}

// One warning per silence, naming the likely cause from what did arrive since the last fix.
void UbloxStage::warn_silence(TimeNs now) noexcept {
  ++c_.silence_warnings;
  const double s = static_cast<double>(silence_.silent_for(now)) * 1e-9;
  const StreamCounters& a = stream_at_last_fix_;
  const StreamCounters& b = parser_.counters();
  const std::uint64_t bytes = c_.bytes - at_last_fix_.bytes;
  const std::uint64_t frames = (b.ubx_frames - a.ubx_frames) + (b.nmea_sentences - a.nmea_sentences);
  const std::uint64_t bad = (b.ubx_bad_checksum - a.ubx_bad_checksum) + (b.nmea_bad_checksum - a.nmea_bad_checksum);
  if (bytes == 0)
    AG_LOG_WARN("gps", "no fix for %.0f s: no bytes at all from %s (wrong device, receiver unplugged or not powered)", s, device_name_.c_str());
  else if (frames == 0 && bad == 0)
    AG_LOG_WARN("gps", "no fix for %.0f s: %llu bytes from %s but no UBX or NMEA message (wrong baud rate: gps.baud)", s,
                static_cast<unsigned long long>(bytes), device_name_.c_str());
  else if (frames == 0)
    AG_LOG_WARN("gps", "no fix for %.0f s: %llu messages with bad checksums from %s (noise on the line or wrong baud rate)", s,
                static_cast<unsigned long long>(bad), device_name_.c_str());
  else
    AG_LOG_WARN("gps", "no fix for %.0f s: %llu messages from %s but no NAV-PVT or GGA (enable UBX-NAV-PVT on the receiver's port)", s,
                static_cast<unsigned long long>(frames), device_name_.c_str());
}

}  // namespace ag::ublox
