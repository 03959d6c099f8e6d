// The uav role table: every stage once, with rate, budget, priority and CPU; checked at compile time.
// Budgets are for the quadrotor's NUC i7-10710U. The mapping stages each have their own thread below
// the drivers' priority: a pose-graph solve or a stereo pair takes tens of milliseconds.
#include "roles.hpp"

#include "airground/comms/stage.hpp"

#include "airground/aerial_mapping/stages.hpp"
#include "airground/drivers/camera/stage/camera_stage.hpp"
#include "airground/drivers/autopilot/mavlink/stage.hpp"
#include "airground/drivers/gps/ublox/stage.hpp"
#include "airground/mission/stages.hpp"
#include "airground/drivers/recording/recorder/recorder_stage.hpp"
#include "airground/platform/status_stage.hpp"
#include "airground/segmentation/stage.hpp"
#include "airground/visual_odometry/stage.hpp"

namespace ag {

namespace {
using mapping::OrthoMapStage;
using mapping::PoseGraphStage;

// name, factory, rate [Hz], budget [µs], SCHED_FIFO priority, CPU (-1 any), parameters, what it does
constexpr StageSpec kUavStages[] = {
    {"status", &StatusStage::make, 1.0, 2'000, 10, -1, StatusStage::kParams, "scheduler counters, once a second", {18.4, 0}},
    // The nadir camera: V4L2 frames converted and resampled to 640x400 (~5 ms at 1280x800), or a
    // frame-stream recording / FIFO with its visual odometry (the simulator's HIL mode).
    {"camera", &camera::CameraStage::make, 20.0, 15'000, 40, -1, camera::CameraStage::kParams,
     "nadir camera: V4L2 capture (or a frame-stream replay with its VO) on 'camera' and 'visual_odometry'", {}, true, "source=sim"},
    // The autopilot's attitude (the VO's gravity): ATTITUDE at 50 Hz over MAVLink, ~0.1 ms of parsing a step.
    {"autopilot", &mavlink::AutopilotStage::make, 50.0, 2'000, 38, -1, mavlink::AutopilotStage::kParams,
     "PX4 / ArduPilot attitude over MAVLink (TELEM2 serial, UDP onboard link or a .tlog), on 'attitude' in REP-103", {}, true, "source=sim"},
    {"gps", &ublox::UbloxStage::make, 20.0, 2'000, 35, -1, ublox::UbloxStage::kParams,
     "u-blox GNSS: UBX NAV-PVT (NMEA GGA fallback) from the serial port or a recording, on 'gps' in the map frame", {}, true, "source=sim"},
    // Monocular keyframe VO on every frame with the autopilot's attitude as gravity: ~5 ms a frame
    // (eval vo, one core here), bundle adjustment on keyframes; its own thread below the drivers.
    {"vo", &vo::VoStage::make, 10.0, 60'000, 33, -1, vo::VoStage::kParams,
     "visual odometry: camera frames + autopilot attitude -> 'visual_odometry' (segment frame, unknown scale)", {5.8, 9729.5, "frame tracked"}},
    {"pose_graph", &PoseGraphStage::make, 5.0, 150'000, 30, -1, PoseGraphStage::kParams,
     "odometry + GPS pose graph (Ceres), keyframes every 2 m, keyframe poses after each solve", {21.9, 19299.3, "graph solve"}},
    {"segmentation", &seg::SegmentationStage::make, 2.5, 300'000, 24, -1, seg::SegmentationStage::kParams,
     "ErfNet on each keyframe (labels = erfnet), or the camera's classes relayed (gt), onto keyframes_labelled", {4.3, 212386.8, "keyframe through ErfNet (2 threads: the step's share)"}},
    {"ortho_map", &OrthoMapStage::make, 5.0, 150'000, 20, -1, OrthoMapStage::kParams,
     "dense stereo between keyframes, binned into the 0.5 m ortho-map tiles", {4.7, 69980.3, "keyframe fused"}},
    {"comms", &comms::CommsStage::make, 20.0, 5'000, 25, -1, comms::CommsStage::kParams,
     "gossip: the team's latest records (poses, map tiles, claims, failures) over the radio mesh", {10.0, 0}},
    // One extraction over the default 1 km^2 area (4M cells) takes ~250 ms (bench_mission: 63 ms per 1M cells); its own thread.
    {"regions", &mission::RegionsStage::make, 1.0, 500'000, 15, -1, mission::RegionsStage::kParams,
     "regions of interest: vehicle cells of the map clustered, a reachable goal each, versioned on gossip", {3.9, 10840.0, "regions update"}},
    // The robot's own recorder (off unless recorder.path is set): taps the channels above without ever
    // holding a writer back, zstd and disk writes on its own lowest-priority thread.
    {"recorder", &recording::RecorderStage::make_uav, 10.0, 50'000, 1, -1, recording::RecorderStage::kUavParams,
     "MCAP recording of the robot's channels in recorder.path (Foxglove JSON, rotating files, bounded total)", {3.4, 0}},
};
static_assert(role_table_ok(kUavStages));

constexpr ParamSection kUavSections[] = {
    {"camera_calibration", mapping::kCameraCalibrationParams, "the nadir camera's intrinsics at 640x400 (OpenCV model)"},
};
}  // namespace

const RoleDescription& uav_role() {
  static const RoleDescription role{"uav", "quadrotor: semantic ortho-mapping and the regions of interest it finds", kUavStages, kUavSections};
  return role;
}

}  // namespace ag
