// recording.mcap of a team run: frame tree map -> uav -> uav/camera and map -> ugvN -> ugvN/lidar (the
// truth), the robots' own estimates, camera frames as JPEG, LiDAR scans as point clouds, the quadrotor's
// map tiles as grids (class, elevation, RGB), radio and scheduler counters (recording_counters), planned
// paths, regions, claims and visits (recording_mission).
#include "team_recording.hpp"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <cstring>
#include <fstream>

#include "airground/aerial_mapping/ortho_map.hpp"
#include "airground/messages/messages.hpp"
#include "airground/drivers/recording/mcap/foxglove_json.hpp"
#include "airground/platform/perf_counters.hpp"
#include "airground/platform/role_instance.hpp"
#include "recording_counters.hpp"

namespace ag::sim {
namespace fg = ag::foxglove;

namespace {
fg::Pose pose3(const Pose3& p) { return fg::Pose{{p.x, p.y, p.z}, fg::quat_from_rpy(p.roll, p.pitch, p.yaw)}; }
fg::Pose pose2(const Pose2& p, double z = 0) { return fg::Pose{{p.x, p.y, z}, fg::quat_from_rpy(0, 0, p.yaw)}; }
std::uint64_t ns(TimeNs t) { return t < 0 ? 0u : static_cast<std::uint64_t>(t); }
}  // namespace

Result<std::unique_ptr<TeamRecording>> TeamRecording::open(const std::string& path, const World& world, bool uav, int ugvs,
                                                           std::uint64_t seed, const TeamRecordingOptions& options) {
  std::unique_ptr<TeamRecording> r(new TeamRecording());
  r->opt_ = options;
  r->path_ = path;
  mcap::WriterOptions wo;
  wo.library = "airground-sim";
  if (Status s = r->writer_.open(path, wo); !s) return s.error();
  const Datum& d = world.header.datum;
  if (Status s = r->writer_.add_metadata("run", {{"seed", std::to_string(seed)}, {"world", world.header.name},
                                                  {"datum_lat_deg", fg::json_number(d.lat_deg)}, {"datum_lon_deg", fg::json_number(d.lon_deg)},
                                                  {"datum_height_m", fg::json_number(d.height_m)},
                                                  {"frames", "map: local ENU at the datum (x east, y north, z up); log times are simulated time"}});
      !s)
    return s.error();
  r->tf_ = r->channel("foxglove.FrameTransforms", "/tf");
  if (uav) {
    r->uav_truth_ = r->channel("foxglove.PoseInFrame", "/uav/truth");
    r->uav_gps_ = r->channel("foxglove.LocationFix", "/uav/gps");
    r->camera_ = r->channel("foxglove.CompressedImage", "/uav/camera/image");
    r->map_ch_ = r->channel("foxglove.Grid", "/uav/map_tiles");
  }
  for (int i = 0; i < ugvs; ++i) {
    const std::string n = "/ugv" + std::to_string(i + 1);
    UgvChannels c;
    c.truth = r->channel("foxglove.PoseInFrame", n + "/truth");
    c.estimate = r->channel("foxglove.PoseInFrame", n + "/pose");
    c.odometry = r->channel("foxglove.PoseInFrame", n + "/odometry");
    c.lidar = r->channel("foxglove.PointCloud", n + "/lidar/points");
    r->ugv_.push_back(c);
  }
  MissionRecorder::Channels mc;
  if (options.mission) {
    for (int i = 0; i < ugvs; ++i) mc.paths.push_back(r->channel("foxglove.SceneUpdate", "/ugv" + std::to_string(i + 1) + "/path"));
    if (uav || ugvs > 0) mc.regions = r->channel("foxglove.SceneUpdate", "/mission/regions");
    if (ugvs > 0) mc.events = r->channel("foxglove.Log", "/mission/events");
  }
  TeamRecording* self = r.get();
  r->mission_ = std::make_unique<MissionRecorder>(std::move(mc), [self](std::uint16_t ch, TimeNs now, const std::string& json) { self->put(ch, now, json); });
  r->radio_ = r->channel("airground.RadioTraffic", "/radio");
  if (options.scheduler_period_s > 0) r->scheduler_ = r->channel("airground.SchedulerCounters", "/scheduler");
  return r;
}

std::uint16_t TeamRecording::channel(const std::string& schema, const std::string& topic) {
  auto it = schema_ids_.find(schema);
  if (it == schema_ids_.end()) it = schema_ids_.emplace(schema, writer_.add_schema(schema, fg::kSchemaEncoding, recording_schema(schema))).first;
  const std::uint16_t id = writer_.add_channel(it->second, topic, fg::kMessageEncoding);
  topics_[id] = topic;
  return id;
}

void TeamRecording::watch(std::vector<std::pair<std::string, RoleInstance*>> roles, const mapping::OrthoMap* map) {
  roles_ = std::move(roles);
  map_ = map;
  RoleInstance* uav = nullptr;
  std::vector<RoleInstance*> ugvs(ugv_.size(), nullptr);
  for (const auto& [name, role] : roles_) {
    if (name == "uav") uav = role;
    const int n = name.rfind("ugv", 0) == 0 ? std::atoi(name.c_str() + 3) : 0;
    if (n >= 1 && static_cast<std::size_t>(n) <= ugvs.size()) ugvs[static_cast<std::size_t>(n - 1)] = role;
  }
  mission_->watch(uav, std::move(ugvs));
}

void TeamRecording::put(std::uint16_t ch, TimeNs now, const std::string& json) {
  if (!first_error_) return;
  if (Status s = writer_.write(ch, ns(now), json); !s) first_error_ = s;
}

void TeamRecording::uav_pose(TimeNs now, const Pose3& truth) {
  put(uav_truth_, now, fg::pose_in_frame(ns(now), "map", pose3(truth)));
  // the camera looks down: x forward, z along the optical axis (down), y to the right
  put(tf_, now, fg::frame_transforms(ns(now), {{"map", "uav", {truth.x, truth.y, truth.z}, fg::quat_from_rpy(truth.roll, truth.pitch, truth.yaw)},
                                               {"uav", "uav/camera", {0, 0, -0.1}, fg::quat_from_rpy(M_PI, 0, -M_PI / 2)}}));
}

void TeamRecording::uav_gps(TimeNs now, double lat_deg, double lon_deg, double height_m, double h_accuracy_m) {
  put(uav_gps_, now, fg::location_fix(ns(now), "uav", lat_deg, lon_deg, height_m, h_accuracy_m));
}

void TeamRecording::camera_frame(TimeNs now, std::uint64_t frame, const cv::Mat& rgb) {
  if (opt_.camera_every < 1 || (frame - 1) % static_cast<std::uint64_t>(opt_.camera_every) != 0 || rgb.empty()) return;
  cv::Mat bgr;
  cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
  std::vector<std::uint8_t> jpeg;
  cv::imencode(".jpg", bgr, jpeg, {cv::IMWRITE_JPEG_QUALITY, opt_.jpeg_quality});
  put(camera_, now, fg::compressed_image(ns(now), "uav/camera", "jpeg", jpeg));
}

void TeamRecording::ugv_pose(TimeNs now, int i, const Pose3& truth, const Pose2* odometry_in_map, const Pose2* estimate) {
  const UgvChannels& c = ugv_[static_cast<std::size_t>(i)];
  const std::string name = "ugv" + std::to_string(i + 1);
  put(c.truth, now, fg::pose_in_frame(ns(now), "map", pose3(truth)));
  if (odometry_in_map != nullptr) put(c.odometry, now, fg::pose_in_frame(ns(now), "map", pose2(*odometry_in_map)));
  if (estimate != nullptr) put(c.estimate, now, fg::pose_in_frame(ns(now), "map", pose2(*estimate)));
  put(tf_, now, fg::frame_transforms(ns(now), {{"map", name, {truth.x, truth.y, truth.z}, fg::quat_from_rpy(truth.roll, truth.pitch, truth.yaw)},
                                               {name, name + "/lidar", {0, 0, opt_.lidar_mount_height_m}, {}}}));
}

void TeamRecording::ugv_scan(TimeNs now, int i, std::uint64_t scan, const std::vector<LidarPoint>* parts, std::size_t n_parts) {
  if (opt_.lidar_every < 1 || (scan - 1) % static_cast<std::uint64_t>(opt_.lidar_every) != 0) return;
  scratch_.clear();
  const auto stride = static_cast<std::uint16_t>(std::max(1, opt_.lidar_column_stride));
  for (std::size_t k = 0; k < n_parts; ++k)
    for (const LidarPoint& p : parts[k]) {
      if (p.col % stride != 0) continue;
      const float v[4] = {p.x, p.y, p.z, p.range};
      const auto* b = reinterpret_cast<const std::uint8_t*>(v);
      scratch_.insert(scratch_.end(), b, b + sizeof v);
    }
  const std::string frame = "ugv" + std::to_string(i + 1) + "/lidar";
  put(ugv_[static_cast<std::size_t>(i)].lidar, now,
      fg::point_cloud(ns(now), frame, {}, 16,
                      {{"x", 0, fg::NumericType::kFloat32}, {"y", 4, fg::NumericType::kFloat32}, {"z", 8, fg::NumericType::kFloat32},
                       {"range", 12, fg::NumericType::kFloat32}},
                      scratch_));
}

void TeamRecording::tick(TimeNs now, const LinkStats* radio) {
  if (map_ != nullptr && now >= next_map_) {
    next_map_ = now + from_seconds(opt_.map_period_s);
    // changed tiles in key order (the map's own order is a hash order)
    std::vector<const mapping::Tile*> changed;
    map_->for_each_tile([&](const mapping::Tile& tile) {
      auto [it, fresh] = tile_versions_.try_emplace(tile.key.packed(), tile.version);
      if (!fresh && it->second == tile.version) return;
      it->second = tile.version;
      changed.push_back(&tile);
    });
    std::sort(changed.begin(), changed.end(), [](const mapping::Tile* a, const mapping::Tile* b) { return a->key.packed() < b->key.packed(); });
    const auto min_points = static_cast<std::uint32_t>(std::max(1, map_->params().min_elevation_points));
    for (const mapping::Tile* tile : changed) {
      // per cell: elevation float32 (NaN unknown), class, red, green, blue; rows south to north
      scratch_.assign(kTileCellCount * 8, 0);
      for (std::size_t k = 0; k < kTileCellCount && k < tile->live.size(); ++k) {
        const mapping::Cell& c = tile->live[k];
        const float e = c.reported_elevation(min_points);
        std::memcpy(&scratch_[k * 8], &e, 4);
        scratch_[k * 8 + 4] = c.cls;
        scratch_[k * 8 + 5] = c.r;
        scratch_[k * 8 + 6] = c.g;
        scratch_[k * 8 + 7] = c.b;
      }
      const double tile_m = kTileCells * kMapResolutionM;
      put(map_ch_, now, fg::grid(ns(now), "map", {{tile->key.tx * tile_m, tile->key.ty * tile_m, 0}, {}}, kTileCells, kMapResolutionM,
                              kMapResolutionM, kTileCells * 8, 8,
                              {{"elevation", 0, fg::NumericType::kFloat32}, {"class", 4, fg::NumericType::kUint8},
                               {"red", 5, fg::NumericType::kUint8}, {"green", 6, fg::NumericType::kUint8}, {"blue", 7, fg::NumericType::kUint8}},
                              scratch_));
    }
  }
  if (now >= next_radio_) {
    next_radio_ = now + kNsPerS;
    const std::vector<RobotTraffic> traffic = robot_traffic(roles_);
    if (radio != nullptr || !traffic.empty()) put(radio_, now, radio_traffic(ns(now), radio, traffic));
  }
  if (scheduler_ != 0 && opt_.scheduler_period_s > 0 && now >= next_scheduler_) {
    next_scheduler_ = now + from_seconds(opt_.scheduler_period_s);
    put(scheduler_, now, scheduler_counters(ns(now), roles_));
  }
  mission_->tick(now);
}

Status TeamRecording::close(double sim_s) {
  Status st = writer_.close();
  if (!first_error_) st = first_error_;
  if (!st) return st;
  const mcap::WriterStats& w = writer_.stats();
  const std::string json_path = path_.substr(0, path_.size() - std::string(".mcap").size()) + ".json";
  std::ofstream f(json_path);
  f << "{\"file\": \"recording.mcap\", \"bytes\": " << w.bytes << ", \"sim_s\": " << fg::json_number(sim_s)
    << ", \"bytes_per_sim_min\": " << fg::json_number(sim_s > 0 ? std::round(static_cast<double>(w.bytes) * 60.0 / sim_s) : 0.0)
    << ", \"messages\": " << w.messages << ", \"chunks\": " << w.chunks << ", \"channel_messages\": {";
  bool first = true;
  for (const auto& [id, n] : w.channel_messages) {
    f << (first ? "" : ", ") << fg::json_string(topics_[id]) << ": " << n;
    first = false;
  }
  f << "}}\n";
  if (!f) return Error::make(ErrorCode::kIo, "cannot write " + json_path);
  return ok_status();
}

}  // namespace ag::sim
