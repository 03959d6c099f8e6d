// Simulated radio between robots: one shared medium (802.11 DCF-like CSMA/CA) with a log-distance path-loss
// and shadowing delivery curve, carrier sense, hidden-terminal collisions, latency with jitter.
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <span>
#include <string_view>
#include <vector>

#include "airground/platform/config.hpp"
#include "airground/platform/result.hpp"
#include "airground/platform/time.hpp"
#include "airground/messages/geometry.hpp"
#include "airground/platform/rng.hpp"

namespace YAML {
class Node;
}

namespace ag::sim {

// Every node shares the air with the nodes within its carrier-sense range. A datagram handed to send():
//  1. waits in its sender's transmit queue (queue_limit_bytes per node, tail drop: dropped_queue; larger
//     than max_datagram_bytes: dropped_queue);
//  2. goes on the air after the medium around the sender was idle for DIFS (sifs + 2 slots) plus a random
//     backoff of U{0..cw} slots, frozen while a node within carrier-sense range transmits (802.11 DCF);
//     two nodes whose backoffs end in the same slot both transmit;
//  3. occupies the air for preamble + (payload + overhead + MAC overhead bytes + 22 bits) / phy_rate, in
//     4 us OFDM symbols, plus SIFS + an ACK for a unicast: a broadcast costs this once, for all receivers;
//  4. reaches each addressed receiver with probability P(d) * (1 - loss_probability): P(d) is the
//     log-distance path loss with log-normal shadowing, 50 % at range_m (dropped_loss), unless another
//     transmission overlapped it from a node within carrier-sense range of the receiver and not
//     capture_threshold_db weaker there, or the receiver was transmitting itself (dropped_collision);
//  5. a unicast that is not received is retried (retry_limit times, the contention window doubling up to
//     cw_max); a broadcast is never retried (802.11 sends group frames once);
//  6. arrives latency_s + U(0, jitter_s) after its transmission ends (jitter can reorder), and is dropped
//     (dropped_range) if the receiver is by then beyond the reach of the curve (P < 1e-3, e.g. powered off).
// A broadcast addresses the nodes within reach when it is sent. Randomness comes from one seeded stream,
// drawn in event order, so a seed and a call order give the same result.
struct RadioConfig {
  double range_m{100.0};               // [m] distance at which a frame's delivery probability is 50 %
  double path_loss_exponent{3.0};      // [-] log-distance exponent n
  double shadowing_sigma_db{6.0};      // [dB] per frame and receiver; 0 = a hard edge at range_m
  double carrier_sense_range_m{0.0};   // [m] nodes this close defer to each other; 0 = derived (margin)
  double carrier_sense_margin_db{6.0}; // [dB] carrier sense below the decode threshold (used when the range is 0)
  double capture_threshold_db{10.0};   // [dB] a frame this much stronger than an overlapping one survives it
  double loss_probability{0.01};       // [-] per frame, independent of distance (Bernoulli)
  double latency_s{0.005};             // [s] fixed part of the delay after transmission (stack, driver)
  double jitter_s{0.002};              // [s] uniform extra delay in [0, jitter_s]
  double phy_rate_bps{6.0e6};          // [bit/s] PHY data rate (802.11a/g OFDM, lowest MCS)
  double preamble_s{20e-6};            // [s] PLCP preamble + SIGNAL
  double slot_s{9e-6};                 // [s] backoff slot
  double sifs_s{16e-6};                // [s] short interframe space (DIFS = SIFS + 2 slots)
  int cw_min{15};                      // [slots] initial contention window
  int cw_max{1023};                    // [slots] largest contention window (unicast retries)
  int retry_limit{7};                  // [-] unicast retransmissions before giving up
  double mac_overhead_bytes{36.0};     // [B] MAC header 24 + FCS 4 + LLC/SNAP 8, per frame
  double ack_bytes{14.0};              // [B] ACK frame (unicast)
  double overhead_bytes{28.0};         // [B] IPv4 + UDP header, per datagram
  double queue_limit_bytes{262144.0};  // [B] waiting bytes per node before tail drop
  double max_datagram_bytes{65507.0};  // [B] larger datagrams are refused (UDP over IPv4 limit)
};

std::span<const ParamSection> radio_config_schema() noexcept;  // one section, "radio"
Result<RadioConfig> load_radio_config(const YAML::Node& node, std::string_view origin);
Result<RadioConfig> load_radio_config(std::string_view yaml, std::string_view origin);

// The delivery curve and airtime of a configuration (pure: the tests and the docs use them too).
[[nodiscard]] double delivery_probability(const RadioConfig& c, double distance_m) noexcept;  // P(d), without loss_probability
[[nodiscard]] double reach_m(const RadioConfig& c) noexcept;                // [m] where P(d) falls to 1e-3
[[nodiscard]] double carrier_sense_range_m(const RadioConfig& c) noexcept;  // [m] configured or derived
[[nodiscard]] double frame_airtime_s(const RadioConfig& c, std::size_t payload_bytes, bool unicast) noexcept;
[[nodiscard]] inline double difs_s(const RadioConfig& c) noexcept { return c.sifs_s + 2.0 * c.slot_s; }

struct Delivery {
  int from{0};
  int to{0};
  TimeNs sent{0};     // [ns] when send() was called
  TimeNs arrival{0};  // [ns] when it reached the receiver (<= the deliver() time)
  std::vector<std::uint8_t> bytes;
};

struct LinkStats {
  std::uint64_t sent{0};               // datagrams offered for this receiver (send() calls that addressed it)
  std::uint64_t delivered{0};
  std::uint64_t dropped_range{0};      // beyond the curve's reach when it arrived, or a unicast out of reach
  std::uint64_t dropped_loss{0};       // the channel (path loss, shadowing, loss_probability)
  std::uint64_t dropped_queue{0};      // sender's queue full or oversize
  std::uint64_t dropped_collision{0};  // overlapped by another transmission, or the receiver was sending
  std::uint64_t retries{0};            // unicast retransmissions
  std::uint64_t bytes_sent{0};         // payload bytes offered
  std::uint64_t bytes_delivered{0};    // payload bytes delivered
  LinkStats& operator+=(const LinkStats& o) noexcept;
};

struct MediumStats {
  std::uint64_t transmissions{0};  // frames put on the air (a broadcast once, each unicast retry again)
  double airtime_s{0};             // [s] summed over transmissions (overlaps counted twice)
  std::uint64_t payload_bytes{0};  // [B] payload of those transmissions
};

class RadioModel {
 public:
  static constexpr int kBroadcast = -1;

  // Nodes 0 .. num_nodes-1, all at (0, 0) until placed. Deterministic given the seed and the call order.
  RadioModel(const RadioConfig& cfg, std::uint64_t seed, int num_nodes);

  void set_position(int node, double x, double y) noexcept;
  // Queues a datagram from `from` to `to` (kBroadcast: every other node within reach). Returns the number
  // of receivers it addresses (0 if none or refused; invalid node ids are ignored and return 0).
  std::size_t send(TimeNs now, int from, int to, std::span<const std::uint8_t> bytes);
  // Runs the medium up to `now` and appends every datagram whose arrival time is <= now, in arrival order
  // (ties: transmission order); returns how many were appended.
  std::size_t deliver(TimeNs now, std::vector<Delivery>& out);

  [[nodiscard]] const LinkStats& stats(int from, int to) const noexcept;
  [[nodiscard]] LinkStats total() const noexcept;
  [[nodiscard]] const MediumStats& medium(int node) const noexcept;  // what `node` put on the air
  [[nodiscard]] MediumStats medium_total() const noexcept;
  [[nodiscard]] std::size_t in_flight() const noexcept;
  [[nodiscard]] double queue_bytes(int node) const noexcept;  // [B] waiting to go on the air (with overheads)
  [[nodiscard]] bool in_range(int a, int b) const noexcept;   // within range_m (delivery >= 50 %)
  [[nodiscard]] int num_nodes() const noexcept { return n_; }
  [[nodiscard]] const RadioConfig& config() const noexcept { return cfg_; }

 private:
  struct Frame {
    int from{0}, to{0};
    TimeNs sent{0};
    std::vector<std::uint8_t> bytes;
    std::vector<int> receivers;  // addressed when sent
    int attempts{0};
  };
  struct Node {
    std::deque<Frame> queue;
    double queue_bytes{0};
    TimeNs resume_at{0};  // when its backoff countdown (re)started (after DIFS of idle medium)
    int backoff{0};       // [slots] left to count down from resume_at
    int cw{15};
    bool contending{false};
    TimeNs tx_end{0};     // when its last transmission ends
  };
  struct Tx {
    TimeNs start{0}, end{0};
    Frame frame;
    bool done{false};
  };
  struct Pending {
    TimeNs arrival;
    std::uint64_t seq;
    Delivery d;
  };
  struct Later {  // heap order: the earliest arrival (then the earliest transmission) on top
    bool operator()(const Pending& a, const Pending& b) const noexcept {
      return a.arrival != b.arrival ? a.arrival > b.arrival : a.seq > b.seq;
    }
  };
  [[nodiscard]] std::size_t link(int from, int to) const noexcept {
    return static_cast<std::size_t>(from) * static_cast<std::size_t>(n_) + static_cast<std::size_t>(to);
  }
  [[nodiscard]] double dist(int a, int b) const noexcept;
  [[nodiscard]] TimeNs ready_at(const Node& nd) const noexcept;
  void start_contention(int node, TimeNs idle_from, bool fresh_cw);
  void advance(TimeNs until);
  void finish(Tx& tx);
  [[nodiscard]] bool collided(const Tx& tx, int receiver) const noexcept;

  RadioConfig cfg_;
  Rng rng_;
  int n_;
  double cs_range_m_, reach_m_;
  std::vector<double> x_, y_;
  std::vector<Node> nodes_;
  std::deque<Tx> air_;  // transmissions in start order, kept while they can still matter
  std::vector<LinkStats> stats_;
  std::vector<MediumStats> medium_;
  std::vector<Pending> pending_;  // a heap under Later
  std::uint64_t seq_{0};
};

}  // namespace ag::sim
