// The simulator's own stages in a robot's table: readers on the robot's channels for the runner's
// counters, scores and tests (they publish nothing the robot reads).
#pragma once

#include <memory>
#include <span>

#include "airground/messages/channels.hpp"
#include "airground/messages/drive_messages.hpp"
#include "airground/messages/messages.hpp"
#include "airground/platform/channels.hpp"
#include "airground/platform/param_binding.hpp"
#include "airground/platform/stage.hpp"

namespace ag::sim::lockstep {

struct Team;
struct Ugv;
struct Uav;

// The simulator's reader on the quadrotor's own odometry (its vo stage's output, as the pose graph gets it),
// appended to its table in field mode: counts segments and writes vo_uav.csv.
class SimVoTapStage final : public Stage {
 public:
  static constexpr ParamSpec kParams[] = {ParamSpec::boolean("log", true, "count and log 'visual_odometry'")};
  static std::unique_ptr<Stage> make() { return std::make_unique<SimVoTapStage>(); }
  Status init(StageContext& ctx) override {
    auto r = ctx.channels.ring_reader(chan::kVisualOdometry);
    if (!r) return r.error();
    in_ = r.value();
    return ok_status();
  }
  void step(TimeNs) noexcept override;
  Uav* uav{nullptr};

 private:
  RingReader<VoMsg, kVoRing> in_{};
};

struct SimProbeSettings {
  bool scans{false};
  bool odometry{false};
  bool tiles{false};
  bool initial_pose{false};
};
inline constexpr ParamField<SimProbeSettings> kSimProbeFields[] = {
    field::boolean("scans", &SimProbeSettings::scans, "read lidar_scan"),
    field::boolean("odometry", &SimProbeSettings::odometry, "read wheel_odometry"),
    field::boolean("tiles", &SimProbeSettings::tiles, "read map_tiles"),
    field::boolean("initial_pose", &SimProbeSettings::initial_pose, "read initial_pose"),
};
inline constexpr auto kSimProbeParams = param_specs(kSimProbeFields);

// The simulator's reader on a ground robot's channels, appended to its table: the newest "localization"
// for the sampling callback and the scores, the drive stage's wheel commands and, for tests, what
// arrives on the robot's input channels.
class SimProbeStage final : public Stage {
 public:
  static constexpr std::span<const ParamSpec> kParams{kSimProbeParams};
  static std::unique_ptr<Stage> make() { return std::make_unique<SimProbeStage>(); }

  Status init(StageContext& ctx) override;

  void step(TimeNs now) noexcept override;

  [[nodiscard]] bool received() const noexcept { return received_; }
  // The drive stage's newest wheel command, once per new value (drive_by_stages).
  bool take_command(WheelCommandMsg& out) noexcept {
    if (!new_command_) return false;
    new_command_ = false;
    out = command_;
    return true;
  }

  Team* team{nullptr};
  Ugv* ugv{nullptr};

 private:
  LatestReader<LocalizationMsg> loc_{};
  RingReader<LidarScanMsg, kLidarRing> scans_{};
  RingReader<WheelOdometryMsg, kWheelOdometryRing> odom_{};
  RingReader<MapTileMsg, kMapTileRing> tiles_{};
  LatestReader<InitialPoseMsg> init_{};
  LatestReader<WheelCommandMsg> cmd_{};
  WheelCommandMsg command_{};
  bool new_command_{false};
  bool read_scans_{false}, read_odom_{false}, read_tiles_{false}, read_init_{false};
  bool received_{false};
  TimeNs next_sample_{0}, next_user_sample_{0};
};

}  // namespace ag::sim::lockstep
