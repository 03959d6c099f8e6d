// libFuzzer target: the gossip's receive path. The first byte picks what the rest is:
//   0      a raw datagram off the air (header checks, authentication, replay window)
//   1..3   the body of an authentic digest / have-list / records datagram, sealed here with the team
//          key, so the fuzzer reaches the body decoders, reassembly and the store behind authentication
//   4      a map-tile payload for the tile decoder
// Between inputs the node also ticks (digests, have-lists, pushes into a discarding link), and it is
// rebuilt every 20000 inputs so its state stays varied but bounded.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "airground/comms/gossip_node.hpp"
#include "airground/comms/tile_codec.hpp"

namespace {
using namespace ag;
using namespace ag::comms;

class Discard final : public DatagramLink {
 public:
  SendStatus send(TimeNs, const LinkAddress&, std::span<const std::uint8_t> b) noexcept override {
    bytes += b.size();
    return SendStatus::kSent;
  }
  std::size_t receive(TimeNs, LinkAddress&, std::span<std::uint8_t>, bool&) noexcept override { return 0; }
  [[nodiscard]] std::size_t mtu() const noexcept override { return 1200; }
  std::size_t bytes{0};
};

TeamKey key() {
  TeamKey k;
  for (std::size_t i = 0; i < k.bytes.size(); ++i) k.bytes[i] = static_cast<std::uint8_t>(i * 13 + 1);
  return k;
}

struct World {
  RecordStore store{StoreLimits{512, 1u << 20, 70000}};
  GossipNode node;
  DatagramCodec sealer{key()};
  TileCodec tiles;
  MapTileMsg tile;
  Discard link;
  std::vector<std::uint8_t> out = std::vector<std::uint8_t>(70000);
  std::uint64_t counter{0};
  TimeNs now{1'000'000'000};
  std::uint64_t inputs{0};
  World() : node(params(), key(), store, 1, nullptr) {
    // Something to compare digests and have-lists against.
    std::vector<std::uint8_t> p(3000, 7);
    for (std::uint32_t t = 0; t < 20; ++t) node.publish(make_topic(TopicKind::kMapTile, t), 2, t, p);
  }
  static GossipParams params() {
    GossipParams gp;
    gp.self = 1;
    gp.reassembly_slots = 4;
    return gp;
  }
};

std::unique_ptr<World> g_world;

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (!g_world || ++g_world->inputs > 20000) g_world = std::make_unique<World>();
  World& w = *g_world;
  if (size == 0) return 0;
  const std::uint8_t mode = data[0] % 5;
  const std::span<const std::uint8_t> rest(data + 1, size - 1);
  w.now += 7'000'000;
  if (mode == 0) {
    w.node.receive(w.now, LinkAddress{5, false}, rest);
  } else if (mode <= 3) {
    if (rest.size() + kSealOverhead > w.out.size()) return 0;
    DatagramHeader h;
    h.type = static_cast<MsgType>(mode);
    h.sender = static_cast<RobotId>(2 + (w.counter % 7));
    h.dest = (w.counter % 3 == 0) ? RobotId{1} : kNoRobot;
    h.epoch = 1;
    h.counter = ++w.counter;
    const std::size_t n = w.sealer.seal(h, rest, w.out);
    w.node.receive(w.now, LinkAddress{h.sender, false}, std::span<const std::uint8_t>(w.out.data(), n));
  } else {
    (void)w.tiles.decode(rest, w.tile);
  }
  if (w.counter % 16 == 0) w.node.tick(w.now, w.link);
  return 0;
}
