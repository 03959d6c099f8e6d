// Encoding and bounds-checked decoding of the mission's gossip records.
#include "airground/mission/records.hpp"

#include <bit>
#include <cmath>

#include "airground/comms/bytes.hpp"

namespace ag::mission {

namespace {
using comms::ByteReader;
using comms::ByteWriter;

void f32(ByteWriter& w, float v) noexcept { w.u32(std::bit_cast<std::uint32_t>(v)); }
bool f32(ByteReader& r, float& v) noexcept {
  std::uint32_t u = 0;
  if (!r.u32(u)) return false;
  v = std::bit_cast<float>(u);
  return true;
}
bool finite(float v) noexcept { return std::isfinite(v); }

// Common prologue: size bounds and format byte.
DecodeError check_size(std::span<const std::uint8_t> in, std::size_t need) noexcept {
  if (in.size() < need) return DecodeError::kTruncated;
  if (in.size() > need) return DecodeError::kTrailing;
  return DecodeError::kOk;
}
DecodeError coarse(DecodeError e) noexcept { return e == DecodeError::kNotFinite ? DecodeError::kValue : e; }
}  // namespace

const char* to_string(DecodeError e) noexcept {
  switch (e) {
    case DecodeError::kOk: return "ok";
    case DecodeError::kTruncated: return "truncated";
    case DecodeError::kTrailing: return "trailing bytes";
    case DecodeError::kFormat: return "unknown format";
    case DecodeError::kCount: return "count above the limit";
    case DecodeError::kValue: return "value out of range";
    case DecodeError::kNotFinite: return "non-finite number";
  }
  return "?";
}
const char* to_string(ClaimState s) noexcept {
  switch (s) {
    case ClaimState::kIdle: return "idle";
    case ClaimState::kGoing: return "going";
    case ClaimState::kReturning: return "returning";
    case ClaimState::kDone: return "done";
    case ClaimState::kFailedRetrying: return "failed-retrying";
    case ClaimState::kStopped: return "stopped";
  }
  return "?";
}
const char* to_string(FailureReason r) noexcept {
  switch (r) {
    case FailureReason::kNoRoute: return "no_route";
    case FailureReason::kNoProgress: return "no_progress";
    case FailureReason::kLostLocalization: return "lost_localization";
    case FailureReason::kBlocked: return "blocked";
  }
  return "?";
}

// ---------------------------------------------------------------- regions
std::size_t encode(const RegionBatch& b, std::span<std::uint8_t> out) noexcept {
  if (b.count > kRegionsPerBatch) return 0;
  ByteWriter w(out);
  w.u8(kRecordFormat);
  w.u8(b.count);
  w.u16(b.batches);
  w.u32(b.regions_version);
  for (std::size_t i = 0; i < b.count; ++i) {
    const RegionRecord& r = b.regions[i];
    w.u32(r.id);
    f32(w, r.cx);
    f32(w, r.cy);
    f32(w, r.goal_x);
    f32(w, r.goal_y);
    w.u16(r.cells);
    w.u8(r.goal_valid ? 1 : 0);
    w.u8(0);
  }
  return w.ok() ? w.size() : 0;
}

DecodeError decode_detailed(std::span<const std::uint8_t> in, RegionBatch& b) noexcept {
  if (in.size() < kRegionBatchHeader) return DecodeError::kTruncated;
  ByteReader r(in);
  std::uint8_t fmt = 0, count = 0;
  (void)r.u8(fmt);
  if (fmt != kRecordFormat) return DecodeError::kFormat;
  (void)r.u8(count);
  if (count > kRegionsPerBatch) return DecodeError::kCount;
  if (const DecodeError e = check_size(in, kRegionBatchHeader + kRegionEntryBytes * count); e != DecodeError::kOk) return e;
  RegionBatch out;
  out.count = count;
  (void)r.u16(out.batches);
  (void)r.u32(out.regions_version);
  if (out.batches == 0) return DecodeError::kValue;  // an empty set still travels as one empty batch
  for (std::size_t i = 0; i < count; ++i) {
    RegionRecord& e = out.regions[i];
    std::uint8_t flags = 0, reserved = 0;
    (void)r.u32(e.id);
    (void)f32(r, e.cx);
    (void)f32(r, e.cy);
    (void)f32(r, e.goal_x);
    (void)f32(r, e.goal_y);
    (void)r.u16(e.cells);
    (void)r.u8(flags);
    (void)r.u8(reserved);
    e.goal_valid = (flags & 1u) != 0;
    if (!finite(e.cx) || !finite(e.cy) || !finite(e.goal_x) || !finite(e.goal_y)) return DecodeError::kNotFinite;
  }
  if (!r.ok()) return DecodeError::kTruncated;
  b = out;
  return DecodeError::kOk;
}

// ---------------------------------------------------------------- claim
std::size_t encode(const ClaimRecord& c, std::span<std::uint8_t> out) noexcept {
  ByteWriter w(out);
  w.u8(kRecordFormat);
  w.u8(static_cast<std::uint8_t>(c.state));
  w.u8(c.priority);
  w.u8(0);
  w.u32(c.region_id);
  f32(w, c.goal_x);
  f32(w, c.goal_y);
  f32(w, c.pose_sigma_m);
  return w.ok() ? w.size() : 0;
}

DecodeError decode_detailed(std::span<const std::uint8_t> in, ClaimRecord& c) noexcept {
  if (!in.empty() && in[0] != kRecordFormat) return DecodeError::kFormat;
  if (const DecodeError e = check_size(in, kClaimBytes); e != DecodeError::kOk) return e;
  ByteReader r(in);
  std::uint8_t fmt = 0, state = 0, reserved = 0;
  ClaimRecord out;
  (void)r.u8(fmt);
  (void)r.u8(state);
  (void)r.u8(out.priority);
  (void)r.u8(reserved);
  (void)r.u32(out.region_id);
  (void)f32(r, out.goal_x);
  (void)f32(r, out.goal_y);
  (void)f32(r, out.pose_sigma_m);
  if (!finite(out.goal_x) || !finite(out.goal_y) || !finite(out.pose_sigma_m)) return DecodeError::kNotFinite;
  if (state > static_cast<std::uint8_t>(ClaimState::kStopped)) return DecodeError::kValue;
  out.state = static_cast<ClaimState>(state);
  c = out;
  return DecodeError::kOk;
}

// ---------------------------------------------------------------- visited
std::size_t encode(const VisitedRecord& v, std::span<std::uint8_t> out) noexcept {
  if (v.count > kMaxVisited) return 0;
  ByteWriter w(out);
  w.u8(kRecordFormat);
  w.u8(0);
  w.u16(v.count);
  for (std::size_t i = 0; i < v.count; ++i) {
    w.u32(v.entries[i].region_id);
    f32(w, v.entries[i].x);
    f32(w, v.entries[i].y);
  }
  return w.ok() ? w.size() : 0;
}

DecodeError decode_detailed(std::span<const std::uint8_t> in, VisitedRecord& v) noexcept {
  if (in.size() < kVisitedHeader) return DecodeError::kTruncated;
  ByteReader r(in);
  std::uint8_t fmt = 0, reserved = 0;
  std::uint16_t count = 0;
  (void)r.u8(fmt);
  if (fmt != kRecordFormat) return DecodeError::kFormat;
  (void)r.u8(reserved);
  (void)r.u16(count);
  if (count > kMaxVisited) return DecodeError::kCount;
  if (const DecodeError e = check_size(in, kVisitedHeader + kVisitedEntryBytes * count); e != DecodeError::kOk) return e;
  VisitedRecord out;
  out.count = count;
  for (std::size_t i = 0; i < count; ++i) {
    (void)r.u32(out.entries[i].region_id);
    (void)f32(r, out.entries[i].x);
    (void)f32(r, out.entries[i].y);
    if (!finite(out.entries[i].x) || !finite(out.entries[i].y)) return DecodeError::kNotFinite;
  }
  if (!r.ok()) return DecodeError::kTruncated;
  v = out;
  return DecodeError::kOk;
}

// ---------------------------------------------------------------- failure
std::size_t encode(const FailureRecord& f, std::span<std::uint8_t> out) noexcept {
  ByteWriter w(out);
  w.u8(kRecordFormat);
  w.u8(static_cast<std::uint8_t>(f.reason));
  w.u16(f.attempts);
  w.u32(f.region_id);
  f32(w, f.x);
  f32(w, f.y);
  return w.ok() ? w.size() : 0;
}

DecodeError decode_detailed(std::span<const std::uint8_t> in, FailureRecord& f) noexcept {
  if (!in.empty() && in[0] != kRecordFormat) return DecodeError::kFormat;
  if (const DecodeError e = check_size(in, kFailureBytes); e != DecodeError::kOk) return e;
  ByteReader r(in);
  std::uint8_t fmt = 0, reason = 0;
  FailureRecord out;
  (void)r.u8(fmt);
  (void)r.u8(reason);
  (void)r.u16(out.attempts);
  (void)r.u32(out.region_id);
  (void)f32(r, out.x);
  (void)f32(r, out.y);
  if (!finite(out.x) || !finite(out.y)) return DecodeError::kNotFinite;
  if (reason < 1 || reason > 4) return DecodeError::kValue;
  out.reason = static_cast<FailureReason>(reason);
  f = out;
  return DecodeError::kOk;
}

// ---------------------------------------------------------------- object
std::size_t encode(const ObjectRecord& o, std::span<std::uint8_t> out) noexcept {
  ByteWriter w(out);
  w.u8(kRecordFormat);
  w.u8(o.cls);
  w.u16(o.detections);
  w.u32(o.object_id);
  f32(w, o.x);
  f32(w, o.y);
  f32(w, o.cxx);
  f32(w, o.cxy);
  f32(w, o.cyy);
  return w.ok() ? w.size() : 0;
}

DecodeError decode_detailed(std::span<const std::uint8_t> in, ObjectRecord& o) noexcept {
  if (!in.empty() && in[0] != kRecordFormat) return DecodeError::kFormat;
  if (const DecodeError e = check_size(in, kObjectBytes); e != DecodeError::kOk) return e;
  ByteReader r(in);
  std::uint8_t fmt = 0;
  ObjectRecord out;
  (void)r.u8(fmt);
  (void)r.u8(out.cls);
  (void)r.u16(out.detections);
  (void)r.u32(out.object_id);
  (void)f32(r, out.x);
  (void)f32(r, out.y);
  (void)f32(r, out.cxx);
  (void)f32(r, out.cxy);
  (void)f32(r, out.cyy);
  for (float v : {out.x, out.y, out.cxx, out.cxy, out.cyy})
    if (!finite(v)) return DecodeError::kNotFinite;
  if (out.cxx < 0 || out.cyy < 0) return DecodeError::kValue;
  o = out;
  return DecodeError::kOk;
}

DecodeError decode(std::span<const std::uint8_t> in, RegionBatch& b) noexcept { return coarse(decode_detailed(in, b)); }
DecodeError decode(std::span<const std::uint8_t> in, ClaimRecord& c) noexcept { return coarse(decode_detailed(in, c)); }
DecodeError decode(std::span<const std::uint8_t> in, VisitedRecord& v) noexcept { return coarse(decode_detailed(in, v)); }
DecodeError decode(std::span<const std::uint8_t> in, FailureRecord& f) noexcept { return coarse(decode_detailed(in, f)); }
DecodeError decode(std::span<const std::uint8_t> in, ObjectRecord& o) noexcept { return coarse(decode_detailed(in, o)); }

}  // namespace ag::mission
