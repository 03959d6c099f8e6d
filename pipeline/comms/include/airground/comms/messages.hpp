// Messages between the comms stage and the other stages of a robot (plain fixed-size structs, units in
// comments, sample and publish stamps in ns).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>

#include "airground/comms/topics.hpp"
#include "airground/comms/wire.hpp"
#include "airground/messages/channels.hpp"
#include "airground/messages/geometry.hpp"
#include "airground/platform/time.hpp"

namespace ag::comms {

inline constexpr std::size_t kGossipPayloadMax = 1024;  // [B] records through the generic channels
inline constexpr std::size_t kGossipRing = 64;
inline constexpr std::size_t kTeamMax = 32;

// Channel "gossip_out" (ring, any stage -> comms): a record of this robot to share with the team
// (regions of interest, claims, failures, status; map tiles and poses have their own inputs).
struct GossipPublishMsg {
  TimeNs stamp{0};
  TimeNs published{0};
  Topic topic{0};
  std::uint8_t priority{0};  // 0 = the kind's default
  std::uint32_t size{0};     // [B] valid bytes of payload
  std::array<std::uint8_t, kGossipPayloadMax> payload{};
};

// Channel "gossip_in" (ring, comms -> mission etc.): a newer record of another robot, any kind but poses
// and map tiles (which arrive on "team_poses" and "map_tiles").
struct GossipRecordMsg {
  TimeNs stamp{0};          // [ns] origin's stamp
  TimeNs published{0};
  RecordKey key;
  std::uint64_t seq{0};
  std::uint8_t priority{0};
  std::uint32_t size{0};    // [B] (records above kGossipPayloadMax are not delivered here; counted)
  std::array<std::uint8_t, kGossipPayloadMax> payload{};
};

// The pose topic's payload: x, y, yaw (f64, m, m, rad, map frame), status u8, then sqrt of the x, y
// and yaw variances (f32, m, m, rad), little-endian: 37 bytes.
inline constexpr std::size_t kPosePayloadBytes = 8 * 3 + 1 + 4 * 3;

struct TeamPose {
  RobotId robot{kNoRobot};
  std::uint8_t status{0};     // LocalizationStatus of the origin
  TimeNs stamp{0};            // [ns] origin's clock
  Pose2 pose;                 // [m, rad] map frame
  float sigma_x_m{0}, sigma_y_m{0}, sigma_yaw_rad{0};
};

// Channel "team_poses" (latest value): the newest pose of every other robot heard of.
struct TeamPosesMsg {
  TimeNs stamp{0};
  TimeNs published{0};
  std::uint32_t count{0};
  std::array<TeamPose, kTeamMax> robots{};
};

// The command topic's payload (TopicKind::kCommand, index = the robot it is for): command u8
// (OperatorCommand), request u32 (the operator's count, little-endian): 5 bytes. The record's stamp is
// when the operator gave it (the base station's clock): a robot acts on it only while it is fresh
// (comms.command_max_age_s), so a command never acts again after the robot restarts.
enum class OperatorCommand : std::uint8_t { kArm = 1, kDisarm = 2 };
inline constexpr std::size_t kCommandPayloadBytes = 5;
[[nodiscard]] constexpr Topic command_topic(RobotId robot) noexcept { return make_topic(TopicKind::kCommand, robot); }
inline std::size_t encode_command(OperatorCommand c, std::uint32_t request, std::span<std::uint8_t> out) noexcept {
  if (out.size() < kCommandPayloadBytes) return 0;
  out[0] = static_cast<std::uint8_t>(c);
  for (int i = 0; i < 4; ++i) out[static_cast<std::size_t>(1 + i)] = static_cast<std::uint8_t>(request >> (8 * i));
  return kCommandPayloadBytes;
}
// False for a payload of another size or an unknown command.
inline bool decode_command(std::span<const std::uint8_t> in, OperatorCommand& c, std::uint32_t& request) noexcept {
  if (in.size() != kCommandPayloadBytes || (in[0] != 1 && in[0] != 2)) return false;
  c = static_cast<OperatorCommand>(in[0]);
  request = 0;
  for (int i = 0; i < 4; ++i) request |= static_cast<std::uint32_t>(in[static_cast<std::size_t>(1 + i)]) << (8 * i);
  return true;
}

struct CommsPeerRow {
  RobotId robot{kNoRobot};
  std::uint64_t datagrams_in{0}, bytes_in{0}, records_in{0};
  std::uint64_t datagrams_out{0}, bytes_out{0}, records_out{0};
  std::uint64_t duplicates_in{0};
  TimeNs last_heard{0};       // [ns] this robot's clock
};

// Channel "comms_stats" (latest value, every step): the store, the traffic per peer, drops by reason.
struct CommsStatsMsg {
  TimeNs stamp{0};
  TimeNs published{0};
  std::uint32_t records{0};           // records in the store
  std::uint64_t payload_bytes{0};     // [B] their payloads
  std::uint64_t datagrams_in{0}, bytes_in{0}, datagrams_out{0}, bytes_out{0};
  std::uint64_t records_in{0}, records_out{0}, own_records{0};
  std::uint64_t journal_appends{0}, journal_errors{0};
  std::uint64_t link_send_failures{0}, budget_waits{0};
  std::uint64_t tiles_out{0}, tiles_in{0}, tiles_bad{0};  // map tiles published, delivered, undecodable
  std::uint64_t commands_in{0}, commands_stale{0}, commands_bad{0};  // operator commands for this robot: acted on, too old, undecodable
  std::array<std::uint64_t, static_cast<std::size_t>(DropReason::kCount)> drops{};
  std::uint32_t peers{0};
  std::array<CommsPeerRow, kTeamMax> peer{};
};

}  // namespace ag::comms

// The comms channels, declared once (see airground/messages/channels.hpp; these live beside their
// messages because messages/ cannot see pipeline/ types).
namespace ag::chan {
// regions (quadrotor), mission (ground robot) -> comms (optional there: the base station shares nothing).
inline constexpr RingTopic<comms::GossipPublishMsg, comms::kGossipRing> kGossipOut{"gossip_out"};
// comms -> mission, web (base station).
inline constexpr RingTopic<comms::GossipRecordMsg, comms::kGossipRing> kGossipIn{"gossip_in"};
// comms -> mission, web (base station).
inline constexpr LatestTopic<comms::TeamPosesMsg> kTeamPoses{"team_poses"};
// comms -> mission, web (base station).
inline constexpr LatestTopic<comms::CommsStatsMsg> kCommsStats{"comms_stats"};

inline constexpr std::array<std::string_view, 4> kCommsNames{kGossipOut.name, kGossipIn.name, kTeamPoses.name, kCommsStats.name};
static_assert(names_distinct(kNames, kCommsNames), "two channels share a name");
}  // namespace ag::chan
