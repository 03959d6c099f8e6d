// What a team mission recorded as it ran and how its visits were judged: shared by the run
// (eval_mission.cpp) and its report folder (mission_report.cpp).
#pragma once

#include <cstdint>
#include <map>
#include <vector>

#include "airground/aerial_mapping/ortho_map.hpp"
#include "airground/messages/geometry.hpp"
#include "airground/mission/messages.hpp"
#include "airground/mission/records.hpp"
#include "airground/platform/result.hpp"
#include "airground/sim/eval_mission.hpp"
#include "airground/sim/eval_scoring.hpp"
#include "airground/sim/generator.hpp"
#include "airground/sim/world.hpp"

namespace ag::sim::mission_eval {

struct Sample {
  double t{0};
  Pose2 truth, odom;
  Pose2 est;             // the robot's published pose (have_est)
  bool have_est{false};  // the robot had published a pose
  bool tracking{false};
  double err{-1};        // [m] its estimate against the truth at the estimate's stamp, tracking or not
  const char* loc{"none"};  // localization status
};

struct Visit {
  double t{0};
  int robot{0};
  std::uint32_t region{0};
  double est_x{0}, est_y{0};
  bool have_goal{false};  // the goal the robot was sent to (a region's goal moves as the map grows)
  double goal_x{0}, goal_y{0};
  double true_x{0}, true_y{0};  // [m] where the robot truly stood when it marked the visit
  double radius{3.0};           // [m] its visit radius
};
struct Claim {
  std::uint32_t region{mission::kNoRegion};
  double goal_x{0}, goal_y{0};
};

struct StateChange {
  double t{0};
  mission::ClaimState state{mission::ClaimState::kIdle};
  std::uint32_t region{mission::kNoRegion};
};

// What the mission looks like as it runs; the vectors hold one entry per ground robot.
struct MissionLog {
  explicit MissionLog(std::size_t n, double status_period_s)
      : samples(n), changes(n), status(n), visits_seen(n, 0), done_at(n, -1.0), killed(n, false), last_claim(n),
        next_status(status_period_s), last_sample(n) {}

  std::vector<std::vector<Sample>> samples;
  std::vector<std::vector<StateChange>> changes;
  std::vector<mission::MissionStatusMsg> status;
  std::vector<std::uint16_t> visits_seen;
  std::vector<double> done_at;
  std::vector<bool> killed;
  std::vector<Visit> visits;
  std::vector<Claim> last_claim;
  std::map<std::uint32_t, mission::RegionRecord> regions;  // newest record of every region id
  std::vector<double> traffic_t, traffic_kbps;
  std::uint64_t last_bytes{0};
  double last_traffic_t{0};
  double next_status{0};
  std::vector<Sample> last_sample;
  mapping::MapRaster raster;  // the quadrotor's map at the end
};

// The verdict on every visit, and what the true ones reached.
struct VisitJudgement {
  std::vector<VisitVerdict> verdict;             // per visit
  std::vector<bool> target_hit;                  // per target
  std::map<std::uint32_t, bool> region_visited;  // regions with a true visit
};

// Writes the maps, pictures, tables, metrics.json and report.md into o.out_dir.
Status write_mission_files(const MissionOptions& o, const World& w, const std::vector<TargetCluster>& targets, const MissionLog& log,
                           const VisitJudgement& judged, const MissionMetrics& m);

}  // namespace ag::sim::mission_eval
