// The regions stage (a one-stage "uav") and the mission stage (a one-stage "ugv") built through
// RoleInstance (real config, real channels), with the writers and readers the other stages would hold.
#pragma once

#include <gtest/gtest.h>

#include <memory>
#include <string>
#include <vector>

#include "airground/comms/messages.hpp"
#include "airground/messages/channels.hpp"
#include "airground/mission/messages.hpp"
#include "airground/mission/stages.hpp"
#include "airground/platform/role_instance.hpp"
#include "grid_world.hpp"

namespace ag::mission::test {

// Readers of the stages' outputs must subscribe in init(): a probe stage that only does that.
struct UavProbe final : Stage {
  static std::unique_ptr<Stage> make() { return std::make_unique<UavProbe>(); }
  Status init(StageContext& ctx) override {
    gossip_r = ctx.channels.ring_reader(chan::kGossipOut).value();
    regions_r = ctx.channels.latest_reader(chan::kRegions).value();
    return ok_status();
  }
  void step(TimeNs) noexcept override {}
  RingReader<comms::GossipPublishMsg, comms::kGossipRing> gossip_r;
  LatestReader<RegionsMsg> regions_r;
};
struct UgvProbe final : Stage {
  static std::unique_ptr<Stage> make() { return std::make_unique<UgvProbe>(); }
  Status init(StageContext& ctx) override {
    gossip_r = ctx.channels.ring_reader(chan::kGossipOut).value();
    goal_r = ctx.channels.latest_reader(chan::kGoal).value();
    status_r = ctx.channels.latest_reader(chan::kMissionStatus).value();
    return ok_status();
  }
  void step(TimeNs) noexcept override {}
  RingReader<comms::GossipPublishMsg, comms::kGossipRing> gossip_r;
  LatestReader<GoalMsg> goal_r;
  LatestReader<MissionStatusMsg> status_r;
};

inline constexpr StageSpec kUavStages[] = {
    {"regions", &RegionsStage::make, 1.0, 200'000, 15, -1, RegionsStage::kParams, "regions of interest"},
    {"probe", &UavProbe::make, 1.0, 1'000, 14, -1, {}, "test probe"},
};
inline constexpr RoleDescription kUavRole{"uav", "regions rig", kUavStages, {}};
inline constexpr StageSpec kUgvStages[] = {
    {"mission", &MissionStage::make, 5.0, 2'000, 20, -1, MissionStage::kParams, "mission manager"},
    {"probe", &UgvProbe::make, 1.0, 1'000, 14, -1, {}, "test probe"},
    {"targets", &TargetsStage::make, 10.0, 20'000, 21, -1, TargetsStage::kParams, "target mapper"},
};
inline constexpr RoleDescription kUgvRole{"ugv", "mission rig", kUgvStages, {}};

inline Config make_config(const RoleDescription& role, const std::vector<std::string>& sets) {
  Config cfg = Config::defaults(role_schema(role));
  for (const std::string& s : sets) EXPECT_TRUE(cfg.set(s).ok()) << s;
  return cfg;
}

struct RegionsRig {
  SimClock clock{0};
  std::unique_ptr<RoleInstance> role;
  RegionsStage* stage{nullptr};
  RingWriter<MapTileMsg, kMapTileRing> tile_w;
  RingReader<comms::GossipPublishMsg, comms::kGossipRing> gossip_r;
  LatestReader<RegionsMsg> regions_r;
  std::unique_ptr<MapTileMsg> tile = std::make_unique<MapTileMsg>();

  explicit RegionsRig(const GridWorld& w, double period_s = 1.0) {
    const Config cfg = make_config(kUavRole, {"regions.area_x0_m=0", "regions.area_y0_m=0", "regions.area_x1_m=" + std::to_string(w.tiles_x * 32.0 - 0.01),
                                              "regions.area_y1_m=" + std::to_string(w.tiles_y * 32.0 - 0.01), "regions.period_s=" + std::to_string(period_s)});
    auto r = RoleInstance::create(kUavRole, cfg, clock, "uav");
    EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().message);
    role = std::move(r).value();
    stage = static_cast<RegionsStage*>(role->stages()[0].stage.get());
    tile_w = role->channels().ring_writer(chan::kMapTiles).value();
    auto* probe = static_cast<UavProbe*>(role->stages()[1].stage.get());
    gossip_r = probe->gossip_r;
    regions_r = probe->regions_r;
  }
  void push(const GridWorld& w, int tx, int ty, std::uint64_t version) { push(w.tile(tx, ty), tx, ty, version); }
  void push(const std::vector<std::uint8_t>& t, int tx, int ty, std::uint64_t version) {
    tile->tx = tx;
    tile->ty = ty;
    tile->version = version;
    std::copy(t.begin(), t.end(), tile->cls.begin());
    EXPECT_EQ(tile_w.push(*tile), 0U);
  }
};

struct MissionRig {
  SimClock clock{0};
  std::unique_ptr<RoleInstance> role;
  MissionStage* stage{nullptr};
  RingWriter<comms::GossipRecordMsg, comms::kGossipRing> gossip_w;
  LatestWriter<comms::TeamPosesMsg> team_w;
  LatestWriter<LocalizationMsg> loc_w;
  LatestWriter<PlannedPathMsg> path_w;
  RingWriter<LidarScanMsg, kLidarRing> lidar_w;
  TargetsStage* targets{nullptr};
  RingReader<comms::GossipPublishMsg, comms::kGossipRing> gossip_r;
  LatestReader<GoalMsg> goal_r;
  LatestReader<MissionStatusMsg> status_r;
  std::unique_ptr<comms::GossipRecordMsg> rec = std::make_unique<comms::GossipRecordMsg>();
  std::unique_ptr<PlannedPathMsg> path = std::make_unique<PlannedPathMsg>();
  std::uint64_t seq{0};

  explicit MissionRig(int id, int priority, const std::vector<std::string>& extra = {}) {
    std::vector<std::string> sets = {"robot.id=" + std::to_string(id), "mission.priority=" + std::to_string(priority), "mission.start_x_m=1",
                                     "mission.start_y_m=2"};
    sets.insert(sets.end(), extra.begin(), extra.end());
    const Config cfg = make_config(kUgvRole, sets);
    auto r = RoleInstance::create(kUgvRole, cfg, clock, "ugv" + std::to_string(id));
    EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().message);
    role = std::move(r).value();
    stage = static_cast<MissionStage*>(role->stages()[0].stage.get());
    ChannelRegistry& ch = role->channels();
    gossip_w = ch.ring_writer(chan::kGossipIn).value();
    team_w = ch.latest_writer(chan::kTeamPoses).value();
    loc_w = ch.latest_writer(chan::kLocalization).value();
    path_w = ch.latest_writer(chan::kPlannedPath).value();
    lidar_w = ch.ring_writer(chan::kLidarScan).value();
    targets = static_cast<TargetsStage*>(role->stages()[2].stage.get());
    auto* probe = static_cast<UgvProbe*>(role->stages()[1].stage.get());
    gossip_r = probe->gossip_r;
    goal_r = probe->goal_r;
    status_r = probe->status_r;
  }
  void record(comms::RobotId origin, comms::Topic topic, std::span<const std::uint8_t> payload) {
    rec->key = comms::RecordKey{origin, topic};
    rec->seq = ++seq;
    rec->size = static_cast<std::uint32_t>(payload.size());
    std::copy(payload.begin(), payload.end(), rec->payload.begin());
    EXPECT_EQ(gossip_w.push(*rec), 0U);
  }
  void pose(double x, double y, double sigma, LocalizationStatus st = LocalizationStatus::kTracking) {
    LocalizationMsg l;
    l.stamp = clock.now();
    l.status = st;
    l.pose = Pose2{x, y, 0};
    l.covariance = {sigma * sigma, 0, 0, 0, sigma * sigma, 0, 0, 0, 0.01};
    loc_w.publish(l);
  }
  void step(double dt = 0.2) {
    clock.set(clock.now() + from_seconds(dt));
    stage->step(clock.now());
  }
};

}  // namespace ag::mission::test
