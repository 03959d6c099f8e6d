// The lockstep team runner's set-up: the simulator's models, the radio, and each robot's role instance
// with what the simulator writes for its devices (team_setup.cpp).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "airground/platform/clock.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/result.hpp"
#include "airground/platform/role_table.hpp"
#include "team.hpp"

namespace ag::sim::lockstep {

// The simulator's device and vehicle models: the defaults, or what --config-dir overrides.
struct Models {
  GpsConfig gps;
  VoConfig vo;
  WheelOdometryConfig odometry;
  RadioConfig radio;
  DiffDriveConfig drive;
  QuadrotorConfig quad;
  AttitudeConfig attitude;
  CameraModel camera;  // scaled by RunOptions::camera_scale
  CameraShading shading;
  CameraSensor sensor{CameraSensor::field()};  // a real camera unless camera.yaml says otherwise
  LidarNoise lidar_noise;
  OusterBeamModel beams;
};

// The ErfNet weights a simulated quadrotor loads: `shipped` (segmentation.weights in uav.yaml, where the
// package installs them) when that file exists, else the source tree's copy for a run from the build tree.
inline constexpr const char* kShippedErfnetWeights = "/usr/share/airground/erfnet_c7.agw";
std::string erfnet_weights_path(const std::string& shipped = kShippedErfnetWeights);

// Options that cannot make a run: the first one, named.
Status check_options(const RunOptions& opt);
Result<Models> load_models(const RunOptions& opt);
// The world's sensors (camera, LiDAR), the road router and the radio (node 0 the quadrotor or unused,
// then the ground robots, then the base station).
Status set_up_world(Team& t, const Models& m);

// Gossip: the names of the in-process radio links, unregistered when the run ends (the radio goes with the Team).
struct LinkRegistration {
  LinkRegistration() = default;
  LinkRegistration(const LinkRegistration&) = delete;
  LinkRegistration& operator=(const LinkRegistration&) = delete;
  ~LinkRegistration();
  std::vector<std::string> names;
};
// Every role's comms stage over its radio endpoint, under a team key written for this run: the settings
// all roles share (none without gossip).
Result<std::vector<std::string>> set_up_gossip(Team& t, LinkRegistration& links);

// Robot role instances: the real stage tables, quiet status stages (the runner reports instead).
// Each robot starts from its role's shipped configuration (built in from firmware_host/<role>/<role>.yaml),
// read over its full table's schema plus the simulator's own stages, so the sections of the device
// stages the simulator replaces stay and the start-up check sees what the simulated devices give. The
// simulator then sets only what it must: robot id and name, device backends, comms transport, mission
// area and start keys (tests/unit/sim/test_runner_shipped_config.cpp holds it to that).
class RoleFactory {
 public:
  // `configs` keeps every role's configuration for the run (the role instances refer to them).
  RoleFactory(const RunOptions& opt, SimClock& clock, std::vector<Config>& configs);
  Result<std::unique_ptr<RoleInstance>> make(const RoleDescription& role, const RoleDescription& shipped_role, int id, const std::string& name,
                                             const std::vector<std::string>& extra = {}, const char* what = "");
  // make() in two steps, for a robot whose simulated devices follow its configuration (the ground robot's
  // wheels and LiDAR mount): the shipped file, the simulator's keys and `extra`, kept for the run ...
  Result<const Config*> configure(const RoleDescription& role, const RoleDescription& shipped_role, int id, const std::string& name,
                                  const std::vector<std::string>& extra, const char* what);
  // ... and the role on it.
  Result<std::unique_ptr<RoleInstance>> create(const RoleDescription& role, const Config& config, const std::string& name);
  [[nodiscard]] const Clock& clock() const noexcept { return clock_; }

 private:
  const RunOptions& opt_;
  SimClock& clock_;
  std::vector<Config>& configs_;
  std::vector<std::string> warned_;  // stage-agreement warnings already printed (once per run, not per robot)
};

// The quadrotor: its vehicle on the survey route, its sensors, and its role. Returns the route's
// estimated flying time [s].
Result<double> set_up_uav(Team& t, const Models& m, RoleFactory& roles, const std::vector<std::string>& comms_common);
// The ground robots, lined up on the staging pad (or where the options put them).
Status set_up_ugvs(Team& t, const Models& m, RoleFactory& roles, const std::vector<std::string>& comms_common, double survey_time_s);
Status set_up_base(Team& t, RoleFactory& roles, const std::vector<std::string>& comms_common);
// Prints each channel a robot reads that neither its stages nor the simulator write (after every device
// writer is taken): a misspelled channel name, or a stage the simulator dropped without standing in for it.
void warn_unwritten_channels(const Team& t);

}  // namespace ag::sim::lockstep
