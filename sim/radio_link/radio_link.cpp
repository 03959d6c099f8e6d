// comms::DatagramLink over the simulated radio: sends go on the air, deliveries wait in inboxes.
#include "airground/sim/radio_link.hpp"

#include <algorithm>
#include <cstring>

namespace ag::sim {

class RadioNet::End final : public comms::DatagramLink {
 public:
  End(RadioNet& net, int id) : net_(net), id_(id) {}
  comms::SendStatus send(TimeNs now, const comms::LinkAddress& to, std::span<const std::uint8_t> bytes) noexcept override {
    if (bytes.size() > net_.mtu_) return comms::SendStatus::kTooLarge;
    const int dest = to.broadcast ? RadioModel::kBroadcast : static_cast<int>(to.value);
    if (!to.broadcast && (to.value >= static_cast<std::uint64_t>(net_.radio_.num_nodes()))) return comms::SendStatus::kUnreachable;
    if (net_.deferred_) {  // stepped beside other robots: onto the air at flush(), in node order
      auto& box = net_.outbox_[static_cast<std::size_t>(id_)];
      box.sends.push_back(Pending{now, dest, box.bytes.size(), bytes.size()});
      box.bytes.insert(box.bytes.end(), bytes.begin(), bytes.end());
      return comms::SendStatus::kSent;
    }
    (void)net_.radio_.send(now, id_, dest, bytes);  // out of range or lost: the sender cannot tell
    return comms::SendStatus::kSent;
  }
  std::size_t receive(TimeNs, comms::LinkAddress& from, std::span<std::uint8_t> buf, bool& truncated) noexcept override {
    auto& in = net_.inbox_[static_cast<std::size_t>(id_)];
    truncated = false;
    if (in.empty()) return 0;
    const Delivery& d = in.front();
    const std::size_t n = std::min(d.bytes.size(), buf.size());
    std::memcpy(buf.data(), d.bytes.data(), n);
    truncated = n < d.bytes.size();
    from = comms::LinkAddress{static_cast<std::uint64_t>(d.from), false};
    in.pop_front();
    return n;
  }
  [[nodiscard]] std::size_t mtu() const noexcept override { return net_.mtu_; }

 private:
  RadioNet& net_;
  int id_;
};

RadioNet::RadioNet(const RadioConfig& cfg, std::uint64_t seed, int nodes, std::size_t mtu)
    : radio_(cfg, seed, nodes), mtu_(mtu), inbox_(static_cast<std::size_t>(std::max(nodes, 0))),
      outbox_(static_cast<std::size_t>(std::max(nodes, 0))) {
  for (int i = 0; i < nodes; ++i) ends_.push_back(std::make_unique<End>(*this, i));
}

RadioNet::~RadioNet() = default;

comms::DatagramLink& RadioNet::endpoint(int node) { return *ends_.at(static_cast<std::size_t>(node)); }

void RadioNet::flush() {
  for (std::size_t n = 0; n < outbox_.size(); ++n) {
    Outbox& box = outbox_[n];
    for (const Pending& p : box.sends)
      (void)radio_.send(p.now, static_cast<int>(n), p.dest, std::span<const std::uint8_t>(box.bytes.data() + p.offset, p.size));
    box.sends.clear();  // capacity kept: no allocation once the busiest tick has been seen
    box.bytes.clear();
  }
}

void RadioNet::pump(TimeNs now) {
  scratch_.clear();
  radio_.deliver(now, scratch_);
  for (auto& d : scratch_) inbox_[static_cast<std::size_t>(d.to)].push_back(std::move(d));
}

}  // namespace ag::sim
