// What the team gossips about: a record's key is (origin robot, topic); a topic is a kind and an index.
#pragma once

#include <cstdint>

#include "airground/platform/time.hpp"

namespace ag::comms {

using RobotId = std::uint8_t;               // robot.id, 0..254 (DESIGN.md §5)
inline constexpr RobotId kNoRobot = 255;    // "everyone" as a destination, "nobody" as an origin
inline constexpr int kMaxRobots = 255;

// The top 8 bits of a topic are its kind, the low 24 bits an index within the kind (a tile's (tx, ty),
// a goal number). Kinds are part of the wire format: never renumber them.
enum class TopicKind : std::uint8_t {
  kPose = 1,        // the robot's latest pose (index 0)
  kTrajectory = 2,  // its driven path, in chunks (index = chunk number)
  kMapTile = 3,     // one aerial map tile (index = packed tx, ty), so only changed tiles travel
  kRegions = 4,     // regions of interest found in the map (index = batch)
  kClaims = 5,      // current and visited goals (index 0 current, 1 visited)
  kFailures = 6,    // goals the robot failed to reach (index = goal)
  kStatus = 7,      // health, battery, mode (index 0)
  kApp = 8,         // anything else a stage publishes through the generic channel (index free)
  kCommand = 9,     // an operator's command to one robot (index = that robot's id; messages.hpp)
};

using Topic = std::uint32_t;

constexpr Topic make_topic(TopicKind k, std::uint32_t index) noexcept {
  return (static_cast<std::uint32_t>(k) << 24) | (index & 0xFFFFFFu);
}
constexpr TopicKind topic_kind(Topic t) noexcept { return static_cast<TopicKind>(t >> 24); }
constexpr std::uint32_t topic_index(Topic t) noexcept { return t & 0xFFFFFFu; }
constexpr bool topic_kind_known(Topic t) noexcept { return (t >> 24) >= 1 && (t >> 24) <= 9; }

// A tile index (tx, ty) in [-2048, 2047]^2 (±65 km at 32 m tiles) packed into 24 bits.
inline constexpr std::int32_t kTileIndexLimit = 2048;
constexpr bool tile_index_ok(std::int32_t tx, std::int32_t ty) noexcept {
  return tx >= -kTileIndexLimit && tx < kTileIndexLimit && ty >= -kTileIndexLimit && ty < kTileIndexLimit;
}
constexpr Topic tile_topic(std::int32_t tx, std::int32_t ty) noexcept {
  return make_topic(TopicKind::kMapTile, (static_cast<std::uint32_t>(tx + kTileIndexLimit) << 12) |
                                             static_cast<std::uint32_t>(ty + kTileIndexLimit));
}
constexpr std::int32_t tile_topic_tx(Topic t) noexcept { return static_cast<std::int32_t>(topic_index(t) >> 12) - kTileIndexLimit; }
constexpr std::int32_t tile_topic_ty(Topic t) noexcept { return static_cast<std::int32_t>(topic_index(t) & 0xFFFu) - kTileIndexLimit; }

// Default priority per kind: what travels first when the link is thin (higher first).
constexpr std::uint8_t default_priority(TopicKind k) noexcept {
  switch (k) {
    case TopicKind::kCommand: return 7;
    case TopicKind::kFailures: return 7;
    case TopicKind::kClaims: return 6;
    case TopicKind::kPose: return 5;
    case TopicKind::kStatus: return 4;
    case TopicKind::kRegions: return 4;
    case TopicKind::kApp: return 3;
    case TopicKind::kMapTile: return 2;
    case TopicKind::kTrajectory: return 1;
  }
  return 0;
}

struct RecordKey {
  RobotId origin{kNoRobot};
  Topic topic{0};
  friend constexpr bool operator==(const RecordKey&, const RecordKey&) = default;
};

// What is known about a record besides its payload. seq is the origin's own counter: it grows with every
// record the origin writes (over all its topics and across its restarts), so for one key the higher seq
// is the newer record, and (origin, seq) names one record content team-wide.
struct RecordMeta {
  RecordKey key;
  std::uint64_t seq{0};
  std::uint8_t priority{0};
  TimeNs stamp{0};          // [ns] when the origin wrote it (the origin's clock)
  std::uint32_t size{0};    // [B] payload
};

// A 64-bit mix (splitmix64's finaliser): digests and content hashes.
constexpr std::uint64_t mix64(std::uint64_t x) noexcept {
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ULL;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebULL;
  x ^= x >> 31;
  return x;
}
// The digest's fingerprint of one record version: XOR-summed over an origin's records, so replacing
// one record updates the origin's hash in O(1).
constexpr std::uint64_t version_hash(RecordKey k, std::uint64_t seq) noexcept {
  return mix64(mix64((static_cast<std::uint64_t>(k.origin) << 32) ^ k.topic ^ 0x9E3779B97F4A7C15ULL) ^ seq);
}

}  // namespace ag::comms
