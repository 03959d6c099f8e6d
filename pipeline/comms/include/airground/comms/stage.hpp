// The comms stage, the same in every role (thin wrapper over GossipNode):
//   "gossip_out" (ring) and, if enabled, "localization" (pose, every pose_period_s) and "map_tiles"
//   (ring, the quadrotor's mapper) -> own records -> store + journal -> gossip over the link
//   link -> records of others -> "team_poses" (latest), "gossip_in" (ring), and, if enabled, "map_tiles"
//   (ring, to the ground robot's localizer); "comms_stats" (latest, every step).
// Transports: udp (drivers/net/udp, the robots' mesh), inproc (a DatagramLink registered under the
// robot's instance name by the simulator or a test), none (store and journal only).
// init() opens the journal (replaying it), the key and the socket and allocates everything; step()
// never allocates and never blocks (journal appends are single write(2)s to the page cache).
#pragma once

#include <memory>
#include <span>
#include <string>
#include <string_view>

#include "airground/comms/gossip_node.hpp"
#include "airground/comms/journal.hpp"
#include "airground/comms/messages.hpp"
#include "airground/comms/tile_codec.hpp"
#include "airground/messages/messages.hpp"
#include "airground/platform/param_binding.hpp"
#include "airground/platform/stage.hpp"

namespace ag::comms {

// Where the "inproc" transport finds each robot's link (set before the role starts; not thread-safe
// against concurrent starts, like the rest of init()).
void register_inproc_link(std::string_view instance, DatagramLink* link);
DatagramLink* find_inproc_link(std::string_view instance);

// The stage's parameters as read (store_mb and the periods are converted in init()).
struct CommsSettings {
  std::string transport{"none"};
  std::string key_file{"/etc/airground/team.key"};
  std::string journal;
  bool epoch_from_clock{true};
  std::string bind{"0.0.0.0"};
  std::uint16_t port{47100};
  std::string broadcast{"255.255.255.255"};
  std::string peers;  // comma-separated
  std::string device;
  int mtu_bytes{1200};                          // [B]
  double digest_period_s{1.0};                  // [s]
  double budget_bytes_per_s{100000.0};          // [B/s]
  double broadcast_budget_bytes_per_s{8000.0};  // [B/s]
  double peer_timeout_s{5.0};                   // [s]
  int max_records{8192};
  double store_mb{32.0};  // [MiB]
  double pose_period_s{1.0};  // [s]
  bool send_pose{false}, send_map_tiles{false}, deliver_map_tiles{false};
  int tiles_per_step{8};
  bool deliver_commands{true};
};
inline constexpr ParamField<CommsSettings> kCommsStageFields[] = {
    field::text("transport", &CommsSettings::transport, "none", "udp|inproc|none",
                "udp: the IP mesh; inproc: a link the simulator registered; none: store and journal only"),
    field::text("key_file", &CommsSettings::key_file, "/etc/airground/team.key", "", "the team key: 64 hex digits (e.g. od -An -tx1 -v -N32 /dev/urandom | tr -d ' \\n')"),
    field::text("journal", &CommsSettings::journal, "", "", "the store's journal file; empty = memory only (a restart forgets)"),
    field::boolean("epoch_from_clock", &CommsSettings::epoch_from_clock, "boot epoch >= wall-clock seconds (a robot that lost its disk still writes newer records); off for repeatable simulations"),
    field::text("bind", &CommsSettings::bind, "0.0.0.0", "", "udp: IPv4 address to bind"),
    field::integer("port", &CommsSettings::port, 1, 65535, "", "udp: the team's gossip port"),
    field::text("broadcast", &CommsSettings::broadcast, "255.255.255.255", "", "udp: broadcast address for digests; empty = none"),
    field::text("peers", &CommsSettings::peers, "", "", "udp: comma-separated a.b.c.d[:port] unicast peers that also get digests (routed meshes)"),
    field::text("device", &CommsSettings::device, "", "", "udp: network interface to bind to (SO_BINDTODEVICE); empty = any"),
    field::integer("mtu_bytes", &CommsSettings::mtu_bytes, 256, 65507, "B", "largest datagram (path MTU less IP/UDP headers)"),
    field::real("digest_period_s", &CommsSettings::digest_period_s, 0.05, 60.0, "s", "between digest broadcasts"),
    field::real("budget_bytes_per_s", &CommsSettings::budget_bytes_per_s, 1000.0, 1e9, "B/s", "per peer link: have-lists and records"),
    field::real("broadcast_budget_bytes_per_s", &CommsSettings::broadcast_budget_bytes_per_s, 100.0, 1e9, "B/s", "digests"),
    field::real("peer_timeout_s", &CommsSettings::peer_timeout_s, 0.1, 3600.0, "s", "silence after which a peer's send queue is dropped"),
    field::integer("max_records", &CommsSettings::max_records, 16, 1'000'000, "records", "keys (robot, topic) the store holds"),
    field::real("store_mb", &CommsSettings::store_mb, 0.1, 4096.0, "MiB", "payload memory of the store"),
    field::real("pose_period_s", &CommsSettings::pose_period_s, 0.05, 60.0, "s", "send_pose: how often the pose is shared"),
    field::boolean("send_pose", &CommsSettings::send_pose, "share the 'localization' pose (ground robots)"),
    field::boolean("send_map_tiles", &CommsSettings::send_map_tiles, "share the tiles on 'map_tiles' (the quadrotor)"),
    field::boolean("deliver_map_tiles", &CommsSettings::deliver_map_tiles, "write the team's tiles to 'map_tiles' (ground robots)"),
    field::integer("tiles_per_step", &CommsSettings::tiles_per_step, 1, 1024, "tiles", "map tiles encoded or decoded per step"),
    field::boolean("deliver_commands", &CommsSettings::deliver_commands,
                   "write the base station's arm / disarm for this robot to 'radio_arm' (once each as it arrives; never one the journal held at start-up)"),
};
inline constexpr auto kCommsStageParams = param_specs(kCommsStageFields);

class CommsStage final : public Stage {
 public:
  static constexpr std::span<const ParamSpec> kParams{kCommsStageParams};
  static std::unique_ptr<Stage> make() { return std::make_unique<CommsStage>(); }

  Status init(StageContext& ctx) override;
  void step(TimeNs now) noexcept override;
  void stop() noexcept override;

  [[nodiscard]] const GossipNode& node() const noexcept { return *node_; }
  [[nodiscard]] const RecordStore& store() const noexcept { return *store_; }
  [[nodiscard]] const CommsStatsMsg& stats() const noexcept { return *stats_; }
  [[nodiscard]] const TeamPosesMsg& team() const noexcept { return *team_; }
  [[nodiscard]] const JournalReport& journal_report() const noexcept { return report_; }

  static std::size_t encode_pose(const LocalizationMsg& m, std::span<std::uint8_t> out) noexcept;
  static bool decode_pose(std::span<const std::uint8_t> in, TeamPose& out) noexcept;

 private:
  void take_own(TimeNs now) noexcept;
  void deliver(TimeNs now) noexcept;
  void take_command(const RecordMeta& m, std::span<const std::uint8_t> payload, TimeNs now) noexcept;
  void publish_stats(TimeNs now) noexcept;

  RobotId self_{0};
  std::unique_ptr<RecordStore> store_;
  std::unique_ptr<Journal> journal_;
  std::unique_ptr<GossipNode> node_;
  std::unique_ptr<DatagramLink> owned_link_;
  DatagramLink* link_{nullptr};
  std::unique_ptr<TileCodec> codec_;
  std::unique_ptr<MapTileMsg> tile_;
  std::vector<std::uint8_t> buf_;
  JournalReport report_;
  bool send_pose_{false}, send_tiles_{false}, deliver_tiles_{false}, deliver_commands_{false};
  std::size_t tiles_per_step_{8};
  TimeNs pose_period_{kNsPerS};
  TimeNs last_pose_{-1};
  TimeNs last_pose_stamp_{-1};
  RingReader<GossipPublishMsg, kGossipRing> out_in_;
  RingWriter<GossipRecordMsg, kGossipRing> gossip_in_;
  LatestReader<LocalizationMsg> pose_in_;
  RingReader<MapTileMsg, kMapTileRing> tiles_in_;
  RingWriter<MapTileMsg, kMapTileRing> tiles_out_;
  LatestWriter<TeamPosesMsg> team_out_;
  LatestWriter<CommsStatsMsg> stats_out_;
  LatestWriter<BaseArmMsg> arm_out_;
  std::array<std::uint64_t, kMaxRobots> command_seen_{};  // per origin: the newest command seq acted on or restored
  std::uint64_t commands_in_{0}, commands_stale_{0}, commands_bad_{0};
  std::unique_ptr<GossipRecordMsg> rec_;
  std::unique_ptr<TeamPosesMsg> team_;
  std::unique_ptr<CommsStatsMsg> stats_;
  std::uint64_t tiles_out_n_{0}, tiles_in_n_{0}, tiles_bad_{0}, undeliverable_{0};
  std::array<std::uint64_t, static_cast<std::size_t>(DropReason::kCount)> logged_drops_{};
};

}  // namespace ag::comms
