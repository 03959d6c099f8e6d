// Differential-drive base over CAN Simple: arming, watchdog, fault detection, wheel odometry.
#include "airground/drivers/base/diff_drive_base.hpp"

#include <algorithm>
#include <cmath>

#include "airground/messages/geometry.hpp"
#include "airground/platform/log.hpp"

namespace ag::base {

BaseParams load_base_params(const SectionView& s) {
  BaseParams p = load_params(s, kBaseFields);
  p.left_sign = p.left_sign < 0 ? -1 : 1;
  p.right_sign = p.right_sign < 0 ? -1 : 1;
  return p;
}

const char* to_string(BaseState s) noexcept {
  switch (s) {
    case BaseState::kDisarmed: return "disarmed";
    case BaseState::kArming: return "arming";
    case BaseState::kRunning: return "running";
    case BaseState::kFault: return "fault";
  }
  return "?";
}
const char* to_string(BaseFault f) noexcept {
  switch (f) {
    case BaseFault::kNone: return "none";
    case BaseFault::kAxisError: return "axis error reported in the heartbeat";
    case BaseFault::kControllerSilent: return "controller silent (no heartbeat)";
    case BaseFault::kLeftClosedLoop: return "axis left closed-loop control";
    case BaseFault::kArmTimeout: return "closed loop not reached after arming";
    case BaseFault::kBusDown: return "CAN bus refused to send";
  }
  return "?";
}

DiffDriveBase::DiffDriveBase(const BaseParams& p, can::CanBus& bus) noexcept : p_(p), bus_(bus) {
  ax_[0].node = p.left_node;
  ax_[0].sign = p.left_sign;
  ax_[1].node = p.right_node;
  ax_[1].sign = p.right_sign;
}

void DiffDriveBase::send(const can::CanFrame& f, TimeNs now) noexcept {
  if (bus_.send(f) != can::CanResult::kOk) {
    ++c_.tx_failed;
    if (st_.state == BaseState::kRunning || st_.state == BaseState::kArming) fault(BaseFault::kBusDown, nullptr, 0, now);
  }
}

void DiffDriveBase::arm(TimeNs now) noexcept {
  st_ = BaseStatus{};
  st_.state = BaseState::kArming;
  arm_time_ = now;
  cmd_time_ = -1;
  for (Axis& a : ax_) {
    a.last_heartbeat = now;
    a.seen_closed_loop = false;
    send(odrive::encode_set_controller_mode(a.node, odrive::kControlModeVelocity, odrive::kInputModePassthrough), now);
    send(odrive::encode_set_input_vel(a.node, 0.0F), now);
    send(odrive::encode_set_axis_state(a.node, odrive::AxisState::kClosedLoopControl), now);
  }
  AG_LOG_INFO("base", "arming nodes %u and %u", static_cast<unsigned>(ax_[0].node), static_cast<unsigned>(ax_[1].node));
}

void DiffDriveBase::disarm(TimeNs now) noexcept {
  for (Axis& a : ax_) {
    send(odrive::encode_set_input_vel(a.node, 0.0F), now);
    send(odrive::encode_set_axis_state(a.node, odrive::AxisState::kIdle), now);
  }
  sent_ = {0.0F, 0.0F};
  st_.state = BaseState::kDisarmed;
}

void DiffDriveBase::command(double left_mps, double right_mps, TimeNs now) noexcept {
  ++c_.commands;
  if (!std::isfinite(left_mps) || !std::isfinite(right_mps)) left_mps = right_mps = 0.0;
  cmd_l_ = std::clamp(left_mps, -p_.max_wheel_speed_mps, p_.max_wheel_speed_mps);
  cmd_r_ = std::clamp(right_mps, -p_.max_wheel_speed_mps, p_.max_wheel_speed_mps);
  cmd_time_ = now;
}

bool DiffDriveBase::command_fresh(TimeNs now) const noexcept {
  return cmd_time_ >= 0 && now - cmd_time_ <= from_seconds(p_.command_timeout_s);
}

void DiffDriveBase::fault(BaseFault f, const Axis* a, std::uint32_t axis_error, TimeNs now) noexcept {
  if (st_.state == BaseState::kFault) return;
  st_.state = BaseState::kFault;
  st_.fault = f;
  st_.fault_node = a != nullptr ? a->node : 0;
  st_.fault_axis_error = axis_error;
  st_.fault_time = now;
  ++c_.faults;
  AG_LOG_ERROR("base", "stopping: %s (node %u, axis error 0x%08x)", to_string(f), static_cast<unsigned>(st_.fault_node),
               static_cast<unsigned>(axis_error));
}

void DiffDriveBase::drain(TimeNs now) noexcept {
  can::CanFrame f;
  while (bus_.receive(f) == can::CanResult::kOk) {
    Axis* a = nullptr;
    for (Axis& x : ax_)
      if (!f.extended && odrive::node_of(f.id) == x.node) a = &x;
    const std::uint8_t cmd = odrive::cmd_of(f.id);
    const bool ours = a != nullptr && (cmd == static_cast<std::uint8_t>(odrive::Cmd::kHeartbeat) ||
                                       cmd == static_cast<std::uint8_t>(odrive::Cmd::kGetEncoderEstimates));
    if (!ours) {
      ++c_.rx_foreign;
      continue;
    }
    odrive::Heartbeat hb;
    odrive::EncoderEstimates ee;
    if (odrive::decode_heartbeat(f, hb)) {
      ++c_.heartbeats;
      a->last_heartbeat = now;
      a->state = hb.axis_state;
      if (hb.axis_state == static_cast<std::uint32_t>(odrive::AxisState::kClosedLoopControl)) a->seen_closed_loop = true;
      if (hb.axis_error != 0 && (st_.state == BaseState::kRunning || st_.state == BaseState::kArming)) fault(BaseFault::kAxisError, a, hb.axis_error, now);
      else if (st_.state == BaseState::kRunning && a->seen_closed_loop &&
               hb.axis_state != static_cast<std::uint32_t>(odrive::AxisState::kClosedLoopControl))
        fault(BaseFault::kLeftClosedLoop, a, hb.axis_error, now);
    } else if (odrive::decode_encoder_estimates(f, ee)) {
      if (!std::isfinite(ee.pos_turns) || !std::isfinite(ee.vel_turns_s)) {
        ++c_.non_finite_estimates;
        continue;
      }
      ++c_.encoder_frames;
      a->pos_turns = static_cast<double>(ee.pos_turns);
      a->vel_turns_s = static_cast<double>(ee.vel_turns_s);
      a->estimate_stamp = f.stamp;
      if (!a->have_estimate) a->prev_pos_turns = a->pos_turns;
      a->have_estimate = true;
      a->fresh_estimate = true;
      if (ax_[0].fresh_estimate && ax_[1].fresh_estimate) integrate();
    } else {
      ++c_.rx_malformed;
    }
  }
}

void DiffDriveBase::integrate() noexcept {
  const double per_turn = 2.0 * kPi * p_.wheel_radius_m / p_.gear_ratio;
  const double dl = (ax_[0].pos_turns - ax_[0].prev_pos_turns) * per_turn * ax_[0].sign;
  const double dr = (ax_[1].pos_turns - ax_[1].prev_pos_turns) * per_turn * ax_[1].sign;
  for (Axis& a : ax_) {
    a.prev_pos_turns = a.pos_turns;
    a.fresh_estimate = false;
  }
  const TimeNs stamp = std::max(ax_[0].estimate_stamp, ax_[1].estimate_stamp);
  const double ds = 0.5 * (dl + dr), dth = (dr - dl) / p_.track_m;
  if (!odom_started_) {
    odom_started_ = true;
  } else {
    const double mid = odom_.pose.yaw + 0.5 * dth;
    odom_.pose.x += ds * std::cos(mid);
    odom_.pose.y += ds * std::sin(mid);
    odom_.pose.yaw = wrap_angle(odom_.pose.yaw + dth);
  }
  const double vl = ax_[0].vel_turns_s * per_turn * ax_[0].sign, vr = ax_[1].vel_turns_s * per_turn * ax_[1].sign;
  odom_.v_mps = 0.5 * (vl + vr);
  odom_.w_radps = (vr - vl) / p_.track_m;
  odom_.moving = std::fabs(dl) + std::fabs(dr) > 1e-6;
  odom_.stamp = stamp;
  odom_.published = stamp;
  ++c_.odometry_samples;
  if (ring_n_ == kRing) {
    ++c_.odometry_dropped;
    ring_head_ = (ring_head_ + 1) % kRing;
    --ring_n_;
  }
  ring_[(ring_head_ + ring_n_) % kRing] = odom_;
  ++ring_n_;
}

bool DiffDriveBase::take_odometry(WheelOdometryMsg& out) noexcept {
  if (ring_n_ == 0) return false;
  out = ring_[ring_head_];
  ring_head_ = (ring_head_ + 1) % kRing;
  --ring_n_;
  return true;
}

void DiffDriveBase::send_velocity(TimeNs now, double left_mps, double right_mps) noexcept {
  const double per_turn = 2.0 * kPi * p_.wheel_radius_m / p_.gear_ratio;
  sent_[0] = static_cast<float>(left_mps / per_turn * ax_[0].sign);
  sent_[1] = static_cast<float>(right_mps / per_turn * ax_[1].sign);
  for (int i = 0; i < 2; ++i) send(odrive::encode_set_input_vel(ax_[static_cast<std::size_t>(i)].node, sent_[static_cast<std::size_t>(i)]), now);
}

void DiffDriveBase::step(TimeNs now) noexcept {
  drain(now);
  if (st_.state == BaseState::kArming || st_.state == BaseState::kRunning) {
    for (const Axis& a : ax_)
      if (now - a.last_heartbeat > from_seconds(p_.heartbeat_timeout_s)) {
        fault(BaseFault::kControllerSilent, &a, 0, now);
        break;
      }
  }
  if (st_.state == BaseState::kArming) {
    if (ax_[0].seen_closed_loop && ax_[1].seen_closed_loop) {
      st_.state = BaseState::kRunning;
      AG_LOG_INFO("base", "both axes in closed-loop control: running");
    } else if (now - arm_time_ > from_seconds(p_.arm_timeout_s)) {
      fault(BaseFault::kArmTimeout, ax_[0].seen_closed_loop ? &ax_[1] : &ax_[0], 0, now);
    }
  }
  const bool fresh = command_fresh(now);
  if (st_.state == BaseState::kRunning && was_fresh_ && !fresh) {
    ++c_.watchdog_trips;
    AG_LOG_WARN("base", "no fresh wheel command for %.0f ms: wheels stopped", p_.command_timeout_s * 1e3);
  }
  was_fresh_ = fresh;
  if (st_.state == BaseState::kRunning && fresh && !inhibit_) send_velocity(now, cmd_l_, cmd_r_);
  else send_velocity(now, 0.0, 0.0);
}

}  // namespace ag::base
