// The mission stages' own latest-value channels (fixed size, for the simulator, the tools and tests).
#pragma once

#include <array>
#include <cstdint>
#include <string_view>

#include "airground/comms/messages.hpp"
#include "airground/messages/channels.hpp"
#include "airground/mission/records.hpp"
#include "airground/platform/time.hpp"

namespace ag::mission {

inline constexpr std::size_t kMaxRegionsMsg = 320;  // 8 gossip batches of 40

// Channel "regions" (latest value, quadrotor): the current regions of interest, sorted by id.
struct RegionsMsg {
  TimeNs stamp{0};
  TimeNs published{0};
  std::uint32_t version{0};      // regions_version of the gossip batches
  std::uint32_t count{0};
  std::uint32_t batches{0};
  std::uint64_t extractions{0};
  std::uint64_t dropped{0};      // regions beyond kMaxRegionsMsg (counted, not published)
  std::array<RegionRecord, kMaxRegionsMsg> regions{};
};

// Channel "mission_status" (latest value, ground robot): the mission manager's state.
struct MissionStatusMsg {
  TimeNs stamp{0};
  TimeNs published{0};
  ClaimState state{ClaimState::kIdle};
  std::uint32_t region_id{kNoRegion};  // current claim
  std::uint32_t goal_id{0};            // the id of the last goal sent to the planner
  double goal_x{0}, goal_y{0};         // [m]
  double pose_sigma_m{0};              // [m]
  std::uint32_t regions_known{0};      // regions with a goal heard from the quadrotor
  std::uint32_t visited_team{0};       // of those, visited by anyone
  std::uint32_t visited_own{0};        // marked by this robot
  std::uint32_t failed_own{0};         // failures this robot published
  std::uint32_t clashes_lost{0};       // claims given up to a robot of higher priority
  std::uint32_t takeovers{0};          // regions taken from a robot not heard for claim_timeout_s
  std::uint32_t refused_visits{0};     // near a goal but not marked: localization not good enough (counts steps)
  std::uint64_t records_in{0}, records_bad{0};
  bool done{false};                    // returned to the start: the mission is over for this robot
};

inline constexpr std::size_t kMaxObjectsMsg = 64;

// Channel "objects" (latest value, ground robot): the target mapper's objects (EKF estimates).
struct ObjectsMsg {
  TimeNs stamp{0};
  TimeNs published{0};
  std::uint32_t count{0};
  std::uint64_t scans{0}, detections{0}, dropped{0};
  std::array<ObjectRecord, kMaxObjectsMsg> objects{};
  std::array<bool, kMaxObjectsMsg> confirmed{};  // enough detections to be shared
};

}  // namespace ag::mission

// The mission channels, declared once (see airground/messages/channels.hpp; these live beside their
// messages because messages/ cannot see pipeline/ types).
namespace ag::chan {
// regions (quadrotor) -> nobody yet (tools, tests).
inline constexpr LatestTopic<mission::RegionsMsg> kRegions{"regions"};
// mission (ground robot) -> nobody yet (tools, tests).
inline constexpr LatestTopic<mission::MissionStatusMsg> kMissionStatus{"mission_status"};
// targets (ground robot) -> mission.
inline constexpr LatestTopic<mission::ObjectsMsg> kObjects{"objects"};

inline constexpr std::array<std::string_view, 3> kMissionNames{kRegions.name, kMissionStatus.name, kObjects.name};
static_assert(names_distinct(kNames, kCommsNames, kMissionNames), "two channels share a name");
}  // namespace ag::chan
