// The gossip's transport in simulation: comms::DatagramLink endpoints over the simulated radio
// (RadioModel), one per node, addressed by node number. Datagrams the radio delivers wait in each
// node's inbox until its link's receive() takes them.
#pragma once

#include <deque>
#include <memory>
#include <vector>

#include "airground/comms/link.hpp"
#include "airground/sim/radio.hpp"

namespace ag::sim {

class RadioNet {
 public:
  RadioNet(const RadioConfig& cfg, std::uint64_t seed, int nodes, std::size_t mtu = 1200);
  ~RadioNet();
  RadioNet(const RadioNet&) = delete;
  RadioNet& operator=(const RadioNet&) = delete;

  [[nodiscard]] comms::DatagramLink& endpoint(int node);
  // Moves everything that has arrived by `now` into the receivers' inboxes (call once per tick).
  void pump(TimeNs now);
  // Deferred sends, for robots stepped in parallel: each endpoint's sends wait in its own outbox until
  // flush() puts them on the air in node order (each node's in the order sent), which is the order a
  // serial step of the robots gives. Receiving is per node and unaffected.
  void set_deferred(bool on) noexcept { deferred_ = on; }
  void flush();
  [[nodiscard]] RadioModel& radio() noexcept { return radio_; }

 private:
  class End;
  RadioModel radio_;
  std::size_t mtu_;
  std::vector<std::deque<Delivery>> inbox_;
  std::vector<std::unique_ptr<End>> ends_;
  std::vector<Delivery> scratch_;
  bool deferred_{false};
  struct Pending {
    TimeNs now;
    int dest;
    std::size_t offset, size;  // in the node's outbox bytes
  };
  struct Outbox {
    std::vector<Pending> sends;
    std::vector<std::uint8_t> bytes;
  };
  std::vector<Outbox> outbox_;
};

}  // namespace ag::sim
