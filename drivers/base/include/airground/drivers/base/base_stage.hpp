// The base stage: the ground robot's wheels. Every step it reads the e-stop line (an asserted or
// unreadable e-stop zeroes the wheels in that same step and latches until released and re-armed on
// "base_arm" or "radio_arm"), takes the newest "wheel_command", runs the CAN driver (watchdog: zero velocity when no
// fresh command arrived within command_timeout_s), publishes the wheel odometry and "base_status", and
// drives the status LED (on: running, slow blink: fault, fast blink: e-stop).
// Backends: CAN over SocketCAN, the cannelloni CAN-over-UDP bridge, a recorded candump log (replay:
// the controllers' frames are handed out at their recorded times and the driver only listens, so the
// odometry of the recorded run is reproduced), or the simulator's in-process link; e-stop and LED over
// libgpiod, the simulator's fake lines, or none. Any backend's traffic can be recorded as a candump log
// (can_record_path) and the odometry written as CSV (odometry_log_path).
// A CAN interface or GPIO chip that is missing at start-up does not stop the robot: it is logged,
// counted (device_errors), the wheels stay stopped (base_status: fault "CAN bus refused to send", or
// the e-stop unreadable), and localization and the radio relay keep running. A replay log that cannot
// be read is a configuration error.
#pragma once

#include <array>
#include <cstdio>
#include <memory>
#include <span>
#include <string>

#include "airground/messages/channels.hpp"
#include "airground/messages/drive_messages.hpp"
#include "airground/messages/messages.hpp"
#include "airground/drivers/can/candump_log.hpp"
#include "airground/drivers/base/diff_drive_base.hpp"
#include "airground/drivers/gpio/estop.hpp"
#include "airground/drivers/gpio/gpio_line.hpp"
#include "airground/platform/param_binding.hpp"
#include "airground/platform/stage.hpp"

namespace ag::base {

// What the motor controllers send (heartbeats, encoder estimates), not the driver's own commands: what
// a replayed log feeds back to the driver.
[[nodiscard]] bool frame_from_controller(const can::CanFrame& f) noexcept;

// The base stage's own parameters (the wheels' follow: kBaseFields).
struct BaseStageSettings {
  std::string can_backend{"socketcan"};
  std::string can_interface{"can0"};
  std::string can_replay_path;
  int can_bridge_port{20000};
  std::string can_bridge_remote{"127.0.0.1:20000"};
  std::string can_record_path;
  std::string odometry_log_path;
  std::string estop_backend{"gpiod"};
  std::string estop_chip{"gpiochip0"};
  int estop_line{17};
  bool estop_active_low{true};
  bool start_armed{false};
  std::string led_backend{"gpiod"};
  std::string led_chip{"gpiochip0"};
  int led_line{27};
  std::string odometry_channel{chan::kWheelOdometry.name};
};
inline constexpr ParamField<BaseStageSettings> kBaseStageOwnFields[] = {
    field::text("can_backend", &BaseStageSettings::can_backend, "socketcan", "socketcan|cannelloni|replay|sim", "CAN bus: SocketCAN (the robot), the cannelloni UDP bridge, a recorded candump log, or the simulator's ODrives (in-process)"),
    field::text("can_interface", &BaseStageSettings::can_interface, "can0", "", "SocketCAN interface of the motor controllers"),
    field::text("can_replay_path", &BaseStageSettings::can_replay_path, "", "", "candump log replayed when can_backend is replay"),
    field::integer("can_bridge_port", &BaseStageSettings::can_bridge_port, 0, 65535, "", "local UDP port of the cannelloni bridge"),
    field::text("can_bridge_remote", &BaseStageSettings::can_bridge_remote, "127.0.0.1:20000", "", "HOST:PORT of the bridge's other end (cannelloni)"),
    field::text("can_record_path", &BaseStageSettings::can_record_path, "", "", "record every frame sent and received as a candump log (empty: off)"),
    field::text("odometry_log_path", &BaseStageSettings::odometry_log_path, "", "", "write the wheel odometry as CSV (stamp_ns,x_m,y_m,yaw_rad,v_mps,w_radps; empty: off)"),
    field::text("estop_backend", &BaseStageSettings::estop_backend, "gpiod", "gpiod|fake|none", "e-stop input: libgpiod, the simulator's fake line, or none"),
    field::text("estop_chip", &BaseStageSettings::estop_chip, "gpiochip0", "", "GPIO chip of the e-stop input (name, path or number)"),
    field::integer("estop_line", &BaseStageSettings::estop_line, 0, 1023, "", "line offset of the e-stop input"),
    field::boolean("estop_active_low", &BaseStageSettings::estop_active_low, "the e-stop input is active low (a pressed button pulls it to ground)"),
    field::boolean("start_armed", &BaseStageSettings::start_armed, "drive without an operator's arm after start-up (false: wait for base_arm)"),
    field::text("led_backend", &BaseStageSettings::led_backend, "gpiod", "gpiod|fake|none", "status LED output: libgpiod, the simulator's fake line, or none"),
    field::text("led_chip", &BaseStageSettings::led_chip, "gpiochip0", "", "GPIO chip of the status LED"),
    field::integer("led_line", &BaseStageSettings::led_line, 0, 1023, "", "line offset of the status LED"),
    field::text("odometry_channel", &BaseStageSettings::odometry_channel, chan::kWheelOdometry.name, "", "ring channel the wheel odometry is published on"),
};
inline constexpr auto kBaseStageParamArray = param_specs(kBaseStageOwnFields, kBaseFields);

struct BaseStageCounters {
  std::uint64_t commands_in{0};
  std::uint64_t commands_non_finite{0};
  std::uint64_t arm_requests{0};
  std::uint64_t led_errors{0};
  std::uint64_t odometry_ring_full{0};
  std::uint64_t device_errors{0};  // a CAN interface or GPIO line that could not be opened at start-up
  std::uint64_t silence_warnings{0};  // "no odometry for a few seconds" warnings logged
};

class BaseStage final : public Stage {
 public:
  static constexpr std::span<const ParamSpec> kParams{kBaseStageParamArray};
  static std::unique_ptr<Stage> make() { return std::make_unique<BaseStage>(); }

  BaseStage() = default;
  ~BaseStage() override;
  Status init(StageContext& ctx) override;
  void step(TimeNs now) noexcept override;
  void stop() noexcept override;

  [[nodiscard]] const DiffDriveBase& base() const noexcept { return *base_; }
  [[nodiscard]] const gpio::EStopLatch& estop() const noexcept { return latch_; }
  [[nodiscard]] const BaseStatusMsg& published() const noexcept { return status_; }
  [[nodiscard]] const BaseStageCounters& counters() const noexcept { return c_; }
  [[nodiscard]] const can::CanBus& bus() const noexcept { return *bus_; }
  [[nodiscard]] bool replaying() const noexcept { return replay_ != nullptr; }
  [[nodiscard]] bool replay_finished() const noexcept { return replay_ != nullptr && replay_->finished(); }

 private:
  std::unique_ptr<can::CanBus> owned_bus_, recording_bus_;
  can::CanBus* bus_{nullptr};
  can::CandumpReplayBus* replay_{nullptr};
  std::unique_ptr<can::CandumpWriter> recorder_;
  std::FILE* odom_log_{nullptr};
  std::unique_ptr<char[]> odom_log_buf_;
  bool replay_end_logged_{false};
  std::unique_ptr<DiffDriveBase> base_;
  std::unique_ptr<gpio::DigitalLine> owned_estop_, owned_led_;
  gpio::DigitalLine* estop_line_{nullptr};
  bool estop_missing_{false};  // the e-stop line could not be opened: read as unreadable (stopped)
  gpio::DigitalLine* led_{nullptr};
  gpio::EStopLatch latch_{false};
  LatestReader<WheelCommandMsg> cmd_;
  LatestReader<BaseArmMsg> arm_, radio_arm_;
  RingWriter<WheelOdometryMsg, kWheelOdometryRing> odom_out_;
  LatestWriter<BaseStatusMsg> status_out_;
  BaseStatusMsg status_{};
  TimeNs last_cmd_stamp_{-1}, last_arm_stamp_{-1}, last_radio_arm_stamp_{-1};
  bool started_{false};
  BaseStageCounters c_;
  void note_device(TimeNs now) noexcept;
  DeviceCounters own_device_;
  DeviceCounters* device_{&own_device_};
  DeviceSilence silence_;
  std::uint64_t rx_at_last_sample_{0};
  std::uint8_t left_node_{0}, right_node_{1};
};

}  // namespace ag::base
