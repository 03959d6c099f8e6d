// The mission's gossip record payloads (the contract of /work/notes/mission-records.md, docs/missions.md):
// regions of interest (quadrotor), claim, visited and failure records (ground robots), detected objects.
// All little-endian, fixed layouts, each payload <= comms::kGossipPayloadMax. Encoding writes into a
// caller's buffer and returns the bytes written (0: the buffer is too small or the content is out of
// range); decoding checks every length, count, enum and float and returns a DecodeError instead of
// reading past the end: a malformed payload is an error the caller counts, never a crash. The one codec
// of these records: the robots' stages and the base station (pipeline/base_station) both decode with it.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

#include "airground/comms/topics.hpp"

namespace ag::mission {

inline constexpr std::uint8_t kRecordFormat = 1;
inline constexpr std::uint32_t kNoRegion = 0xFFFFFFFFu;
inline constexpr std::size_t kRegionsPerBatch = 40;
inline constexpr std::size_t kRegionBatchHeader = 8;
inline constexpr std::size_t kRegionEntryBytes = 24;
inline constexpr std::size_t kClaimBytes = 20;
inline constexpr std::size_t kMaxVisited = 80;
inline constexpr std::size_t kVisitedHeader = 4;
inline constexpr std::size_t kVisitedEntryBytes = 12;
inline constexpr std::size_t kFailureBytes = 16;
inline constexpr std::size_t kObjectBytes = 28;
inline constexpr std::uint32_t kObjectIndexBase = 0x100000u;

enum class DecodeError : std::uint8_t {
  kOk = 0,
  kTruncated = 1,   // shorter than its header or than its count says
  kTrailing = 2,    // longer than its count says
  kFormat = 3,      // unknown format byte
  kCount = 4,       // count above the record's limit
  kValue = 5,       // an enum out of range, zero batches, a negative variance (decode(): a non-finite float too)
  kNotFinite = 6,   // a non-finite float, told apart by decode_detailed() only
};
const char* to_string(DecodeError e) noexcept;
// decode() is what the robots use: they only count a bad record, so a non-finite float is one more kValue.
// decode_detailed() is the same decoder with kNotFinite kept apart, for the base station, which names the
// error in its log and page.

// ---------------------------------------------------------------- regions (kRegions, index = batch)
struct RegionRecord {
  std::uint32_t id{0};
  float cx{0}, cy{0};          // [m] centroid, map frame
  float goal_x{0}, goal_y{0};  // [m] goal point
  std::uint16_t cells{0};      // vehicle cells (0.5 m) in the region
  bool goal_valid{false};
  friend bool operator==(const RegionRecord&, const RegionRecord&) = default;
};
struct RegionBatch {
  std::uint8_t count{0};
  std::uint16_t batches{0};           // total batches of this version
  std::uint32_t regions_version{0};
  std::array<RegionRecord, kRegionsPerBatch> regions{};
};
std::size_t encode(const RegionBatch& b, std::span<std::uint8_t> out) noexcept;
DecodeError decode(std::span<const std::uint8_t> in, RegionBatch& b) noexcept;
DecodeError decode_detailed(std::span<const std::uint8_t> in, RegionBatch& b) noexcept;
constexpr comms::Topic regions_topic(std::uint32_t batch) noexcept { return comms::make_topic(comms::TopicKind::kRegions, batch); }

// ---------------------------------------------------------------- claim (kClaims, index 0)
enum class ClaimState : std::uint8_t { kIdle = 0, kGoing = 1, kReturning = 2, kDone = 3, kFailedRetrying = 4, kStopped = 5 };
const char* to_string(ClaimState s) noexcept;
struct ClaimRecord {
  ClaimState state{ClaimState::kIdle};
  std::uint8_t priority{0};     // lower number wins a clash
  std::uint32_t region_id{kNoRegion};
  float goal_x{0}, goal_y{0};   // [m]
  float pose_sigma_m{0};        // [m]
  friend bool operator==(const ClaimRecord&, const ClaimRecord&) = default;
};
std::size_t encode(const ClaimRecord& c, std::span<std::uint8_t> out) noexcept;
DecodeError decode(std::span<const std::uint8_t> in, ClaimRecord& c) noexcept;
DecodeError decode_detailed(std::span<const std::uint8_t> in, ClaimRecord& c) noexcept;
inline constexpr comms::Topic kClaimTopic = comms::make_topic(comms::TopicKind::kClaims, 0);

// ---------------------------------------------------------------- visited (kClaims, index 1)
struct VisitedEntry {
  std::uint32_t region_id{0};
  float x{0}, y{0};  // [m] where the robot stood when it marked it
  friend bool operator==(const VisitedEntry&, const VisitedEntry&) = default;
};
struct VisitedRecord {
  std::uint16_t count{0};
  std::array<VisitedEntry, kMaxVisited> entries{};
};
std::size_t encode(const VisitedRecord& v, std::span<std::uint8_t> out) noexcept;
DecodeError decode(std::span<const std::uint8_t> in, VisitedRecord& v) noexcept;
DecodeError decode_detailed(std::span<const std::uint8_t> in, VisitedRecord& v) noexcept;
inline constexpr comms::Topic kVisitedTopic = comms::make_topic(comms::TopicKind::kClaims, 1);

// ---------------------------------------------------------------- failure (kFailures, index = region & 0xFFFFFF)
enum class FailureReason : std::uint8_t { kNoRoute = 1, kNoProgress = 2, kLostLocalization = 3, kBlocked = 4 };
const char* to_string(FailureReason r) noexcept;
struct FailureRecord {
  FailureReason reason{FailureReason::kNoRoute};
  std::uint16_t attempts{0};
  std::uint32_t region_id{0};
  float x{0}, y{0};  // [m] the goal it failed to reach
  friend bool operator==(const FailureRecord&, const FailureRecord&) = default;
};
std::size_t encode(const FailureRecord& f, std::span<std::uint8_t> out) noexcept;
DecodeError decode(std::span<const std::uint8_t> in, FailureRecord& f) noexcept;
DecodeError decode_detailed(std::span<const std::uint8_t> in, FailureRecord& f) noexcept;
constexpr comms::Topic failure_topic(std::uint32_t region_id) noexcept {
  return comms::make_topic(comms::TopicKind::kFailures, region_id & 0xFFFFFFu);
}

// ---------------------------------------------------------------- detected object (kApp, index = 0x100000 | n)
struct ObjectRecord {
  std::uint8_t cls{5};
  std::uint16_t detections{0};
  std::uint32_t object_id{0};
  float x{0}, y{0};           // [m] EKF mean
  float cxx{0}, cxy{0}, cyy{0};  // [m^2] EKF covariance
  friend bool operator==(const ObjectRecord&, const ObjectRecord&) = default;
};
std::size_t encode(const ObjectRecord& o, std::span<std::uint8_t> out) noexcept;
DecodeError decode(std::span<const std::uint8_t> in, ObjectRecord& o) noexcept;
DecodeError decode_detailed(std::span<const std::uint8_t> in, ObjectRecord& o) noexcept;
constexpr comms::Topic object_topic(std::uint32_t n) noexcept {
  return comms::make_topic(comms::TopicKind::kApp, kObjectIndexBase | (n & 0xFFFFFu));
}
constexpr bool is_object_topic(comms::Topic t) noexcept {
  return comms::topic_kind(t) == comms::TopicKind::kApp && (comms::topic_index(t) & kObjectIndexBase) != 0;
}

}  // namespace ag::mission
