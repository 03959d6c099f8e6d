// What the base station knows of the mission, in fixed-size arrays (no allocation after construction):
// every robot's latest pose, trail, claim and visited goals; the regions of interest; failures;
// detected objects; the comms counters. The web stage updates it in step() and hands a copy to the
// server thread through a triple buffer (platform/latest_value.hpp).
#pragma once

#include <array>
#include <cstdint>

#include "airground/base_station/records.hpp"
#include "airground/comms/messages.hpp"

namespace ag::base_station {

inline constexpr std::size_t kModelRobots = comms::kTeamMax;
inline constexpr std::size_t kTrailPoints = 600;
inline constexpr std::size_t kRegionBatches = 16;
inline constexpr std::size_t kModelFailures = 256;
inline constexpr std::size_t kModelObjects = 256;
inline constexpr float kTrailMinStepM = 0.25f;  // a trail point only when the robot moved this far

struct TrailPoint {
  float x{0}, y{0};
};

struct RobotView {
  comms::RobotId id{comms::kNoRobot};
  bool has_pose{false};
  std::uint8_t loc_status{0};  // LocalizationStatus of the robot
  TimeNs pose_stamp{0};        // [ns] the robot's clock
  TimeNs heard{0};             // [ns] base clock: when anything of it was last received
  float x{0}, y{0}, yaw{0};    // [m, m, rad]
  float sigma_x{0}, sigma_y{0};
  std::uint32_t trail_head{0}, trail_count{0};  // ring: oldest at (head - count)
  std::array<TrailPoint, kTrailPoints> trail{};
  bool has_claim{false};
  mission::ClaimRecord claim;
  bool has_visited{false};
  mission::VisitedRecord visited;
};

struct FailureView {
  comms::RobotId origin{comms::kNoRobot};
  TimeNs received{0};
  mission::FailureRecord f;
};
struct ObjectView {
  comms::RobotId origin{comms::kNoRobot};
  mission::ObjectRecord o;
};

struct ModelCounters {
  std::uint64_t records_in{0}, poses_in{0}, tiles_in{0};
  std::uint64_t regions_in{0}, claims_in{0}, visited_in{0}, failures_in{0}, objects_in{0}, other_in{0};
  std::uint64_t decode_errors{0};
  std::uint64_t stale_regions{0};     // a batch older than the one held
  std::uint64_t table_full{0};        // robots, failures or objects beyond the fixed tables
  std::uint64_t tiles_held_back{0};   // steps where the tile hand-over to the server was full
  std::uint64_t log_dropped{0};       // log entries the writer thread could not take (the model has them)
  std::uint64_t commands_sent{0};     // operator commands (arm, disarm) published to the team
  std::uint8_t last_error_kind{0};    // RecordKind of the last record that failed to decode
  std::uint8_t last_error{0};         // its mission::DecodeError
  comms::RobotId last_error_origin{comms::kNoRobot};
};

struct MissionModel {
  std::uint64_t seq{0};   // grows with every change
  TimeNs now{0};          // [ns] base clock at the last update
  std::uint32_t robot_count{0};
  std::array<RobotView, kModelRobots> robots{};
  std::array<std::int16_t, 256> robot_index{};  // robot id -> position in robots, -1 none (set by reset())
  comms::RobotId regions_origin{comms::kNoRobot};
  std::uint32_t regions_version{0};
  std::uint16_t regions_batches{0};
  std::array<bool, kRegionBatches> batch_valid{};
  std::array<mission::RegionBatch, kRegionBatches> batches{};
  std::uint32_t failure_count{0};
  std::array<FailureView, kModelFailures> failures{};
  std::uint32_t object_count{0};
  std::array<ObjectView, kModelObjects> objects{};
  bool has_comms{false};
  comms::CommsStatsMsg comms;
  ModelCounters counters;

  MissionModel() { reset(); }
  void reset() noexcept;
  // The robot's view, created on first sight; nullptr when the table is full (counted).
  RobotView* robot(comms::RobotId id) noexcept;
  [[nodiscard]] const RobotView* find_robot(comms::RobotId id) const noexcept;
  // Applies the team's latest poses (new stamps extend the trails). Returns whether anything changed.
  bool apply_poses(const comms::TeamPosesMsg& m, TimeNs now) noexcept;
  // Applies one gossip record; returns its kind and sets `err` when it did not decode (counted).
  RecordKind apply_record(const comms::GossipRecordMsg& r, TimeNs now, mission::DecodeError& err) noexcept;
  void apply_comms(const comms::CommsStatsMsg& m) noexcept;
  // Regions currently shown: every valid batch below the held version's batch count.
  template <typename F>
  void for_each_region(F&& f) const {
    for (std::size_t b = 0; b < kRegionBatches && b < regions_batches; ++b)
      if (batch_valid[b])
        for (std::size_t i = 0; i < batches[b].count; ++i) f(batches[b].regions[i]);
  }
};

}  // namespace ag::base_station
