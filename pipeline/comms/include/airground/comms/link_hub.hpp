// An in-process transport: N endpoints, a contact graph the caller changes at will, Bernoulli loss and
// per-endpoint inboxes of fixed size. For tests and for running several gossip nodes in one process.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "airground/comms/link.hpp"

namespace ag::comms {

struct HubStats {
  std::uint64_t sent{0}, delivered{0}, lost{0}, out_of_reach{0}, inbox_full{0};
  std::uint64_t bytes_sent{0}, bytes_delivered{0};  // [B] datagram bytes (no IP/UDP overhead)
};

class LinkHub {
 public:
  LinkHub(int nodes, double loss_probability, std::uint64_t seed, std::size_t mtu = 1200, std::size_t inbox = 4096);
  ~LinkHub();
  LinkHub(const LinkHub&) = delete;
  LinkHub& operator=(const LinkHub&) = delete;
  // Every pair starts connected. Symmetric.
  void set_contact(int a, int b, bool connected) noexcept;
  void set_all_contacts(bool connected) noexcept;
  [[nodiscard]] bool contact(int a, int b) const noexcept;
  void set_loss(double p) noexcept { loss_ = p; }
  [[nodiscard]] DatagramLink& endpoint(int node) noexcept;
  [[nodiscard]] const HubStats& stats() const noexcept { return stats_; }
  [[nodiscard]] int nodes() const noexcept { return n_; }
  // Drops everything waiting in a node's inbox (a robot that died loses what its socket held).
  void clear_inbox(int node) noexcept;

 private:
  class End;
  struct Inbox {
    std::vector<std::vector<std::uint8_t>> slots;
    std::vector<std::size_t> sizes;
    std::vector<int> from;
    std::size_t head{0}, count{0};
  };
  bool draw_loss() noexcept;
  void put(int from, int to, std::span<const std::uint8_t> bytes) noexcept;

  int n_;
  double loss_;
  std::uint64_t rng_;
  std::size_t mtu_;
  std::vector<std::uint8_t> contact_;
  std::vector<Inbox> inbox_;
  std::vector<std::unique_ptr<End>> ends_;
  HubStats stats_;
};

// Fault injection in user space around any link (tc netem is not everywhere): drops each datagram
// received with a probability, and a cut link passes nothing either way.
class LossyLink final : public DatagramLink {
 public:
  LossyLink(DatagramLink& inner, double loss_probability, std::uint64_t seed) noexcept
      : inner_(inner), loss_(loss_probability), rng_(seed * 0x9E3779B97F4A7C15ULL + 7) {}
  SendStatus send(TimeNs now, const LinkAddress& to, std::span<const std::uint8_t> bytes) noexcept override;
  std::size_t receive(TimeNs now, LinkAddress& from, std::span<std::uint8_t> buf, bool& truncated) noexcept override;
  [[nodiscard]] std::size_t mtu() const noexcept override { return inner_.mtu(); }
  void set_cut(bool cut) noexcept { cut_ = cut; }
  void set_loss(double p) noexcept { loss_ = p; }
  [[nodiscard]] std::uint64_t dropped() const noexcept { return dropped_; }

 private:
  bool lose() noexcept;
  DatagramLink& inner_;
  double loss_;
  std::uint64_t rng_;
  bool cut_{false};
  std::uint64_t dropped_{0};
};

}  // namespace ag::comms
