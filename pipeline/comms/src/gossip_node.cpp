// The gossip protocol: digests, have-lists, prioritised pushes within per-link budgets, reassembly.
#include "airground/comms/gossip_node.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "airground/comms/bytes.hpp"

namespace ag::comms {

std::uint64_t GossipStats::total_drops() const noexcept {
  std::uint64_t n = 0;
  for (const auto d : drops) n += d;
  return n;
}

GossipNode::GossipNode(const GossipParams& p, const TeamKey& key, RecordStore& store, std::uint32_t epoch, Journal* journal)
    : p_(p), codec_(key), store_(store), journal_(journal), epoch_(epoch), rng_(mix64(p.seed ^ (p.self + 1ULL) * 0x9E3779B97F4A7C15ULL)) {
  p_.mtu_bytes = std::clamp<std::size_t>(p_.mtu_bytes, kSealOverhead + kFragmentHeaderBytes + 2 * kBlock, kMaxDatagramBytes);
  p_.max_peers = std::max<std::size_t>(p_.max_peers, 1);
  p_.reassembly_slots = std::max<std::size_t>(p_.reassembly_slots, 1);
  const std::size_t cap = store_.limits().max_records;
  peers_.resize(p_.max_peers);
  for (Peer& pe : peers_) {
    pe.queue.resize(cap);
    pe.queued_pos.assign(cap, 0);
  }
  peer_index_.fill(-1);
  const std::size_t maxp = store_.limits().max_payload_bytes;
  reasm_.resize(p_.reassembly_slots);
  for (Reassembly& r : reasm_) {
    r.buf.resize(std::max<std::size_t>(maxp, 1));
    r.blocks.resize(maxp / kBlock / 64 + 2);
  }
  rx_.resize(kMaxDatagramBytes + 1);
  body_in_.resize(kMaxDatagramBytes);
  body_out_.resize(p_.mtu_bytes - kSealOverhead);
  tx_.resize(p_.mtu_bytes);
  scratch_.resize(cap);
  have_per_datagram_ = (body_out_.size() - 11) / kHaveEntryBytes;
  changes_.resize(cap);
  next_seq_ = std::max(store_.summary(p_.self).max_seq + 1, static_cast<std::uint64_t>(epoch_) << 32);
}

double GossipNode::next_jitter() noexcept {
  rng_ = rng_ * 6364136223846793005ULL + 1442695040888963407ULL;
  return static_cast<double>(mix64(rng_) >> 11) * 0x1.0p-53;
}

std::size_t GossipNode::queued_to(RobotId r) const noexcept {
  const int i = peer_index_[r];
  return i < 0 ? 0 : peers_[static_cast<std::size_t>(i)].qn;
}

// ------------------------------------------------------------------------------------ own records

PutResult GossipNode::publish(Topic topic, std::uint8_t priority, TimeNs stamp, std::span<const std::uint8_t> payload) noexcept {
  RecordMeta m;
  m.key = RecordKey{p_.self, topic};
  m.seq = next_seq_;
  m.priority = priority;
  m.stamp = stamp;
  const PutResult r = store_.put(m, payload);
  if (r == PutResult::kNew || r == PutResult::kReplaced) {
    ++next_seq_;
    ++stats_.own_records;
    if (journal_ != nullptr && !journal_->append(store_.meta(store_.find(m.key)), payload)) ++stats_.journal_errors;
    note_change(store_.find(m.key));
  }
  return r;
}

void GossipNode::note_change(RecordStore::Slot s) noexcept {
  if (changes_.empty()) return;
  if (change_count_ == changes_.size()) {
    change_head_ = (change_head_ + 1) % changes_.size();
    --change_count_;
    ++stats_.changes_overflowed;
  }
  changes_[(change_head_ + change_count_) % changes_.size()] = s;
  ++change_count_;
}

bool GossipNode::pending_change(RecordStore::Slot& slot) const noexcept {
  if (change_count_ == 0) return false;
  slot = changes_[change_head_];
  return true;
}

void GossipNode::announce_all() noexcept {
  for (RecordStore::Slot s = 0; s < store_.size(); ++s) note_change(s);
}

void GossipNode::pop_change() noexcept {
  if (change_count_ == 0) return;
  change_head_ = (change_head_ + 1) % changes_.size();
  --change_count_;
}

// ------------------------------------------------------------------------------------ peers, queues

GossipNode::Peer* GossipNode::peer_for(RobotId id, TimeNs now, const LinkAddress& addr) noexcept {
  int i = peer_index_[id];
  if (i < 0) {
    // A free slot, else the one heard from longest ago.
    std::size_t best = 0;
    for (std::size_t k = 0; k < peers_.size(); ++k) {
      if (peers_[k].id == kNoRobot) {
        best = k;
        break;
      }
      if (peers_[k].last_heard < peers_[best].last_heard) best = k;
    }
    Peer& pe = peers_[best];
    if (pe.id != kNoRobot) {
      peer_index_[pe.id] = -1;
      for (std::size_t q = 0; q < pe.qn; ++q) pe.queued_pos[pe.queue[q].slot] = 0;
      pe.qn = 0;
      pe.have_due.reset();
    }
    pe.mismatch.fill(0);
    pe.id = id;
    pe.active = false;
    i = static_cast<int>(best);
    peer_index_[id] = static_cast<std::int16_t>(i);
  }
  Peer& pe = peers_[static_cast<std::size_t>(i)];
  if (!pe.active) {
    pe.active = true;
    pe.tokens = 0;
    pe.tokens_at = now;
  }
  pe.addr = addr;
  pe.last_heard = now;
  return &pe;
}

void GossipNode::enqueue(Peer& peer, RecordStore::Slot slot) noexcept {
  const std::uint64_t seq = store_.meta(slot).seq;
  if (peer.queued_pos[slot] != 0) {
    QueueEntry& e = peer.queue[peer.queued_pos[slot] - 1];
    if (e.seq != seq) {
      e.seq = seq;
      e.offset = 0;
    }
    return;
  }
  peer.queue[peer.qn] = QueueEntry{slot, seq, 0};
  peer.queued_pos[slot] = static_cast<std::uint32_t>(++peer.qn);
}

void GossipNode::dequeue(Peer& peer, std::size_t qi) noexcept {
  peer.queued_pos[peer.queue[qi].slot] = 0;
  const std::size_t last = --peer.qn;
  if (qi != last) {
    peer.queue[qi] = peer.queue[last];
    peer.queued_pos[peer.queue[qi].slot] = static_cast<std::uint32_t>(qi + 1);
  }
}

// ------------------------------------------------------------------------------------ receiving

void GossipNode::receive(TimeNs now, const LinkAddress& from, std::span<const std::uint8_t> datagram) noexcept {
  ++stats_.datagrams_in;
  stats_.bytes_in += datagram.size();
  DatagramHeader h;
  std::size_t len = 0;
  DropReason why = DropReason::kMalformed;
  if (!codec_.open(datagram, p_.self, guard_, h, body_in_, len, why)) {
    // Our id on an authentic datagram: our own broadcast coming back, unless we never sent it.
    if (why == DropReason::kOwnEcho && (h.epoch != epoch_ || h.counter >= counter_)) why = DropReason::kIdClash;
    drop(why);
    return;
  }
  Peer* peer = peer_for(h.sender, now, from);
  PeerStats& ps = peer_stats_[h.sender];
  ++ps.datagrams_in;
  ps.bytes_in += datagram.size();
  ps.last_heard = now;
  ps.seen = true;
  const std::span<const std::uint8_t> body(body_in_.data(), len);
  switch (h.type) {
    case MsgType::kDigest: on_digest(now, *peer, body); break;
    case MsgType::kHave: on_have(*peer, body); break;
    case MsgType::kRecords: on_records(now, *peer, body); break;
  }
}

void GossipNode::on_digest(TimeNs, Peer& peer, std::span<const std::uint8_t> body) noexcept {
  ByteReader r(body);
  std::uint8_t lo = 0, hi = 0, n = 0;
  r.u8(lo);
  r.u8(hi);
  r.u8(n);
  if (!r.ok() || lo > hi || hi == kNoRobot || r.remaining() != static_cast<std::size_t>(n) * kDigestEntryBytes) {
    drop(DropReason::kMalformed);
    return;
  }
  std::array<OriginSummary, 256> theirs{};
  int prev = -1;
  for (int i = 0; i < n; ++i) {
    std::uint8_t o = 0;
    OriginSummary s;
    r.u8(o);
    r.u32(s.count);
    r.u64(s.max_seq);
    r.u64(s.hash);
    if (o < lo || o > hi || static_cast<int>(o) <= prev || s.count == 0) {
      drop(DropReason::kMalformed);
      return;
    }
    prev = o;
    theirs[o] = s;
  }
  std::bitset<256> differ;
  for (int o = lo; o <= hi; ++o) {
    const OriginSummary& mine = store_.summary(static_cast<RobotId>(o));
    const OriginSummary& t = theirs[static_cast<std::size_t>(o)];
    std::uint8_t& streak = peer.mismatch[static_cast<std::size_t>(o)];
    if (mine == t) {
      streak = 0;
      continue;
    }
    if (streak < 255) ++streak;
    // They hold something of this origin that we may lack: ask them to push it with our have-list. A
    // list of one datagram goes at once; a longer one (the quadrotor's tiles) only when they hold keys
    // we lack or the difference survives a first round, since the common case, one side simply ahead,
    // needs no list: the side ahead pushes everything above the other's highest seq.
    if (t.count > 0 && (mine.count <= have_per_datagram_ || t.count > mine.count || streak >= 2))
      peer.have_due.set(static_cast<std::size_t>(o));
    if (mine.count > 0) differ.set(static_cast<std::size_t>(o));
  }
  if (differ.none()) return;
  for (RecordStore::Slot s = 0; s < store_.size(); ++s) {
    const RecordMeta& m = store_.meta(s);
    if (!differ.test(m.key.origin)) continue;
    const OriginSummary& t = theirs[m.key.origin];
    if (t.count == 0 || m.seq > t.max_seq) enqueue(peer, s);
  }
}

void GossipNode::on_have(Peer& peer, std::span<const std::uint8_t> body) noexcept {
  ByteReader r(body);
  std::uint8_t origin = 0;
  std::uint32_t lo = 0, hi = 0;
  std::uint16_t n = 0;
  r.u8(origin);
  r.u32(lo);
  r.u32(hi);
  r.u16(n);
  if (!r.ok() || origin == kNoRobot || lo > hi || r.remaining() != static_cast<std::size_t>(n) * kHaveEntryBytes) {
    drop(DropReason::kMalformed);
    return;
  }
  const std::span<const std::uint8_t> entries = body.subspan(r.position());
  auto topic_at = [&](std::size_t i) {
    ByteReader e(entries.subspan(i * kHaveEntryBytes, 4));
    std::uint32_t t = 0;
    e.u32(t);
    return t;
  };
  auto seq_at = [&](std::size_t i) {
    ByteReader e(entries.subspan(i * kHaveEntryBytes + 4, 8));
    std::uint64_t s = 0;
    e.u64(s);
    return s;
  };
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint32_t t = topic_at(i);
    if (t < lo || t > hi || (i > 0 && t <= topic_at(i - 1))) {
      drop(DropReason::kMalformed);
      return;
    }
  }
  for (RecordStore::Slot s = 0; s < store_.size(); ++s) {
    const RecordMeta& m = store_.meta(s);
    if (m.key.origin != origin || m.key.topic < lo || m.key.topic > hi) continue;
    std::size_t a = 0, b = n;  // binary search for the topic
    while (a < b) {
      const std::size_t mid = (a + b) / 2;
      if (topic_at(mid) < m.key.topic) a = mid + 1;
      else b = mid;
    }
    if (a == n || topic_at(a) != m.key.topic || seq_at(a) < m.seq) enqueue(peer, s);
  }
}

void GossipNode::on_records(TimeNs now, Peer& peer, std::span<const std::uint8_t> body) noexcept {
  ByteReader r(body);
  const std::size_t maxp = store_.limits().max_payload_bytes;
  while (r.remaining() > 0) {
    RecordMeta m;
    std::uint32_t total = 0, offset = 0;
    std::uint16_t len = 0;
    r.u8(m.key.origin);
    r.u32(m.key.topic);
    r.u64(m.seq);
    r.u8(m.priority);
    r.i64(m.stamp);
    r.u32(total);
    r.u32(offset);
    r.u16(len);
    const std::span<const std::uint8_t> bytes = r.bytes(len);
    if (!r.ok() || m.key.origin == kNoRobot || !topic_kind_known(m.key.topic) || offset > total ||
        len > total - offset || offset % kBlock != 0 || (len % kBlock != 0 && offset + len != total) ||
        (len == 0 && total != 0)) {
      drop(DropReason::kMalformed);
      return;
    }
    ++stats_.fragments_in;
    if (total > maxp) {
      drop(DropReason::kRecordTooLarge);
      continue;
    }
    m.size = total;
    if (store_.has_at_least(m.key, m.seq)) {
      if (offset == 0) {
        ++stats_.duplicates_in;
        ++peer_stats_[peer.id].duplicates_in;
      }
      continue;
    }
    if (offset == 0 && len == total) {
      accept_record(peer, m, bytes);
      continue;
    }
    // Reassembly, keyed by (origin, topic, seq) whoever sends the fragments.
    Reassembly* slot = nullptr;
    bool older = false;
    for (Reassembly& a : reasm_) {
      if (!a.active || !(a.meta.key == m.key)) continue;
      if (a.meta.seq == m.seq) slot = &a;
      else if (a.meta.seq > m.seq) older = true;
      else a.active = false;  // a newer version supersedes the partial one
      break;
    }
    if (older) continue;
    if (slot != nullptr && (slot->meta.size != total || slot->meta.priority != m.priority || slot->meta.stamp != m.stamp)) {
      drop(DropReason::kMalformed);
      return;
    }
    if (slot == nullptr) {
      Reassembly* lru = &reasm_[0];
      for (Reassembly& a : reasm_) {
        if (!a.active) {
          lru = &a;
          break;
        }
        if (a.touched < lru->touched) lru = &a;
      }
      if (lru->active) drop(DropReason::kReassemblyEvicted);
      slot = lru;
      slot->active = true;
      slot->meta = m;
      slot->blocks_total = (total + kBlock - 1) / kBlock;
      slot->blocks_have = 0;
      std::fill(slot->blocks.begin(), slot->blocks.begin() + static_cast<std::ptrdiff_t>(slot->blocks_total / 64 + 1), 0);
    }
    slot->touched = now;
    if (len > 0) std::memcpy(slot->buf.data() + offset, bytes.data(), len);
    const std::size_t b0 = offset / kBlock, b1 = (offset + len + kBlock - 1) / kBlock;
    for (std::size_t b = b0; b < b1; ++b) {
      const std::uint64_t bit = std::uint64_t{1} << (b % 64);
      if (!(slot->blocks[b / 64] & bit)) {
        slot->blocks[b / 64] |= bit;
        ++slot->blocks_have;
      }
    }
    if (slot->blocks_have == slot->blocks_total) {
      slot->active = false;
      accept_record(peer, slot->meta, std::span<const std::uint8_t>(slot->buf.data(), total));
    }
  }
}

void GossipNode::accept_record(Peer& peer, const RecordMeta& m, std::span<const std::uint8_t> payload) noexcept {
  const PutResult r = store_.put(m, payload);
  switch (r) {
    case PutResult::kNew:
    case PutResult::kReplaced: {
      ++stats_.records_in;
      ++peer_stats_[peer.id].records_in;
      const RecordStore::Slot s = store_.find(m.key);
      if (journal_ != nullptr && !journal_->append(store_.meta(s), payload)) ++stats_.journal_errors;
      note_change(s);
      // Our own records coming back from the team (after a restart that lost some): write above them.
      if (m.key.origin == p_.self) next_seq_ = std::max(next_seq_, m.seq + 1);
      break;
    }
    case PutResult::kStale:
      ++stats_.duplicates_in;
      ++peer_stats_[peer.id].duplicates_in;
      break;
    case PutResult::kTooLarge: drop(DropReason::kRecordTooLarge); break;
    case PutResult::kFull: drop(DropReason::kStoreFull); break;
  }
}

// ------------------------------------------------------------------------------------ sending

bool GossipNode::transmit(TimeNs now, MsgType type, RobotId dest, const LinkAddress& to, std::size_t body_len,
                          DatagramLink& link) noexcept {
  DatagramHeader h;
  h.type = type;
  h.sender = p_.self;
  h.dest = dest;
  h.epoch = epoch_;
  h.counter = counter_++;
  const std::size_t n = codec_.seal(h, std::span<const std::uint8_t>(body_out_.data(), body_len), tx_);
  if (n == 0 || link.send(now, to, std::span<const std::uint8_t>(tx_.data(), n)) != SendStatus::kSent) {
    ++stats_.send_failures;
    return false;
  }
  ++stats_.datagrams_out;
  stats_.bytes_out += n;
  if (dest != kNoRobot) {
    ++peer_stats_[dest].datagrams_out;
    peer_stats_[dest].bytes_out += n;
  }
  return true;
}

void GossipNode::refill(Peer& peer, TimeNs now) noexcept {
  const double burst = std::max(p_.budget_bytes_per_s * p_.burst_s, 2.0 * static_cast<double>(p_.mtu_bytes + p_.wire_overhead_bytes));
  peer.tokens = std::min(burst, peer.tokens + p_.budget_bytes_per_s * to_seconds(now - peer.tokens_at));
  peer.tokens_at = now;
}

void GossipNode::send_digests(TimeNs now, DatagramLink& link) noexcept {
  const double burst = std::max(p_.broadcast_budget_bytes_per_s * p_.burst_s, 2.0 * static_cast<double>(p_.mtu_bytes));
  bcast_tokens_ = std::min(burst, bcast_tokens_ + p_.broadcast_budget_bytes_per_s * to_seconds(now - bcast_at_));
  bcast_at_ = now;
  if (bcast_tokens_ <= 0) {  // in debt from the last digests: wait, the budget holds over time
    ++stats_.budget_waits;
    return;
  }
  const std::size_t per = (body_out_.size() - 3) / kDigestEntryBytes;
  int o = 0;
  int lo = 0;
  while (true) {
    ByteWriter w(body_out_);
    w.u8(static_cast<std::uint8_t>(lo));
    w.u8(0);  // hi, patched below
    w.u8(0);  // n
    std::size_t n = 0;
    int last = lo - 1;
    for (; o < kMaxRobots && n < per; ++o) {
      const OriginSummary& s = store_.summary(static_cast<RobotId>(o));
      if (s.count == 0) continue;
      w.u8(static_cast<std::uint8_t>(o));
      w.u32(s.count);
      w.u64(s.max_seq);
      w.u64(s.hash);
      last = o;
      ++n;
    }
    // Is any origin left after this chunk? Then this chunk ends at its last origin.
    int more = o;
    while (more < kMaxRobots && store_.summary(static_cast<RobotId>(more)).count == 0) ++more;
    const int hi = more < kMaxRobots ? last : kMaxRobots - 1;
    body_out_[1] = static_cast<std::uint8_t>(hi);
    body_out_[2] = static_cast<std::uint8_t>(n);
    if (transmit(now, MsgType::kDigest, kNoRobot, LinkAddress::everyone(), w.size(), link)) {
      ++stats_.digests_out;
      bcast_tokens_ -= static_cast<double>(w.size() + kSealOverhead + p_.wire_overhead_bytes);
    }
    if (hi >= kMaxRobots - 1) break;
    lo = hi + 1;
    o = more;
  }
}

bool GossipNode::send_have(TimeNs now, Peer& peer, RobotId origin, DatagramLink& link, std::size_t& budget_datagrams) noexcept {
  std::size_t k = 0;
  for (RecordStore::Slot s = 0; s < store_.size(); ++s) {
    const RecordMeta& m = store_.meta(s);
    if (m.key.origin == origin) scratch_[k++] = (static_cast<std::uint64_t>(m.key.topic) << 32) | s;
  }
  std::sort(scratch_.begin(), scratch_.begin() + static_cast<std::ptrdiff_t>(k));
  const std::size_t per = have_per_datagram_;
  std::size_t i = 0;
  std::uint32_t lo = 0;
  do {
    const std::size_t n = std::min(per, k - i);
    const bool last = i + n >= k;
    const std::uint32_t hi = last ? 0xFFFFFFFFu : static_cast<std::uint32_t>(scratch_[i + n - 1] >> 32);
    ByteWriter w(body_out_);
    w.u8(origin);
    w.u32(lo);
    w.u32(hi);
    w.u16(static_cast<std::uint16_t>(n));
    for (std::size_t j = i; j < i + n; ++j) {
      w.u32(static_cast<std::uint32_t>(scratch_[j] >> 32));
      w.u64(store_.meta(static_cast<RecordStore::Slot>(scratch_[j] & 0xFFFFFFFFu)).seq);
    }
    if (!transmit(now, MsgType::kHave, peer.id, peer.addr, w.size(), link)) return false;
    ++stats_.haves_out;
    peer.tokens -= static_cast<double>(w.size() + kSealOverhead + p_.wire_overhead_bytes);
    if (budget_datagrams > 0) --budget_datagrams;
    i += n;
    lo = hi + 1;
  } while (i < k);
  return true;
}

void GossipNode::serve_peer(TimeNs now, Peer& peer, DatagramLink& link, std::size_t& budget_datagrams) noexcept {
  refill(peer, now);
  const std::size_t cap = body_out_.size();
  while (budget_datagrams > 0 && (peer.have_due.any() || peer.qn > 0)) {
    if (peer.tokens <= 0) {
      ++stats_.budget_waits;
      return;
    }
    if (peer.have_due.any()) {
      std::size_t o = 0;
      while (!peer.have_due.test(o)) ++o;
      if (!send_have(now, peer, static_cast<RobotId>(o), link, budget_datagrams)) return;
      peer.have_due.reset(o);
      continue;
    }
    ByteWriter w(body_out_);
    bool full = false;
    while (!full && peer.qn > 0) {
      std::size_t best = 0;
      for (std::size_t q = 1; q < peer.qn; ++q) {
        const RecordMeta& a = store_.meta(peer.queue[q].slot);
        const RecordMeta& b = store_.meta(peer.queue[best].slot);
        if (a.priority != b.priority ? a.priority > b.priority
                                     : (a.stamp != b.stamp ? a.stamp > b.stamp : peer.queue[q].slot < peer.queue[best].slot))
          best = q;
      }
      QueueEntry& e = peer.queue[best];
      const RecordMeta& m = store_.meta(e.slot);
      if (m.seq != e.seq) {  // replaced since queued: send the current version from its start
        e.seq = m.seq;
        e.offset = 0;
      }
      const std::size_t remaining = m.size - e.offset;
      const std::size_t room = cap - w.size() < kFragmentHeaderBytes ? 0 : cap - w.size() - kFragmentHeaderBytes;
      if (remaining > room && room < kBlock) break;
      const std::size_t flen = remaining <= room ? remaining : (room / kBlock) * kBlock;
      w.u8(m.key.origin);
      w.u32(m.key.topic);
      w.u64(m.seq);
      w.u8(m.priority);
      w.i64(m.stamp);
      w.u32(m.size);
      w.u32(e.offset);
      w.u16(static_cast<std::uint16_t>(flen));
      w.bytes(store_.payload(e.slot).subspan(e.offset, flen));
      e.offset += static_cast<std::uint32_t>(flen);
      if (flen < remaining) {
        full = true;
      } else {
        dequeue(peer, best);
        ++stats_.records_out;
        ++peer_stats_[peer.id].records_out;
      }
    }
    if (w.size() == 0) return;
    if (!transmit(now, MsgType::kRecords, peer.id, peer.addr, w.size(), link)) return;
    ++stats_.records_datagrams_out;
    peer.tokens -= static_cast<double>(w.size() + kSealOverhead + p_.wire_overhead_bytes);
    --budget_datagrams;
  }
}

void GossipNode::tick(TimeNs now, DatagramLink& link) noexcept {
  for (std::size_t k = 0; k < p_.datagrams_per_tick; ++k) {
    LinkAddress from;
    bool truncated = false;
    const std::size_t n = link.receive(now, from, rx_, truncated);
    if (n == 0) break;
    if (truncated || n > kMaxDatagramBytes) {
      ++stats_.datagrams_in;
      drop(DropReason::kTooLong);
      continue;
    }
    receive(now, from, std::span<const std::uint8_t>(rx_.data(), n));
  }
  const TimeNs timeout = from_seconds(p_.peer_timeout_s);
  for (Peer& pe : peers_) {
    if (!pe.active || now - pe.last_heard <= timeout) continue;
    pe.active = false;
    for (std::size_t q = 0; q < pe.qn; ++q) pe.queued_pos[pe.queue[q].slot] = 0;
    pe.qn = 0;
    pe.have_due.reset();
    ++stats_.peers_timed_out;
  }
  const TimeNs period = from_seconds(p_.digest_period_s);
  if (!started_) {
    started_ = true;
    next_digest_ = now + static_cast<TimeNs>(static_cast<double>(period) * next_jitter());
    bcast_at_ = now;
  }
  if (now >= next_digest_) {
    send_digests(now, link);
    next_digest_ = now + static_cast<TimeNs>(static_cast<double>(period) * (0.9 + 0.2 * next_jitter()));
  }
  std::size_t budget = p_.datagrams_per_tick;
  const std::size_t start = static_cast<std::size_t>(counter_ % peers_.size());
  for (std::size_t k = 0; k < peers_.size(); ++k) {
    Peer& pe = peers_[(start + k) % peers_.size()];
    if (pe.active) serve_peer(now, pe, link, budget);
  }
}

}  // namespace ag::comms
