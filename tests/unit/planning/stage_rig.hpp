// The planner and drive stages on one robot: a two-stage role built through RoleInstance (real config,
// real channels), with the writers the other stages and drivers would hold, fed from a synthetic world.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "airground/messages/channels.hpp"
#include "airground/planning/stages.hpp"
#include "airground/platform/role_instance.hpp"
#include "planning_world.hpp"

namespace ag::plan::test {

inline constexpr StageSpec kStages[] = {
    {"planner", &PlannerStage::make, 2.0, 100'000, 30, -1, PlannerStage::kParams, "global planner"},
    {"drive", &DriveStage::make, 20.0, 2'000, 45, -1, DriveStage::kParams, "drive control"},
};
inline constexpr RoleDescription kRole{"ugv", "planner + drive rig", kStages, {}};

struct Rig {
  SimClock clock{0};
  std::unique_ptr<RoleInstance> role;
  PlannerStage* planner{nullptr};
  DriveStage* drive{nullptr};
  RingWriter<MapTileMsg, kMapTileRing> tile_w;
  LatestWriter<LocalizationMsg> loc_w;
  LatestWriter<GoalMsg> goal_w;
  std::unique_ptr<MapTileMsg> tile = std::make_unique<MapTileMsg>();
  Pose2 pose{};
  LocalizationStatus status{LocalizationStatus::kTracking};  // what the localizer says

  explicit Rig(const test::SyntheticWorld& w) {
    static const std::vector<ParamSection> schema = role_schema(kRole);
    Config cfg = Config::defaults(schema);
    const double sx = w.tiles_x() * 32.0, sy = w.tiles_y() * 32.0;
    for (const std::string& s : {std::string("planner.area_x0_m=0"), std::string("planner.area_y0_m=0"), "planner.area_x1_m=" + std::to_string(sx - 0.01),
                                 "planner.area_y1_m=" + std::to_string(sy - 0.01), std::string("planner.tiles_per_step=8")})
      EXPECT_TRUE(cfg.set(s).ok()) << s;
    auto r = RoleInstance::create(kRole, cfg, clock, "ugv1");
    EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().message);
    role = std::move(r).value();
    planner = dynamic_cast<PlannerStage*>(role->stages()[0].stage.get());
    drive = dynamic_cast<DriveStage*>(role->stages()[1].stage.get());
    tile_w = role->channels().ring_writer(chan::kMapTiles).value();
    loc_w = role->channels().latest_writer(chan::kLocalization).value();
    goal_w = role->channels().latest_writer(chan::kGoal).value();
  }
  void push_tile(int tx, int ty, std::uint64_t version, const std::vector<std::uint8_t>& cls) {
    tile->tx = tx;
    tile->ty = ty;
    tile->version = version;
    std::copy(cls.begin(), cls.end(), tile->cls.begin());
    EXPECT_EQ(tile_w.push(*tile), 0U);
  }
  void load(const test::SyntheticWorld& w) {
    int n = 0;
    for (int ty = 0; ty < w.tiles_y(); ++ty)
      for (int tx = 0; tx < w.tiles_x(); ++tx) {
        push_tile(tx, ty, 1, w.tile(tx, ty));
        if (++n % 32 == 0) step_planner();
      }
    do step_planner();
    while (planner->roadmap().pending_tiles() > 0);
  }
  void publish_pose() {
    LocalizationMsg m;
    m.stamp = clock.now();
    m.status = status;
    m.pose = pose;
    loc_w.publish(m);
  }
  void step_planner() {
    publish_pose();
    planner->step(clock.now());
  }
  void goal(double x, double y, std::uint32_t id, bool cancel = false) {
    GoalMsg g;
    g.stamp = clock.now() + id + 1;  // a new stamp per goal
    g.id = id;
    g.goal = RoutePoint{x, y};
    g.cancel = cancel;
    goal_w.publish(g);
  }
  // 20 Hz: drive every tick, the planner every 10th; the robot moves by the commanded wheel speeds.
  void tick(int k) {
    clock.set(clock.now() + 50 * kNsPerMs);
    publish_pose();
    if (k % 10 == 0) planner->step(clock.now());
    drive->step(clock.now());
    const WheelCommandMsg& c = drive->published();
    const double v = 0.5 * (c.left_mps + c.right_mps), wz = (c.right_mps - c.left_mps) / 0.55, dt = 0.05;
    pose.x += v * dt * std::cos(pose.yaw + 0.5 * wz * dt);
    pose.y += v * dt * std::sin(pose.yaw + 0.5 * wz * dt);
    pose.yaw = wrap_angle(pose.yaw + wz * dt);
  }
};

}  // namespace ag::plan::test
