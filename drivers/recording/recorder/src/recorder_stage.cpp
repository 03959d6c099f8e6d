// RecorderStage: the robot's channels as Foxglove JSON in rotating MCAP files (topics as the simulator's
// recording.mcap: /tf, /<robot>/pose, /<robot>/gps, /<robot>/lidar/points, /<robot>/map_tiles, /scheduler).
#include "airground/drivers/recording/recorder/recorder_stage.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <ctime>

#include "airground/drivers/recording/mcap/counters_json.hpp"
#include "airground/drivers/recording/mcap/foxglove_json.hpp"
#include "airground/messages/channels.hpp"
#include "airground/platform/log.hpp"

namespace ag::recording {
namespace fg = ag::foxglove;

namespace {
std::uint64_t ns(TimeNs t) noexcept { return t < 0 ? 0u : static_cast<std::uint64_t>(t); }

// The wall clock's UTC now as 20261205T063000Z: file names sort by start time.
std::string utc_stamp() {
  const std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y%m%dT%H%M%SZ", &tm);
  return buf;
}

// Map-frame east/north/up [m] to WGS-84 around the datum: the exact inverse of ublox::LocalEnu, through
// ECEF (latitude by fixed-point iteration, well under a millimetre after five rounds at robot altitudes).
void enu_to_geodetic(double lat0_deg, double lon0_deg, double h0_m, double e, double n, double u, double& lat_deg, double& lon_deg,
                     double& h_m) noexcept {
  constexpr double kA = 6378137.0, kE2 = 6.69437999014e-3, kDeg = 180.0 / M_PI;
  const double sp = std::sin(lat0_deg / kDeg), cp = std::cos(lat0_deg / kDeg);
  const double sl = std::sin(lon0_deg / kDeg), cl = std::cos(lon0_deg / kDeg);
  const double n0 = kA / std::sqrt(1.0 - kE2 * sp * sp);
  const double x = (n0 + h0_m) * cp * cl - sl * e - sp * cl * n + cp * cl * u;
  const double y = (n0 + h0_m) * cp * sl + cl * e - sp * sl * n + cp * sl * u;
  const double z = (n0 * (1.0 - kE2) + h0_m) * sp + cp * n + sp * u;
  const double p = std::hypot(x, y);
  double lat = std::atan2(z, p * (1.0 - kE2)), h = 0;
  for (int k = 0; k < 5; ++k) {
    const double s = std::sin(lat);
    const double nk = kA / std::sqrt(1.0 - kE2 * s * s);
    h = p / std::cos(lat) - nk;
    lat = std::atan2(z, p * (1.0 - kE2 * nk / (nk + h)));
  }
  lat_deg = lat * kDeg;
  lon_deg = std::atan2(y, x) * kDeg;
  h_m = h;
}

}  // namespace

Status RecorderStage::init(StageContext& ctx) {
  const RecorderSettings cfg = load_params(ctx.params(), kRecorderFields);
  const std::string& path = cfg.path;
  if (path.empty()) return ok_status();  // off: no taps, step() does nothing
  enabled_ = true;
  robot_ = std::string(ctx.instance);
  pose_source_ = cfg.pose_source;
  lidar_every_ = cfg.lidar_every;
  lidar_stride_ = static_cast<std::uint16_t>(cfg.lidar_column_stride);
  scheduler_period_ = from_seconds(cfg.scheduler_period_s);

  auto& ch = ctx.channels;
  if (pose_source_ == "localization") {
    auto r = ch.latest_reader(chan::kLocalization);
    if (!r) return r.error();
    localization_ = r.value();
  } else if (pose_source_ == "keyframe_poses") {
    auto r = ch.latest_reader(chan::kKeyframePoses);
    if (!r) return r.error();
    keyframe_poses_ = r.value();
  }
  if (const std::string& c = cfg.odometry_channel; !c.empty()) {
    auto r = ch.ring_tap(chan::kWheelOdometry.with_name(c));
    if (!r) return r.error();
    odometry_ = r.value();
  }
  if (const std::string& c = cfg.gps_channel; !c.empty()) {
    if (!ctx.config.has("gps.datum_lat_deg"))
      return Error::make(ErrorCode::kConfig, std::string(ctx.stage_name) + ".gps_channel '" + c +
                                                 "': this role has no gps.datum_lat_deg/datum_lon_deg/datum_height_m to place the fixes");
    datum_lat_deg_ = ctx.config.get_real("gps.datum_lat_deg");
    datum_lon_deg_ = ctx.config.get_real("gps.datum_lon_deg");
    datum_height_m_ = ctx.config.get_real("gps.datum_height_m");
    auto r = ch.ring_tap(chan::kGps.with_name(c));
    if (!r) return r.error();
    gps_ = r.value();
  }
  if (const std::string& c = cfg.lidar_channel; !c.empty()) {
    auto r = ch.ring_tap(chan::kLidarScan.with_name(c));
    if (!r) return r.error();
    lidar_ = r.value();
  }
  if (const std::string& c = cfg.map_tiles_channel; !c.empty()) {
    auto r = ch.ring_tap(chan::kMapTiles.with_name(c));
    if (!r) return r.error();
    tiles_ = r.value();
  }
  if (const std::string& c = cfg.camera_channel; !c.empty()) {
    auto r = ch.ring_tap(chan::kCamera.with_name(c));
    if (!r) return r.error();
    camera_ = r.value();
    camera_period_ = from_seconds(cfg.camera_period_s);
  }
  if (scheduler_period_ > 0) {
    auto r = ch.latest_reader(chan::kSchedulerStatus);
    if (!r) return r.error();
    scheduler_ = r.value();
  }
  scratch_.reserve(std::max(kMaxScanPoints * 16, kImagePixels * 3 / 4));

  mcap::RotationOptions ro;
  ro.dir = path;
  ro.family = role_name_ + "-" + robot_ + "-";
  ro.prefix = ro.family + utc_stamp();
  ro.max_file_bytes = static_cast<std::uint64_t>(cfg.max_file_mb) << 20;
  ro.max_total_bytes = static_cast<std::uint64_t>(cfg.max_total_mb) << 20;
  ro.writer.library = "airground-recorder";
  ro.writer.zstd_level = cfg.zstd_level;
  if (ro.max_total_bytes < ro.max_file_bytes)
    return Error::make(ErrorCode::kConfig, std::string(ctx.stage_name) + ".max_total_mb (" + std::to_string(cfg.max_total_mb) +
                                               ") must be at least " + std::string(ctx.stage_name) + ".max_file_mb (" +
                                               std::to_string(cfg.max_file_mb) + ")");
  if (Status s = files_.open(ro, [this](mcap::McapWriter& w) { return declare(w); }); !s)
    return Error::make(ErrorCode::kConfig, std::string(ctx.stage_name) + ".path: " + s.error().message);
  AG_LOG_INFO("recorder", "recording %s to %s (files of %lld MiB, %lld MiB in all)", robot_.c_str(), files_.current_path().c_str(),
              static_cast<long long>(cfg.max_file_mb), static_cast<long long>(cfg.max_total_mb));
  return ok_status();
}

Status RecorderStage::declare(mcap::McapWriter& w) {
  std::vector<std::pair<std::string, std::uint16_t>> schemas;
  auto channel = [&](const std::string& schema, const std::string& topic) -> std::uint16_t {
    std::uint16_t sid = 0;
    for (const auto& [name, id] : schemas)
      if (name == schema) sid = id;
    if (sid == 0) {
      sid = w.add_schema(schema, fg::kSchemaEncoding, schema == fg::kSchedulerCountersSchema ? fg::scheduler_counters_schema() : fg::schema(schema));
      schemas.emplace_back(schema, sid);
    }
    return w.add_channel(sid, topic, fg::kMessageEncoding);
  };
  const std::string n = "/" + robot_;
  ch_tf_ = channel("foxglove.FrameTransforms", "/tf");
  if (localization_.connected() || keyframe_poses_.connected()) ch_pose_ = channel("foxglove.PoseInFrame", n + "/pose");
  if (odometry_.connected()) ch_odometry_ = channel("foxglove.PoseInFrame", n + "/odometry");
  if (gps_.connected()) ch_gps_ = channel("foxglove.LocationFix", n + "/gps");
  if (lidar_.connected()) ch_lidar_ = channel("foxglove.PointCloud", n + "/lidar/points");
  if (tiles_.connected()) ch_tiles_ = channel("foxglove.Grid", n + "/map_tiles");
  if (camera_.connected()) ch_camera_ = channel("foxglove.RawImage", n + "/camera/image");
  if (scheduler_.connected()) ch_scheduler_ = channel(std::string(fg::kSchedulerCountersSchema), "/scheduler");
  return w.add_metadata("recording", {{"role", role_name_}, {"robot", robot_}, {"started_utc", utc_stamp()},
                                      {"frames", "map: local ENU at the mission datum (x east, y north, z up)"},
                                      {"log_time", "the robot's monotonic clock [ns]"}});
}

void RecorderStage::put(std::uint16_t channel, TimeNs t, const std::string& json) noexcept {
  if (failed_) return;
  // Log time: when recorded (in order on every channel); publish time: when the data was sampled.
  if (Status s = files_.write(channel, ns(now_), ns(t), json); !s) {
    failed_ = true;
    ++counters_.write_errors;
    AG_LOG_ERROR("recorder", "recording stopped: %s", s.error().message.c_str());
  }
}

void RecorderStage::record_pose(TimeNs t, double x, double y, double z, double roll, double pitch, double yaw) noexcept {
  const fg::Quat q = fg::quat_from_rpy(roll, pitch, yaw);
  put(ch_pose_, t, fg::pose_in_frame(ns(t), "map", {{x, y, z}, q}));
  put(ch_tf_, t, fg::frame_transforms(ns(t), {{"map", robot_, {x, y, z}, q}}));
  ++counters_.pose.written;
}

void RecorderStage::record_lidar(const LidarScanMsg& scan) noexcept {
  ++counters_.lidar.read;
  if ((counters_.lidar.read - 1) % static_cast<std::uint64_t>(lidar_every_) != 0) return;
  scratch_.clear();
  for (std::size_t k = 0; k < scan.valid(); ++k) {
    const ScanReturn& p = scan.points[k];
    if (p.col % lidar_stride_ != 0) continue;
    const float v[4] = {p.x, p.y, p.z, p.range};
    const auto* b = reinterpret_cast<const std::uint8_t*>(v);
    scratch_.insert(scratch_.end(), b, b + sizeof v);
  }
  const std::string frame = robot_ + "/lidar";
  const Pose3& m = scan.sensor_in_body;
  put(ch_tf_, scan.stamp, fg::frame_transforms(ns(scan.stamp), {{robot_, frame, {m.x, m.y, m.z}, fg::quat_from_rpy(m.roll, m.pitch, m.yaw)}}));
  put(ch_lidar_, scan.stamp,
      fg::point_cloud(ns(scan.stamp), frame, {}, 16,
                      {{"x", 0, fg::NumericType::kFloat32}, {"y", 4, fg::NumericType::kFloat32}, {"z", 8, fg::NumericType::kFloat32},
                       {"range", 12, fg::NumericType::kFloat32}},
                      scratch_));
  ++counters_.lidar.written;
}

void RecorderStage::record_tile(const MapTileMsg& tile) noexcept {
  ++counters_.map_tiles.read;
  // per cell: elevation float32 (NaN unknown), class, 3 bytes padding (the simulator's RGB); rows south to north
  scratch_.assign(kTileCellCount * 8, 0);
  for (std::size_t k = 0; k < kTileCellCount; ++k) {
    std::memcpy(&scratch_[k * 8], &tile.elevation[k], 4);
    scratch_[k * 8 + 4] = tile.cls[k];
  }
  const double tile_m = kTileCells * kMapResolutionM;
  const TimeNs t = tile.published != 0 ? tile.published : tile.stamp;
  put(ch_tiles_, t,
      fg::grid(ns(t), "map", {{tile.tx * tile_m, tile.ty * tile_m, 0}, {}}, kTileCells, kMapResolutionM, kMapResolutionM, kTileCells * 8, 8,
               {{"elevation", 0, fg::NumericType::kFloat32}, {"class", 4, fg::NumericType::kUint8}}, scratch_));
  ++counters_.map_tiles.written;
}

void RecorderStage::record_scheduler(const SchedulerStatus& st) noexcept {
  ++counters_.scheduler.read;
  const std::size_t n = std::min<std::size_t>(st.stage_count, SchedulerStatus::kMaxStages);
  stage_counters_.clear();
  for (std::size_t k = 0; k < n; ++k) {
    const auto& l = st.stages[k];
    stage_counters_.push_back(fg::StageCounters{robot_, l.name.data(), l.runs, l.overruns, l.slips, static_cast<double>(l.exec_p50_us),
                                                static_cast<double>(l.exec_p99_us), static_cast<double>(l.exec_max_us),
                                                static_cast<double>(l.budget_us)});
  }
  put(ch_scheduler_, st.sample_time_ns, fg::scheduler_counters_json(ns(st.sample_time_ns), stage_counters_));
  ++counters_.scheduler.written;
}

void RecorderStage::record_camera(const CameraImageMsg& image) noexcept {
  ++counters_.camera.read;
  if (image.stamp < next_camera_) return;
  next_camera_ = image.stamp + camera_period_;
  // Half size by 2x2 box averaging: 320 x 200 rgb8 (a quarter of the bytes; the map tiles carry the detail).
  constexpr std::size_t w = kImageWidth / 2, h = kImageHeight / 2, W = kImageWidth;
  scratch_.resize(w * h * 3);
  for (std::size_t y = 0; y < h; ++y)
    for (std::size_t x = 0; x < w; ++x)
      for (std::size_t c = 0; c < 3; ++c) {
        const std::size_t a = ((2 * y) * W + 2 * x) * 3 + c, b = a + W * 3;
        const unsigned sum = 2u + image.rgb[a] + image.rgb[a + 3] + image.rgb[b] + image.rgb[b + 3];
        scratch_[(y * w + x) * 3 + c] = static_cast<std::uint8_t>(sum / 4u);
      }
  const std::string frame = robot_ + "/camera";
  put(ch_camera_, image.stamp, fg::raw_image(ns(image.stamp), frame, w, h, "rgb8", w * 3, scratch_));
  ++counters_.camera.written;
}

void RecorderStage::step(TimeNs now) noexcept {
  if (!enabled_ || failed_) return;
  now_ = now;
  // Each ring at most kMaxPerStep messages a step; what does not fit waits (or drops, counted).
  if (localization_.connected() && localization_.fresh()) {
    const LocalizationMsg& m = localization_.read();
    ++counters_.pose.read;
    if (m.status != LocalizationStatus::kNoMap) record_pose(m.stamp, m.pose.x, m.pose.y, 0, 0, 0, m.pose.yaw);
  }
  if (keyframe_poses_.connected() && keyframe_poses_.fresh()) {
    const KeyframePosesMsg& m = keyframe_poses_.read();
    ++counters_.pose.read;
    if (m.initialised && m.count > 0 && m.count <= KeyframePosesMsg::kCapacity) {
      const Pose3& p = m.poses[m.count - 1];
      record_pose(m.stamp, p.x, p.y, p.z, p.roll, p.pitch, p.yaw);
    }
  }
  if (odometry_.connected())
    for (std::size_t k = 0; k < kMaxPerStep; ++k) {
      const WheelOdometryMsg* m = odometry_.front();
      if (m == nullptr) break;
      ++counters_.odometry.read;
      put(ch_odometry_, m->stamp, fg::pose_in_frame(ns(m->stamp), robot_ + "/odom", {{m->pose.x, m->pose.y, 0}, fg::quat_from_rpy(0, 0, m->pose.yaw)}));
      ++counters_.odometry.written;
      odometry_.pop();
    }
  if (gps_.connected())
    for (std::size_t k = 0; k < kMaxPerStep; ++k) {
      const GpsMsg* m = gps_.front();
      if (m == nullptr) break;
      ++counters_.gps.read;
      double lat = 0, lon = 0, h = 0;
      enu_to_geodetic(datum_lat_deg_, datum_lon_deg_, datum_height_m_, m->east_m, m->north_m, m->up_m, lat, lon, h);
      put(ch_gps_, m->stamp, fg::location_fix(ns(m->stamp), robot_, lat, lon, h, m->h_accuracy_m));
      ++counters_.gps.written;
      gps_.pop();
    }
  if (lidar_.connected())
    for (std::size_t k = 0; k < kLidarRing; ++k) {
      const LidarScanMsg* m = lidar_.front();
      if (m == nullptr) break;
      record_lidar(*m);
      lidar_.pop();
    }
  if (tiles_.connected())
    for (std::size_t k = 0; k < kMaxTilesPerStep; ++k) {
      const MapTileMsg* m = tiles_.front();
      if (m == nullptr) break;
      record_tile(*m);
      tiles_.pop();
    }
  if (camera_.connected())
    for (std::size_t k = 0; k < kCameraRing; ++k) {
      const CameraImageMsg* m = camera_.front();
      if (m == nullptr) break;
      record_camera(*m);
      camera_.pop();
    }
  if (scheduler_.connected() && now >= next_scheduler_ && scheduler_.fresh()) {
    next_scheduler_ = now + scheduler_period_;
    record_scheduler(scheduler_.read());
  }
}

void RecorderStage::stop() noexcept {
  if (!enabled_) return;
  if (Status s = files_.close(); !s) {
    ++counters_.write_errors;
    AG_LOG_ERROR("recorder", "closing the recording: %s", s.error().message.c_str());
  }
}

RecorderCounters RecorderStage::counters() const noexcept {
  RecorderCounters c = counters_;
  c.odometry.drops = odometry_.connected() ? odometry_.drops() : 0;
  c.gps.drops = gps_.connected() ? gps_.drops() : 0;
  c.lidar.drops = lidar_.connected() ? lidar_.drops() : 0;
  c.map_tiles.drops = tiles_.connected() ? tiles_.drops() : 0;
  c.camera.drops = camera_.connected() ? camera_.drops() : 0;
  c.files_opened = files_.stats().files_opened;
  c.files_deleted = files_.stats().files_deleted;
  return c;
}

}  // namespace ag::recording
