// Radio model: per-link FIFO transmitters with a bandwidth cap and tail drop, Bernoulli loss, range, delay.
#include "airground/sim/radio.hpp"

#include <algorithm>
#include <cmath>

#include "airground/sim/model_params.hpp"

namespace ag::sim {

namespace {

constexpr ParamSpec kRadioParams[] = {
    ParamSpec::real("range_m", 100.0, 0.0, 1e6, "m", "xy distance within which two nodes hear each other"),
    ParamSpec::real("loss_probability", 0.05, 0.0, 1.0, "", "probability that a datagram is lost"),
    ParamSpec::real("latency_s", 0.005, 0.0, 60.0, "s", "fixed delay after transmission"),
    ParamSpec::real("jitter_s", 0.002, 0.0, 60.0, "s", "uniform extra delay in [0, jitter_s]"),
    ParamSpec::real("bandwidth_bytes_per_s", 250000.0, 0.0, 1e10, "B/s", "per link, 0 = unlimited"),
    ParamSpec::real("queue_limit_bytes", 262144.0, 0.0, 1e10, "B", "bytes waiting per link before tail drop"),
    ParamSpec::real("overhead_bytes", 0.0, 0.0, 1e4, "B", "per-datagram bytes on the air besides the payload"),
    ParamSpec::real("max_datagram_bytes", 65507.0, 1.0, 1e9, "B", "larger datagrams are refused"),
};
constexpr ParamSection kRadioSchema[] = {{"radio", kRadioParams, "simulated radio mesh"}};

Result<RadioConfig> radio_from(const Result<Config>& c) {
  if (!c) return c.error();
  const SectionView v(c.value(), "radio");
  RadioConfig r;
  r.range_m = v.real("range_m");
  r.loss_probability = v.real("loss_probability");
  r.latency_s = v.real("latency_s");
  r.jitter_s = v.real("jitter_s");
  r.bandwidth_bytes_per_s = v.real("bandwidth_bytes_per_s");
  r.queue_limit_bytes = v.real("queue_limit_bytes");
  r.overhead_bytes = v.real("overhead_bytes");
  r.max_datagram_bytes = v.real("max_datagram_bytes");
  return r;
}

}  // namespace

std::span<const ParamSection> radio_config_schema() noexcept { return kRadioSchema; }

Result<RadioConfig> load_radio_config(const YAML::Node& node, std::string_view origin) {
  return radio_from(load_model_params(kRadioSchema, node, origin));
}
Result<RadioConfig> load_radio_config(std::string_view yaml, std::string_view origin) {
  return radio_from(load_model_params(kRadioSchema, yaml, origin));
}

LinkStats& LinkStats::operator+=(const LinkStats& o) noexcept {
  sent += o.sent;
  delivered += o.delivered;
  dropped_range += o.dropped_range;
  dropped_loss += o.dropped_loss;
  dropped_queue += o.dropped_queue;
  bytes_sent += o.bytes_sent;
  bytes_delivered += o.bytes_delivered;
  return *this;
}

RadioModel::RadioModel(const RadioConfig& cfg, std::uint64_t seed, int num_nodes)
    : cfg_(cfg), rng_(seed), n_(std::max(num_nodes, 0)) {
  const auto n = static_cast<std::size_t>(n_);
  x_.assign(n, 0.0);
  y_.assign(n, 0.0);
  link_free_at_.assign(n * n, std::numeric_limits<TimeNs>::min());
  stats_.assign(n * n, LinkStats{});
}

void RadioModel::set_position(int node, double x, double y) noexcept {
  if (node < 0 || node >= n_) return;
  x_[static_cast<std::size_t>(node)] = x;
  y_[static_cast<std::size_t>(node)] = y;
}

bool RadioModel::in_range(int a, int b) const noexcept {
  if (a < 0 || b < 0 || a >= n_ || b >= n_) return false;
  const double dx = x_[static_cast<std::size_t>(a)] - x_[static_cast<std::size_t>(b)];
  const double dy = y_[static_cast<std::size_t>(a)] - y_[static_cast<std::size_t>(b)];
  return dx * dx + dy * dy <= cfg_.range_m * cfg_.range_m;
}

double RadioModel::link_backlog_bytes(TimeNs now, int from, int to) const noexcept {
  if (from < 0 || to < 0 || from >= n_ || to >= n_ || !(cfg_.bandwidth_bytes_per_s > 0)) return 0.0;
  const TimeNs free_at = link_free_at_[link(from, to)];
  return free_at > now ? to_seconds(free_at - now) * cfg_.bandwidth_bytes_per_s : 0.0;
}

bool RadioModel::send_one(TimeNs now, int from, int to, std::span<const std::uint8_t> bytes) {
  LinkStats& st = stats_[link(from, to)];
  ++st.sent;
  st.bytes_sent += bytes.size();
  if (!in_range(from, to)) {
    ++st.dropped_range;
    return false;
  }
  const double size = static_cast<double>(bytes.size());
  const double on_air = size + cfg_.overhead_bytes;
  if (size > cfg_.max_datagram_bytes || link_backlog_bytes(now, from, to) + on_air > cfg_.queue_limit_bytes + 1e-6) {
    ++st.dropped_queue;
    return false;
  }
  TimeNs& free_at = link_free_at_[link(from, to)];
  const TimeNs tx_start = std::max(now, free_at);
  const TimeNs tx_end =
      cfg_.bandwidth_bytes_per_s > 0 ? time_after(tx_start, on_air / cfg_.bandwidth_bytes_per_s) : tx_start;
  free_at = tx_end;
  // Draws happen for every datagram put on the air, lost or not, so the stream depends only on the calls.
  const bool lost = rng_.bernoulli(cfg_.loss_probability);
  const double delay = cfg_.latency_s + rng_.uniform(0.0, cfg_.jitter_s);
  if (lost) {
    ++st.dropped_loss;
    return true;  // it used the air all the same
  }
  Pending p{time_after(tx_end, delay), seq_++, Delivery{from, to, now, 0, {bytes.begin(), bytes.end()}}};
  p.d.arrival = p.arrival;
  pending_.push_back(std::move(p));
  std::push_heap(pending_.begin(), pending_.end(), Later{});
  return true;
}

std::size_t RadioModel::send(TimeNs now, int from, int to, std::span<const std::uint8_t> bytes) {
  if (from < 0 || from >= n_ || to < kBroadcast || to >= n_ || to == from) return 0;
  if (to != kBroadcast) return send_one(now, from, to, bytes) ? 1 : 0;
  std::size_t copies = 0;
  for (int r = 0; r < n_; ++r) {
    // A broadcast only addresses the nodes that can hear it: the others are not counted as drops.
    if (r == from || !in_range(from, r)) continue;
    if (send_one(now, from, r, bytes)) ++copies;
  }
  return copies;
}

std::size_t RadioModel::deliver(TimeNs now, std::vector<Delivery>& out) {
  std::size_t n = 0;
  while (!pending_.empty() && pending_.front().arrival <= now) {
    std::pop_heap(pending_.begin(), pending_.end(), Later{});
    Pending p = std::move(pending_.back());
    pending_.pop_back();
    LinkStats& st = stats_[link(p.d.from, p.d.to)];
    if (!in_range(p.d.from, p.d.to)) {  // the receiver left while the datagram waited or flew
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

}  // namespace ag::sim
