// The base stage: e-stop, wheel commands, the CAN driver, odometry, status, LED.
#include "airground/drivers/base/base_stage.hpp"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <string>

#include "airground/drivers/base/odrive_can_simple.hpp"
#include "airground/drivers/can/cannelloni.hpp"
#include "airground/drivers/can/inprocess_bus.hpp"
#include "airground/drivers/can/socketcan_bus.hpp"
#include "airground/messages/channels.hpp"
#include "airground/platform/log.hpp"

namespace ag::base {

namespace {
constexpr std::size_t kOdomLogBuffer = 64 * 1024;  // one write(2) per ~1,000 samples
}  // namespace

bool frame_from_controller(const can::CanFrame& f) noexcept {
  const std::uint8_t c = odrive::cmd_of(f.id);
  return c == static_cast<std::uint8_t>(odrive::Cmd::kHeartbeat) || c == static_cast<std::uint8_t>(odrive::Cmd::kGetEncoderEstimates);
}

BaseStage::~BaseStage() {
  if (odom_log_ != nullptr) std::fclose(odom_log_);
}

Status BaseStage::init(StageContext& ctx) {
  const SectionView v = ctx.params();
  const std::string where = std::string(ctx.stage_name) + ".";
  const BaseParams bp = load_base_params(v);
  const BaseStageSettings cfg = load_params(v, kBaseStageOwnFields);
  if (bp.left_node == bp.right_node)
    return Error::make(ErrorCode::kConfig, "config error: " + where + "left_node_id and right_node_id must differ");
  const std::string can_backend = cfg.can_backend;
  if (ctx.device != nullptr) device_ = ctx.device;
  device_->describe("samples", {"rx_errors", "error_frames", "tx_dropped", "ring_full"});
  left_node_ = bp.left_node;
  right_node_ = bp.right_node;
  if (can_backend == "sim") {
    can::InProcessCanLink* link = can::find_inprocess_link(ctx.instance);
    if (link == nullptr)
      return Error::make(ErrorCode::kConfig, "config error: " + where + "can_backend is sim but the simulator gave robot '" +
                                                 std::string(ctx.instance) + "' no CAN link");
    bus_ = &link->robot();
  } else if (can_backend == "replay") {
    const std::string path = cfg.can_replay_path;
    if (path.empty()) return Error::make(ErrorCode::kConfig, "config error: " + where + "can_backend is replay but can_replay_path is empty");
    auto log = can::read_candump_file(path);
    if (!log) return Error::make(log.error().code, where + "can_replay_path: " + log.error().message);
    if (log.value().records.empty())
      return Error::make(ErrorCode::kConfig, "config error: " + where + "can_replay_path: " + path + " holds no frames" +
                                                 (log.value().first_error.empty() ? "" : " (" + log.value().first_error + ")"));
    if (log.value().bad_lines > 0)
      AG_LOG_WARN("base", "%s: %zu bad lines skipped, first: %s", path.c_str(), log.value().bad_lines, log.value().first_error.c_str());
    const std::size_t n = log.value().records.size();
    // Only what the controllers said: the driver's own recorded commands are not fed back to it.
    auto r = std::make_unique<can::CandumpReplayBus>(std::move(log).value().records, ctx.clock, ctx.clock.now(), &frame_from_controller);
    AG_LOG_INFO("base", "replaying %zu frames (%.1f s) from %s", n, to_seconds(r->log_end() - r->log_start()), path.c_str());
    replay_ = r.get();
    owned_bus_ = std::move(r);
    bus_ = owned_bus_.get();
  } else if (can_backend == "cannelloni") {
    can::CannelloniConfig cc;
    cc.local_port = static_cast<std::uint16_t>(cfg.can_bridge_port);
    const std::string remote = cfg.can_bridge_remote;
    const auto colon = remote.rfind(':');
    char* end = nullptr;
    const long port = colon == std::string::npos ? -1 : std::strtol(remote.c_str() + colon + 1, &end, 10);
    if (colon == std::string::npos || colon == 0 || end == nullptr || *end != '\0' || port <= 0 || port > 65535)
      return Error::make(ErrorCode::kConfig, "config error: " + where + "can_bridge_remote '" + remote + "' is not HOST:PORT");
    cc.remote_address = remote.substr(0, colon);
    cc.remote_port = static_cast<std::uint16_t>(port);
    auto b = can::CannelloniBus::open(cc);
    if (!b) return Error::make(b.error().code, where + "can_bridge_port: " + b.error().message);
    owned_bus_ = std::move(b).value();
    bus_ = owned_bus_.get();
  } else {
    auto b = can::SocketCanBus::open(cfg.can_interface);
    if (b) {
      owned_bus_ = std::move(b).value();
    } else {
      // The robot keeps localizing and relaying; its wheels stay stopped and base_status says why.
      AG_LOG_ERROR("base", "%scan_interface: %s; the wheels stay stopped until the service restarts with the interface up", where.c_str(),
                   b.error().message.c_str());
      ++c_.device_errors;
      owned_bus_ = std::make_unique<can::AbsentCanBus>();
    }
    bus_ = owned_bus_.get();
  }
  if (const std::string rec = cfg.can_record_path; !rec.empty()) {
    auto w = can::CandumpWriter::create(rec, can_backend == "socketcan" ? cfg.can_interface : "can0");
    if (!w) return Error::make(w.error().code, where + "can_record_path: " + w.error().message);
    recorder_ = std::move(w).value();
    recording_bus_ = std::make_unique<can::RecordingCanBus>(*bus_, *recorder_, ctx.clock);
    bus_ = recording_bus_.get();
  }
  if (const std::string odo = cfg.odometry_log_path; !odo.empty()) {
    odom_log_ = std::fopen(odo.c_str(), "w");
    if (odom_log_ == nullptr) return Error::make(ErrorCode::kIo, where + "odometry_log_path: cannot write " + odo + ": " + std::strerror(errno));
    odom_log_buf_ = std::make_unique<char[]>(kOdomLogBuffer);
    (void)std::setvbuf(odom_log_, odom_log_buf_.get(), _IOFBF, kOdomLogBuffer);
    std::fputs("stamp_ns,x_m,y_m,yaw_rad,v_mps,w_radps\n", odom_log_);
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
    if (!l) {  // logged and counted; a missing e-stop reads as unreadable, so the wheels stay stopped
      AG_LOG_ERROR("base", "%s%s: %s%s", where.c_str(), name, l.error().message.c_str(),
                   dir == gpio::Direction::kInput ? "; the e-stop reads as unreadable: the wheels stay stopped" : "; no status LED");
      ++c_.device_errors;
      if (dir == gpio::Direction::kInput) estop_missing_ = true;
      return ok_status();
    }
    owned = std::move(l).value();
    out = owned.get();
    return ok_status();
  };
  if (Status s = open_line(cfg.estop_backend, "estop", cfg.estop_chip, cfg.estop_line, cfg.estop_active_low,
                           gpio::Direction::kInput, owned_estop_, estop_line_);
      !s)
    return s;
  if (Status s = open_line(cfg.led_backend, "led", cfg.led_chip, cfg.led_line, false, gpio::Direction::kOutput, owned_led_, led_);
      !s)
    return s;
  latch_ = gpio::EStopLatch(cfg.start_armed);

  auto cmd = ctx.channels.latest_reader(chan::kWheelCommand);
  if (!cmd) return cmd.error();
  cmd_ = cmd.value();
  auto arm = ctx.channels.latest_reader(chan::kBaseArm);
  if (!arm) return arm.error();
  arm_ = arm.value();
  ctx.channels.allow_unwritten(chan::kBaseArm);  // optional: an operator's re-arm request, when a tool sends one
  auto radio_arm = ctx.channels.latest_reader(chan::kRadioArm);
  if (!radio_arm) return radio_arm.error();
  radio_arm_ = radio_arm.value();
  ctx.channels.allow_unwritten(chan::kRadioArm);  // optional: the base station's arm over the radio (comms)
  auto odom = ctx.channels.ring_writer(chan::kWheelOdometry.with_name(cfg.odometry_channel));
  if (!odom) return odom.error();
  odom_out_ = odom.value();
  auto st = ctx.channels.latest_writer(chan::kBaseStatus);
  if (!st) return st.error();
  status_out_ = st.value();
  return ok_status();
}

void BaseStage::step(TimeNs now) noexcept {
  if (!started_) {
    started_ = true;
    base_->arm(now);
  }
  // Operator arm / re-arm: a tool on the robot, or the base station over the radio.
  bool rearm = false;
  const auto take_arm = [&](LatestReader<BaseArmMsg>& in, TimeNs& last, const char* from) {
    if (!in.fresh()) return;
    const BaseArmMsg& a = in.read();
    if (a.stamp == last) return;
    last = a.stamp;
    ++c_.arm_requests;
    AG_LOG_INFO("base", "%s from %s", a.arm ? "arm" : "disarm", from);
    if (a.arm) {
      rearm = true;
      if (base_->status().state == BaseState::kFault || base_->status().state == BaseState::kDisarmed) base_->arm(now);
    } else {
      base_->disarm(now);
    }
  };
  take_arm(arm_, last_arm_stamp_, "base_arm");
  take_arm(radio_arm_, last_radio_arm_stamp_, "the base station (radio)");
  // The e-stop first: it acts in this very step.
  bool asserted = false;
  const bool line_ok = !estop_missing_ && (estop_line_ == nullptr || estop_line_->get(asserted) == gpio::LineResult::kOk);
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
  if (replay_ != nullptr) {  // the recorded controllers talk; the driver listens (nothing to arm or command)
    base_->receive_only(now);
    if (replay_->finished() && !replay_end_logged_) {
      replay_end_logged_ = true;
      AG_LOG_INFO("base", "replay finished: %llu frames", static_cast<unsigned long long>(replay_->counters().rx));
    }
  } else {
    base_->step(now);
  }
  WheelOdometryMsg o;
  while (base_->take_odometry(o)) {
    o.published = now;
    device_->unit_received(true, now);
    if (bus_ != nullptr) rx_at_last_sample_ = bus_->counters().rx;
    if (odom_out_.push(o) != 0) ++c_.odometry_ring_full;
    if (odom_log_ != nullptr)
      std::fprintf(odom_log_, "%lld,%.17g,%.17g,%.17g,%.17g,%.17g\n", static_cast<long long>(o.stamp), o.pose.x, o.pose.y, o.pose.yaw, o.v_mps,
                   o.w_radps);
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
  note_device(now);
}

// The stage's device counters (bytes: received frames as 16-byte SocketCAN frames), and one warning when
// the controllers give no odometry for a few seconds.
void BaseStage::note_device(TimeNs now) noexcept {
  if (bus_ == nullptr) return;
  const can::CanBusCounters& b = bus_->counters();
  device_->error_total(0, b.rx_errors);
  device_->error_total(1, b.error_frames);
  device_->error_total(2, b.tx_dropped);
  device_->error_total(3, c_.odometry_ring_full);
  device_->bytes.store(b.rx * 16u, std::memory_order_relaxed);
  if ((replay_ != nullptr && replay_->finished()) || !silence_.check(*device_, now)) return;
  ++c_.silence_warnings;
  const double s = static_cast<double>(silence_.silent_for(now)) * 1e-9;
  if (b.rx == rx_at_last_sample_)
    AG_LOG_WARN("base", "no wheel odometry for %.0f s: no CAN frames at all (interface down, wrong bitrate, controllers unpowered)", s);
  else
    AG_LOG_WARN("base", "no wheel odometry for %.0f s: %llu CAN frames but no encoder estimates from nodes %u/%u "
                "(wrong node ids: base.left_node_id, base.right_node_id)", s,
                static_cast<unsigned long long>(b.rx - rx_at_last_sample_), static_cast<unsigned>(left_node_), static_cast<unsigned>(right_node_));
}

void BaseStage::stop() noexcept {
  if (base_ != nullptr) base_->disarm(0);
  if (led_ != nullptr) (void)led_->set(false);
  if (recorder_ != nullptr) recorder_->flush();
  if (odom_log_ != nullptr) std::fflush(odom_log_);
}

}  // namespace ag::base
