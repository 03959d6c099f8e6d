// The ground robot's localization stage (thin wrapper over SemanticLocalizer):
//   map_tiles -> class distance fields (a few tiles per step)      initial_pose -> (re)initialise
//   wheel_odometry -> gated motion          lidar_scan -> labels -> polar render -> particle filter
//   -> "localization" (latest value, every step: the fused pose, its covariance and status)
// Everything is allocated in init(); step() never allocates and never blocks.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>

#include "airground/messages/drive_messages.hpp"
#include "airground/messages/messages.hpp"
#include "airground/messages/mission_area.hpp"
#include "airground/localization/semantic_localizer.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/stage.hpp"

namespace ag::loc {

// What the stage saw and refused; published in its log lines and read by tests and evaluations.
struct LocalizationStageCounters {
  std::uint64_t scans_in{0}, scans_matched{0};
  std::uint64_t scans_skipped_standing{0};   // the robot had not moved enough since the last update
  std::uint64_t scans_before_map{0};          // no map tile yet, or no initial pose yet
  std::uint64_t scans_malformed{0};           // point count beyond the message, or no rings/columns
  std::uint64_t odometry_in{0};
  std::uint64_t odometry_out_of_order{0};     // stamp not after the previous sample: dropped
  std::uint64_t odometry_non_finite{0};       // NaN/inf pose: dropped
  std::uint64_t tiles_in{0}, tiles_applied{0};
  std::uint64_t tiles_outside_area{0};        // beyond the configured mission area: dropped
  std::uint64_t tiles_stale{0};               // same version as the stored tile
  std::uint64_t initial_poses{0};
  std::uint64_t initial_pose_invalid{0};      // non-finite pose or sigma: ignored
  std::uint64_t recoveries{0};
  std::uint64_t planner_start_blocked{0};     // routes the planner could not start from the tracked pose
};

// The stage's own parameters (the localizer's follow them in the same section).
enum class ScanLabels : std::uint8_t { kDriver, kGeometric };
struct LocalizationStageSettings {
  ScanLabels labels{ScanLabels::kDriver};
  int field_tiles_per_step{2};
  std::int64_t seed{0};
  bool set_initial_pose{false};
  double initial_x_m{0.0}, initial_y_m{0.0}, initial_yaw_rad{0.0};
  double initial_sigma_m{8.0}, initial_sigma_yaw_rad{0.5};
};
inline constexpr ParamField<LocalizationStageSettings> kLocalizationLabelsParam[] = {
    field::choice<&LocalizationStageSettings::labels>(
        "labels", "gt|geometric", {ScanLabels::kDriver, ScanLabels::kGeometric},
        "scan labels: the driver's classes (simulator ground truth or a segmentation), or the paper's geometric ground/obstacle split"),
};
inline constexpr auto kLocalizationAreaFields =
    mission_area_fields("mission area in the map frame: west edge (the distance fields cover it)");
inline constexpr ParamField<LocalizationStageSettings> kLocalizationStageOwnParams[] = {
    field::integer("field_tiles_per_step", &LocalizationStageSettings::field_tiles_per_step, 1, 1024, "tiles",
                   "changed map tiles folded into the distance fields per step"),
    field::integer("seed", &LocalizationStageSettings::seed, 0, 1'000'000'000, "", "particle filter seed; 0 = from the robot's name"),
    // A robot started from its YAML alone (no operator, no simulator) gets its guess here, like nav2
    // amcl's set_initial_pose; a later message on "initial_pose" replaces it.
    field::boolean("set_initial_pose", &LocalizationStageSettings::set_initial_pose,
                   "start from the initial_* guess below instead of waiting for an initial_pose message"),
    field::real("initial_x_m", &LocalizationStageSettings::initial_x_m, -1e6, 1e6, "m", "initial guess (map frame): east"),
    field::real("initial_y_m", &LocalizationStageSettings::initial_y_m, -1e6, 1e6, "m", "initial guess: north"),
    field::real("initial_yaw_rad", &LocalizationStageSettings::initial_yaw_rad, -6.3, 6.3, "rad", "initial guess: heading (0 = east, counter-clockwise)"),
    field::real("initial_sigma_m", &LocalizationStageSettings::initial_sigma_m, 0.5, 1000.0, "m", "the initial guess's standard deviation per axis (a guess within R m: R/2)"),
    field::real("initial_sigma_yaw_rad", &LocalizationStageSettings::initial_sigma_yaw_rad, 0.02, 3.2, "rad", "how far off its heading may be"),
};
// The stage's section: its own keys, then every localizer parameter.
inline constexpr auto kLocalizationStageParams =
    param_specs(kLocalizationLabelsParam, kLocalizationAreaFields, kLocalizationStageOwnParams, kOdometryGateFields, kPolarRenderParamSpecs, kParticleFilterFields,
                kFusedPoseFields, kGeometricLabelFields, kDistanceFieldFields);

class LocalizationStage final : public Stage {
 public:
  static constexpr std::span<const ParamSpec> kParams{kLocalizationStageParams};
  static std::unique_ptr<Stage> make() { return std::make_unique<LocalizationStage>(); }

  Status init(StageContext& ctx) override;
  void step(TimeNs now) noexcept override;

  [[nodiscard]] const SemanticLocalizer& localizer() const noexcept { return *loc_; }
  [[nodiscard]] const ClassDistanceFields& fields() const noexcept { return *fields_; }
  [[nodiscard]] const LocalizationStageCounters& counters() const noexcept { return c_; }
  [[nodiscard]] bool geometric_labels() const noexcept { return geometric_; }
  // The message the last step() published on "localization".
  [[nodiscard]] const LocalizationMsg& published() const noexcept { return msg_; }
  // The localizer's memory plus the distance fields and the labeller.
  [[nodiscard]] std::size_t memory_bytes() const noexcept;

 private:
  void take_tiles() noexcept;
  void take_initial_pose() noexcept;
  void feed_odometry_until(TimeNs t) noexcept;  // every queued sample stamped at or before t
  void take_scan(LidarScanMsg& scan) noexcept;
  void take_route() noexcept;

  std::unique_ptr<ClassDistanceFields> fields_;
  std::unique_ptr<SemanticLocalizer> loc_;
  std::unique_ptr<ScanLabeller> labeller_;
  bool geometric_{false};
  RingReader<LidarScanMsg, kLidarRing> scans_;
  RingReader<WheelOdometryMsg, kWheelOdometryRing> odom_;
  RingReader<MapTileMsg, kMapTileRing> tiles_;
  LatestReader<InitialPoseMsg> init_;
  LatestReader<PlannedPathMsg> path_;  // optional: the planner's word on the tracked pose
  std::uint32_t path_seq_{0};
  LocalizationStatus last_status_{LocalizationStatus::kNoMap};
  TimeNs status_since_{0};  // [ns] odometry stamp of the published status's last change
  LatestWriter<LocalizationMsg> out_;
  LocalizationMsg msg_{};
  std::size_t tiles_per_step_{4};
  bool have_map_{false}, have_init_{false}, have_odom_{false};
  TimeNs last_odom_stamp_{0};
  TimeNs init_stamp_{-1};
  bool config_init_pending_{false};
  InitialPoseMsg config_init_{};
  LocalizationStageCounters c_;
};

}  // namespace ag::loc
