// The localization stage on its own robot: a one-stage role built through RoleInstance (real config,
// real channels), with the writers the drivers would hold, fed from a synthetic world.
#pragma once

#include <gtest/gtest.h>

#include <memory>
#include <span>
#include <string>
#include <vector>

#include "airground/localization/stage.hpp"
#include "airground/messages/channels.hpp"
#include "airground/platform/role_instance.hpp"
#include "synthetic_world.hpp"

namespace ag::loc::test {

inline constexpr StageSpec kRigStages[] = {
    {"localization", &LocalizationStage::make, 10.0, 60'000, 40, -1, LocalizationStage::kParams, "the stage under test"},
};
inline constexpr RoleDescription kRigRole{"ugv", "localization stage rig", kRigStages, {}};

struct StageRig {
  SimClock clock{0};
  std::unique_ptr<RoleInstance> role;
  LocalizationStage* stage{nullptr};
  RingWriter<LidarScanMsg, kLidarRing> scan_w;
  RingWriter<WheelOdometryMsg, kWheelOdometryRing> odom_w;
  RingWriter<MapTileMsg, kMapTileRing> tile_w;
  LatestWriter<InitialPoseMsg> init_w;
  std::unique_ptr<LidarScanMsg> scan = std::make_unique<LidarScanMsg>();
  std::unique_ptr<MapTileMsg> tile = std::make_unique<MapTileMsg>();
  std::uint32_t seq{0};

  // `sets`: "localization.key=value" overrides; the area defaults to the synthetic world's extent.
  static std::unique_ptr<StageRig> make(const SyntheticWorld& w, std::vector<std::string> sets = {}) {
    auto rig = std::make_unique<StageRig>();
    static const std::vector<ParamSection> schema = role_schema(kRigRole);
    Config cfg = Config::defaults(schema);
    const double sx = w.tiles_x() * w.tile_cells * w.resolution, sy = w.tiles_y() * w.tile_cells * w.resolution;
    sets.insert(sets.begin(), {"localization.area_x0_m=0", "localization.area_y0_m=0", "localization.area_x1_m=" + std::to_string(sx - 0.01),
                               "localization.area_y1_m=" + std::to_string(sy - 0.01), "localization.field_tiles_per_step=64"});
    for (const std::string& s : sets) {
      const Status st = cfg.set(s);
      EXPECT_TRUE(st.ok()) << s;
    }
    auto r = RoleInstance::create(kRigRole, cfg, rig->clock, "ugv1");
    EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().message);
    if (!r.ok()) return nullptr;
    rig->role = std::move(r).value();
    rig->stage = dynamic_cast<LocalizationStage*>(rig->role->stages().front().stage.get());
    ChannelRegistry& ch = rig->role->channels();
    rig->scan_w = ch.ring_writer(chan::kLidarScan).value();
    rig->odom_w = ch.ring_writer(chan::kWheelOdometry).value();
    rig->tile_w = ch.ring_writer(chan::kMapTiles).value();
    rig->init_w = ch.latest_writer(chan::kInitialPose).value();
    return rig;
  }

  void push_tile(int tx, int ty, std::uint64_t version, std::span<const std::uint8_t> cls) {
    tile->tx = tx;
    tile->ty = ty;
    tile->version = version;
    std::copy(cls.begin(), cls.end(), tile->cls.begin());
    EXPECT_EQ(tile_w.push(*tile), 0U);
  }
  // Every tile of the world, stepping the stage whenever the ring is nearly full.
  void push_world(const SyntheticWorld& w, TimeNs now) {
    int n = 0;
    for (int ty = 0; ty < w.tiles_y(); ++ty)
      for (int tx = 0; tx < w.tiles_x(); ++tx) {
        push_tile(tx, ty, 1, w.tile(tx, ty));
        if (++n % 32 == 0) step(now);
      }
  }
  void push_odometry(const Pose2& pose, TimeNs stamp) {
    WheelOdometryMsg m;
    m.stamp = stamp;
    m.pose = pose;
    m.moving = true;
    EXPECT_EQ(odom_w.push(m), 0U);
  }
  void push_scan(std::span<const ScanPoint> pts, TimeNs stamp, int rings, int columns) {
    scan->stamp = stamp;
    scan->seq = seq++;
    scan->rings = static_cast<std::uint16_t>(rings);
    scan->columns = static_cast<std::uint16_t>(columns);
    scan->labels = LabelSource::kGroundTruth;
    scan->count = static_cast<std::uint32_t>(pts.size());
    std::copy(pts.begin(), pts.end(), scan->points.begin());
    EXPECT_EQ(scan_w.push(*scan), 0U);
  }
  void initial_pose(const Pose2& p, double sigma_xy, double sigma_yaw, TimeNs stamp) {
    InitialPoseMsg m;
    m.stamp = stamp;
    m.pose = p;
    m.sigma_xy_m = sigma_xy;
    m.sigma_yaw_rad = sigma_yaw;
    init_w.publish(m);
  }
  void step(TimeNs now) {
    clock.set(now);
    stage->step(now);
  }
  // What the stage published last (channels are sealed once the role runs: no reader can join now).
  const LocalizationMsg& latest() { return stage->published(); }
};

}  // namespace ag::loc::test
