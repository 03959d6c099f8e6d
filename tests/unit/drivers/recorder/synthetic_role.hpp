// Test helper: a role of synthetic sources (wheel odometry 50 Hz, GPS 20 Hz, LiDAR 50 Hz into a ring of
// 2, map tiles 20 Hz, the localizer's pose 10 Hz, the scheduler's counters) and the recorder stage, run
// in lockstep. The sources' steps copy into preallocated ring slots: they allocate nothing.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "airground/messages/channels.hpp"
#include "airground/messages/messages.hpp"
#include "airground/drivers/recording/recorder/recorder_stage.hpp"
#include "airground/platform/executor.hpp"
#include "airground/platform/role_instance.hpp"
#include "airground/platform/role_table.hpp"
#include "airground/platform/status_stage.hpp"

namespace ag::test {

using recording::RecorderStage;

// What the synthetic sources published (the test reads it after the run).
struct Published {
  std::uint64_t odometry{0}, gps{0}, lidar{0}, tiles{0}, poses{0}, images{0};
};
inline Published g_published;
inline std::size_t g_scan_points = 2048;  // points per synthetic revolution

class OdometrySource final : public Stage {
 public:
  static std::unique_ptr<Stage> make() { return std::make_unique<OdometrySource>(); }
  Status init(StageContext& ctx) override {
    auto w = ctx.channels.ring_writer(chan::kWheelOdometry);
    if (!w) return w.error();
    out_ = w.value();
    return ok_status();
  }
  void step(TimeNs now) noexcept override {
    msg_.stamp = msg_.published = now;
    msg_.pose.x += 0.02;
    (void)out_.push(msg_);
    ++g_published.odometry;
  }

 private:
  RingWriter<WheelOdometryMsg, kWheelOdometryRing> out_;
  WheelOdometryMsg msg_{};
};

class GpsSource final : public Stage {
 public:
  static std::unique_ptr<Stage> make() { return std::make_unique<GpsSource>(); }
  Status init(StageContext& ctx) override {
    auto w = ctx.channels.ring_writer(chan::kGps);
    if (!w) return w.error();
    out_ = w.value();
    return ok_status();
  }
  void step(TimeNs now) noexcept override {
    msg_.stamp = msg_.published = now;
    msg_.fix_type = 3;
    msg_.north_m = 111.0 * static_cast<double>(g_published.gps);  // ~0.001 deg of latitude a fix
    msg_.h_accuracy_m = 1.5;
    (void)out_.push(msg_);
    ++g_published.gps;
  }

 private:
  RingWriter<GpsMsg, kGpsRing> out_;
  GpsMsg msg_{};
};

// 50 Hz into a ring of 2 that the 10 Hz recorder drains: most scans drop for the recorder, counted.
class LidarSource final : public Stage {
 public:
  static std::unique_ptr<Stage> make() { return std::make_unique<LidarSource>(); }
  Status init(StageContext& ctx) override {
    auto w = ctx.channels.ring_writer(chan::kLidarScan);
    if (!w) return w.error();
    out_ = w.value();
    msg_ = std::make_unique<LidarScanMsg>();
    msg_->count = static_cast<std::uint32_t>(g_scan_points);
    msg_->sensor_in_body.z = 0.6;
    for (std::size_t k = 0; k < g_scan_points; ++k) {
      ScanReturn& p = msg_->points[k];
      p.col = static_cast<std::uint16_t>(k % 1024);
      p.ring = static_cast<std::uint16_t>(k / 1024);
      p.x = static_cast<float>(std::cos(static_cast<double>(k) * 0.37) * 10.0 + static_cast<double>(k % 7));
      p.y = static_cast<float>(std::sin(static_cast<double>(k) * 0.53) * 10.0);
      p.z = static_cast<float>(k % 13) * 0.1f;
      p.range = std::hypot(p.x, p.y);
    }
    return ok_status();
  }
  void step(TimeNs now) noexcept override {
    msg_->stamp = msg_->published = now;
    ++msg_->seq;
    msg_->points[0].x = static_cast<float>(msg_->seq);  // no two scans alike
    (void)out_.push(*msg_);
    ++g_published.lidar;
  }

 private:
  RingWriter<LidarScanMsg, kLidarRing> out_;
  std::unique_ptr<LidarScanMsg> msg_;
};

class TileSource final : public Stage {
 public:
  static std::unique_ptr<Stage> make() { return std::make_unique<TileSource>(); }
  Status init(StageContext& ctx) override {
    auto w = ctx.channels.ring_writer(chan::kMapTiles);
    if (!w) return w.error();
    out_ = w.value();
    return ok_status();
  }
  void step(TimeNs now) noexcept override {
    msg_.stamp = msg_.published = now;
    msg_.tx = static_cast<std::int32_t>(g_published.tiles % 8);
    msg_.ty = -3;
    ++msg_.version;
    msg_.cls.fill(static_cast<std::uint8_t>(g_published.tiles % 7));
    msg_.elevation.fill(static_cast<float>(g_published.tiles));
    (void)out_.push(msg_);
    ++g_published.tiles;
  }

 private:
  RingWriter<MapTileMsg, kMapTileRing> out_;
  MapTileMsg msg_{};
};

class PoseSource final : public Stage {
 public:
  static std::unique_ptr<Stage> make() { return std::make_unique<PoseSource>(); }
  Status init(StageContext& ctx) override {
    auto w = ctx.channels.latest_writer(chan::kLocalization);
    if (!w) return w.error();
    out_ = w.value();
    return ok_status();
  }
  void step(TimeNs now) noexcept override {
    msg_.stamp = msg_.published = now;
    msg_.status = LocalizationStatus::kTracking;
    msg_.pose.x += 0.1;
    out_.publish(msg_);
    ++g_published.poses;
  }

 private:
  LatestWriter<LocalizationMsg> out_;
  LocalizationMsg msg_{};
};

// The quadrotor's camera: 640x400 RGB, a horizontal ramp (red = column / 2.5) that the recorder's 2x2
// averaging keeps.
class CameraSource final : public Stage {
 public:
  static std::unique_ptr<Stage> make() { return std::make_unique<CameraSource>(); }
  Status init(StageContext& ctx) override {
    auto w = ctx.channels.ring_writer(chan::kCamera);
    if (!w) return w.error();
    out_ = w.value();
    msg_ = std::make_unique<CameraImageMsg>();
    for (std::size_t k = 0; k < kImagePixels; ++k) {
      msg_->rgb[k * 3] = static_cast<std::uint8_t>(static_cast<double>(k % kImageWidth) / 2.5);
      msg_->rgb[k * 3 + 1] = 100;
      msg_->rgb[k * 3 + 2] = 200;
    }
    return ok_status();
  }
  void step(TimeNs now) noexcept override {
    msg_->stamp = msg_->published = now;
    ++msg_->seq;
    (void)out_.push(*msg_);
    ++g_published.images;
  }

 private:
  RingWriter<CameraImageMsg, kCameraRing> out_;
  std::unique_ptr<CameraImageMsg> msg_;
};

inline std::unique_ptr<Stage> make_test_recorder() { return std::make_unique<RecorderStage>("test"); }

constexpr ParamSpec kDatumParams[] = {
    ParamSpec::real("datum_lat_deg", 47.0, -90.0, 90.0, "deg", "datum latitude"),
    ParamSpec::real("datum_lon_deg", 8.0, -180.0, 180.0, "deg", "datum longitude"),
    ParamSpec::real("datum_height_m", 400.0, -1000.0, 10000.0, "m", "datum height"),
};
constexpr ParamSection kSections[] = {{"gps", kDatumParams, "the datum the GPS fixes are placed around"}};

// name, factory, rate [Hz], budget [µs], priority, CPU, parameters, what it does
constexpr StageSpec kStages[] = {
    {"status", &StatusStage::make, 1.0, 2'000, 10, -1, StatusStage::kParams, "scheduler counters"},
    {"odometry", &OdometrySource::make, 50.0, 1'000, 50, -1, {}, "wheel odometry"},
    {"gps", &GpsSource::make, 20.0, 1'000, 40, -1, {}, "fixes"},
    {"lidar", &LidarSource::make, 50.0, 5'000, 45, -1, {}, "revolutions, faster than the recorder drains them"},
    {"tiles", &TileSource::make, 20.0, 1'000, 30, -1, {}, "map tiles"},
    {"localization", &PoseSource::make, 10.0, 1'000, 35, -1, {}, "the robot's pose"},
    {"camera", &CameraSource::make, 5.0, 5'000, 44, -1, {}, "camera images"},
    {"recorder", &make_test_recorder, 10.0, 50'000, 1, -1, RecorderStage::kUgvParams, "the recorder under test"},
};
static_assert(role_table_ok(kStages));
inline const RoleDescription kRole{"test", "synthetic sources and the recorder", kStages, kSections};

struct Run {
  std::unique_ptr<Config> config;  // outlives the robot
  std::unique_ptr<RoleInstance> robot;
  recording::RecorderCounters counters;
};

// Builds the role with `sets` ("recorder.path=...") and runs it for `seconds` of simulated time.
inline Result<Run> run_role(const std::vector<std::string>& sets, double seconds, LockstepExecutor::TraceFn trace = nullptr,
                            void* trace_user = nullptr) {
  g_published = {};
  auto cfg = std::make_unique<Config>(Config::defaults(role_schema(kRole)));
  for (const std::string& s : sets)
    if (Status st = cfg->set(s); !st) return st.error();
  static SimClock clock;
  auto r = RoleInstance::create(kRole, *cfg, clock, "rob1");
  if (!r) return r.error();
  Run run{std::move(cfg), std::move(r).value(), {}};
  LockstepExecutor ex(clock);
  ex.add(*run.robot);
  if (trace != nullptr) ex.set_trace(trace, trace_user);
  ex.start(clock.now());
  ex.run_until(clock.now() + from_seconds(seconds));
  run.robot->stop_all();  // closes the last file
  if (const RecorderStage* rec = find_stage<RecorderStage>(run.robot.get())) run.counters = rec->counters();
  return run;
}

}  // namespace ag::test
