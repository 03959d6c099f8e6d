// The in-process transport: a contact matrix, loss draws and fixed inbox rings.
#include "airground/comms/link_hub.hpp"

#include <algorithm>
#include <cstring>

#include "airground/comms/topics.hpp"

namespace ag::comms {

class LinkHub::End final : public DatagramLink {
 public:
  End(LinkHub& hub, int id) : hub_(hub), id_(id) {}
  SendStatus send(TimeNs, const LinkAddress& to, std::span<const std::uint8_t> bytes) noexcept override {
    if (bytes.size() > hub_.mtu_) return SendStatus::kTooLarge;
    if (to.broadcast) {
      for (int r = 0; r < hub_.n_; ++r)
        if (r != id_ && hub_.contact(id_, r)) hub_.put(id_, r, bytes);
      return SendStatus::kSent;
    }
    if (to.value >= static_cast<std::uint64_t>(hub_.n_)) return SendStatus::kUnreachable;
    hub_.put(id_, static_cast<int>(to.value), bytes);
    return SendStatus::kSent;
  }
  std::size_t receive(TimeNs, LinkAddress& from, std::span<std::uint8_t> buf, bool& truncated) noexcept override {
    Inbox& in = hub_.inbox_[static_cast<std::size_t>(id_)];
    truncated = false;
    if (in.count == 0) return 0;
    const std::size_t n = in.sizes[in.head];
    const std::size_t c = std::min(n, buf.size());
    std::memcpy(buf.data(), in.slots[in.head].data(), c);
    truncated = c < n;
    from = LinkAddress{static_cast<std::uint64_t>(in.from[in.head]), false};
    in.head = (in.head + 1) % in.slots.size();
    --in.count;
    return c;
  }
  [[nodiscard]] std::size_t mtu() const noexcept override { return hub_.mtu_; }

 private:
  LinkHub& hub_;
  int id_;
};

LinkHub::LinkHub(int nodes, double loss_probability, std::uint64_t seed, std::size_t mtu, std::size_t inbox)
    : n_(nodes), loss_(loss_probability), rng_(seed * 0x9E3779B97F4A7C15ULL + 1), mtu_(mtu) {
  const auto n = static_cast<std::size_t>(std::max(nodes, 0));
  contact_.assign(n * n, 1);
  inbox_.resize(n);
  for (auto& in : inbox_) {
    in.slots.assign(inbox, std::vector<std::uint8_t>(mtu));
    in.sizes.assign(inbox, 0);
    in.from.assign(inbox, 0);
  }
  for (int i = 0; i < nodes; ++i) ends_.push_back(std::make_unique<End>(*this, i));
}

LinkHub::~LinkHub() = default;

DatagramLink& LinkHub::endpoint(int node) noexcept { return *ends_[static_cast<std::size_t>(node)]; }

void LinkHub::set_contact(int a, int b, bool connected) noexcept {
  if (a < 0 || b < 0 || a >= n_ || b >= n_) return;
  const auto n = static_cast<std::size_t>(n_);
  contact_[static_cast<std::size_t>(a) * n + static_cast<std::size_t>(b)] = connected ? 1 : 0;
  contact_[static_cast<std::size_t>(b) * n + static_cast<std::size_t>(a)] = connected ? 1 : 0;
}

void LinkHub::set_all_contacts(bool connected) noexcept { std::fill(contact_.begin(), contact_.end(), connected ? 1 : 0); }

bool LinkHub::contact(int a, int b) const noexcept {
  if (a < 0 || b < 0 || a >= n_ || b >= n_) return false;
  return contact_[static_cast<std::size_t>(a) * static_cast<std::size_t>(n_) + static_cast<std::size_t>(b)] != 0;
}

void LinkHub::clear_inbox(int node) noexcept {
  if (node < 0 || node >= n_) return;
  inbox_[static_cast<std::size_t>(node)].count = 0;
}

bool LinkHub::draw_loss() noexcept {
  rng_ = rng_ * 6364136223846793005ULL + 1442695040888963407ULL;
  const double u = static_cast<double>(mix64(rng_) >> 11) * 0x1.0p-53;
  return u < loss_;
}

void LinkHub::put(int from, int to, std::span<const std::uint8_t> bytes) noexcept {
  ++stats_.sent;
  stats_.bytes_sent += bytes.size();
  if (!contact(from, to)) {
    ++stats_.out_of_reach;
    return;
  }
  if (draw_loss()) {
    ++stats_.lost;
    return;
  }
  Inbox& in = inbox_[static_cast<std::size_t>(to)];
  if (in.count == in.slots.size()) {
    ++stats_.inbox_full;
    return;
  }
  const std::size_t k = (in.head + in.count) % in.slots.size();
  std::memcpy(in.slots[k].data(), bytes.data(), bytes.size());
  in.sizes[k] = bytes.size();
  in.from[k] = from;
  ++in.count;
  ++stats_.delivered;
  stats_.bytes_delivered += bytes.size();
}

bool LossyLink::lose() noexcept {
  rng_ = rng_ * 6364136223846793005ULL + 1442695040888963407ULL;
  return static_cast<double>(mix64(rng_) >> 11) * 0x1.0p-53 < loss_;
}

SendStatus LossyLink::send(TimeNs now, const LinkAddress& to, std::span<const std::uint8_t> bytes) noexcept {
  if (cut_) {
    ++dropped_;
    return SendStatus::kSent;  // lost in the air: the sender cannot tell
  }
  return inner_.send(now, to, bytes);
}

std::size_t LossyLink::receive(TimeNs now, LinkAddress& from, std::span<std::uint8_t> buf, bool& truncated) noexcept {
  for (;;) {
    const std::size_t n = inner_.receive(now, from, buf, truncated);
    if (n == 0) return 0;
    if (!cut_ && !lose()) return n;  // each receiver loses its own copies (a broadcast is not all-or-nothing)
    ++dropped_;
  }
}

}  // namespace ag::comms
