// Ouster metadata JSON into SensorInfo (nlohmann-json; init-time code, exceptions stay inside).
#include "airground/drivers/lidar/ouster/metadata.hpp"

#include <charconv>
#include <cmath>
#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>

namespace ag::ouster {

const char* to_string(UdpProfile p) noexcept {
  switch (p) {
    case UdpProfile::kLegacy: return "LEGACY";
    case UdpProfile::kRng19Rfl8Sig16Nir16: return "RNG19_RFL8_SIG16_NIR16";
    case UdpProfile::kRng19Rfl8Sig16Nir16Dual: return "RNG19_RFL8_SIG16_NIR16_DUAL";
    case UdpProfile::kRng15Rfl8Nir8: return "RNG15_RFL8_NIR8";
  }
  return "?";
}

Result<UdpProfile> parse_udp_profile(std::string_view text) {
  std::string supported;
  for (UdpProfile p : kSupportedProfiles) {
    if (text == to_string(p)) return p;
    supported += (supported.empty() ? "" : ", ") + std::string(to_string(p));
  }
  return Error::make(ErrorCode::kConfig, "udp_profile_lidar '" + std::string(text) +
                                             "' is not a packet profile this decoder supports (supported: " + supported + ")");
}

Result<LidarMode> parse_lidar_mode(std::string_view text) {
  const auto x = text.find('x');
  LidarMode m;
  if (x == std::string_view::npos) return Error::make(ErrorCode::kConfig, "lidar_mode '" + std::string(text) + "' is not COLSxHZ");
  const auto a = std::from_chars(text.data(), text.data() + x, m.columns);
  const auto b = std::from_chars(text.data() + x + 1, text.data() + text.size(), m.frequency_hz);
  if (a.ec != std::errc{} || a.ptr != text.data() + x || b.ec != std::errc{} || b.ptr != text.data() + text.size())
    return Error::make(ErrorCode::kConfig, "lidar_mode '" + std::string(text) + "' is not COLSxHZ");
  const bool cols_ok = m.columns == 512 || m.columns == 1024 || m.columns == 2048 || m.columns == 4096;
  const bool hz_ok = m.frequency_hz == 5 || m.frequency_hz == 10 || m.frequency_hz == 20;
  if (!cols_ok || !hz_ok) return Error::make(ErrorCode::kConfig, "lidar_mode '" + std::string(text) + "' is not an Ouster mode");
  return m;
}

namespace {

using nlohmann::json;

const json* find(const json& j, std::initializer_list<const char*> path) {
  const json* cur = &j;
  for (const char* k : path) {
    if (!cur->is_object()) return nullptr;
    auto it = cur->find(k);
    if (it == cur->end()) return nullptr;
    cur = &*it;
  }
  return cur;
}

// The first of several places a key may live (flat legacy file, nested FW 2.2+ file).
const json* find_any(const json& j, std::initializer_list<std::initializer_list<const char*>> paths) {
  for (auto p : paths)
    if (const json* v = find(j, p)) return v;
  return nullptr;
}

Status read_mat4(const json* v, const char* name, Mat4& out) {
  if (v == nullptr) return ok_status();
  if (!v->is_array() || v->size() != 16) return Error::make(ErrorCode::kConfig, std::string(name) + " must be 16 numbers");
  for (std::size_t i = 0; i < 16; ++i) {
    if (!(*v)[i].is_number()) return Error::make(ErrorCode::kConfig, std::string(name) + "[" + std::to_string(i) + "] is not a number");
    out[i] = (*v)[i].get<double>();
  }
  return ok_status();
}

Status read_angles(const json* v, const char* name, std::vector<double>& out) {
  if (v == nullptr) return Error::make(ErrorCode::kConfig, std::string("missing ") + name);
  if (!v->is_array() || v->empty()) return Error::make(ErrorCode::kConfig, std::string(name) + " must be a non-empty array");
  out.clear();
  for (std::size_t i = 0; i < v->size(); ++i) {
    const json& e = (*v)[i];
    if (!e.is_number() || !std::isfinite(e.get<double>()) || std::abs(e.get<double>()) > 90.0)
      return Error::make(ErrorCode::kConfig, std::string(name) + "[" + std::to_string(i) + "] is not an angle in degrees");
    out.push_back(e.get<double>());
  }
  return ok_status();
}

Result<int> read_int(const json* v, const char* name, int lo, int hi, int fallback) {
  if (v == nullptr) return fallback;
  if (!v->is_number_integer()) return Error::make(ErrorCode::kConfig, std::string(name) + " is not an integer");
  const auto x = v->get<long long>();
  if (x < lo || x > hi)
    return Error::make(ErrorCode::kConfig, std::string(name) + " = " + std::to_string(x) + " is outside [" + std::to_string(lo) +
                                               ", " + std::to_string(hi) + "]");
  return static_cast<int>(x);
}

Result<SensorInfo> parse(const json& j) {
  SensorInfo s;
  if (!j.is_object()) return Error::make(ErrorCode::kConfig, "top level is not an object");
  if (const json* v = find_any(j, {{"prod_line"}, {"sensor_info", "prod_line"}}); v && v->is_string()) s.prod_line = v->get<std::string>();
  if (const json* v = find_any(j, {{"build_rev"}, {"sensor_info", "build_rev"}}); v && v->is_string()) s.firmware = v->get<std::string>();

  const json* mode = find_any(j, {{"lidar_mode"}, {"config_params", "lidar_mode"}});
  if (mode == nullptr || !mode->is_string()) return Error::make(ErrorCode::kConfig, "missing lidar_mode");
  auto m = parse_lidar_mode(mode->get<std::string>());
  if (!m) return m.error();
  s.mode = m.value();

  // What the packets are: the data format (flat 2.x "data_format", nested "lidar_data_format") first,
  // then what was asked of the sensor; a file with none is a legacy sensor.
  if (const json* v = find_any(j, {{"data_format", "udp_profile_lidar"}, {"lidar_data_format", "udp_profile_lidar"},
                                   {"config_params", "udp_profile_lidar"}, {"udp_profile_lidar"}})) {
    if (!v->is_string()) return Error::make(ErrorCode::kConfig, "udp_profile_lidar is not a string");
    auto p = parse_udp_profile(v->get<std::string>());
    if (!p) return p.error();
    s.profile = p.value();
  }

  if (auto st = read_angles(find_any(j, {{"beam_altitude_angles"}, {"beam_intrinsics", "beam_altitude_angles"}}), "beam_altitude_angles",
                            s.beam_altitude_deg); !st)
    return st.error();
  if (auto st = read_angles(find_any(j, {{"beam_azimuth_angles"}, {"beam_intrinsics", "beam_azimuth_angles"}}), "beam_azimuth_angles",
                            s.beam_azimuth_deg); !st)
    return st.error();
  if (s.beam_altitude_deg.size() != s.beam_azimuth_deg.size())
    return Error::make(ErrorCode::kConfig, "beam_altitude_angles has " + std::to_string(s.beam_altitude_deg.size()) +
                                               " beams but beam_azimuth_angles " + std::to_string(s.beam_azimuth_deg.size()));
  const int beams = static_cast<int>(s.beam_altitude_deg.size());

  const json* fmt = find_any(j, {{"data_format"}, {"lidar_data_format"}});
  if (find(j, {"sensor_info"}) != nullptr || find(j, {"lidar_data_format"}) != nullptr) s.layout = "nested";
  else if (fmt != nullptr && find(*fmt, {"udp_profile_lidar"}) != nullptr) s.layout = "flat-2.x";
  else if (fmt != nullptr) s.layout = "legacy";
  else s.layout = "reduced";
  const json empty = json::object();
  if (fmt == nullptr) fmt = &empty;
  auto ppc = read_int(find(*fmt, {"pixels_per_column"}), "pixels_per_column", 16, 128, beams);
  if (!ppc) return ppc.error();
  s.pixels_per_column = ppc.value();
  if (s.pixels_per_column != beams)
    return Error::make(ErrorCode::kConfig, "pixels_per_column = " + std::to_string(s.pixels_per_column) + " but the file has " +
                                               std::to_string(beams) + " beam angles");
  const json* cpp_v = find(*fmt, {"columns_per_packet"});
  if (cpp_v == nullptr) cpp_v = find(j, {"config_params", "columns_per_packet"});
  auto cpp = read_int(cpp_v, "columns_per_packet", 1, kMaxColumnsPerPacketSupported, 16);
  if (!cpp) return cpp.error();
  s.columns_per_packet = cpp.value();
  auto cpf = read_int(find(*fmt, {"columns_per_frame"}), "columns_per_frame", 512, 4096, s.mode.columns);
  if (!cpf) return cpf.error();
  if (cpf.value() != s.mode.columns)
    return Error::make(ErrorCode::kConfig, "columns_per_frame = " + std::to_string(cpf.value()) + " disagrees with lidar_mode");
  s.column_window_first = 0;
  s.column_window_last = s.mode.columns - 1;
  if (const json* w = find(*fmt, {"column_window"})) {
    if (!w->is_array() || w->size() != 2 || !(*w)[0].is_number_integer() || !(*w)[1].is_number_integer())
      return Error::make(ErrorCode::kConfig, "column_window must be [first, last]");
    s.column_window_first = (*w)[0].get<int>();
    s.column_window_last = (*w)[1].get<int>();
    if (s.column_window_first < 0 || s.column_window_first >= s.mode.columns || s.column_window_last < 0 ||
        s.column_window_last >= s.mode.columns)
      return Error::make(ErrorCode::kConfig, "column_window is outside the frame's columns");
  }
  if (const json* v = find(*fmt, {"pixel_shift_by_row"})) {
    if (!v->is_array() || static_cast<int>(v->size()) != beams) return Error::make(ErrorCode::kConfig, "pixel_shift_by_row must have one entry per beam");
    for (const json& e : *v) {
      if (!e.is_number_integer()) return Error::make(ErrorCode::kConfig, "pixel_shift_by_row has a non-integer");
      s.pixel_shift_by_row.push_back(e.get<int>());
    }
  }

  if (const json* v = find_any(j, {{"lidar_origin_to_beam_origin_mm"}, {"beam_intrinsics", "lidar_origin_to_beam_origin_mm"}})) {
    if (!v->is_number() || !(v->get<double>() >= 0.0 && v->get<double>() < 1000.0))
      return Error::make(ErrorCode::kConfig, "lidar_origin_to_beam_origin_mm is not a distance in mm");
    s.lidar_origin_to_beam_origin_mm = v->get<double>();
  }
  s.beam_to_lidar = kIdentity4;
  s.beam_to_lidar[3] = s.lidar_origin_to_beam_origin_mm;
  if (auto st = read_mat4(find_any(j, {{"beam_to_lidar_transform"}, {"beam_intrinsics", "beam_to_lidar_transform"}}), "beam_to_lidar_transform",
                          s.beam_to_lidar); !st)
    return st.error();
  if (auto st = read_mat4(find_any(j, {{"lidar_to_sensor_transform"}, {"lidar_intrinsics", "lidar_to_sensor_transform"}}),
                          "lidar_to_sensor_transform", s.lidar_to_sensor); !st)
    return st.error();
  if (auto st = read_mat4(find_any(j, {{"imu_to_sensor_transform"}, {"imu_intrinsics", "imu_to_sensor_transform"}}), "imu_to_sensor_transform",
                          s.imu_to_sensor); !st)
    return st.error();

  auto pl = read_int(find_any(j, {{"udp_port_lidar"}, {"config_params", "udp_port_lidar"}}), "udp_port_lidar", 0, 65535, 7502);
  if (!pl) return pl.error();
  auto pi = read_int(find_any(j, {{"udp_port_imu"}, {"config_params", "udp_port_imu"}}), "udp_port_imu", 0, 65535, 7503);
  if (!pi) return pi.error();
  s.udp_port_lidar = static_cast<std::uint16_t>(pl.value() == 0 ? 7502 : pl.value());
  s.udp_port_imu = static_cast<std::uint16_t>(pi.value() == 0 ? 7503 : pi.value());
  return s;
}

}  // namespace

Result<SensorInfo> parse_metadata(std::string_view json_text, std::string_view origin) {
  const json j = json::parse(json_text.begin(), json_text.end(), nullptr, false);
  if (j.is_discarded()) return Error::make(ErrorCode::kMalformed, std::string(origin) + ": not valid JSON");
  try {
    auto r = parse(j);
    if (!r) return Error::make(r.error().code, std::string(origin) + ": " + r.error().message);
    return r;
  } catch (const std::exception& e) {
    return Error::make(ErrorCode::kConfig, std::string(origin) + ": " + e.what());
  }
}

Result<SensorInfo> read_metadata_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error::make(ErrorCode::kIo, "cannot open Ouster metadata " + path);
  std::ostringstream ss;
  ss << in.rdbuf();
  return parse_metadata(ss.str(), path);
}

}  // namespace ag::ouster
