// The comms stage on its own robot: a role of the stage and a probe stage (which holds the readers the
// robot's other stages would), built through RoleInstance with a real config and real channels.
#pragma once

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "airground/comms/messages.hpp"
#include "airground/comms/stage.hpp"
#include "airground/messages/channels.hpp"
#include "airground/platform/role_instance.hpp"

namespace ag::comms::test {

// Subscribes, in init(), to what the comms stage publishes.
class Probe final : public Stage {
 public:
  static constexpr ParamSpec kOwn[] = {ParamSpec::boolean("read_tiles", false, "subscribe to map_tiles")};
  static constexpr std::span<const ParamSpec> kParams{kOwn};
  static inline Probe* last = nullptr;
  static std::unique_ptr<Stage> make() { return std::make_unique<Probe>(); }
  Status init(StageContext& ctx) override {
    last = this;
    if (ctx.params().boolean("read_tiles")) tiles = ctx.channels.ring_reader(chan::kMapTiles).value();
    records = ctx.channels.ring_reader(chan::kGossipIn).value();
    team = ctx.channels.latest_reader(chan::kTeamPoses).value();
    stats = ctx.channels.latest_reader(chan::kCommsStats).value();
    arm = ctx.channels.latest_reader(chan::kRadioArm).value();
    ctx.channels.allow_unwritten(chan::kRadioArm);
    return ok_status();
  }
  void step(TimeNs) noexcept override {}
  RingReader<MapTileMsg, kMapTileRing> tiles;
  RingReader<GossipRecordMsg, kGossipRing> records;
  LatestReader<TeamPosesMsg> team;
  LatestReader<CommsStatsMsg> stats;
  LatestReader<BaseArmMsg> arm;
};

inline constexpr StageSpec kRigStages[] = {
    {"comms", &CommsStage::make, 20.0, 10'000, 20, -1, CommsStage::kParams, "the stage under test"},
    {"probe", &Probe::make, 20.0, 1'000, 20, -1, Probe::kParams, "the robot's other stages"},
};
inline constexpr RoleDescription kRigRole{"rig", "comms stage rig", kRigStages, {}};

inline std::string write_key_file(const std::string& path) {
  std::ofstream(path) << "00112233445566778899aabbccddeeff00112233445566778899aabbccddeeff\n";
  ::chmod(path.c_str(), 0600);
  return path;
}

struct CommsRig {
  SimClock clock{0};
  std::unique_ptr<RoleInstance> role;
  CommsStage* stage{nullptr};
  Probe* probe{nullptr};
  RingWriter<GossipPublishMsg, kGossipRing> out_w;
  RingWriter<MapTileMsg, kMapTileRing> tiles_w;  // only without deliver_map_tiles
  LatestWriter<LocalizationMsg> pose_w;

  static Result<std::unique_ptr<CommsRig>> make(const std::string& instance, std::vector<std::string> sets) {
    auto rig = std::make_unique<CommsRig>();
    static const std::vector<ParamSection> schema = role_schema(kRigRole);
    Config cfg = Config::defaults(schema);
    bool deliver = false;
    for (const std::string& s : sets) {
      if (s == "comms.deliver_map_tiles=true") deliver = true;
      if (auto st = cfg.set(s); !st) return st.error();
    }
    auto r = RoleInstance::create(kRigRole, cfg, rig->clock, instance);
    if (!r) return r.error();
    rig->role = std::move(r).value();
    rig->stage = dynamic_cast<CommsStage*>(rig->role->stages().front().stage.get());
    rig->probe = Probe::last;
    ChannelRegistry& ch = rig->role->channels();
    rig->out_w = ch.ring_writer(chan::kGossipOut).value();
    if (!deliver) rig->tiles_w = ch.ring_writer(chan::kMapTiles).value();
    rig->pose_w = ch.latest_writer(chan::kLocalization).value();
    return rig;
  }
  void step(TimeNs now) {
    for (auto& s : role->stages()) s.stage->step(now);
  }
};

}  // namespace ag::comms::test
