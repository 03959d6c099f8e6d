// The datagram transport contract: what the gossip (pipeline/comms) sends over, and what each transport
// implements: UDP on the robots' IP mesh (drivers/net/udp), the simulator's radio (sim/radio_link) and
// an in-process hub for tests (pipeline/comms link_hub). A driver-layer contract like PacketSource and
// CanBus, so drivers need nothing from the pipeline.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

#include "airground/platform/time.hpp"

namespace ag::net {

// Where a datagram came from or goes to, as the transport knows it (UDP: IPv4 address and port; the
// radio and the hub: a node number). The gossip learns a peer's address from its authentic datagrams.
struct LinkAddress {
  std::uint64_t value{0};
  bool broadcast{false};
  static constexpr LinkAddress everyone() noexcept { return LinkAddress{0, true}; }
  friend constexpr bool operator==(const LinkAddress&, const LinkAddress&) = default;
};

enum class SendStatus : std::uint8_t { kSent, kWouldBlock, kTooLarge, kUnreachable, kError };

class DatagramLink {
 public:
  DatagramLink() = default;
  DatagramLink(const DatagramLink&) = delete;
  DatagramLink& operator=(const DatagramLink&) = delete;
  virtual ~DatagramLink() = default;

  // Never blocks, never allocates. kSent only says the datagram left; it may still be lost.
  virtual SendStatus send(TimeNs now, const LinkAddress& to, std::span<const std::uint8_t> bytes) noexcept = 0;
  // Never blocks, never allocates: copies the next waiting datagram into buf and returns its size, or 0
  // when none waits. A datagram longer than buf sets `truncated` (its first buf.size() bytes are in buf).
  virtual std::size_t receive(TimeNs now, LinkAddress& from, std::span<std::uint8_t> buf, bool& truncated) noexcept = 0;
  // Largest datagram worth sending (the path MTU less IP and UDP headers).
  [[nodiscard]] virtual std::size_t mtu() const noexcept = 0;
};

}  // namespace ag::net
