// The `vo` stage alone in a role instance, driven by the lockstep executor: the test publishes camera
// frames of the synthetic ground (5 m/s east at 40 m) and the autopilot's attitude on their channels and
// reads what the stage publishes on 'visual_odometry'.
#pragma once

#include <gtest/gtest.h>

#include <memory>
#include <string>
#include <vector>

#include "airground/aerial_mapping/stages.hpp"
#include "airground/messages/channels.hpp"
#include "airground/messages/messages.hpp"
#include "airground/platform/clock.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/executor.hpp"
#include "airground/platform/role_instance.hpp"
#include "airground/platform/role_table.hpp"
#include "airground/visual_odometry/stage.hpp"
#include "synthetic_ground.hpp"

namespace ag::vo::test {

// Reads what the vo stage publishes (readers must exist before the role is sealed), after it at each instant.
class VoSink final : public Stage {
 public:
  static std::unique_ptr<Stage> make() { return std::make_unique<VoSink>(); }
  Status init(StageContext& ctx) override {
    auto r = ctx.channels.ring_reader(chan::kVisualOdometry);
    if (!r) return r.error();
    in_ = r.value();
    got.reserve(4096);
    return ok_status();
  }
  void step(TimeNs) noexcept override {
    while (const VoMsg* m = in_.front()) {
      if (got.size() < got.capacity()) got.push_back(*m);
      in_.pop();
    }
  }
  std::vector<VoMsg> got;

 private:
  RingReader<VoMsg, kVoRing> in_;
};

inline constexpr StageSpec kVoStages[] = {
    {"vo", &VoStage::make, 10.0, 60'000, 30, -1, VoStage::kParams, "visual odometry"},
    {"vo_sink", &VoSink::make, 10.0, 1'000, 20, -1, {}, "the test's reader"},
};
inline constexpr ParamSection kVoSections[] = {{"camera_calibration", mapping::kCameraCalibrationParams, "camera"}};

inline const RoleDescription& vo_role() {
  static const RoleDescription r{"vo-test", "the vo stage alone", kVoStages, kVoSections};
  return r;
}

struct Feed {
  double duration_s{8.0};
  double frame_hz{5.0};
  double attitude_hz{50.0};
  double attitude_delay_s{0.0};   // each attitude sample is published this long after its stamp
  double attitude_stop_s{1e9};    // no attitude samples stamped after this
  bool attitude{true};
  double blank_from_s{-1}, blank_to_s{-1};  // frames in this interval are uniform grey (tracking is lost)
};

struct Rig {
  Config config{Config::defaults(role_schema(vo_role()))};
  SimClock clock{0};
  std::unique_ptr<RoleInstance> robot;
  VoStage* stage{nullptr};
  RingWriter<CameraImageMsg, kCameraRing> camera;
  RingWriter<AttitudeMsg, kAttitudeRing> attitude;
  VoSink* sink{nullptr};
  std::unique_ptr<CameraImageMsg> image{std::make_unique<CameraImageMsg>()};
  std::unique_ptr<LockstepExecutor> ex;
  PinholeCamera cam;
  std::vector<VoMsg>& published() { return sink->got; }  // everything the stage published
  std::vector<TimeNs> frame_stamps;   // every frame the test published

  explicit Rig(const std::vector<std::string>& sets = {}) {
    // The synthetic renderer is an ideal pinhole.
    for (const char* kv : {"camera_calibration.k1=0.0", "camera_calibration.k2=0.0"}) EXPECT_TRUE(config.set(kv).ok());
    for (const std::string& kv : sets) EXPECT_TRUE(config.set(kv).ok()) << kv;
    auto created = RoleInstance::create(vo_role(), config, clock, "uav-vo-test");
    EXPECT_TRUE(created.ok()) << created.error().message;
    if (!created.ok()) return;
    robot = std::move(created).value();
    for (auto& slot : robot->stages())
      if (auto* s = dynamic_cast<VoStage*>(slot.stage.get())) stage = s;
      else if (auto* k = dynamic_cast<VoSink*>(slot.stage.get())) sink = k;
    camera = robot->channels().ring_writer(chan::kCamera).value();
    attitude = robot->channels().ring_writer(chan::kAttitude).value();
    cam = mapping::load_camera_calibration(config);
    frame_stamps.reserve(4096);
    ex = std::make_unique<LockstepExecutor>(clock, ExecTimer::kThreadCpu);
    ex->add(*robot);
    ex->start(0);
  }

  static Eigen::Vector3d position(double s) { return {5.0 * s, 0.0, 40.0}; }
  // A gentle weave so that the attitude matters.
  static Eigen::Matrix3d truth_attitude(double s) { return test::attitude(0.03 * std::sin(1.3 * s), 0.04 * std::sin(0.9 * s), 0.05 * std::sin(0.4 * s)); }

  // Runs the feed from the executor's current time to `until_s`.
  void run(const Feed& f, double until_s) {
    const TimeNs end = static_cast<TimeNs>(until_s * 1e9);
    const TimeNs frame_dt = static_cast<TimeNs>(1e9 / f.frame_hz), att_dt = static_cast<TimeNs>(1e9 / f.attitude_hz);
    const TimeNs delay = static_cast<TimeNs>(f.attitude_delay_s * 1e9);
    for (TimeNs t = ex->next_release(); t <= end; t = ex->next_release()) {
      for (; next_att_ + delay <= t; next_att_ += att_dt) {
        const double s = to_seconds(next_att_);
        if (!f.attitude || s > f.attitude_stop_s) continue;
        const Eigen::Vector3d rpy = truth_attitude(s).eulerAngles(2, 1, 0);
        AttitudeMsg m;
        m.stamp = next_att_;
        m.published = next_att_ + delay;
        m.yaw = rpy[0];
        m.pitch = rpy[1];
        m.roll = rpy[2];
        (void)attitude.push(m);
      }
      for (; next_frame_ <= t; next_frame_ += frame_dt) {
        const double s = to_seconds(next_frame_);
        if (s >= f.blank_from_s && s < f.blank_to_s)
          image->rgb.fill(128);
        else
          render_ground(cam, position(s), truth_attitude(s), image->rgb.data());
        image->stamp = next_frame_;
        image->published = next_frame_;
        ++image->seq;
        if (camera.push(*image) == 0) frame_stamps.push_back(next_frame_);
      }
      ex->run_until(t);
    }
  }

 private:
  TimeNs next_att_{0}, next_frame_{0};
};

}  // namespace ag::vo::test
