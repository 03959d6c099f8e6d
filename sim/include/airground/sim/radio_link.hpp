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
  [[nodiscard]] RadioModel& radio() noexcept { return radio_; }

 private:
  class End;
  RadioModel radio_;
  std::size_t mtu_;
  std::vector<std::deque<Delivery>> inbox_;
  std::vector<std::unique_ptr<End>> ends_;
  std::vector<Delivery> scratch_;
};

}  // namespace ag::sim
