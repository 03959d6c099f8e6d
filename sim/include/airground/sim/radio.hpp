// Simulated radio mesh between robots: range on the xy plane, loss, latency with jitter, per-link bandwidth.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>
#include <vector>

#include "airground/platform/config.hpp"
#include "airground/platform/result.hpp"
#include "airground/platform/time.hpp"
#include "airground/sim/rng.hpp"

namespace YAML {
class Node;
}

namespace ag::sim {

// A link is one direction between two nodes (a -> b and b -> a are separate links, each with its own
// bandwidth and queue). A datagram on a link:
//  1. is dropped (dropped_range) if the nodes are farther apart than range_m when it is sent;
//  2. is dropped (dropped_queue) if the bytes still waiting on the link plus its own exceed
//     queue_limit_bytes (tail drop, as a full transmit queue does), or if it is larger than
//     max_datagram_bytes;
//  3. otherwise occupies the link for (size + overhead_bytes) / bandwidth_bytes_per_s after the
//     datagrams queued before it (FIFO), lost or not;
//  4. is lost in the air with probability loss_probability (dropped_loss, drawn when sent);
//  5. arrives latency_s + U(0, jitter_s) after its transmission ends (so jitter can reorder);
//  6. is dropped (dropped_range) if the nodes are out of range when deliver() hands it over.
// A broadcast is one copy per other node: each copy is a datagram on its own link.
struct RadioConfig {
  double range_m{100.0};                  // [m] xy distance within which two nodes hear each other
  double loss_probability{0.05};          // [-] per datagram (Bernoulli)
  double latency_s{0.005};                // [s] fixed part of the delay after transmission
  double jitter_s{0.002};                 // [s] uniform extra delay in [0, jitter_s]
  double bandwidth_bytes_per_s{250000.0}; // [B/s] per link, 0 = unlimited
  double queue_limit_bytes{262144.0};     // [B] waiting bytes per link before tail drop
  double overhead_bytes{0.0};             // [B] counted per datagram on the air (28 for IPv4 + UDP)
  double max_datagram_bytes{65507.0};     // [B] larger datagrams are refused (UDP over IPv4 limit)
};

std::span<const ParamSection> radio_config_schema() noexcept;  // one section, "radio"
Result<RadioConfig> load_radio_config(const YAML::Node& node, std::string_view origin);
Result<RadioConfig> load_radio_config(std::string_view yaml, std::string_view origin);

struct Delivery {
  int from{0};
  int to{0};
  TimeNs sent{0};     // [ns] when send() was called
  TimeNs arrival{0};  // [ns] when it reached the receiver (<= the deliver() time)
  std::vector<std::uint8_t> bytes;
};

struct LinkStats {
  std::uint64_t sent{0};            // datagrams offered to the link (send() calls that addressed it)
  std::uint64_t delivered{0};
  std::uint64_t dropped_range{0};
  std::uint64_t dropped_loss{0};
  std::uint64_t dropped_queue{0};   // queue full or oversize
  std::uint64_t bytes_sent{0};      // payload bytes offered
  std::uint64_t bytes_delivered{0}; // payload bytes delivered
  LinkStats& operator+=(const LinkStats& o) noexcept;
};

class RadioModel {
 public:
  static constexpr int kBroadcast = -1;

  // Nodes 0 .. num_nodes-1, all at (0, 0) until placed. Deterministic given the seed and the call order.
  RadioModel(const RadioConfig& cfg, std::uint64_t seed, int num_nodes);

  void set_position(int node, double x, double y) noexcept;
  // Queues a datagram from `from` to `to` (kBroadcast: every other node within range). Returns the number
  // of copies put on the air (0 if none; invalid node ids are ignored and return 0).
  std::size_t send(TimeNs now, int from, int to, std::span<const std::uint8_t> bytes);
  // Appends every datagram whose arrival time is <= now, in arrival order (ties: send order); returns
  // how many were appended.
  std::size_t deliver(TimeNs now, std::vector<Delivery>& out);

  [[nodiscard]] const LinkStats& stats(int from, int to) const noexcept;
  [[nodiscard]] LinkStats total() const noexcept;
  [[nodiscard]] std::size_t in_flight() const noexcept { return pending_.size(); }
  // Bytes (including overhead) still waiting to be sent on a link at `now`.
  [[nodiscard]] double link_backlog_bytes(TimeNs now, int from, int to) const noexcept;
  [[nodiscard]] bool in_range(int a, int b) const noexcept;
  [[nodiscard]] int num_nodes() const noexcept { return n_; }
  [[nodiscard]] const RadioConfig& config() const noexcept { return cfg_; }

 private:
  struct Pending {
    TimeNs arrival;
    std::uint64_t seq;
    Delivery d;
  };
  struct Later {  // heap order: the earliest arrival (then the earliest send) on top
    bool operator()(const Pending& a, const Pending& b) const noexcept {
      return a.arrival != b.arrival ? a.arrival > b.arrival : a.seq > b.seq;
    }
  };
  [[nodiscard]] std::size_t link(int from, int to) const noexcept {
    return static_cast<std::size_t>(from) * static_cast<std::size_t>(n_) + static_cast<std::size_t>(to);
  }
  bool send_one(TimeNs now, int from, int to, std::span<const std::uint8_t> bytes);

  RadioConfig cfg_;
  Rng rng_;
  int n_;
  std::vector<double> x_, y_;
  std::vector<TimeNs> link_free_at_;  // when each link's transmitter becomes idle
  std::vector<LinkStats> stats_;
  std::vector<Pending> pending_;  // a heap under Later
  std::uint64_t seq_{0};
};

}  // namespace ag::sim
