// The team database: slots, an open-addressing index and a payload arena compacted in place.
#include "airground/comms/record_store.hpp"

#include <algorithm>
#include <cstring>

namespace ag::comms {

namespace {
std::size_t pow2_at_least(std::size_t n) {
  std::size_t p = 16;
  while (p < n) p <<= 1;
  return p;
}
}  // namespace

RecordStore::RecordStore(const StoreLimits& limits) : limits_(limits) {
  limits_.max_records = std::max<std::size_t>(limits_.max_records, 1);
  slots_.resize(limits_.max_records);
  index_.assign(pow2_at_least(limits_.max_records * 2), kNoSlot);
  order_.resize(limits_.max_records);
  arena_.resize(std::max<std::size_t>(limits_.arena_bytes, 1));
}

std::size_t RecordStore::bucket(RecordKey k) const noexcept {
  return static_cast<std::size_t>(mix64((static_cast<std::uint64_t>(k.origin) << 32) | k.topic)) & (index_.size() - 1);
}

RecordStore::Slot RecordStore::find(RecordKey key) const noexcept {
  for (std::size_t b = bucket(key);; b = (b + 1) & (index_.size() - 1)) {
    const Slot s = index_[b];
    if (s == kNoSlot) return kNoSlot;
    if (slots_[s].meta.key == key) return s;
  }
}

bool RecordStore::has_at_least(RecordKey key, std::uint64_t seq) const noexcept {
  const Slot s = find(key);
  return s != kNoSlot && slots_[s].meta.seq >= seq;
}

void RecordStore::compact() noexcept {
  for (std::size_t i = 0; i < count_; ++i) order_[i] = static_cast<Slot>(i);
  std::sort(order_.begin(), order_.begin() + static_cast<std::ptrdiff_t>(count_),
            [this](Slot a, Slot b) { return slots_[a].offset < slots_[b].offset; });
  std::size_t end = 0;
  for (std::size_t i = 0; i < count_; ++i) {
    Entry& e = slots_[order_[i]];
    if (e.offset != end && e.meta.size > 0) std::memmove(arena_.data() + end, arena_.data() + e.offset, e.meta.size);
    e.offset = end;
    end += e.meta.size;
  }
  arena_end_ = end;
  ++compactions_;
}

bool RecordStore::reserve(std::size_t bytes) noexcept {
  if (arena_end_ + bytes <= arena_.size()) return true;
  if (live_bytes_ + bytes > arena_.size()) return false;
  compact();
  return arena_end_ + bytes <= arena_.size();
}

PutResult RecordStore::put(const RecordMeta& meta_in, std::span<const std::uint8_t> payload) noexcept {
  if (payload.size() > limits_.max_payload_bytes) return PutResult::kTooLarge;
  RecordMeta meta = meta_in;
  meta.size = static_cast<std::uint32_t>(payload.size());
  const RecordKey key = meta.key;
  OriginSummary& o = origins_[key.origin];
  Slot s = find(key);
  if (s != kNoSlot) {
    Entry& e = slots_[s];
    if (meta.seq <= e.meta.seq) return PutResult::kStale;
    if (arena_end_ + payload.size() > arena_.size()) {
      // Room only after dropping the old payload and compacting; if not even then, keep the old record.
      if (live_bytes_ - e.meta.size + payload.size() > arena_.size()) return PutResult::kFull;
      live_bytes_ -= e.meta.size;
      e.meta.size = 0;
      compact();
    } else {
      live_bytes_ -= e.meta.size;
    }
    o.hash ^= version_hash(key, e.meta.seq);
    e.meta = meta;
    e.offset = arena_end_;
    if (!payload.empty()) std::memcpy(arena_.data() + arena_end_, payload.data(), payload.size());
    arena_end_ += payload.size();
    live_bytes_ += payload.size();
    o.hash ^= version_hash(key, meta.seq);
    o.max_seq = std::max(o.max_seq, meta.seq);
    return PutResult::kReplaced;
  }
  if (count_ >= limits_.max_records || !reserve(payload.size())) return PutResult::kFull;
  s = static_cast<Slot>(count_++);
  Entry& e = slots_[s];
  e.meta = meta;
  e.offset = arena_end_;
  if (!payload.empty()) std::memcpy(arena_.data() + arena_end_, payload.data(), payload.size());
  arena_end_ += payload.size();
  live_bytes_ += payload.size();
  std::size_t b = bucket(key);
  while (index_[b] != kNoSlot) b = (b + 1) & (index_.size() - 1);
  index_[b] = s;
  ++o.count;
  o.hash ^= version_hash(key, meta.seq);
  o.max_seq = std::max(o.max_seq, meta.seq);
  return PutResult::kNew;
}

std::uint64_t RecordStore::content_hash() const noexcept {
  std::uint64_t h = 0;
  for (std::size_t i = 0; i < count_; ++i) {
    const Entry& e = slots_[i];
    std::uint64_t p = 0xcbf29ce484222325ULL;
    for (std::size_t j = 0; j < e.meta.size; ++j) p = (p ^ arena_[e.offset + j]) * 0x100000001b3ULL;
    h ^= mix64(version_hash(e.meta.key, e.meta.seq) ^ p ^ (static_cast<std::uint64_t>(e.meta.priority) << 56));
  }
  return h;
}

}  // namespace ag::comms
