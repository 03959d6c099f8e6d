#include "airground/base_station/records.hpp"

namespace ag::base_station {

RecordKind record_kind(comms::Topic t) noexcept {
  using comms::TopicKind;
  if (t == mission::kClaimTopic) return RecordKind::kClaim;
  if (t == mission::kVisitedTopic) return RecordKind::kVisited;
  if (mission::is_object_topic(t)) return RecordKind::kObject;
  switch (comms::topic_kind(t)) {
    case TopicKind::kRegions: return RecordKind::kRegions;
    case TopicKind::kFailures: return RecordKind::kFailure;
    case TopicKind::kStatus: return RecordKind::kStatus;
    default: return RecordKind::kOther;
  }
}

const char* to_string(RecordKind k) noexcept {
  switch (k) {
    case RecordKind::kRegions: return "regions";
    case RecordKind::kClaim: return "claim";
    case RecordKind::kVisited: return "visited";
    case RecordKind::kFailure: return "failure";
    case RecordKind::kObject: return "object";
    case RecordKind::kStatus: return "status";
    case RecordKind::kOther: return "other";
  }
  return "other";
}

const char* error_name(mission::DecodeError e) noexcept {
  return e == mission::DecodeError::kFormat ? "unknown format byte" : mission::to_string(e);
}

}  // namespace ag::base_station
