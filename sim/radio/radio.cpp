// The shared medium: per-node transmit queues contending with carrier sense and frozen backoff (802.11 DCF),
// transmissions judged per receiver for collisions and path loss once every overlapping one is known.
#include "airground/sim/radio.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace ag::sim {

namespace {

TimeNs ns_of(double s) noexcept { return static_cast<TimeNs>(std::llround(s * 1e9)); }

}  // namespace

LinkStats& LinkStats::operator+=(const LinkStats& o) noexcept {
  sent += o.sent;
  delivered += o.delivered;
  dropped_range += o.dropped_range;
  dropped_loss += o.dropped_loss;
  dropped_queue += o.dropped_queue;
  dropped_collision += o.dropped_collision;
  retries += o.retries;
  bytes_sent += o.bytes_sent;
  bytes_delivered += o.bytes_delivered;
  return *this;
}

RadioModel::RadioModel(const RadioConfig& cfg, std::uint64_t seed, int num_nodes)
    : cfg_(cfg), rng_(seed), n_(std::max(num_nodes, 0)), cs_range_m_(carrier_sense_range_m(cfg)),
      reach_m_(std::max(reach_m(cfg), cfg.range_m)) {
  const auto n = static_cast<std::size_t>(n_);
  x_.assign(n, 0.0);
  y_.assign(n, 0.0);
  nodes_.resize(n);
  for (Node& nd : nodes_) nd.cw = cfg_.cw_min;
  stats_.assign(n * n, LinkStats{});
  medium_.assign(n, MediumStats{});
}

void RadioModel::set_position(int node, double x, double y) noexcept {
  if (node < 0 || node >= n_) return;
  x_[static_cast<std::size_t>(node)] = x;
  y_[static_cast<std::size_t>(node)] = y;
}

double RadioModel::dist(int a, int b) const noexcept {
  return std::hypot(x_[static_cast<std::size_t>(a)] - x_[static_cast<std::size_t>(b)],
                    y_[static_cast<std::size_t>(a)] - y_[static_cast<std::size_t>(b)]);
}

bool RadioModel::in_range(int a, int b) const noexcept {
  if (a < 0 || b < 0 || a >= n_ || b >= n_) return false;
  return dist(a, b) <= cfg_.range_m;
}

double RadioModel::queue_bytes(int node) const noexcept {
  return node < 0 || node >= n_ ? 0.0 : nodes_[static_cast<std::size_t>(node)].queue_bytes;
}

std::size_t RadioModel::in_flight() const noexcept {
  std::size_t k = pending_.size();
  for (const Node& nd : nodes_) k += nd.queue.size();
  for (const Tx& t : air_) k += t.done ? 0 : 1;
  return k;
}

TimeNs RadioModel::ready_at(const Node& nd) const noexcept { return nd.resume_at + nd.backoff * ns_of(cfg_.slot_s); }

void RadioModel::start_contention(int node, TimeNs idle_from, bool fresh_cw) {
  Node& nd = nodes_[static_cast<std::size_t>(node)];
  if (fresh_cw) nd.cw = cfg_.cw_min;
  nd.contending = true;
  nd.resume_at = idle_from + ns_of(difs_s(cfg_));
  nd.backoff = static_cast<int>(rng_.below(static_cast<std::uint64_t>(nd.cw) + 1));
}

std::size_t RadioModel::send(TimeNs now, int from, int to, std::span<const std::uint8_t> bytes) {
  if (from < 0 || from >= n_ || to < kBroadcast || to >= n_ || to == from) return 0;
  advance(now);  // the air up to now is settled before this frame joins it
  Frame f{from, to, now, {}, {}, 0};
  if (to == kBroadcast) {
    // A broadcast only addresses the nodes that can hear it: the others are not counted as drops.
    for (int r = 0; r < n_; ++r)
      if (r != from && dist(from, r) <= reach_m_) f.receivers.push_back(r);
  } else {
    f.receivers.push_back(to);
  }
  if (f.receivers.empty()) return 0;
  for (const int r : f.receivers) {
    ++stats_[link(from, r)].sent;
    stats_[link(from, r)].bytes_sent += bytes.size();
  }
  Node& nd = nodes_[static_cast<std::size_t>(from)];
  const double size = static_cast<double>(bytes.size());
  const double on_air = size + cfg_.overhead_bytes + cfg_.mac_overhead_bytes;
  if (size > cfg_.max_datagram_bytes || nd.queue_bytes + on_air > cfg_.queue_limit_bytes + 1e-6) {
    for (const int r : f.receivers) ++stats_[link(from, r)].dropped_queue;
    return 0;
  }
  const std::size_t addressed = f.receivers.size();
  f.bytes.assign(bytes.begin(), bytes.end());
  nd.queue.push_back(std::move(f));
  nd.queue_bytes += on_air;
  if (!nd.contending) start_contention(from, std::max(now, nd.tx_end), true);
  return addressed;
}

void RadioModel::advance(TimeNs until) {
  const TimeNs slot = ns_of(cfg_.slot_s), difs = ns_of(difs_s(cfg_));
  auto finish_ended = [&](TimeNs t) {
    bool any = false;
    for (Tx& tx : air_)
      if (!tx.done && tx.end <= t) {
        finish(tx);
        any = true;
      }
    return any;
  };
  for (;;) {
    int best = -1;
    TimeNs bt = 0;
    for (int k = 0; k < n_; ++k) {
      const Node& nd = nodes_[static_cast<std::size_t>(k)];
      if (!nd.contending || nd.queue.empty()) continue;
      const TimeNs t = ready_at(nd);
      if (best < 0 || t < bt) {
        best = k;
        bt = t;
      }
    }
    if (best < 0 || bt > until) break;
    if (finish_ended(bt)) continue;  // a failed unicast may have changed who contends, and how
    Node& nd = nodes_[static_cast<std::size_t>(best)];
    // Carrier sense: transmissions from nodes within range that began at least a slot ago and overlapped
    // the idle DIFS + countdown this node needed freeze its backoff until they end.
    const TimeNs window = nd.resume_at - difs;
    TimeNs first_busy = std::numeric_limits<TimeNs>::max(), busy_end = std::numeric_limits<TimeNs>::min();
    for (const Tx& tx : air_) {
      if (tx.frame.from == best || tx.start > bt - slot || tx.end <= window) continue;
      if (dist(tx.frame.from, best) > cs_range_m_) continue;
      first_busy = std::min(first_busy, tx.start);
      busy_end = std::max(busy_end, tx.end);
    }
    if (busy_end > window) {
      const TimeNs counted = first_busy > nd.resume_at ? (first_busy - nd.resume_at) / slot : 0;
      nd.backoff = static_cast<int>(std::max<TimeNs>(0, nd.backoff - counted));
      nd.resume_at = busy_end + difs;
      continue;
    }
    Frame f = std::move(nd.queue.front());
    nd.queue.pop_front();
    nd.queue_bytes = std::max(0.0, nd.queue_bytes - (static_cast<double>(f.bytes.size()) + cfg_.overhead_bytes + cfg_.mac_overhead_bytes));
    const double air_s = frame_airtime_s(cfg_, f.bytes.size(), f.to != kBroadcast);
    MediumStats& ms = medium_[static_cast<std::size_t>(best)];
    ++ms.transmissions;
    ms.airtime_s += air_s;
    ms.payload_bytes += f.bytes.size();
    const TimeNs end = bt + ns_of(air_s);
    air_.push_back(Tx{bt, end, std::move(f), false});
    nd.tx_end = end;
    nd.contending = false;
    if (!nd.queue.empty()) start_contention(best, end, true);
  }
  finish_ended(until);
  // Forget transmissions no contender's window or unfinished frame can overlap any more.
  TimeNs horizon = until;
  for (const Node& nd : nodes_)
    if (nd.contending && !nd.queue.empty()) horizon = std::min(horizon, nd.resume_at - difs);
  for (const Tx& tx : air_)
    if (!tx.done) horizon = std::min(horizon, tx.start);
  while (!air_.empty() && air_.front().done && air_.front().end <= horizon) air_.pop_front();
}

bool RadioModel::collided(const Tx& tx, int receiver) const noexcept {
  const double ds = dist(tx.frame.from, receiver);
  for (const Tx& g : air_) {
    if (&g == &tx || g.start >= tx.end || g.end <= tx.start) continue;
    if (g.frame.from == receiver) return true;  // half duplex: it was sending
    if (g.frame.from == tx.frame.from) continue;
    const double dg = dist(g.frame.from, receiver);
    if (dg > cs_range_m_) continue;
    // Capture: the wanted frame survives an interferer this much weaker at the receiver.
    if (ds > 0 && dg > 0 && 10.0 * cfg_.path_loss_exponent * std::log10(dg / ds) >= cfg_.capture_threshold_db) continue;
    if (ds <= 0 && dg > 0) continue;
    return true;
  }
  return false;
}

void RadioModel::finish(Tx& tx) {
  tx.done = true;
  Frame& f = tx.frame;
  const bool unicast = f.to != kBroadcast;
  for (const int r : f.receivers) {
    LinkStats& st = stats_[link(f.from, r)];
    const double d = dist(f.from, r);
    enum class Fate { kDelivered, kRange, kCollision, kLoss } fate = Fate::kDelivered;
    if (d > reach_m_) {
      fate = Fate::kRange;
    } else if (collided(tx, r)) {
      fate = Fate::kCollision;
    } else {
      const double p = delivery_probability(cfg_, d) * (1.0 - cfg_.loss_probability);
      if (!(rng_.uniform() < p)) fate = Fate::kLoss;
    }
    if (fate == Fate::kDelivered) {
      const double delay = cfg_.latency_s + rng_.uniform(0.0, cfg_.jitter_s);
      Pending p{tx.end + ns_of(delay), seq_++, Delivery{f.from, r, f.sent, 0, {}}};
      p.d.arrival = p.arrival;
      p.d.bytes = unicast ? std::move(f.bytes) : f.bytes;
      pending_.push_back(std::move(p));
      std::push_heap(pending_.begin(), pending_.end(), Later{});
      continue;
    }
    if (unicast && f.attempts < cfg_.retry_limit) {  // no ACK: the sender tries again with a wider window
      ++st.retries;
      const int from = f.from;
      Node& nd = nodes_[static_cast<std::size_t>(from)];
      nd.queue_bytes += static_cast<double>(f.bytes.size()) + cfg_.overhead_bytes + cfg_.mac_overhead_bytes;
      ++f.attempts;
      nd.cw = std::min(2 * (nd.cw + 1) - 1, cfg_.cw_max);
      nd.queue.push_front(std::move(f));
      start_contention(from, tx.end, false);
      return;  // a unicast has one receiver
    }
    if (fate == Fate::kRange) ++st.dropped_range;
    if (fate == Fate::kCollision) ++st.dropped_collision;
    if (fate == Fate::kLoss) ++st.dropped_loss;
  }
}

std::size_t RadioModel::deliver(TimeNs now, std::vector<Delivery>& out) {
  advance(now);
  std::size_t n = 0;
  while (!pending_.empty() && pending_.front().arrival <= now) {
    std::pop_heap(pending_.begin(), pending_.end(), Later{});
    Pending p = std::move(pending_.back());
    pending_.pop_back();
    LinkStats& st = stats_[link(p.d.from, p.d.to)];
    if (dist(p.d.from, p.d.to) > reach_m_) {  // the receiver left (or was powered off) while it flew
      ++st.dropped_range;
      continue;
    }
    ++st.delivered;
    st.bytes_delivered += p.d.bytes.size();
    out.push_back(std::move(p.d));
    ++n;
  }
  return n;
}

const LinkStats& RadioModel::stats(int from, int to) const noexcept {
  static const LinkStats kNone{};
  if (from < 0 || to < 0 || from >= n_ || to >= n_) return kNone;
  return stats_[link(from, to)];
}

LinkStats RadioModel::total() const noexcept {
  LinkStats t;
  for (const auto& s : stats_) t += s;
  return t;
}

const MediumStats& RadioModel::medium(int node) const noexcept {
  static const MediumStats kNone{};
  return node < 0 || node >= n_ ? kNone : medium_[static_cast<std::size_t>(node)];
}

MediumStats RadioModel::medium_total() const noexcept {
  MediumStats t;
  for (const auto& m : medium_) {
    t.transmissions += m.transmissions;
    t.airtime_s += m.airtime_s;
    t.payload_bytes += m.payload_bytes;
  }
  return t;
}

}  // namespace ag::sim
