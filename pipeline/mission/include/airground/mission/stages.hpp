// The mission stages (thin wrappers, docs/missions.md):
//   regions (quadrotor): map_tiles -> class grid over the mission area -> RegionExtractor at most every
//            period_s when tiles changed -> on a new regions version: the batches on "gossip_out"
//            (TopicKind::kRegions, index = batch) and the set on "regions" (RegionsMsg).
//   mission (ground robot): gossip_in (regions, claims, visited, failures), team_poses (liveness),
//            localization, planned_path (route status) -> MissionManager -> "goal" (GoalMsg for the
//            planner, on every new goal or cancel), own claim / visited / failure records on
//            "gossip_out", the state on "mission_status" (MissionStatusMsg); the target mapper's confirmed
//            objects ("objects") forwarded as object records (the mission stage is gossip_out's one writer).
//   targets (ground robot): lidar_scan + localization -> VehicleDetector -> ObjectTracker -> "objects".
// Everything is allocated in init(); step() never allocates and never blocks.
#pragma once

#include <array>
#include <memory>
#include <span>
#include <string_view>

#include "airground/comms/messages.hpp"
#include "airground/messages/drive_messages.hpp"
#include "airground/messages/messages.hpp"
#include "airground/messages/mission_area.hpp"
#include "airground/mission/manager.hpp"
#include "airground/mission/messages.hpp"
#include "airground/mission/regions.hpp"
#include "airground/mission/targets.hpp"
#include "airground/platform/param_binding.hpp"
#include "airground/platform/stage.hpp"

namespace ag::mission {

// The regions stage's own parameters (the extractor's follow them in the same section).
inline constexpr auto kRegionsAreaFields = mission_area_fields("mission area in the map frame: west edge (the class grid covers it)");
struct RegionsSettings {
  double period_s{1.0};
};
inline constexpr ParamField<RegionsSettings> kRegionsStageFields[] = {
    field::real("period_s", &RegionsSettings::period_s, 0.1, 600.0, "s", "re-extract the regions at most this often (and only when tiles changed)"),
};
inline constexpr ParamField<RegionParams> kRegionFields[] = {
    field::real("merge_distance_m", &RegionParams::merge_distance_m, 0.5, 100.0, "m", "vehicle blobs closer than this (gap) form one region"),
    field::integer("open_radius_cells", &RegionParams::open_radius_cells, 0, 5, "cells", "opening of the vehicle mask (removes noise cells); 0 = off"),
    field::integer("min_region_cells", &RegionParams::min_region_cells, 1, 100000, "cells", "regions with fewer vehicle cells (0.5 m) are dropped"),
    field::real("goal_search_radius_m", &RegionParams::goal_search_radius_m, 1.0, 100.0, "m", "the goal is searched this far around the region"),
    field::real("min_goal_clearance_m", &RegionParams::min_goal_clearance_m, 0.0, 10.0, "m", "the goal keeps this from anything not traversable"),
    field::real("goal_clearance_cap_m", &RegionParams::goal_clearance_cap_m, 0.5, 50.0, "m", "clearance beyond this does not make a goal better"),
    field::integer("reachable_min_cells", &RegionParams::reachable_min_cells, 1, 100000000, "cells", "a traversable component this big (or the largest) is reachable"),
    field::choice<&RegionParams::max_level>("traversable", "free|rough|costly",
                                            {Traversability::kFree, Traversability::kRough, Traversability::kCostly},
                                            "highest traversability level a goal may lie on (as the planner's)"),
};
inline constexpr auto kRegionsParams = param_specs(kRegionsAreaFields, kRegionsStageFields, kRegionFields);

struct RegionsCounters {
  std::uint64_t tiles_in{0}, tiles_applied{0}, tiles_rejected{0};
  std::uint64_t extractions{0}, versions_published{0}, batches_published{0}, publish_deferred{0}, regions_dropped{0};
};

class RegionsStage final : public Stage {
 public:
  static constexpr std::span<const ParamSpec> kParams{kRegionsParams};
  static std::unique_ptr<Stage> make() { return std::make_unique<RegionsStage>(); }
  Status init(StageContext& ctx) override;
  void step(TimeNs now) noexcept override;
  [[nodiscard]] const RegionExtractor& extractor() const noexcept { return *ex_; }
  [[nodiscard]] const RegionsMsg& published() const noexcept { return *msg_; }
  [[nodiscard]] const RegionsCounters& counters() const noexcept { return c_; }

 private:
  bool publish_batches(TimeNs now) noexcept;
  std::unique_ptr<RegionExtractor> ex_;
  std::unique_ptr<RegionsMsg> msg_;
  std::unique_ptr<comms::GossipPublishMsg> pub_;
  std::unique_ptr<RegionBatch> batch_;
  RingReader<MapTileMsg, kMapTileRing> tiles_;
  RingWriter<comms::GossipPublishMsg, comms::kGossipRing> gossip_;
  LatestWriter<RegionsMsg> out_;
  TimeNs period_{0}, last_extract_{-1};
  std::uint32_t published_version_{0};
  bool pending_{false};
  RegionsCounters c_;
};

inline constexpr ParamField<ManagerParams> kManagerFields[] = {
    field::integer("priority", &ManagerParams::priority, 0, 255, "", "fixed mission priority: the lower number keeps a region two robots claim"),
    field::real("start_x_m", &ManagerParams::start_x, -1e6, 1e6, "m", "start pose (map frame): where the robot returns at the end"),
    field::real("start_y_m", &ManagerParams::start_y, -1e6, 1e6, "m", "start pose: north"),
    field::real("visit_radius_m", &ManagerParams::visit_radius_m, 0.5, 20.0, "m", "a region is visited when the robot is this close to its goal ..."),
    field::real("max_sigma_m", &ManagerParams::max_sigma_m, 0.1, 50.0, "m", "... while tracking with a pose sigma (largest xy axis) below this"),
    field::real("visit_margin_m", &ManagerParams::visit_margin_m, 0.0, 20.0, "m", "... and is marked only this much inside visit_radius_m (at least half of it): a pose error must not carry the mark outside"),
    field::real("revisit_moved_m", &ManagerParams::revisit_moved_m, 0.0, 1000.0, "m", "a visit mark this far from the region's goal as it is now no longer counts: visited again (0 = never)"),
    field::integer("max_no_route", &ManagerParams::max_no_route, 1, 1000, "plans", "failed plans in a row for the current goal: the goal failed"),
    field::real("no_progress_timeout_s", &ManagerParams::no_progress_timeout_s, 5.0, 3600.0, "s", "no progress_min_m closer for this long: the goal failed"),
    field::real("progress_min_m", &ManagerParams::progress_min_m, 0.1, 50.0, "m", "what counts as progress"),
    field::real("retry_after_s", &ManagerParams::retry_after_s, 0.0, 36000.0, "s", "a region this robot failed is not chosen by it again for this long"),
    field::integer("give_up_failures", &ManagerParams::give_up_failures, 0, 1000, "failures",
                   "the team gives a region up after this many no_progress / lost_localization failures at its goal (any robot); 0 = never"),
    field::real("claim_timeout_s", &ManagerParams::claim_timeout_s, 1.0, 3600.0, "s", "a robot not heard this long: its claim is void, others take over"),
    field::real("idle_return_s", &ManagerParams::idle_return_s, 0.0, 36000.0, "s", "nothing left and no new region or map tile this long: return to the start"),
    field::real("mission_end_s", &ManagerParams::mission_end_s, 0.0, 360000.0, "s", "> 0: return to the start this long after start-up regardless"),
    field::real("survey_end_s", &ManagerParams::survey_end_s, 0.0, 360000.0, "s", "> 0: the quadrotor's survey ends about this long after start-up: until then wait for regions, idle_return_s counts from then"),
    field::real("republish_s", &ManagerParams::republish_s, 0.1, 600.0, "s", "own claim and visited records are re-sent this often"),
    field::real("map_growing_s", &ManagerParams::map_growing_s, 0.0, 3600.0, "s", "no route within this of the last map tile is not a failure (the way may not be mapped yet) ..."),
    field::real("defer_s", &ManagerParams::defer_s, 0.0, 3600.0, "s", "... the region is dropped and not chosen by this robot again for this long"),
};
inline constexpr ParamSpec kMissionWaypointsParam[] = {  // parsed into waypoint_x/_y by parse_waypoints()
    ParamSpec::text("waypoints", "", "", "waypoints mission: 'x,y;x,y;...' [m, map frame] driven in order, then back to start; empty = regions"),
};
inline constexpr auto kMissionParams = param_specs(kManagerFields, kMissionWaypointsParam);

// Parses "x,y;x,y;..." (at most kMaxWaypoints) into p; an error names the item.
Status parse_waypoints(std::string_view text, ManagerParams& p);

struct MissionCounters {
  std::uint64_t records_in{0}, records_bad{0}, records_published{0}, publish_refused{0}, goals_published{0};
};

class MissionStage final : public Stage {
 public:
  static constexpr std::span<const ParamSpec> kParams{kMissionParams};
  static std::unique_ptr<Stage> make() { return std::make_unique<MissionStage>(); }
  Status init(StageContext& ctx) override;
  void step(TimeNs now) noexcept override;
  [[nodiscard]] const MissionManager& manager() const noexcept { return *mgr_; }
  [[nodiscard]] const MissionCounters& counters() const noexcept { return c_; }

 private:
  std::unique_ptr<MissionManager> mgr_;
  std::unique_ptr<comms::GossipPublishMsg> pub_;
  std::unique_ptr<std::array<TimeNs, 256>> heard_;
  RingReader<comms::GossipRecordMsg, comms::kGossipRing> gossip_in_;
  RingWriter<comms::GossipPublishMsg, comms::kGossipRing> gossip_out_;
  LatestReader<comms::TeamPosesMsg> team_;
  LatestReader<comms::CommsStatsMsg> comms_stats_;  // tiles_in: map data still arriving
  std::uint64_t tiles_seen_{0};
  std::uint64_t given_up_logged_{0};  // regions given up, as last logged
  LatestReader<LocalizationMsg> loc_;
  LatestReader<PlannedPathMsg> path_;
  LatestWriter<GoalMsg> goal_out_;
  LatestWriter<MissionStatusMsg> status_out_;
  LatestReader<ObjectsMsg> objects_in_;
  std::unique_ptr<ObjectsMsg> objects_;
  std::unique_ptr<std::array<ObjectRecord, kMaxObjectsMsg>> objects_sent_;
  std::unique_ptr<std::array<TimeNs, kMaxObjectsMsg>> objects_sent_at_;
  std::uint32_t goal_sent_{0};
  TimeNs republish_{0};
  MissionCounters c_;
};

// The targets stage's own parameter (the detector's and the tracker's come first in the section).
struct TargetsSettings {
  double max_sigma_m{1.5};
};
inline constexpr ParamField<DetectorParams> kDetectorFields[] = {
    field::real("max_range_m", &DetectorParams::max_range_m, 5.0, 120.0, "m", "vehicle returns farther than this are not detected"),
    field::integer("min_points", &DetectorParams::min_points, 3, 100000, "points", "a cluster of vehicle returns needs this many points"),
    field::real("sigma0_m", &DetectorParams::sigma0_m, 0.01, 10.0, "m", "detection sigma at 0 m (grows by sigma_per_m)"),
    field::real("sigma_per_m", &DetectorParams::sigma_per_m, 0.0, 1.0, "m/m", "detection sigma growth per metre of range"),
};
inline constexpr ParamField<TrackerParams> kObjectTrackerFields[] = {
    field::real("gate_chi2", &TrackerParams::gate_chi2, 1.0, 100.0, "", "association gate on the squared Mahalanobis distance (9.21: 99 %, 2 dof)"),
    field::integer("min_detections", &TrackerParams::min_detections, 1, 1000, "", "an object is shared after this many detections"),
};
inline constexpr ParamField<TargetsSettings> kTargetsStageFields[] = {
    field::real("max_sigma_m", &TargetsSettings::max_sigma_m, 0.1, 50.0, "m", "scans taken with a pose sigma above this are not used"),
};
inline constexpr auto kTargetsParams = param_specs(kDetectorFields, kObjectTrackerFields, kTargetsStageFields);

struct TargetsCounters {
  std::uint64_t scans{0}, scans_skipped_pose{0}, detections{0};
};

class TargetsStage final : public Stage {
 public:
  static constexpr std::span<const ParamSpec> kParams{kTargetsParams};
  static std::unique_ptr<Stage> make() { return std::make_unique<TargetsStage>(); }
  Status init(StageContext& ctx) override;
  void step(TimeNs now) noexcept override;
  [[nodiscard]] const ObjectTracker& tracker() const noexcept { return *trk_; }
  [[nodiscard]] const TargetsCounters& counters() const noexcept { return c_; }

 private:
  std::unique_ptr<VehicleDetector> det_;
  std::unique_ptr<ObjectTracker> trk_;
  std::unique_ptr<ObjectsMsg> msg_;
  RingReader<LidarScanMsg, kLidarRing> scans_;
  LatestReader<LocalizationMsg> loc_;
  LatestWriter<ObjectsMsg> out_;
  LocalizationMsg pose_{};
  bool have_pose_{false};
  TargetsSettings cfg_{};
  TargetsCounters c_;
};

}  // namespace ag::mission
