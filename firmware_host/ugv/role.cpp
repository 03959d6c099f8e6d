// The ugv role table: every stage once, with rate, budget, priority and CPU; checked at compile time.
#include "roles.hpp"

#include "airground/comms/stage.hpp"
#include "airground/drivers/base/base_stage.hpp"
#include "airground/drivers/lidar/ouster/stage.hpp"

#include "airground/localization/stage.hpp"
#include "airground/mission/stages.hpp"
#include "airground/planning/stages.hpp"
#include "airground/drivers/recording/recorder/recorder_stage.hpp"
#include "airground/platform/status_stage.hpp"

namespace ag {

namespace {
using loc::LocalizationStage;
using plan::DriveStage;
using plan::PlannerStage;
using plan::TrackerStage;

// Budgets are for the ground robot's Ryzen 5 3600. The localizer matches one scan per update (at most
// 10 Hz) with up to pf_max_particles particles: ~20 ms at 2,000 (make bench); the first updates, at 4,000 while it converges, take longest.
// name, factory, rate [Hz], budget [µs], SCHED_FIFO priority, CPU (-1 any), parameters, what it does
constexpr StageSpec kUgvStages[] = {
    {"status", &StatusStage::make, 1.0, 2'000, 10, -1, StatusStage::kParams, "scheduler counters, once a second", {18.4, 0}},
    // The Ouster OS-1: UDP packets (or a pcap) into revolutions on 'lidar_scan'; a 1024x10 sensor sends
    // 640 packets/s, drained at 20 Hz; the step that finishes a revolution converts 65k pixels through the
    // XYZ table and copies the scan (p99 ~10 ms on the 2-core CI machine under the HIL load).
    {"lidar", &ouster::OusterStage::make, 20.0, 12'000, 48, -1, ouster::OusterStage::kParams,
     "Ouster LiDAR: UDP packets (or a pcap replay) assembled into revolutions on 'lidar_scan'", {}, true, "source=sim"},
    {"localization", &LocalizationStage::make, 10.0, 70'000, 40, -1, LocalizationStage::kParams,
     "LiDAR scans matched against the aerial map (particle filter), fused with wheel odometry: the robot's pose", {9.5, 14617.1, "scan matched"}},
    {"comms", &comms::CommsStage::make, 20.0, 5'000, 25, -1, comms::CommsStage::kParams,
     "gossip: the team's latest records (poses, map tiles, claims, failures) over the radio mesh", {10.0, 0}},
    // The planner folds in a few changed tiles per step (~1-10 ms each) and answers a query in < 1 ms (bench_planning).
    {"planner", &PlannerStage::make, 5.0, 40'000, 30, -1, PlannerStage::kParams,
     "semantic roadmap over the aerial map: a route from the robot's pose to the goal on 'planned_path'", {4.5, 1342.4, "route planned"}},
    {"drive", &DriveStage::make, 20.0, 1'000, 50, -1, DriveStage::kParams,
     "path follower with acceleration limits: wheel speeds on 'wheel_command'", {4.0, 0}},
    // The wheels: e-stop first, then the newest wheel command to the two ODrives over CAN (SocketCAN,
    // the cannelloni bridge or a replayed candump log), their encoders to 'wheel_odometry'.
    {"base", &base::BaseStage::make, 50.0, 1'000, 55, -1, base::BaseStage::kParams,
     "e-stop, wheel commands to the motor controllers over CAN, wheel odometry, status LED", {}, true,
     "can_backend=sim,estop_backend=fake,led_backend=fake"},
    // One LiDAR revolution into the local grid and the local goal: ~1-3 ms at 1024 columns.
    {"tracker", &TrackerStage::make, 10.0, 15'000, 45, -1, TrackerStage::kParams,
     "local waypoint tracker: obstacles the LiDAR sees, the local goal along the route, the reflex stop", {4.0, 2721.0, "scan tracked"}},
    {"mission", &mission::MissionStage::make, 5.0, 2'000, 22, -1, mission::MissionStage::kParams,
     "mission manager: choose, claim and visit regions, resolve clashes by priority, report failures, return to start", {7.6, 0}},
    {"targets", &mission::TargetsStage::make, 10.0, 10'000, 21, -1, mission::TargetsStage::kParams,
     "target mapping: vehicles in the labelled LiDAR points, an EKF per object, on 'objects' (shared by the mission stage)", {3.6, 0}},
    // The robot's own recorder (off unless recorder.path is set): taps the channels above without ever
    // holding a writer back, zstd and disk writes on its own lowest-priority thread.
    {"recorder", &recording::RecorderStage::make_ugv, 10.0, 50'000, 1, -1, recording::RecorderStage::kUgvParams,
     "MCAP recording of the robot's channels in recorder.path (Foxglove JSON, rotating files, bounded total)", {3.4, 0}},
};
static_assert(role_table_ok(kUgvStages));
}  // namespace

const RoleDescription& ugv_role() {
  static const RoleDescription role{"ugv", "ground robot: semantic localization in the aerial map, planning, drive over CAN", kUgvStages, {}};
  return role;
}

}  // namespace ag
