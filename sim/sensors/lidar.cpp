// The simulated Ouster LiDAR: metadata loading, the SDK's beam geometry, ray-cast scans with seeded noise.
#include "airground/sim/lidar.hpp"

#include "airground/messages/classes.hpp"

#include <Eigen/LU>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "airground/platform/config.hpp"
#include "airground/platform/param_binding.hpp"
#include "airground/messages/geometry.hpp"
#include "airground/platform/rng.hpp"

namespace ag::sim {

namespace {

using nlohmann::json;

constexpr std::size_t kMaxRings = 256;  // the metadata loader's limit; the fast scan's stack arrays
constexpr double kInfinity = std::numeric_limits<double>::infinity();
constexpr ParamField<LidarNoise> kNoiseFields[] = {
    field::real("range_sigma_m", &LidarNoise::range_sigma_m, 0.0, 1.0, "m", "Gaussian range noise"),
    field::real("min_range_m", &LidarNoise::min_range_m, 0.0, 10.0, "m", "closer returns are dropped"),
    field::real("max_range_m", &LidarNoise::max_range_m, 1.0, 1000.0, "m", "nothing is seen beyond"),
    field::real("dropout_prob", &LidarNoise::dropout_prob, 0.0, 1.0, "", "chance a return is lost"),
    field::boolean("water_returns", &LidarNoise::water_returns, "water returns like ground (false: no return, as at 865 nm: specular and absorbing)"),
};
constexpr auto kNoiseParams = param_specs(kNoiseFields);
constexpr ParamSection kNoiseSchema[] = {{"lidar_noise", kNoiseParams, "simulated LiDAR range noise"}};

Result<LidarNoise> noise_from(const Result<Config>& cfg, std::string_view origin) {
  if (!cfg) return cfg.error();
  const SectionView s(cfg.value(), "lidar_noise");
  const LidarNoise n = load_params(s, kNoiseFields);
  if (auto st = n.check(); !st)
    return Error::make(ErrorCode::kConfig, "config error: " + std::string(origin) + ": " + st.error().message);
  return n;
}

Error malformed(std::string_view origin, const std::string& what) {
  return Error::make(ErrorCode::kMalformed, "ouster metadata " + std::string(origin) + ": " + what);
}

// A list of finite numbers within [lo, hi] under `key` of `node`.
Result<std::vector<double>> number_list(const json& node, const char* key, double lo, double hi, std::string_view origin) {
  const auto it = node.find(key);
  if (it == node.end()) return malformed(origin, std::string("missing key '") + key + "'");
  if (!it->is_array()) return malformed(origin, std::string("'") + key + "' must be a list of numbers");
  std::vector<double> v;
  v.reserve(it->size());
  for (const auto& e : *it) {
    if (!e.is_number()) return malformed(origin, std::string("'") + key + "' holds a non-number");
    const double x = e.get<double>();
    if (!std::isfinite(x) || x < lo || x > hi)
      return malformed(origin, std::string("'") + key + "' value " + std::to_string(x) + " outside [" +
                                   std::to_string(lo) + ", " + std::to_string(hi) + "]");
    v.push_back(x);
  }
  return v;
}

// Counter-based randomness: splitmix64 (platform/rng.hpp) of (seed, ray) so that every ray's noise is
// independent of the others.
inline double unit_open(std::uint64_t bits) noexcept {  // (0, 1]
  return (static_cast<double>(bits >> 11) + 1.0) * 0x1.0p-53;
}
inline double unit_centred(std::uint64_t bits) noexcept {  // (0, 1), symmetric about 1/2
  return (static_cast<double>(bits >> 11) + 0.5) * 0x1.0p-53;
}

// Polynomial with coefficients from the highest power down.
template <std::size_t N>
inline double horner(const double (&c)[N], double x) noexcept {
  double r = c[0];
  for (std::size_t i = 1; i < N; ++i) r = r * x + c[i];
  return r;
}

// The standard normal quantile, Wichura's AS241 (PPND16, relative error ~1e-16): one uniform gives one
// normal deviate, by a rational function alone in 85 % of cases (Box-Muller needs log, sqrt and cos).
inline double normal_quantile(double p) noexcept {
  constexpr double kA[] = {2.5090809287301226727e+3, 3.3430575583588128105e+4, 6.7265770927008700853e+4,
                           4.5921953931549871457e+4, 1.3731693765509461125e+4, 1.9715909503065514427e+3,
                           1.3314166789178437745e+2, 3.3871328727963666080e+0};
  constexpr double kB[] = {5.2264952788528545610e+3, 2.8729085735721942674e+4, 3.9307895800092710610e+4,
                           2.1213794301586595867e+4, 5.3941960214247511077e+3, 6.8718700749205790830e+2,
                           4.2313330701600911252e+1, 1.0};
  constexpr double kC[] = {7.74545014278341407640e-4, 2.27238449892691845833e-2, 2.41780725177450611770e-1,
                           1.27045825245236838258e+0, 3.64784832476320460504e+0, 5.76949722146069140550e+0,
                           4.63033784615654529590e+0, 1.42343711074968357734e+0};
  constexpr double kD[] = {1.05075007164441684324e-9, 5.47593808499534494600e-4, 1.51986665636164571966e-2,
                           1.48103976427480074590e-1, 6.89767334985100004550e-1, 1.67638483018380384940e+0,
                           2.05319162663775882187e+0, 1.0};
  constexpr double kE[] = {2.01033439929228813265e-7, 2.71155556874348757815e-5, 1.24266094738807843860e-3,
                           2.65321895265761230930e-2, 2.96560571828504891230e-1, 1.78482653991729133580e+0,
                           5.46378491116411436990e+0, 6.65790464350110377720e+0};
  constexpr double kF[] = {2.04426310338993978564e-15, 1.42151175831644588870e-7, 1.84631831751005468180e-5,
                           7.86869131145613259100e-4, 1.48753612908506148525e-2, 1.36929880922735805310e-1,
                           5.99832206555887937690e-1, 1.0};
  const double q = p - 0.5;
  if (std::abs(q) <= 0.425) {
    const double r = 0.180625 - q * q;
    return q * horner(kA, r) / horner(kB, r);
  }
  const double r = std::sqrt(-std::log(q < 0.0 ? p : 1.0 - p));
  const double x = r <= 5.0 ? horner(kC, r - 1.6) / horner(kD, r - 1.6) : horner(kE, r - 5.0) / horner(kF, r - 5.0);
  return q < 0.0 ? -x : x;
}

}  // namespace

Status LidarNoise::check() const {
  const auto bad = [](const std::string& what) { return Error::make(ErrorCode::kInvalidArgument, what); };
  if (!(range_sigma_m >= 0.0) || !std::isfinite(range_sigma_m)) return bad("lidar_noise.range_sigma_m must be >= 0");
  if (!(min_range_m >= 0.0)) return bad("lidar_noise.min_range_m must be >= 0");
  if (!(max_range_m > min_range_m) || !std::isfinite(max_range_m))
    return bad("lidar_noise.max_range_m must be finite and above min_range_m");
  if (!(dropout_prob >= 0.0 && dropout_prob <= 1.0)) return bad("lidar_noise.dropout_prob must be in [0, 1]");
  return ok_status();
}

Result<LidarNoise> LidarNoise::load_string(std::string_view yaml, std::string_view origin) {
  return noise_from(Config::load_string(kNoiseSchema, yaml, origin), origin);
}
Result<LidarNoise> LidarNoise::load_file(const std::string& path) {
  return noise_from(Config::load_file(kNoiseSchema, path), path);
}

Result<OusterBeamModel> OusterBeamModel::from_metadata_string(std::string_view text, std::string_view origin, int columns) {
  if (columns != 512 && columns != 1024 && columns != 2048)
    return Error::make(ErrorCode::kInvalidArgument, "ouster metadata " + std::string(origin) + ": columns must be 512, 1024 or 2048, got " +
                                                        std::to_string(columns));
  json root;
  try {
    root = json::parse(text.begin(), text.end());
  } catch (const json::exception& e) {
    return malformed(origin, std::string("not valid JSON (") + e.what() + ")");
  }
  if (!root.is_object()) return malformed(origin, "the top level must be a JSON object");
  // Firmware 2.x metadata keeps the intrinsics at the top level; SDK 0.11+ metadata nests them.
  const json& beams = root.contains("beam_intrinsics") && root["beam_intrinsics"].is_object() ? root["beam_intrinsics"] : root;
  const json& lidar = root.contains("lidar_intrinsics") && root["lidar_intrinsics"].is_object() ? root["lidar_intrinsics"] : root;

  OusterBeamModel m;
  m.columns = columns;
  auto alt = number_list(beams, "beam_altitude_angles", -90.0, 90.0, origin);
  if (!alt) return alt.error();
  auto azi = number_list(beams, "beam_azimuth_angles", -180.0, 180.0, origin);
  if (!azi) return azi.error();
  if (alt.value().empty() || alt.value().size() > 256)
    return malformed(origin, "'beam_altitude_angles' must list 1 to 256 beams");
  if (azi.value().size() != alt.value().size())
    return malformed(origin, "'beam_azimuth_angles' has " + std::to_string(azi.value().size()) + " entries, 'beam_altitude_angles' " +
                                 std::to_string(alt.value().size()));
  m.altitude_deg = std::move(alt.value());
  m.azimuth_deg = std::move(azi.value());

  if (const auto it = beams.find("lidar_origin_to_beam_origin_mm"); it != beams.end()) {
    if (!it->is_number() || !std::isfinite(it->get<double>()) || it->get<double>() < 0.0 || it->get<double>() > 200.0)
      return malformed(origin, "'lidar_origin_to_beam_origin_mm' must be a number in [0, 200]");
    m.lidar_origin_to_beam_origin_mm = it->get<double>();
  }
  if (beams.contains("beam_to_lidar_transform")) {  // newer metadata: the beam origin may sit off the plane
    auto t = number_list(beams, "beam_to_lidar_transform", -1.0e4, 1.0e4, origin);
    if (!t) return t.error();
    if (t.value().size() != 16) return malformed(origin, "'beam_to_lidar_transform' must hold 16 numbers (row-major 4x4)");
    m.lidar_origin_to_beam_origin_mm = t.value()[3];
    m.beam_origin_z_mm = t.value()[11];
    if (std::abs(m.lidar_origin_to_beam_origin_mm) > 200.0 || std::abs(m.beam_origin_z_mm) > 200.0)
      return malformed(origin, "'beam_to_lidar_transform' offsets must be within 200 mm");
  }
  m.lidar_to_sensor = Eigen::Matrix4d::Identity();
  m.lidar_to_sensor(0, 0) = -1.0;  // OS-1: lidar frame x points at the connector, sensor frame x away from it
  m.lidar_to_sensor(1, 1) = -1.0;
  m.lidar_to_sensor(2, 3) = 36.18;
  if (lidar.contains("lidar_to_sensor_transform")) {
    auto t = number_list(lidar, "lidar_to_sensor_transform", -1.0e4, 1.0e4, origin);
    if (!t) return t.error();
    if (t.value().size() != 16) return malformed(origin, "'lidar_to_sensor_transform' must hold 16 numbers (row-major 4x4)");
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) m.lidar_to_sensor(r, c) = t.value()[static_cast<std::size_t>(4 * r + c)];
    const Eigen::Matrix3d rot = m.lidar_to_sensor.topLeftCorner<3, 3>();
    if ((rot.transpose() * rot - Eigen::Matrix3d::Identity()).norm() > 1e-3 || rot.determinant() < 0.0 ||
        (m.lidar_to_sensor.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).norm() > 1e-9)
      return malformed(origin, "'lidar_to_sensor_transform' is not a rigid transform");
  }
  return m;
}

Result<OusterBeamModel> OusterBeamModel::from_metadata_json(const std::string& path, int columns) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error::make(ErrorCode::kIo, "ouster metadata " + path + ": cannot open");
  std::ostringstream ss;
  ss << in.rdbuf();
  return from_metadata_string(ss.str(), path, columns);
}

std::string OusterBeamModel::default_metadata_path() {
  return std::string(AG_SOURCE_DIR) + "/config/sensors/ouster/os1-64_legacy_metadata.json";
}

Result<OusterBeamModel> OusterBeamModel::load_default(int columns) {
  return from_metadata_json(default_metadata_path(), columns);
}

LidarSimulator::LidarSimulator(const World& world, const OusterBeamModel& beams, const LidarNoise& noise,
                               std::shared_ptr<const HeightfieldRaycaster> raycaster)
    : world_(world), beams_(beams), noise_(noise), raycaster_(std::move(raycaster)) {
  if (beams_.altitude_deg.empty() || beams_.altitude_deg.size() != beams_.azimuth_deg.size() || beams_.rings() > 65535)
    throw std::invalid_argument("LidarSimulator: the beam model needs matching, non-empty altitude and azimuth lists");
  if (beams_.columns != 512 && beams_.columns != 1024 && beams_.columns != 2048)
    throw std::invalid_argument("LidarSimulator: columns must be 512, 1024 or 2048");
  if (auto st = noise_.check(); !st) throw std::invalid_argument("LidarSimulator: " + st.error().message);
  const GridGeometry& g = world.grid();
  if (world.class_id.type() != CV_8UC1 || world.class_id.rows != g.height || world.class_id.cols != g.width)
    throw std::invalid_argument("LidarSimulator: the world's class_id layer must be CV_8UC1 matching its grid");
  raycaster_ = raycaster_for(world, std::move(raycaster_), "LidarSimulator");

  const double n = beams_.lidar_origin_to_beam_origin_mm * 1e-3, nz = beams_.beam_origin_z_mm * 1e-3;
  beam_offset_m_ = std::hypot(n, nz);
  const Eigen::Matrix3d rot = beams_.lidar_to_sensor.topLeftCorner<3, 3>();
  const Eigen::Vector3d trans = beams_.lidar_to_sensor.topRightCorner<3, 1>() * 1e-3;
  const auto rings = static_cast<std::size_t>(beams_.rings());
  const auto cols = static_cast<std::size_t>(beams_.columns);
  ray_origin_.resize(rings * cols);
  ray_dir_.resize(rings * cols);
  for (std::size_t c = 0; c < cols; ++c) {
    const double encoder = 2.0 * kPi * (1.0 - static_cast<double>(c) / static_cast<double>(cols));
    for (std::size_t i = 0; i < rings; ++i) {
      const double azimuth = -beams_.azimuth_deg[i] * kPi / 180.0;
      const double altitude = beams_.altitude_deg[i] * kPi / 180.0;
      const Eigen::Vector3d dir(std::cos(encoder + azimuth) * std::cos(altitude),
                                std::sin(encoder + azimuth) * std::cos(altitude), std::sin(altitude));
      const Eigen::Vector3d beam_origin(n * std::cos(encoder), n * std::sin(encoder), nz);
      ray_origin_[c * rings + i] = rot * beam_origin + trans;
      ray_dir_[c * rings + i] = (rot * dir).normalized();
    }
  }

  // Slots: ring r of column k + shift[r] for every ring. The OS-1's beams sit at four azimuth offsets
  // (about -3.2, -1.1, +1.0, +3.2 deg), so one column's rings fan out in four directions, while a slot
  // takes each ring from the column that points it (within half a column step) the same way: one walk
  // bounds all of a slot's beams. The shifts round each ring's offset to whole columns against the
  // reference ring that leaves the smallest spread; ties go to the smallest shifts.
  const double step_deg = 360.0 / static_cast<double>(cols);
  double best_spread = kInfinity;
  int best_reach = 0;
  std::vector<int> shift(rings);
  for (std::size_t ref = 0; ref < rings; ++ref) {
    double lo = kInfinity, hi = -kInfinity;
    int reach = 0;
    std::vector<int> sh(rings);
    for (std::size_t i = 0; i < rings; ++i) {
      sh[i] = static_cast<int>(std::lround((beams_.azimuth_deg[ref] - beams_.azimuth_deg[i]) / step_deg));
      const double corrected = beams_.azimuth_deg[i] + sh[i] * step_deg;
      lo = std::min(lo, corrected);
      hi = std::max(hi, corrected);
      reach = std::max(reach, std::abs(sh[i]));
    }
    if (hi - lo < best_spread - 1e-9 || (hi - lo < best_spread + 1e-9 && reach < best_reach)) {
      best_spread = hi - lo;
      best_reach = reach;
      shift = sh;
    }
  }
  slot_shift_ = shift;
  shift_min_ = *std::min_element(shift.begin(), shift.end());
  shift_max_ = *std::max_element(shift.begin(), shift.end());
  slot_rings_.resize(rings);
  for (std::size_t i = 0; i < rings; ++i) slot_rings_[i] = static_cast<int>(i);
  std::stable_sort(slot_rings_.begin(), slot_rings_.end(), [&](int a, int b) {
    return beams_.altitude_deg[static_cast<std::size_t>(a)] < beams_.altitude_deg[static_cast<std::size_t>(b)];
  });
}

void LidarSimulator::emit(std::size_t k, double hit_range, std::int32_t cell_col, std::int32_t cell_row,
                          std::uint64_t key, std::vector<LidarPoint>& out) const {
  const auto rings = static_cast<std::size_t>(beams_.rings());
  const std::uint8_t cls = world_.class_id.at<std::uint8_t>(cell_row, cell_col);
  if (cls == raw(ClassId::kWater) && !noise_.water_returns) return;  // specular and absorbing: no return
  const double sigma = noise_.range_sigma_m;
  const auto col = static_cast<std::uint16_t>(k / rings), ring = static_cast<std::uint16_t>(k % rings);
  double range = hit_range + beam_offset_m_;
  if (sigma > 0.0 || noise_.dropout_prob > 0.0) {
    std::uint64_t state = key ^ ((static_cast<std::uint64_t>(col) << 32) | ring);
    const std::uint64_t bits = splitmix64(state);
    if (noise_.dropout_prob > 0.0 && unit_open(splitmix64(state)) <= noise_.dropout_prob) return;
    if (sigma > 0.0) range += sigma * normal_quantile(unit_centred(bits));  // inversion: one uniform per deviate
  }
  if (range < noise_.min_range_m || range > noise_.max_range_m) return;
  const Eigen::Vector3d p = ray_origin_[k] + (range - beam_offset_m_) * ray_dir_[k];
  out.push_back(LidarPoint{static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()),
                           static_cast<float>(range), cls, ring, col});
}

void LidarSimulator::scan_per_ray(const Pose3& pose, std::uint64_t seed, std::vector<LidarPoint>& out) const {
  scan_per_ray_columns(pose, seed, 0, beams_.columns, out);
}

void LidarSimulator::scan_per_ray_columns(const Pose3& pose, std::uint64_t seed, int col_begin, int col_end,
                                          std::vector<LidarPoint>& out) const {
  col_begin = std::clamp(col_begin, 0, beams_.columns);
  col_end = std::clamp(col_end, col_begin, beams_.columns);
  out.clear();
  out.reserve(ray_dir_.size());
  const Eigen::Matrix3d rot = rotation_of(pose);
  const Eigen::Vector3d pos(pose.x, pose.y, pose.z);
  const HeightfieldRaycaster& rc = *raycaster_;
  const double cast_range = noise_.max_range_m + 6.0 * noise_.range_sigma_m;
  const std::uint64_t key = seed * 0xD1B54A32D192ED03ULL;
  const auto rings = static_cast<std::size_t>(beams_.rings());
  for (std::size_t k = static_cast<std::size_t>(col_begin) * rings; k < static_cast<std::size_t>(col_end) * rings; ++k) {
    const RayHit hit = rc.cast(rot * ray_origin_[k] + pos, rot * ray_dir_[k], cast_range);
    if (hit.hit) emit(k, hit.range, hit.col, hit.row, key, out);
  }
}

void LidarSimulator::scan(const Pose3& pose, std::uint64_t seed, std::vector<LidarPoint>& out) const {
  scan_columns(pose, seed, 0, beams_.columns, out);
}

void LidarSimulator::scan_columns(const Pose3& pose, std::uint64_t seed, int col_begin, int col_end,
                                  std::vector<LidarPoint>& out) const {
  col_begin = std::clamp(col_begin, 0, beams_.columns);
  col_end = std::clamp(col_end, col_begin, beams_.columns);
  const HeightfieldRaycaster& rc = *raycaster_;
  const GridGeometry& g = rc.grid();
  const auto rings = static_cast<std::size_t>(beams_.rings());
  const double inv_res = 1.0 / g.resolution;
  const double u_pos = (pose.x - g.origin_x) * inv_res, v_pos = (g.origin_y - pose.y) * inv_res;
  // The fan needs every column's origin inside the grid: keep a margin for the beam offsets.
  if (!rc.has_fan_bounds() || !(u_pos >= 2.0 && v_pos >= 2.0 && u_pos < g.width - 2.0 && v_pos < g.height - 2.0) ||
      rings > kMaxRings) {
    scan_per_ray_columns(pose, seed, col_begin, col_end, out);
    return;
  }
  out.clear();
  out.reserve(ray_dir_.size());
  const Eigen::Matrix3d rot = rotation_of(pose);
  const Eigen::Vector3d pos(pose.x, pose.y, pose.z);
  const double cast_range = noise_.max_range_m + 6.0 * noise_.range_sigma_m;
  const std::uint64_t key = seed * 0xD1B54A32D192ED03ULL;
  // One walk bounds beams whose horizontal directions span at most kChunkSpread [rad]: measured from
  // the middle direction, a beam strays one cell from the walked line only after 2 kLateral /
  // kChunkSpread cells (62 m at 0.25 m). A level OS-1 slot spans at most one column step (6 mrad at 1024
  // columns); a tilt spreads a slot's beams with their altitude and splits it.
  constexpr double kChunkSpread = 0.008;
  constexpr double kLateral = 0.999;  // [cells] a hair under one cell, for rounding
  constexpr double kBackOff = 1e-7;   // [m] start the exact cast just inside the proven-free part

  struct Beam {
    Eigen::Vector3d dir;  // map frame, unit
    double hu, hv;        // unit horizontal direction, grid coordinates
    double h;             // horizontal cells per metre of range
    double slope;         // [m] of z per horizontal cell
    std::int32_t col, ring;
  };
  struct Hit {
    double range;
    std::int32_t col, row;
    bool hit;
  };
  std::array<Beam, kMaxRings> beam;  // one slot's beams, gathered in slot_rings_ order
  std::array<int, kMaxRings> order;  // indices into beam, ascending slope
  std::array<FanBeam, kMaxRings> fan;
  // Per thread, sized on the first call: every ray of the part gets its entry, then the part's returns
  // go out column by column as scan_per_ray() gives them.
  thread_local std::vector<Hit> hits;
  thread_local std::vector<Eigen::Vector3d> origins;  // each column's beam origin, map frame
  const auto first_col = static_cast<std::size_t>(col_begin);
  const auto ncols = static_cast<std::size_t>(col_end - col_begin);
  if (hits.size() < ncols * rings) hits.resize(ncols * rings);
  if (origins.size() < ncols) origins.resize(ncols);
  for (std::size_t c = 0; c < ncols; ++c) origins[c] = rot * ray_origin_[(first_col + c) * rings] + pos;

  for (int k = col_begin - shift_max_; k < col_end - shift_min_; ++k) {
    int n = 0;
    for (const int r : slot_rings_) {
      const int c = k + slot_shift_[static_cast<std::size_t>(r)];
      if (c < col_begin || c >= col_end) continue;
      Beam& b = beam[static_cast<std::size_t>(n)];
      b.dir = rot * ray_dir_[static_cast<std::size_t>(c) * rings + static_cast<std::size_t>(r)];
      const double du = b.dir.x() * inv_res, dv = -b.dir.y() * inv_res;
      b.h = std::sqrt(du * du + dv * dv);  // not hypot: slow, and a bound has margin for rounding
      b.hu = b.h > 0.0 ? du / b.h : 1.0;
      b.hv = b.h > 0.0 ? dv / b.h : 0.0;
      b.slope = b.h > 0.0 ? b.dir.z() / b.h : (b.dir.z() > 0.0 ? kInfinity : -kInfinity);
      b.col = c;
      b.ring = r;
      hits[(static_cast<std::size_t>(c) - first_col) * rings + static_cast<std::size_t>(r)].hit = false;
      // Ascending slope: ascending altitude is right for a level sensor, and beams of one slot share
      // their direction, so a tilt only swaps neighbours, which insertion fixes at once.
      int q = n;
      while (q > 0 && beam[static_cast<std::size_t>(order[static_cast<std::size_t>(q - 1)])].slope > b.slope) {
        order[static_cast<std::size_t>(q)] = order[static_cast<std::size_t>(q - 1)];
        --q;
      }
      order[static_cast<std::size_t>(q)] = n++;
    }
    const auto at = [&](int j) -> const Beam& { return beam[static_cast<std::size_t>(order[static_cast<std::size_t>(j)])]; };
    for (int a = 0; a < n;) {
      // A chunk: the next beams by slope while their directions span at most kChunkSpread (sines of
      // the angle from the first, whose range stays tiny).
      const Beam& first = at(a);
      double lo = 0.0, hi = 0.0;
      int e = a + 1;
      for (; e < n; ++e) {
        const Beam& o = at(e);
        const double sn = first.hu * o.hv - first.hv * o.hu;
        const double nlo = std::min(lo, sn), nhi = std::max(hi, sn);
        if (nhi - nlo > kChunkSpread) break;
        lo = nlo;
        hi = nhi;
      }
      // Walk the middle direction, from the origin of the middle beam's column, lowered by the most
      // any other origin of the chunk lies below it; the millimetres between the origins come off the
      // lateral margin.
      const double mid = 0.5 * (lo + hi), cmid = std::sqrt(1.0 - mid * mid);
      double cu = first.hu * cmid - first.hv * mid, cv = first.hu * mid + first.hv * cmid;
      const double cn = std::sqrt(cu * cu + cv * cv);
      cu /= cn;
      cv /= cn;
      const Eigen::Vector3d& oc = origins[static_cast<std::size_t>(at((a + e - 1) / 2).col) - first_col];
      double off_h = 0.0, off_z = 0.0, s_stop = 0.0;
      for (int j = a; j < e; ++j) {
        const Beam& o = at(j);
        const Eigen::Vector3d d = origins[static_cast<std::size_t>(o.col) - first_col] - oc;
        off_h = std::max(off_h, std::sqrt(d.x() * d.x() + d.y() * d.y()) * inv_res);
        off_z = std::max(off_z, -d.z());  // how far below the walked origin this one lies
        fan[static_cast<std::size_t>(j - a)].slope = o.slope;
        s_stop = std::max(s_stop, cast_range * o.h);
      }
      const double lateral = kLateral - 1.001 * off_h;
      double walked = 0.0;
      const Eigen::Vector3d fan_origin(oc.x(), oc.y(), oc.z() - off_z - (off_z > 0.0 ? 1e-9 : 0.0));
      const bool fanned = lateral > 0.0 && rc.fan_free_bounds(fan_origin, cu, cv, s_stop, fan.data(), e - a, walked);
      for (int j = a; j < e; ++j) {
        const Beam& o = at(j);
        const FanBeam& f = fan[static_cast<std::size_t>(j - a)];
        double bound = fanned ? f.bound : 0.0;
        const double dev = std::sqrt((o.hu - cu) * (o.hu - cu) + (o.hv - cv) * (o.hv - cv));
        const double s_max = !fanned ? 0.0 : dev > 0.0 ? lateral / dev : kInfinity;  // where it may leave the fan
        bool near = false;
        if (bound == kInfinity) {  // rose above every surface at `walked`, checked before
          bound = s_max < walked ? s_max : kInfinity;
        } else {
          near = fanned && f.blocked && bound < s_max;  // the hit is likely close
          bound = std::min(bound, s_max);
        }
        const double t_start = o.h > 0.0 ? bound / o.h : (bound == kInfinity ? kInfinity : 0.0);
        if (t_start > cast_range) continue;  // free over its whole range
        const Eigen::Vector3d& ob = origins[static_cast<std::size_t>(o.col) - first_col];
        const RayHit hit = rc.cast_from(ob, o.dir, cast_range, std::max(0.0, t_start - kBackOff), near);
        if (hit.hit)
          hits[(static_cast<std::size_t>(o.col) - first_col) * rings + static_cast<std::size_t>(o.ring)] =
              Hit{hit.range, hit.col, hit.row, true};
      }
      a = e;
    }
  }
  for (std::size_t c = 0; c < ncols; ++c) {
    const Hit* row = hits.data() + c * rings;
    for (std::size_t i = 0; i < rings; ++i)
      if (row[i].hit) emit((first_col + c) * rings + i, row[i].range, row[i].col, row[i].row, key, out);
  }
}

}  // namespace ag::sim
