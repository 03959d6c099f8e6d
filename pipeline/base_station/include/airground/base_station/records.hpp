// The mission's records as the base station shows them: which record a topic carries, and the names its
// log and page give a decode error. Layouts, limits, topics and the decoder itself are the mission codec's
// (airground/mission/records.hpp): the base station reads the records exactly as the robots do.
#pragma once

#include <cstdint>

#include "airground/comms/topics.hpp"
#include "airground/mission/records.hpp"

namespace ag::base_station {

// Which record a topic carries.
enum class RecordKind : std::uint8_t { kRegions, kClaim, kVisited, kFailure, kObject, kStatus, kOther };
[[nodiscard]] RecordKind record_kind(comms::Topic t) noexcept;
[[nodiscard]] const char* to_string(RecordKind k) noexcept;

// The codec's names but for a bad format byte, which docs/base_station.md names in full.
[[nodiscard]] const char* error_name(mission::DecodeError e) noexcept;

}  // namespace ag::base_station
