// recording.mcap's mission channels: each ground robot's planned path (/ugvN/path), the regions with
// their claims and visits (/mission/regions), as foxglove.SceneUpdate, and the mission's events (claims,
// state changes, visits) as foxglove.Log (/mission/events). Reads the robots' stages from the world
// stage, after their steps of the tick, so one seed gives the same messages.
#pragma once

#include <Eigen/Core>

#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "airground/platform/time.hpp"

namespace ag {
class RoleInstance;
}

namespace ag::sim {

class MissionRecorder {
 public:
  // Writes one message (channel, log time, JSON); the recording's own writer.
  using Put = std::function<void(std::uint16_t channel, TimeNs now, const std::string& json)>;
  struct Channels {
    std::uint16_t regions{0};           // 0: none
    std::uint16_t events{0};            // 0: none
    std::vector<std::uint16_t> paths;   // per ground robot
  };
  MissionRecorder(Channels channels, Put put) : ch_(std::move(channels)), put_(std::move(put)) {}

  // The quadrotor's role (regions; may be null) and the ground robots' roles (claims, visits, planner).
  void watch(RoleInstance* uav, std::vector<RoleInstance*> ugvs);
  // Ground robot i's route when the simulator drives it (not its own stages); written when it changes.
  void route(TimeNs now, int i, const std::vector<Eigen::Vector2d>& path);
  // Planned paths, regions, claims and visits that changed since the last look (at most `period`).
  void tick(TimeNs now);

  static constexpr double kSceneZ = 0.5;  // [m] above the map frame, as the map tiles' grid lies at z = 0

 private:
  struct RegionView {
    bool known{false};           // from the quadrotor's regions
    double x{0}, y{0};           // goal point (or centroid)
    std::string claimed_by;      // robots going there
    std::string visited_by;
    double visit_x{0}, visit_y{0};
    bool visited{false};
  };
  void write_path(TimeNs now, int i, const std::vector<Eigen::Vector2d>& path);
  void event(TimeNs now, const std::string& robot, bool warning, const std::string& text);

  Channels ch_;
  Put put_;
  RoleInstance* uav_{nullptr};
  std::vector<RoleInstance*> ugvs_;
  TimeNs next_{0};
  std::vector<std::uint32_t> planner_seq_;             // per robot: the planned_path seq last written
  std::vector<std::vector<Eigen::Vector2d>> routes_;   // per robot: the simulator's route last written
  std::vector<std::pair<int, std::uint32_t>> states_;  // per robot: claim state and region last seen
  std::vector<std::uint16_t> visits_seen_;             // per robot: own visits already logged
  std::map<std::uint32_t, std::string> written_;       // region id -> what its entity last showed
};

}  // namespace ag::sim
