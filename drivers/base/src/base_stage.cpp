// The base stage: e-stop, wheel commands, the CAN driver, odometry, status, LED.
#include "airground/drivers/base/base_stage.hpp"

#include <cmath>
#include <string>

#include "airground/drivers/can/inprocess_bus.hpp"
#include "airground/drivers/can/socketcan_bus.hpp"
#include "airground/platform/log.hpp"

namespace ag::base {

Status BaseStage::init(StageContext& ctx) {
  const SectionView v = ctx.params();
  const std::string where = std::string(ctx.stage_name) + ".";
  const BaseParams bp = load_base_params(v);
  if (bp.left_node == bp.right_node)
    return Error::make(ErrorCode::kConfig, "config error: " + where + "left_node_id and right_node_id must differ");
  if (v.text("can_backend") == "inprocess") {
    can::InProcessCanLink* link = can::find_inprocess_link(ctx.instance);
    if (link == nullptr)
      return Error::make(ErrorCode::kConfig, "config error: " + where + "can_backend is inprocess but the simulator gave robot '" +
                                                 std::string(ctx.instance) + "' no CAN link");
    bus_ = &link->robot();
  } else {
    auto b = can::SocketCanBus::open(v.text("can_interface"));
    if (!b) return Error::make(b.error().code, where + "can_interface: " + b.error().message);
    owned_bus_ = std::move(b).value();
    bus_ = owned_bus_.get();
  }
  base_ = std::make_unique<DiffDriveBase>(bp, *bus_);
  auto open_line = [&](const std::string& backend, const char* name, const std::string& chip, std::int64_t line, bool active_low,
                       gpio::Direction dir, std::unique_ptr<gpio::DigitalLine>& owned, gpio::DigitalLine*& out) -> Status {
    out = nullptr;
    if (backend == "none") return ok_status();
    if (backend == "fake") {
      out = gpio::find_fake_line(ctx.instance, name);
      if (out == nullptr)
        return Error::make(ErrorCode::kConfig, "config error: " + where + name + "_backend is fake but robot '" + std::string(ctx.instance) +
                                                   "' has no fake '" + name + "' line");
      return ok_status();
    }
    auto l = gpio::open_gpiod_line(chip, static_cast<unsigned>(line), dir, active_low, "airground-" + std::string(name));
    if (!l) return Error::make(l.error().code, where + name + ": " + l.error().message);
    owned = std::move(l).value();
    out = owned.get();
    return ok_status();
  };
  if (Status s = open_line(v.text("estop_backend"), "estop", v.text("estop_chip"), v.integer("estop_line"), v.boolean("estop_active_low"),
                           gpio::Direction::kInput, owned_estop_, estop_line_);
      !s)
    return s;
  if (Status s = open_line(v.text("led_backend"), "led", v.text("led_chip"), v.integer("led_line"), false, gpio::Direction::kOutput, owned_led_, led_);
      !s)
    return s;
  latch_ = gpio::EStopLatch(v.boolean("start_armed"));

  auto cmd = ctx.channels.latest_reader<WheelCommandMsg>("wheel_command");
  if (!cmd) return cmd.error();
  cmd_ = cmd.value();
  auto arm = ctx.channels.latest_reader<BaseArmMsg>("base_arm");
  if (!arm) return arm.error();
  arm_ = arm.value();
  auto odom = ctx.channels.ring_writer<WheelOdometryMsg, kWheelOdometryRing>(v.text("odometry_channel"));
  if (!odom) return odom.error();
  odom_out_ = odom.value();
  auto st = ctx.channels.latest_writer<BaseStatusMsg>("base_status");
  if (!st) return st.error();
  status_out_ = st.value();
  return ok_status();
}

void BaseStage::step(TimeNs now) noexcept {
  if (!started_) {
    started_ = true;
    base_->arm(now);
  }
  // Operator arm / re-arm.
  bool rearm = false;
  if (arm_.fresh()) {
    const BaseArmMsg& a = arm_.read();
    if (a.stamp != last_arm_stamp_) {
      last_arm_stamp_ = a.stamp;
      ++c_.arm_requests;
      if (a.arm) {
        rearm = true;
        if (base_->status().state == BaseState::kFault || base_->status().state == BaseState::kDisarmed) base_->arm(now);
      } else {
        base_->disarm(now);
      }
    }
  }
  // The e-stop first: it acts in this very step.
  bool asserted = false;
  const bool line_ok = estop_line_ == nullptr || estop_line_->get(asserted) == gpio::LineResult::kOk;
  const gpio::EStopState before = latch_.state();
  const bool stopped = latch_.update(line_ok, estop_line_ != nullptr && asserted, rearm);
  if (latch_.state() != before) AG_LOG_WARN("base", "e-stop %s", gpio::to_string(latch_.state()));
  if (cmd_.fresh()) {
    const WheelCommandMsg& m = cmd_.read();
    if (m.stamp != last_cmd_stamp_) {
      last_cmd_stamp_ = m.stamp;
      ++c_.commands_in;
      if (!std::isfinite(m.left_mps) || !std::isfinite(m.right_mps)) ++c_.commands_non_finite;
      base_->command(m.left_mps, m.right_mps, now);
    }
  }
  base_->set_inhibit(stopped);
  base_->step(now);
  WheelOdometryMsg o;
  while (base_->take_odometry(o)) {
    o.published = now;
    if (odom_out_.push(o) != 0) ++c_.odometry_ring_full;
  }
  if (led_ != nullptr) {
    const BaseState s = base_->status().state;
    const gpio::LedPattern p = stopped                     ? gpio::LedPattern::kFastBlink
                               : s == BaseState::kFault    ? gpio::LedPattern::kSlowBlink
                               : s == BaseState::kRunning  ? gpio::LedPattern::kOn
                                                           : gpio::LedPattern::kOff;
    if (led_->set(gpio::led_level(p, now)) != gpio::LineResult::kOk) ++c_.led_errors;
  }
  const BaseStatus& bs = base_->status();
  const double per_turn = 2.0 * kPi * base_->params().wheel_radius_m / base_->params().gear_ratio;
  status_.stamp = now;
  status_.published = now;
  status_.state = static_cast<std::uint8_t>(bs.state);
  status_.fault = static_cast<std::uint8_t>(bs.fault);
  status_.fault_node = bs.fault_node;
  status_.fault_axis_error = bs.fault_axis_error;
  status_.estop = static_cast<std::uint8_t>(latch_.state());
  status_.left_cmd_mps = static_cast<double>(base_->sent_velocity(0)) * per_turn * base_->params().left_sign;
  status_.right_cmd_mps = static_cast<double>(base_->sent_velocity(1)) * per_turn * base_->params().right_sign;
  status_.watchdog_trips = base_->counters().watchdog_trips;
  status_.estop_assertions = latch_.assertions();
  status_out_.publish(status_);
}

void BaseStage::stop() noexcept {
  if (base_ != nullptr) base_->disarm(0);
  if (led_ != nullptr) (void)led_->set(false);
}

}  // namespace ag::base
