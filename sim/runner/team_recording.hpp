// The team run's recording.mcap: what the world stage sees each tick, written as Foxglove's JSON
// messages (drivers/recording/mcap) so that Foxglove opens it with no plugin. Called only from the
// world stage (one thread), in tick order, so one seed gives the same file.
#pragma once

#include <opencv2/core.hpp>

#include <array>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "airground/messages/geometry.hpp"
#include "airground/drivers/recording/mcap/mcap_writer.hpp"
#include "airground/platform/result.hpp"
#include "airground/platform/time.hpp"
#include "airground/sim/lidar.hpp"
#include "airground/sim/radio.hpp"
#include "airground/sim/world.hpp"
#include "recording_mission.hpp"

namespace ag {
class RoleInstance;
namespace mapping {
class OrthoMap;
}
}  // namespace ag

namespace ag::sim {

struct TeamRecordingOptions {
  int camera_every{5};           // every Nth camera frame (JPEG)
  int jpeg_quality{80};
  int lidar_every{20};           // every Nth scan per robot
  int lidar_column_stride{4};    // every Nth measurement column of that scan
  double map_period_s{10};       // changed map tiles at most this often
  double scheduler_period_s{10};  // 0: no scheduler channel (its times are CPU times: not repeatable)
  double lidar_mount_height_m{0.6};
  bool mission{true};             // the mission channels (paths, regions, events; recording_mission.hpp)
};

class TeamRecording {
 public:
  // Creates DIR/recording.mcap with the team's channels (uav when `uav`, ugv1..ugvN). The error names the file.
  static Result<std::unique_ptr<TeamRecording>> open(const std::string& path, const World& world, bool uav, int ugvs,
                                                     std::uint64_t seed, const TeamRecordingOptions& options);

  // The roles whose stage and comms counters go on /scheduler and /radio ("uav", "ugv1".., "base"; the
  // quadrotor's and the ground robots' also feed the mission channels), and the quadrotor's map (may be null).
  void watch(std::vector<std::pair<std::string, RoleInstance*>> roles, const mapping::OrthoMap* map);

  void uav_pose(TimeNs now, const Pose3& truth);
  void uav_gps(TimeNs now, double lat_deg, double lon_deg, double height_m, double h_accuracy_m);
  void camera_frame(TimeNs now, std::uint64_t frame, const cv::Mat& rgb);
  // Ground robot i (0-based): truth, odometry in the map frame and its own estimate when it has them.
  void ugv_pose(TimeNs now, int i, const Pose3& truth, const Pose2* odometry_in_map, const Pose2* estimate);
  void ugv_scan(TimeNs now, int i, std::uint64_t scan, const std::vector<LidarPoint>* parts, std::size_t n_parts);
  // Ground robot i's route when the simulator drives it (written to /ugvN/path when it changes).
  void ugv_route(TimeNs now, int i, const std::vector<Eigen::Vector2d>& path) {
    if (mission_) mission_->route(now, i, path);
  }
  // Once per tick: map tiles, radio counters, scheduler counters, mission channels when due.
  void tick(TimeNs now, const LinkStats* radio);

  // Closes the file and writes DIR/recording.json (per topic message counts, size); the error names the file.
  Status close(double sim_s);
  [[nodiscard]] const mcap::WriterStats& stats() const noexcept { return writer_.stats(); }

 private:
  TeamRecording() = default;
  std::uint16_t channel(const std::string& schema, const std::string& topic);
  void put(std::uint16_t ch, TimeNs now, const std::string& json);

  mcap::McapWriter writer_;
  TeamRecordingOptions opt_;
  std::string path_;
  std::map<std::string, std::uint16_t> schema_ids_;
  std::map<std::uint16_t, std::string> topics_;
  std::unique_ptr<MissionRecorder> mission_;
  std::uint16_t tf_{0}, uav_truth_{0}, uav_gps_{0}, camera_{0}, radio_{0}, scheduler_{0}, map_ch_{0};
  struct UgvChannels {
    std::uint16_t truth{0}, odometry{0}, estimate{0}, lidar{0};
  };
  std::vector<UgvChannels> ugv_;
  std::vector<std::pair<std::string, RoleInstance*>> roles_;
  const mapping::OrthoMap* map_{nullptr};
  std::map<std::uint64_t, std::uint64_t> tile_versions_;
  TimeNs next_map_{0}, next_radio_{0}, next_scheduler_{0};
  Status first_error_{Ok{}};
  std::vector<std::uint8_t> scratch_;
};

}  // namespace ag::sim
