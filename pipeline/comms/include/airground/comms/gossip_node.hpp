// The gossip protocol of one robot: digests, have-lists and record pushes over any DatagramLink.
//
// Every digest_period_s (jittered) a node broadcasts a DIGEST: per origin it holds, the record count,
// the highest seq and an XOR hash of its (topic, seq) versions. A node hearing a digest that differs
// from its own summary for an origin
//   - pushes at once every record of that origin with a seq above the peer's highest (it surely lacks
//     them; all of them if the peer holds nothing of that origin), and
//   - if the peer holds anything of that origin, answers with its HAVE
//     list for it (topic, seq pairs, split into self-contained topic ranges), so that the peer pushes
//     back what this node lacks. A list longer than one datagram is sent only when the peer holds more
//     keys or the difference outlives the first push (a second differing digest in a row): when one
//     side is simply ahead, the quadrotor's long tile list does not travel at all.
// Pushes go into a per-peer queue, served most important (priority) and newest (stamp) first within a
// token-bucket budget per link; records larger than a datagram travel as 64-byte-aligned fragments,
// reassembled by (origin, topic, seq) whoever sends them. Nothing waits for an answer: a lost datagram
// is repaired by the next digest, a peer not heard for peer_timeout_s has its queue dropped, and every
// message can be applied any number of times (the store keeps the highest seq), so no exchange can
// wedge and there is no session to restart. No node is special and nothing is sent to find peers
// besides the periodic digest.
#pragma once

#include <array>
#include <bitset>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "airground/comms/journal.hpp"
#include "airground/comms/link.hpp"
#include "airground/comms/record_store.hpp"
#include "airground/comms/topics.hpp"
#include "airground/comms/wire.hpp"

namespace ag::comms {

struct GossipParams {
  RobotId self{0};
  std::size_t mtu_bytes{1200};                // [B] largest datagram sent (path MTU less IP/UDP headers)
  double digest_period_s{1.0};                // [s] between digest broadcasts (±10 % jitter)
  double budget_bytes_per_s{100'000};         // [B/s] per peer link for have-lists and records
  double broadcast_budget_bytes_per_s{8'000}; // [B/s] for digests
  double burst_s{0.25};                       // [s] of budget a link may spend at once
  double peer_timeout_s{5.0};                 // [s] silence after which a peer's queue is dropped
  std::size_t max_peers{32};
  std::size_t reassembly_slots{32};           // records received in fragments at the same time
  std::size_t datagrams_per_tick{256};        // receive and send cap per tick (bounds the step time)
  std::size_t wire_overhead_bytes{28};        // [B] IPv4 + UDP header, counted against the budgets
  std::uint64_t seed{1};
};

struct PeerStats {
  std::uint64_t datagrams_in{0}, bytes_in{0}, records_in{0};   // records_in: new or newer records stored
  std::uint64_t datagrams_out{0}, bytes_out{0}, records_out{0}; // records_out: records fully sent
  std::uint64_t duplicates_in{0};                               // records already held (or older)
  TimeNs last_heard{0};
  bool seen{false};
};

struct GossipStats {
  std::array<std::uint64_t, static_cast<std::size_t>(DropReason::kCount)> drops{};
  std::uint64_t datagrams_in{0}, bytes_in{0}, datagrams_out{0}, bytes_out{0};
  std::uint64_t digests_out{0}, haves_out{0}, records_datagrams_out{0};
  std::uint64_t records_in{0}, records_out{0}, duplicates_in{0}, fragments_in{0};
  std::uint64_t own_records{0};
  std::uint64_t send_failures{0};       // the link refused (would block, too large, error)
  std::uint64_t budget_waits{0};        // a datagram waited for its link's budget
  std::uint64_t peers_timed_out{0};
  std::uint64_t journal_errors{0};
  std::uint64_t changes_overflowed{0};  // store changes the application did not drain in time
  [[nodiscard]] std::uint64_t drop(DropReason r) const noexcept { return drops[static_cast<std::size_t>(r)]; }
  [[nodiscard]] std::uint64_t total_drops() const noexcept;
};

class GossipNode {
 public:
  // `store` may already hold records (replayed from the journal); own seqs continue above them and
  // above epoch << 32, so a robot that lost its disk still writes newer records than before.
  GossipNode(const GossipParams& p, const TeamKey& key, RecordStore& store, std::uint32_t epoch, Journal* journal);

  // A record of this robot. Never allocates. Returns the store's verdict (kNew/kReplaced on success).
  PutResult publish(Topic topic, std::uint8_t priority, TimeNs stamp, std::span<const std::uint8_t> payload) noexcept;
  // One datagram from the link.
  void receive(TimeNs now, const LinkAddress& from, std::span<const std::uint8_t> datagram) noexcept;
  // Receives what waits on the link (up to datagrams_per_tick), then sends digests, have-lists and
  // queued records within the budgets. Never allocates, never blocks.
  void tick(TimeNs now, DatagramLink& link) noexcept;

  // Store changes (own or received) for the application, oldest first; pop after use. Overflow is
  // counted and the oldest are lost from this list (never from the store).
  [[nodiscard]] bool pending_change(RecordStore::Slot& slot) const noexcept;
  void pop_change() noexcept;
  // Lists every record in the store as changed (after a restart, so the robot's stages get what the
  // journal restored).
  void announce_all() noexcept;

  [[nodiscard]] const GossipStats& stats() const noexcept { return stats_; }
  [[nodiscard]] const PeerStats& peer_stats(RobotId r) const noexcept { return peer_stats_[r]; }
  [[nodiscard]] const RecordStore& store() const noexcept { return store_; }
  [[nodiscard]] std::uint64_t next_seq() const noexcept { return next_seq_; }
  [[nodiscard]] std::size_t queued_to(RobotId r) const noexcept;
  [[nodiscard]] const GossipParams& params() const noexcept { return p_; }
  [[nodiscard]] std::uint32_t epoch() const noexcept { return epoch_; }

  // Wire body layouts (after the header), exposed for tests and the fuzz target.
  static constexpr std::size_t kDigestEntryBytes = 1 + 4 + 8 + 8;
  static constexpr std::size_t kHaveEntryBytes = 4 + 8;
  static constexpr std::size_t kFragmentHeaderBytes = 1 + 4 + 8 + 1 + 8 + 4 + 4 + 2;
  static constexpr std::size_t kBlock = 64;  // fragment alignment

 private:
  struct QueueEntry {
    RecordStore::Slot slot{0};
    std::uint64_t seq{0};
    std::uint32_t offset{0};  // next byte to send
  };
  struct Peer {
    RobotId id{kNoRobot};
    bool active{false};
    LinkAddress addr;
    TimeNs last_heard{0};
    double tokens{0};
    TimeNs tokens_at{0};
    std::vector<QueueEntry> queue;
    std::size_t qn{0};
    std::vector<std::uint32_t> queued_pos;  // per store slot: index in queue + 1, 0 = not queued
    std::bitset<256> have_due;
    std::array<std::uint8_t, 256> mismatch{};  // consecutive digests of this peer that differed, per origin
  };
  struct Reassembly {
    bool active{false};
    RecordMeta meta;
    std::vector<std::uint8_t> buf;
    std::vector<std::uint64_t> blocks;  // received 64-byte blocks
    std::size_t blocks_have{0}, blocks_total{0};
    TimeNs touched{0};
  };

  Peer* peer_for(RobotId id, TimeNs now, const LinkAddress& addr) noexcept;
  void on_digest(TimeNs now, Peer& peer, std::span<const std::uint8_t> body) noexcept;
  void on_have(Peer& peer, std::span<const std::uint8_t> body) noexcept;
  void on_records(TimeNs now, Peer& peer, std::span<const std::uint8_t> body) noexcept;
  void accept_record(Peer& peer, const RecordMeta& m, std::span<const std::uint8_t> payload) noexcept;
  void enqueue(Peer& peer, RecordStore::Slot slot) noexcept;
  void dequeue(Peer& peer, std::size_t qi) noexcept;
  void note_change(RecordStore::Slot s) noexcept;
  void drop(DropReason r) noexcept { ++stats_.drops[static_cast<std::size_t>(r)]; }

  void send_digests(TimeNs now, DatagramLink& link) noexcept;
  void serve_peer(TimeNs now, Peer& peer, DatagramLink& link, std::size_t& budget_datagrams) noexcept;
  bool send_have(TimeNs now, Peer& peer, RobotId origin, DatagramLink& link, std::size_t& budget_datagrams) noexcept;
  bool transmit(TimeNs now, MsgType type, RobotId dest, const LinkAddress& to, std::size_t body_len,
                DatagramLink& link) noexcept;
  void refill(Peer& peer, TimeNs now) noexcept;
  double next_jitter() noexcept;

  GossipParams p_;
  DatagramCodec codec_;
  RecordStore& store_;
  Journal* journal_;
  std::uint32_t epoch_;
  std::uint64_t next_seq_{0};
  std::uint64_t counter_{0};
  ReplayGuard guard_;
  std::vector<Peer> peers_;
  std::array<std::int16_t, 256> peer_index_{};
  std::vector<Reassembly> reasm_;
  std::vector<std::uint8_t> rx_, body_in_, body_out_, tx_;
  std::size_t have_per_datagram_{0};
  std::vector<std::uint64_t> scratch_;  // have-list building: (topic << 32 | slot) sorted
  std::vector<RecordStore::Slot> changes_;
  std::size_t change_head_{0}, change_count_{0};
  TimeNs next_digest_{0};
  bool started_{false};
  double bcast_tokens_{0};
  TimeNs bcast_at_{0};
  std::uint64_t rng_;
  GossipStats stats_;
  std::array<PeerStats, 256> peer_stats_{};
};

}  // namespace ag::comms
