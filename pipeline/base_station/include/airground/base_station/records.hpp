// Decoders of the mission's gossip records as docs (/work/notes/mission-records.md, docs/base_station.md)
// define them: regions, claims, visited, failures, detected objects. Little-endian, format byte 1.
// Every decoder checks length, format and counts and that floats are finite; it never reads past the
// payload. (The mission library owns the encoders; once merged, these may be replaced by its header.)
#pragma once

#include <array>
#include <cstdint>
#include <span>

#include "airground/comms/topics.hpp"

namespace ag::base {

inline constexpr std::size_t kRegionsPerBatch = 40;
inline constexpr std::size_t kVisitedMax = 80;
inline constexpr std::uint32_t kNoRegion = 0xFFFFFFFFu;
inline constexpr std::uint32_t kObjectIndexFlag = 0x100000u;

struct RegionEntry {
  std::uint32_t id{0};
  float cx{0}, cy{0};          // [m] centroid, map frame
  float goal_x{0}, goal_y{0};  // [m]
  std::uint16_t cells{0};      // vehicle cells (0.5 m)
  std::uint8_t flags{0};       // bit0 goal_valid
};
struct RegionsBatch {
  std::uint8_t count{0};
  std::uint16_t batches{0};
  std::uint32_t version{0};
  std::array<RegionEntry, kRegionsPerBatch> regions{};
};

enum class ClaimState : std::uint8_t { kIdle = 0, kGoing = 1, kReturning = 2, kDone = 3, kFailedRetrying = 4, kStopped = 5 };
struct ClaimRecord {
  std::uint8_t state{0};
  std::uint8_t priority{0};
  std::uint32_t region_id{kNoRegion};
  float goal_x{0}, goal_y{0};  // [m]
  float pose_sigma_m{0};       // [m]
};

struct VisitedEntry {
  std::uint32_t region_id{0};
  float x{0}, y{0};  // [m] where the robot stood
};
struct VisitedRecord {
  std::uint16_t count{0};
  std::array<VisitedEntry, kVisitedMax> entries{};
};

struct FailureRecord {
  std::uint8_t reason{0};  // 1 no_route, 2 no_progress, 3 lost_localization, 4 blocked
  std::uint16_t attempts{0};
  std::uint32_t region_id{0};
  float x{0}, y{0};  // [m]
};

struct ObjectRecord {
  std::uint8_t cls{0};
  std::uint16_t detections{0};
  std::uint32_t object_id{0};
  float x{0}, y{0};             // [m]
  float cxx{0}, cxy{0}, cyy{0};  // [m^2]
};

// Which record a topic carries.
enum class RecordKind : std::uint8_t { kRegions, kClaim, kVisited, kFailure, kObject, kStatus, kOther };
[[nodiscard]] RecordKind record_kind(comms::Topic t) noexcept;
[[nodiscard]] const char* to_string(RecordKind k) noexcept;

enum class DecodeError : std::uint8_t { kNone = 0, kTruncated, kTrailing, kFormat, kCount, kNotFinite, kValue };
[[nodiscard]] const char* to_string(DecodeError e) noexcept;

inline constexpr std::size_t kRegionsHeaderBytes = 8, kRegionEntryBytes = 24;
inline constexpr std::size_t kClaimBytes = 20;
inline constexpr std::size_t kVisitedHeaderBytes = 4, kVisitedEntryBytes = 12;
inline constexpr std::size_t kFailureBytes = 16;
inline constexpr std::size_t kObjectBytes = 28;

DecodeError decode_regions(std::span<const std::uint8_t> in, RegionsBatch& out) noexcept;
DecodeError decode_claim(std::span<const std::uint8_t> in, ClaimRecord& out) noexcept;
DecodeError decode_visited(std::span<const std::uint8_t> in, VisitedRecord& out) noexcept;
DecodeError decode_failure(std::span<const std::uint8_t> in, FailureRecord& out) noexcept;
DecodeError decode_object(std::span<const std::uint8_t> in, ObjectRecord& out) noexcept;

[[nodiscard]] const char* claim_state_name(std::uint8_t s) noexcept;
[[nodiscard]] const char* failure_reason_name(std::uint8_t r) noexcept;

// Encoders (tests and the browser test's mission player; the mission library has its own).
std::size_t encode_regions(const RegionsBatch& b, std::span<std::uint8_t> out) noexcept;
std::size_t encode_claim(const ClaimRecord& c, std::span<std::uint8_t> out) noexcept;
std::size_t encode_visited(const VisitedRecord& v, std::span<std::uint8_t> out) noexcept;
std::size_t encode_failure(const FailureRecord& f, std::span<std::uint8_t> out) noexcept;
std::size_t encode_object(const ObjectRecord& o, std::span<std::uint8_t> out) noexcept;

}  // namespace ag::base
