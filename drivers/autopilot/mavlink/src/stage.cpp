// The autopilot stage: MAVLink bytes to checked frames to "attitude" in REP-103.
#include "airground/drivers/autopilot/mavlink/stage.hpp"

#include <cmath>
#include <string>

#include "airground/drivers/autopilot/mavlink/frames.hpp"
#include "airground/messages/channels.hpp"
#include "airground/platform/log.hpp"

namespace ag::mavlink {

namespace {
constexpr std::uint32_t kResetMs = 2000;  // time_boot_ms going back further than this: the autopilot rebooted
constexpr TimeNs kRequestRetry = 5 * kNsPerS;
const char* autopilot_name(std::uint8_t a) noexcept {
  return a == kAutopilotPx4 ? "PX4" : a == kAutopilotArdupilot ? "ArduPilot" : "another autopilot";
}
}  // namespace

// An autopilot that is absent (no device, no recording) does not stop the robot: the stage logs why,
// counts it and publishes nothing (the VO then runs without gravity), like the GNSS stage.
Status AutopilotStage::init(StageContext& ctx) {
  const AutopilotSettings cfg = load_params(ctx.params(), kAutopilotStageFields);
  const std::string where = std::string(ctx.stage_name) + ".";
  auto w = ctx.channels.ring_writer(chan::kAttitude.with_name(cfg.attitude_channel));
  if (!w) return w.error();
  out_ = w.value();
  const std::string& src = cfg.source;
  if (src != "serial" && src != "udp" && src != "replay" && src != "sim" && src != "none")
    return Error::make(ErrorCode::kConfig, "config error: " + where + "source must be serial, udp, replay, sim or none, got '" + src + "'");
  if (src == "replay" && cfg.replay.empty())
    return Error::make(ErrorCode::kConfig, "config error: " + where + "replay is empty but " + where + "source is replay: name the .tlog to play");
  max_bytes_ = cfg.max_bytes_per_step;
  want_sysid_ = cfg.system_id;
  want_compid_ = cfg.component_id;
  latency_ = from_seconds(cfg.latency_s);
  request_hz_ = cfg.request_hz;
  log_every_ = from_seconds(cfg.log_every_s);
  pace_ = cfg.replay_pace;
  buf_.assign(4096, 0);
  if (src == "none") return ok_status();
  auto absent = [&](const std::string& why) {
    ++c_.device_errors;
    AG_LOG_ERROR("autopilot", "%s; no attitude from the autopilot (the robot keeps running)", why.c_str());
    return ok_status();
  };
  if (src == "sim") {
    SimAutopilotLink* sim = find_sim_autopilot(ctx.instance);
    if (sim == nullptr)
      return Error::make(ErrorCode::kConfig, "config error: " + where + "source is sim but the simulator gave robot '" +
                                                 std::string(ctx.instance) + "' no autopilot");
    link_ = sim->open_link();
  } else if (src == "replay") {
    auto r = TlogReplay::open(cfg.replay);
    if (!r) return absent(where + "replay: " + r.error().message);
    link_ = std::move(r).value();
    replay_ = true;
  } else if (src == "udp") {
    auto u = UdpLink::open(cfg.udp_bind, cfg.udp_port);
    if (!u) {
      if (u.error().code == ErrorCode::kConfig) return Error::make(ErrorCode::kConfig, "config error: " + where + "udp_bind: " + u.error().message);
      return absent(where + "udp_port: " + u.error().message);
    }
    link_ = std::move(u).value();
  } else {
    auto s = SerialLink::open(cfg.device, cfg.baud);
    if (!s) {
      if (s.error().code == ErrorCode::kConfig) return Error::make(ErrorCode::kConfig, "config error: " + where + "baud: " + s.error().message);
      return absent(where + "device: " + s.error().message);
    }
    link_ = std::move(s).value();
  }
  return ok_status();
}

void AutopilotStage::on_attitude(std::uint32_t boot_ms, double roll, double pitch, double yaw, double p, double q, double r,
                                 TimeNs arrival) noexcept {
  if (have_boot_) {
    if (boot_ms == last_boot_ms_) {
      ++c_.duplicates;
      return;
    }
    if (boot_ms < last_boot_ms_) {
      if (last_boot_ms_ - boot_ms <= kResetMs) {
        ++c_.reordered;
        return;
      }
      ++c_.resets;
      AG_LOG_WARN("autopilot", "time_boot_ms went back from %u to %u ms: the autopilot restarted", last_boot_ms_, boot_ms);
    }
  }
  have_boot_ = true;
  last_boot_ms_ = boot_ms;
  if (!std::isfinite(roll) || !std::isfinite(pitch) || !std::isfinite(yaw)) {
    ++c_.bad_payloads;  // an estimator that has not converged sends NaN
    return;
  }
  const EulerAttitude e = frd_ned_to_flu_enu(EulerAttitude{roll, pitch, yaw, p, q, r});
  if (n_pending_ == pending_.size()) flush(arrival);
  Pending& pd = pending_[n_pending_++];
  pd.msg = AttitudeMsg{};
  pd.msg.roll = e.roll;
  pd.msg.pitch = e.pitch;
  pd.msg.yaw = e.yaw;
  pd.msg.roll_rate = e.roll_rate;
  pd.msg.pitch_rate = e.pitch_rate;
  pd.msg.yaw_rate = e.yaw_rate;
  pd.boot_ms = boot_ms;
  pd.arrival = arrival;
}

void AutopilotStage::on_frame(const Frame& f, TimeNs arrival) noexcept {
  ++c_.frames;
  ++window_frames_;
  if ((want_sysid_ != 0 && f.header.sysid != want_sysid_) || (want_compid_ != 0 && f.header.compid != want_compid_)) {
    ++c_.other_sources;
    return;
  }
  switch (f.header.msgid) {
    case kIdHeartbeat: {
      Heartbeat h;
      if (!decode(f.payload, h)) break;
      ++c_.heartbeats;
      c_.autopilot = h.autopilot;
      target_sysid_ = f.header.sysid;
      target_compid_ = f.header.compid;
      if (!first_heartbeat_logged_) {
        first_heartbeat_logged_ = true;
        AG_LOG_INFO("autopilot", "heard %s (MAV_AUTOPILOT %u, MAV_TYPE %u) system %u component %u over MAVLink %u", autopilot_name(h.autopilot),
                    h.autopilot, h.type, f.header.sysid, f.header.compid, f.header.version);
      }
      break;
    }
    case kIdAttitude: {
      Attitude a;
      if (!decode(f.payload, a)) {
        ++c_.bad_payloads;
        break;
      }
      ++c_.attitude;
      ++window_attitude_;
      seen_attitude_ = true;
      on_attitude(a.time_boot_ms, a.roll, a.pitch, a.yaw, a.rollspeed, a.pitchspeed, a.yawspeed, arrival);
      break;
    }
    case kIdAttitudeQuaternion: {
      AttitudeQuaternion a;
      if (!decode(f.payload, a)) {
        ++c_.bad_payloads;
        break;
      }
      ++c_.attitude_quaternion;
      if (seen_attitude_) break;  // the same estimate: ATTITUDE is used when both arrive
      ++window_attitude_;
      const EulerAttitude e = euler_from_quaternion(a.q1, a.q2, a.q3, a.q4);
      on_attitude(a.time_boot_ms, e.roll, e.pitch, e.yaw, a.rollspeed, a.pitchspeed, a.yawspeed, arrival);
      break;
    }
    case kIdCommandAck: {
      CommandAck k;
      if (!decode(f.payload, k) || k.command != kCmdSetMessageInterval) break;
      if (k.result == kResultAccepted) {
        ++c_.rate_accepted;
      } else {
        ++c_.rate_refused;
        if (!refused_logged_) {
          refused_logged_ = true;
          AG_LOG_WARN("autopilot", "the autopilot refused SET_MESSAGE_INTERVAL for ATTITUDE (MAV_RESULT %u): set its stream rate (MAV_x_RATE / SRx_EXTRA1)", k.result);
        }
      }
      break;
    }
    default: break;
  }
}

void AutopilotStage::drain(TimeNs arrival) noexcept {
  Frame f;
  while (parser_.next(f)) on_frame(f, arrival);
}

// Messages that arrived together (one step's read, one tlog time) would share a stamp: the newest keeps
// its arrival time and the earlier ones go back by the autopilot's own intervals between them.
void AutopilotStage::flush(TimeNs now) noexcept {
  for (std::size_t i = 0; i < n_pending_; ++i) {
    std::size_t last = i;
    while (last + 1 < n_pending_ && pending_[last + 1].arrival == pending_[i].arrival) ++last;
    Pending& pd = pending_[i];
    const std::uint32_t newest = pending_[last].boot_ms;
    const TimeNs back = newest >= pd.boot_ms ? static_cast<TimeNs>(newest - pd.boot_ms) * kNsPerMs : 0;
    TimeNs stamp = pd.arrival - latency_ - back;
    if (stamp <= last_stamp_) stamp = last_stamp_ + 1;  // stamps never go back
    last_stamp_ = stamp;
    pd.msg.stamp = stamp;
    pd.msg.published = now;
    last_ = pd.msg;
    ++c_.published;
    if (out_.push(pd.msg) != 0) ++c_.ring_full;
  }
  n_pending_ = 0;
}

void AutopilotStage::request_rate(TimeNs now) noexcept {
  if (request_hz_ <= 0 || replay_ || target_sysid_ < 0 || now < next_request_) return;
  if (c_.attitude_hz >= 0.8 * request_hz_) return;  // it arrives: nothing to ask
  next_request_ = now + kRequestRetry;
  CommandLong cmd;
  cmd.command = kCmdSetMessageInterval;
  cmd.param[0] = static_cast<float>(kIdAttitude);
  cmd.param[1] = static_cast<float>(1e6 / request_hz_);  // [us]
  cmd.target_system = static_cast<std::uint8_t>(target_sysid_);
  cmd.target_component = static_cast<std::uint8_t>(target_compid_);
  FrameHeader h;
  h.version = 2;
  h.seq = tx_seq_++;
  h.sysid = static_cast<std::uint8_t>(target_sysid_);  // a companion computer shares its vehicle's system id
  h.compid = kCompOnboardComputer;
  const std::size_t n = encode_message(h, cmd, request_frame_);
  const long wrote = link_->write(std::span<const std::uint8_t>(request_frame_.data(), n));
  if (wrote == static_cast<long>(n)) ++c_.rate_requests;
  else ++c_.write_errors;
}

void AutopilotStage::update_rates(TimeNs now) noexcept {
  if (window_start_ < 0) {
    window_start_ = now;
    next_log_ = now + log_every_;
    return;
  }
  const TimeNs span = now - window_start_;
  if (span < kNsPerS) return;
  c_.frames_hz = static_cast<double>(window_frames_) / to_seconds(span);
  c_.attitude_hz = static_cast<double>(window_attitude_) / to_seconds(span);
  window_frames_ = window_attitude_ = 0;
  window_start_ = now;
  if (log_every_ > 0 && now >= next_log_) {
    next_log_ = now + log_every_;
    const ParserCounters& p = parser_.counters();
    AG_LOG_INFO("autopilot", "attitude_hz=%.1f frames_hz=%.1f published=%llu bad_crc=%llu unknown_id=%llu bad_length=%llu truncated=%llu reordered=%llu resets=%llu",
                c_.attitude_hz, c_.frames_hz, static_cast<unsigned long long>(c_.published), static_cast<unsigned long long>(p.bad_crc),
                static_cast<unsigned long long>(p.unknown_id), static_cast<unsigned long long>(p.bad_length),
                static_cast<unsigned long long>(p.truncated), static_cast<unsigned long long>(c_.reordered),
                static_cast<unsigned long long>(c_.resets));
  }
}

void AutopilotStage::step(TimeNs now) noexcept {
  if (!link_) return;
  update_rates(now);
  for (int total = 0; total < max_bytes_;) {
    if (replay_ && pace_) {
      const TimeNs rec = link_->next_recorded();
      if (rec >= 0) {
        if (!have_offset_) {
          have_offset_ = true;
          replay_offset_ = now - rec;
        }
        if (rec + replay_offset_ > now) break;  // not due yet
      }
    }
    TimeNs recorded = -1;
    const long n = link_->read(buf_, recorded);
    if (n < 0) {
      if (!link_->at_end()) {
        ++c_.read_errors;
        if (!read_error_logged_) {
          read_error_logged_ = true;
          AG_LOG_ERROR("autopilot", "%s", link_->error().c_str());
        }
      } else if (!finished_logged_) {
        finished_logged_ = true;
        AG_LOG_INFO("autopilot", "replay finished: %llu frames, %llu attitudes published, %llu parser errors",
                    static_cast<unsigned long long>(c_.frames), static_cast<unsigned long long>(c_.published),
                    static_cast<unsigned long long>(parser_.counters().errors()));
      }
      break;
    }
    if (n == 0) break;
    total += static_cast<int>(n);
    TimeNs arrival = now;
    if (recorded >= 0) {  // a recording: its own arrival times, moved onto this clock
      if (!have_offset_) {
        have_offset_ = true;
        replay_offset_ = now - recorded;
      }
      arrival = recorded + replay_offset_;
    }
    std::span<const std::uint8_t> in(buf_.data(), static_cast<std::size_t>(n));
    while (!in.empty()) {
      const std::size_t k = parser_.feed(in);
      in = in.subspan(k);
      if (in.empty() && link_->packetized()) parser_.end_of_packet();
      drain(arrival);
      if (k == 0) break;  // cannot happen: a drained buffer always has room for more than a frame
    }
  }
  flush(now);
  request_rate(now);
}

}  // namespace ag::mavlink
