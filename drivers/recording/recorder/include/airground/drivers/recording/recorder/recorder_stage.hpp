// The robot's own recorder: a low-priority stage that taps its robot's channels (never holding a writer
// back: when it falls behind, its rings drop and it counts the drops per channel) and writes them as
// Foxglove JSON into size-bounded MCAP files, <recorder.path>/<role>-<robot>-<UTC start>-NNN.mcap, with
// the simulator's topics and schemas. Off unless recorder.path is set.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "airground/messages/channels.hpp"
#include "airground/messages/messages.hpp"
#include "airground/drivers/recording/mcap/counters_json.hpp"
#include "airground/drivers/recording/recorder/mcap_rotation.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/param_binding.hpp"
#include "airground/platform/stage.hpp"
#include "airground/platform/status_stage.hpp"

namespace ag::recording {

// What the recorder saw and wrote on one channel.
struct RecorderChannelCounters {
  std::uint64_t read{0};     // messages taken from the channel
  std::uint64_t written{0};  // messages written (read minus the ones skipped by decimation)
  std::uint64_t drops{0};    // messages the channel could not give the recorder (its ring was full)
};

struct RecorderCounters {
  RecorderChannelCounters pose, odometry, gps, lidar, map_tiles, scheduler, camera;
  std::uint64_t write_errors{0};  // the first one stops the recording (logged with the file's name)
  std::uint64_t files_opened{0}, files_deleted{0};
};

// The parameters of both roles. The struct's initializers are a recorder of nothing but map tiles and
// counters; each role sets the defaults of the five source choices in its rows (recorder_params).
struct RecorderSettings {
  std::string path;
  int max_file_mb{512};    // [MiB]
  int max_total_mb{8192};  // [MiB]
  int zstd_level{3};
  std::string pose_source{"none"};
  std::string odometry_channel;
  std::string gps_channel;
  std::string lidar_channel;
  int lidar_every{5};
  int lidar_column_stride{4};
  std::string map_tiles_channel{chan::kMapTiles.name};
  double scheduler_period_s{10.0};  // [s]
  std::string camera_channel;
  double camera_period_s{2.0};  // [s]
};
inline constexpr ParamField<RecorderSettings> kRecorderFields[] = {
    field::text("path", &RecorderSettings::path, "", "", "directory of the MCAP recording (created if missing); empty: the recorder is off"),
    field::integer("max_file_mb", &RecorderSettings::max_file_mb, 1, 65536, "MiB", "a file is closed (complete) and the next one opened before it would pass this"),
    field::integer("max_total_mb", &RecorderSettings::max_total_mb, 1, 16777216, "MiB", "this robot's recordings in path; the oldest files go past it (>= max_file_mb)"),
    field::integer("zstd_level", &RecorderSettings::zstd_level, 0, 19, "", "chunk compression (0: none), paid on the recorder's own thread"),
    field::text("pose_source", &RecorderSettings::pose_source, "none", "localization|keyframe_poses|none",
                "the robot's own pose: the localizer's (ugv) or the pose graph's newest keyframe (uav)"),
    field::text("odometry_channel", &RecorderSettings::odometry_channel, "", "", "wheel odometry ring to record; empty: none"),
    field::text("gps_channel", &RecorderSettings::gps_channel, "", "", "GNSS fix ring to record, as lat/lon around gps.datum_*; empty: none"),
    field::text("lidar_channel", &RecorderSettings::lidar_channel, "", "", "LiDAR revolution ring to record as point clouds; empty: none"),
    field::integer("lidar_every", &RecorderSettings::lidar_every, 1, 1000, "scans", "record every Nth revolution"),
    field::integer("lidar_column_stride", &RecorderSettings::lidar_column_stride, 1, 64, "columns", "of a recorded revolution, every Nth measurement column"),
    field::text("map_tiles_channel", &RecorderSettings::map_tiles_channel, chan::kMapTiles.name, "", "aerial map tile ring to record as grids; empty: none"),
    field::real("scheduler_period_s", &RecorderSettings::scheduler_period_s, 0.0, 3600.0, "s", "scheduler counters this often (0: never)"),
    field::text("camera_channel", &RecorderSettings::camera_channel, "", "", "camera image ring to record (foxglove.RawImage rgb8, half size); empty: none"),
    field::real("camera_period_s", &RecorderSettings::camera_period_s, 0.0, 3600.0, "s", "at most one camera image this often (0: every image the recorder sees)"),
};

// A role's rows: kRecorderFields with that role's sources as the defaults (uav: keyframe poses, GPS,
// map tiles; ugv: localization, wheel odometry, LiDAR, map tiles from gossip).
consteval std::array<ParamSpec, 14> recorder_params(std::string_view pose, std::string_view odometry, std::string_view gps,
                                                    std::string_view lidar, std::string_view camera) {
  std::array<ParamSpec, 14> rows = param_specs(kRecorderFields);
  const std::pair<std::string_view, std::string_view> role_defaults[] = {
      {"pose_source", pose}, {"odometry_channel", odometry}, {"gps_channel", gps}, {"lidar_channel", lidar}, {"camera_channel", camera}};
  for (ParamSpec& r : rows)
    for (const auto& [key, def] : role_defaults)
      if (r.key == key) r.default_text = def;
  return rows;
}

class RecorderStage final : public Stage {
 public:
  static constexpr std::array<ParamSpec, 14> kUavParams = recorder_params("keyframe_poses", "", "gps", "", "camera");
  static constexpr std::array<ParamSpec, 14> kUgvParams = recorder_params("localization", "wheel_odometry", "", "lidar_scan", "");
  // Messages of each ring taken in one step at most: bounds the step (a 10 Hz stage).
  static constexpr std::size_t kMaxPerStep = 64;
  // Map tiles (32 KiB of grid each, ~44 KB as JSON) at most this many a step; a burst waits in the ring.
  static constexpr std::size_t kMaxTilesPerStep = 16;

  // `role` names the files: <role>-<robot>-<UTC start>-NNN.mcap.
  explicit RecorderStage(std::string role) : role_name_(std::move(role)) {}
  static std::unique_ptr<Stage> make_uav() { return std::make_unique<RecorderStage>("uav"); }
  static std::unique_ptr<Stage> make_ugv() { return std::make_unique<RecorderStage>("ugv"); }
  Status init(StageContext& ctx) override;
  void step(TimeNs now) noexcept override;
  void stop() noexcept override;

  [[nodiscard]] bool enabled() const noexcept { return enabled_; }
  [[nodiscard]] RecorderCounters counters() const noexcept;
  // The file being written (empty when off).
  [[nodiscard]] std::string current_file() const { return files_.current_path(); }

 private:
  Status declare(mcap::McapWriter& w);
  void put(std::uint16_t channel, TimeNs t, const std::string& json) noexcept;
  void record_pose(TimeNs t, double x, double y, double z, double roll, double pitch, double yaw) noexcept;
  void record_lidar(const LidarScanMsg& scan) noexcept;
  void record_tile(const MapTileMsg& tile) noexcept;
  void record_scheduler(const SchedulerStatus& s) noexcept;
  void record_camera(const CameraImageMsg& image) noexcept;

  bool enabled_{false};
  std::string role_name_;
  std::string robot_;
  std::string pose_source_;
  mcap::McapRotation files_;
  RingReader<WheelOdometryMsg, kWheelOdometryRing> odometry_;
  RingReader<GpsMsg, kGpsRing> gps_;
  RingReader<LidarScanMsg, kLidarRing> lidar_;
  RingReader<MapTileMsg, kMapTileRing> tiles_;
  RingReader<CameraImageMsg, kCameraRing> camera_;
  TimeNs camera_period_{0}, next_camera_{0};
  LatestReader<LocalizationMsg> localization_;
  LatestReader<KeyframePosesMsg> keyframe_poses_;
  LatestReader<SchedulerStatus> scheduler_;
  TimeNs scheduler_period_{0}, next_scheduler_{0};
  std::int64_t lidar_every_{5};
  std::uint16_t lidar_stride_{4};
  double datum_lat_deg_{0}, datum_lon_deg_{0}, datum_height_m_{0};
  // Channel ids in the MCAP files (the same in every file of the recording).
  std::uint16_t ch_tf_{0}, ch_pose_{0}, ch_odometry_{0}, ch_gps_{0}, ch_lidar_{0}, ch_tiles_{0}, ch_scheduler_{0}, ch_camera_{0};
  RecorderCounters counters_;
  std::vector<std::uint8_t> scratch_;
  std::vector<foxglove::StageCounters> stage_counters_;  // the scheduler message's rows
  bool failed_{false};
  TimeNs now_{0};  // this step's release: the log time of what it writes
};

}  // namespace ag::recording
