// Every channel of messages/'s message types, declared once: name, message type and ring size, with who
// writes it and who reads it. Stages reach a channel through these (ctx.channels.ring_reader(chan::kMapTiles)),
// so writer and readers cannot disagree on type or size. The names are what recordings, the MCAP output
// and Foxglove show: never rename one. The comms and mission channels sit beside their messages in
// pipeline/ (comms/messages.hpp, mission/messages.hpp), chan::kSchedulerStatus beside SchedulerStatus in
// platform/status_stage.hpp; a driver whose output name is a parameter keeps the type via with_name().
#pragma once

#include <array>
#include <cstddef>
#include <string_view>

#include "airground/messages/drive_messages.hpp"
#include "airground/messages/messages.hpp"
#include "airground/platform/channels.hpp"

namespace ag::chan {

// ------------------------------------------------------------------------------------ the quadrotor

// camera driver (or the simulator) -> vo, pose_graph; the recorder taps it.
inline constexpr RingTopic<CameraImageMsg, kCameraRing> kCamera{"camera"};
// vo stage (or the simulator) -> pose_graph; sim probes.
inline constexpr RingTopic<VoMsg, kVoRing> kVisualOdometry{"visual_odometry"};
// camera driver replaying a frame stream: the stream's own odometry (camera.vo_channel's default); unread.
inline constexpr RingTopic<VoMsg, kVoRing> kVisualOdometryRecorded{"visual_odometry_recorded"};
// vo stage in a HIL run (vo.output_channel), where the frame stream's odometry takes visual_odometry; unread.
inline constexpr RingTopic<VoMsg, kVoRing> kVisualOdometryOwn{"visual_odometry_own"};
// autopilot driver (or the simulator) -> vo.
inline constexpr RingTopic<AttitudeMsg, kAttitudeRing> kAttitude{"attitude"};
// u-blox driver (or the simulator) -> pose_graph; the recorder taps it.
inline constexpr RingTopic<GpsMsg, kGpsRing> kGps{"gps"};
// pose_graph -> segmentation, or ortho_map directly (ortho_map.keyframes_channel).
inline constexpr RingTopic<KeyframeMsg, kKeyframeRing> kKeyframes{"keyframes"};
// segmentation -> ortho_map (when ortho_map.keyframes_channel is "keyframes_labelled").
inline constexpr RingTopic<KeyframeMsg, kKeyframeRing> kKeyframesLabelled{"keyframes_labelled"};
// pose_graph -> ortho_map; the recorder (pose_source keyframe_poses).
inline constexpr LatestTopic<KeyframePosesMsg> kKeyframePoses{"keyframe_poses"};
// ortho_map -> nobody yet (tools, tests).
inline constexpr LatestTopic<MapStatusMsg> kMapStatus{"map_status"};

// -------------------------------------------------------------------------------------- all robots

// ortho_map on the quadrotor, comms (gossip) elsewhere, or the simulator -> regions, localization,
// planner, comms, web; the recorder taps it.
inline constexpr RingTopic<MapTileMsg, kMapTileRing> kMapTiles{"map_tiles"};

// ---------------------------------------------------------------------------------- the ground robot

// Ouster driver (or the simulator) -> localization, tracker, targets; the recorder taps it.
inline constexpr RingTopic<LidarScanMsg, kLidarRing> kLidarScan{"lidar_scan"};
// base driver (or the simulator) -> localization; the recorder taps it.
inline constexpr RingTopic<WheelOdometryMsg, kWheelOdometryRing> kWheelOdometry{"wheel_odometry"};
// an operator's tool or the simulator -> localization (optional: allow_unwritten).
inline constexpr LatestTopic<InitialPoseMsg> kInitialPose{"initial_pose"};
// localization -> planner, drive, tracker, mission, targets, comms; the recorder.
inline constexpr LatestTopic<LocalizationMsg> kLocalization{"localization"};

// mission (or the simulator) -> planner.
inline constexpr LatestTopic<GoalMsg> kGoal{"goal"};
// planner -> drive, tracker, mission.
inline constexpr LatestTopic<PlannedPathMsg> kPlannedPath{"planned_path"};
// tracker -> drive.
inline constexpr LatestTopic<LocalGoalMsg> kLocalGoal{"local_goal"};
// drive -> base driver, tracker.
inline constexpr LatestTopic<WheelCommandMsg> kWheelCommand{"wheel_command"};
// an operator's tool -> base driver (optional: allow_unwritten).
inline constexpr LatestTopic<BaseArmMsg> kBaseArm{"base_arm"};
// comms -> base driver: an operator's arm / disarm from the base station over the radio (optional).
inline constexpr LatestTopic<BaseArmMsg> kRadioArm{"radio_arm"};
// base driver -> nobody yet (tools, tests).
inline constexpr LatestTopic<BaseStatusMsg> kBaseStatus{"base_status"};

// ------------------------------------------------------------------------------- one name, one topic

// Whether no name appears twice, within a list and across lists.
template <std::size_t... N>
constexpr bool names_distinct(const std::array<std::string_view, N>&... lists) noexcept {
  constexpr std::size_t kTotal = (N + ... + 0);
  std::array<std::string_view, kTotal> all{};
  std::size_t k = 0;
  auto append = [&](const auto& list) {
    for (std::string_view s : list) all[k++] = s;
  };
  (append(lists), ...);
  for (std::size_t i = 0; i < kTotal; ++i)
    for (std::size_t j = i + 1; j < kTotal; ++j)
      if (all[i] == all[j]) return false;
  return true;
}

// The names declared here; the pipeline/ headers check theirs against these, and test_channel_topics
// checks every list together with platform/'s "scheduler_status".
inline constexpr std::array<std::string_view, 22> kNames{
    kCamera.name,     kVisualOdometry.name, kVisualOdometryRecorded.name, kVisualOdometryOwn.name, kAttitude.name,
    kGps.name,        kKeyframes.name,      kKeyframesLabelled.name,      kKeyframePoses.name,     kMapStatus.name,
    kMapTiles.name,   kLidarScan.name,      kWheelOdometry.name,          kInitialPose.name,       kLocalization.name,
    kGoal.name,       kPlannedPath.name,    kLocalGoal.name,              kWheelCommand.name,      kBaseArm.name,
    kBaseStatus.name, kRadioArm.name,
};
static_assert(names_distinct(kNames), "two channels share a name");

}  // namespace ag::chan
