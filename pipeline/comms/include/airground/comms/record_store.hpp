// The team database: the latest record of every (origin, topic), with fixed memory set at construction.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "airground/comms/topics.hpp"

namespace ag::comms {

struct StoreLimits {
  std::size_t max_records{8192};          // keys (origin, topic) held
  std::size_t arena_bytes{32u << 20};     // [B] payload memory (compacted in place when fragmented)
  std::size_t max_payload_bytes{65536};   // [B] largest payload of one record
};

// Per origin: what a digest carries. Two stores hold the same records of an origin iff count and hash
// agree (up to a 64-bit hash collision).
struct OriginSummary {
  std::uint32_t count{0};
  std::uint64_t max_seq{0};
  std::uint64_t hash{0};  // XOR of version_hash(key, seq) over the origin's records
  friend constexpr bool operator==(const OriginSummary&, const OriginSummary&) = default;
};

enum class PutResult : std::uint8_t {
  kNew,        // a key not held before
  kReplaced,   // newer seq than the held one
  kStale,      // same or older seq: nothing changed (duplicates land here)
  kTooLarge,   // payload above max_payload_bytes
  kFull,       // no key slot or no arena space left
};

class RecordStore {
 public:
  using Slot = std::uint32_t;
  static constexpr Slot kNoSlot = 0xFFFFFFFFu;

  explicit RecordStore(const StoreLimits& limits);

  // Never allocates. A record replaces the held one of its key only with a higher seq.
  PutResult put(const RecordMeta& meta, std::span<const std::uint8_t> payload) noexcept;

  [[nodiscard]] Slot find(RecordKey key) const noexcept;
  [[nodiscard]] std::size_t size() const noexcept { return count_; }
  // Slots are 0 .. size()-1 in the order keys first arrived; a slot keeps its key for ever.
  [[nodiscard]] const RecordMeta& meta(Slot s) const noexcept { return slots_[s].meta; }
  [[nodiscard]] std::span<const std::uint8_t> payload(Slot s) const noexcept {
    return {arena_.data() + slots_[s].offset, slots_[s].meta.size};
  }
  [[nodiscard]] const OriginSummary& summary(RobotId origin) const noexcept { return origins_[origin]; }
  // Has the store this record version or a newer one of its key?
  [[nodiscard]] bool has_at_least(RecordKey key, std::uint64_t seq) const noexcept;
  // Order-independent fingerprint of the whole content (keys, seqs and payload bytes): equal stores agree.
  [[nodiscard]] std::uint64_t content_hash() const noexcept;
  [[nodiscard]] const StoreLimits& limits() const noexcept { return limits_; }
  [[nodiscard]] std::size_t payload_bytes() const noexcept { return live_bytes_; }
  [[nodiscard]] std::uint64_t compactions() const noexcept { return compactions_; }

 private:
  struct Entry {
    RecordMeta meta;
    std::size_t offset{0};
  };
  bool reserve(std::size_t bytes) noexcept;  // ensures `bytes` free at the arena's end (compacting if needed)
  void compact() noexcept;
  [[nodiscard]] std::size_t bucket(RecordKey k) const noexcept;

  StoreLimits limits_;
  std::vector<Entry> slots_;
  std::vector<Slot> index_;        // open addressing, kNoSlot = empty (keys are never removed)
  std::vector<Slot> order_;        // compaction scratch
  std::vector<std::uint8_t> arena_;
  std::size_t count_{0};
  std::size_t arena_end_{0};
  std::size_t live_bytes_{0};
  std::uint64_t compactions_{0};
  std::array<OriginSummary, 256> origins_{};
};

}  // namespace ag::comms
