#include "airground/base_station/records.hpp"

#include <cmath>
#include <cstring>

namespace ag::base {
namespace {
struct Reader {
  std::span<const std::uint8_t> in;
  std::size_t pos{0};
  std::uint8_t u8() noexcept { return in[pos++]; }
  std::uint16_t u16() noexcept {
    const std::uint16_t v = static_cast<std::uint16_t>(in[pos] | (in[pos + 1] << 8));
    pos += 2;
    return v;
  }
  std::uint32_t u32() noexcept {
    const std::uint32_t v = std::uint32_t{in[pos]} | (std::uint32_t{in[pos + 1]} << 8) | (std::uint32_t{in[pos + 2]} << 16) |
                            (std::uint32_t{in[pos + 3]} << 24);
    pos += 4;
    return v;
  }
  float f32() noexcept {
    const std::uint32_t u = u32();
    float f;
    std::memcpy(&f, &u, 4);
    return f;
  }
};
struct Writer {
  std::span<std::uint8_t> out;
  std::size_t pos{0};
  void u8(std::uint8_t v) noexcept { out[pos++] = v; }
  void u16(std::uint16_t v) noexcept {
    u8(static_cast<std::uint8_t>(v));
    u8(static_cast<std::uint8_t>(v >> 8));
  }
  void u32(std::uint32_t v) noexcept {
    for (int i = 0; i < 4; ++i) u8(static_cast<std::uint8_t>(v >> (8 * i)));
  }
  void f32(float f) noexcept {
    std::uint32_t u;
    std::memcpy(&u, &f, 4);
    u32(u);
  }
};
DecodeError exact(std::span<const std::uint8_t> in, std::size_t want) noexcept {
  if (in.size() < want) return DecodeError::kTruncated;
  if (in.size() > want) return DecodeError::kTrailing;
  return DecodeError::kNone;
}
bool finite(std::initializer_list<float> v) noexcept {
  for (float f : v)
    if (!std::isfinite(f)) return false;
  return true;
}
}  // namespace

RecordKind record_kind(comms::Topic t) noexcept {
  using comms::TopicKind;
  switch (comms::topic_kind(t)) {
    case TopicKind::kRegions: return RecordKind::kRegions;
    case TopicKind::kClaims:
      return comms::topic_index(t) == 0 ? RecordKind::kClaim : comms::topic_index(t) == 1 ? RecordKind::kVisited : RecordKind::kOther;
    case TopicKind::kFailures: return RecordKind::kFailure;
    case TopicKind::kApp: return (comms::topic_index(t) & kObjectIndexFlag) != 0 ? RecordKind::kObject : RecordKind::kOther;
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

const char* to_string(DecodeError e) noexcept {
  switch (e) {
    case DecodeError::kNone: return "ok";
    case DecodeError::kTruncated: return "truncated";
    case DecodeError::kTrailing: return "trailing bytes";
    case DecodeError::kFormat: return "unknown format byte";
    case DecodeError::kCount: return "count above the limit";
    case DecodeError::kNotFinite: return "non-finite number";
    case DecodeError::kValue: return "value out of range";
  }
  return "?";
}

const char* claim_state_name(std::uint8_t s) noexcept {
  static constexpr const char* kNames[] = {"idle", "going", "returning", "done", "failed-retrying", "stopped"};
  return s < 6 ? kNames[s] : "unknown";
}
const char* failure_reason_name(std::uint8_t r) noexcept {
  static constexpr const char* kNames[] = {"?", "no_route", "no_progress", "lost_localization", "blocked"};
  return r >= 1 && r <= 4 ? kNames[r] : "unknown";
}

DecodeError decode_regions(std::span<const std::uint8_t> in, RegionsBatch& out) noexcept {
  if (in.size() < kRegionsHeaderBytes) return DecodeError::kTruncated;
  Reader r{in};
  if (r.u8() != 1) return DecodeError::kFormat;
  const std::uint8_t count = r.u8();
  if (count > kRegionsPerBatch) return DecodeError::kCount;
  if (const DecodeError e = exact(in, kRegionsHeaderBytes + count * kRegionEntryBytes); e != DecodeError::kNone) return e;
  out.count = count;
  out.batches = r.u16();
  out.version = r.u32();
  if (out.batches == 0) return DecodeError::kValue;
  for (std::size_t i = 0; i < count; ++i) {
    RegionEntry& e = out.regions[i];
    e.id = r.u32();
    e.cx = r.f32();
    e.cy = r.f32();
    e.goal_x = r.f32();
    e.goal_y = r.f32();
    e.cells = r.u16();
    e.flags = r.u8();
    r.u8();
    if (!finite({e.cx, e.cy, e.goal_x, e.goal_y})) return DecodeError::kNotFinite;
  }
  return DecodeError::kNone;
}

DecodeError decode_claim(std::span<const std::uint8_t> in, ClaimRecord& out) noexcept {
  if (in.empty()) return DecodeError::kTruncated;
  if (in[0] != 1) return DecodeError::kFormat;
  if (const DecodeError e = exact(in, kClaimBytes); e != DecodeError::kNone) return e;
  Reader r{in, 1};
  out.state = r.u8();
  out.priority = r.u8();
  r.u8();
  out.region_id = r.u32();
  out.goal_x = r.f32();
  out.goal_y = r.f32();
  out.pose_sigma_m = r.f32();
  if (!finite({out.goal_x, out.goal_y, out.pose_sigma_m})) return DecodeError::kNotFinite;
  if (out.state > 5) return DecodeError::kValue;
  return DecodeError::kNone;
}

DecodeError decode_visited(std::span<const std::uint8_t> in, VisitedRecord& out) noexcept {
  if (in.size() < kVisitedHeaderBytes) return DecodeError::kTruncated;
  Reader r{in};
  if (r.u8() != 1) return DecodeError::kFormat;
  r.u8();
  const std::uint16_t count = r.u16();
  if (count > kVisitedMax) return DecodeError::kCount;
  if (const DecodeError e = exact(in, kVisitedHeaderBytes + count * kVisitedEntryBytes); e != DecodeError::kNone) return e;
  out.count = count;
  for (std::size_t i = 0; i < count; ++i) {
    out.entries[i].region_id = r.u32();
    out.entries[i].x = r.f32();
    out.entries[i].y = r.f32();
    if (!finite({out.entries[i].x, out.entries[i].y})) return DecodeError::kNotFinite;
  }
  return DecodeError::kNone;
}

DecodeError decode_failure(std::span<const std::uint8_t> in, FailureRecord& out) noexcept {
  if (in.empty()) return DecodeError::kTruncated;
  if (in[0] != 1) return DecodeError::kFormat;
  if (const DecodeError e = exact(in, kFailureBytes); e != DecodeError::kNone) return e;
  Reader r{in, 1};
  out.reason = r.u8();
  out.attempts = r.u16();
  out.region_id = r.u32();
  out.x = r.f32();
  out.y = r.f32();
  if (!finite({out.x, out.y})) return DecodeError::kNotFinite;
  return DecodeError::kNone;
}

DecodeError decode_object(std::span<const std::uint8_t> in, ObjectRecord& out) noexcept {
  if (in.empty()) return DecodeError::kTruncated;
  if (in[0] != 1) return DecodeError::kFormat;
  if (const DecodeError e = exact(in, kObjectBytes); e != DecodeError::kNone) return e;
  Reader r{in, 1};
  out.cls = r.u8();
  out.detections = r.u16();
  out.object_id = r.u32();
  out.x = r.f32();
  out.y = r.f32();
  out.cxx = r.f32();
  out.cxy = r.f32();
  out.cyy = r.f32();
  if (!finite({out.x, out.y, out.cxx, out.cxy, out.cyy})) return DecodeError::kNotFinite;
  return DecodeError::kNone;
}

std::size_t encode_regions(const RegionsBatch& b, std::span<std::uint8_t> out) noexcept {
  const std::size_t n = kRegionsHeaderBytes + b.count * kRegionEntryBytes;
  if (out.size() < n || b.count > kRegionsPerBatch) return 0;
  Writer w{out};
  w.u8(1);
  w.u8(b.count);
  w.u16(b.batches);
  w.u32(b.version);
  for (std::size_t i = 0; i < b.count; ++i) {
    const RegionEntry& e = b.regions[i];
    w.u32(e.id);
    w.f32(e.cx);
    w.f32(e.cy);
    w.f32(e.goal_x);
    w.f32(e.goal_y);
    w.u16(e.cells);
    w.u8(e.flags);
    w.u8(0);
  }
  return n;
}
std::size_t encode_claim(const ClaimRecord& c, std::span<std::uint8_t> out) noexcept {
  if (out.size() < kClaimBytes) return 0;
  Writer w{out};
  w.u8(1);
  w.u8(c.state);
  w.u8(c.priority);
  w.u8(0);
  w.u32(c.region_id);
  w.f32(c.goal_x);
  w.f32(c.goal_y);
  w.f32(c.pose_sigma_m);
  return kClaimBytes;
}
std::size_t encode_visited(const VisitedRecord& v, std::span<std::uint8_t> out) noexcept {
  const std::size_t n = kVisitedHeaderBytes + v.count * kVisitedEntryBytes;
  if (out.size() < n || v.count > kVisitedMax) return 0;
  Writer w{out};
  w.u8(1);
  w.u8(0);
  w.u16(v.count);
  for (std::size_t i = 0; i < v.count; ++i) {
    w.u32(v.entries[i].region_id);
    w.f32(v.entries[i].x);
    w.f32(v.entries[i].y);
  }
  return n;
}
std::size_t encode_failure(const FailureRecord& f, std::span<std::uint8_t> out) noexcept {
  if (out.size() < kFailureBytes) return 0;
  Writer w{out};
  w.u8(1);
  w.u8(f.reason);
  w.u16(f.attempts);
  w.u32(f.region_id);
  w.f32(f.x);
  w.f32(f.y);
  return kFailureBytes;
}
std::size_t encode_object(const ObjectRecord& o, std::span<std::uint8_t> out) noexcept {
  if (out.size() < kObjectBytes) return 0;
  Writer w{out};
  w.u8(1);
  w.u8(o.cls);
  w.u16(o.detections);
  w.u32(o.object_id);
  w.f32(o.x);
  w.f32(o.y);
  w.f32(o.cxx);
  w.f32(o.cxy);
  w.f32(o.cyy);
  return kObjectBytes;
}

}  // namespace ag::base
