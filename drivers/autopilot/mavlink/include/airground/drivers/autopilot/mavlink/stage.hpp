// The autopilot stage: the quadrotor's attitude from its PX4 (or ArduPilot) autopilot over MAVLink, for
// the visual odometry's gravity. Every step it reads what the link delivered (serial TELEM2, the UDP
// onboard link, or a .tlog), checks and decodes the frames, converts each ATTITUDE (ATTITUDE_QUATERNION
// while no ATTITUDE is seen) from FRD/NED to REP-103 FLU/ENU and publishes it on "attitude", stamped on
// this computer's clock: arrival minus latency_s. It asks the autopilot for ATTITUDE at request_hz
// (COMMAND_LONG MAV_CMD_SET_MESSAGE_INTERVAL) until that rate arrives.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "airground/messages/channels.hpp"
#include "airground/messages/messages.hpp"
#include "airground/drivers/autopilot/mavlink/frame_parser.hpp"
#include "airground/drivers/autopilot/mavlink/link.hpp"
#include "airground/platform/param_binding.hpp"
#include "airground/platform/stage.hpp"

namespace ag::mavlink {

// The autopilot stage's parameters as read (the times are converted to TimeNs in init()).
struct AutopilotSettings {
  std::string source{"serial"};
  std::string device{"/dev/ttyUSB0"};
  int baud{921600};
  std::string udp_bind{"0.0.0.0"};
  int udp_port{14540};
  std::string replay;
  bool replay_pace{true};
  int system_id{1};
  int component_id{1};
  double latency_s{0.0};
  double request_hz{50.0};
  int max_bytes_per_step{16384};
  double log_every_s{10.0};
  std::string attitude_channel{chan::kAttitude.name};
};
inline constexpr ParamField<AutopilotSettings> kAutopilotStageFields[] = {
    field::text("source", &AutopilotSettings::source, "serial", "serial|udp|replay|sim|none", "the autopilot's serial port (TELEM2), its UDP onboard link, a .tlog recording, the simulator's autopilot, or no autopilot"),
    field::text("device", &AutopilotSettings::device, "/dev/ttyUSB0", "", "serial device wired to the autopilot's TELEM2"),
    field::integer("baud", &AutopilotSettings::baud, 57600, 3000000, "Bd", "serial speed (PX4 SER_TEL2_BAUD)"),
    field::text("udp_bind", &AutopilotSettings::udp_bind, "0.0.0.0", "", "udp: local IPv4 address to listen on"),
    field::integer("udp_port", &AutopilotSettings::udp_port, 0, 65535, "", "udp: local port PX4's onboard link sends to (0: any free port)"),
    field::text("replay", &AutopilotSettings::replay, "", "", "replay: the .tlog to play"),
    field::boolean("replay_pace", &AutopilotSettings::replay_pace, "replay: hand records out at their recorded intervals (false: as fast as read)"),
    field::integer("system_id", &AutopilotSettings::system_id, 0, 255, "", "MAVLink system id of the autopilot to listen to; 0 = any"),
    field::integer("component_id", &AutopilotSettings::component_id, 0, 255, "", "MAVLink component id of the autopilot (MAV_COMP_ID_AUTOPILOT1 = 1); 0 = any"),
    field::real("latency_s", &AutopilotSettings::latency_s, 0.0, 0.5, "s", "subtracted from the arrival time: the autopilot's estimate-to-wire delay plus transfer"),
    field::real("request_hz", &AutopilotSettings::request_hz, 0.0, 400.0, "Hz", "ATTITUDE rate asked of the autopilot (MAV_CMD_SET_MESSAGE_INTERVAL); 0 = ask nothing"),
    field::integer("max_bytes_per_step", &AutopilotSettings::max_bytes_per_step, 64, 65536, "B", "bytes read per step (921600 Bd is 92 kB/s: 1.8 kB per 50 Hz step)"),
    field::real("log_every_s", &AutopilotSettings::log_every_s, 0.0, 3600.0, "s", "log the link's counters this often; 0 = only problems"),
    field::text("attitude_channel", &AutopilotSettings::attitude_channel, chan::kAttitude.name, "", "ring channel the attitude is published on"),
};
inline constexpr auto kAutopilotStageParams = param_specs(kAutopilotStageFields);

struct AutopilotCounters {
  std::uint64_t frames{0};                 // checked frames of any message
  std::uint64_t heartbeats{0}, attitude{0}, attitude_quaternion{0};
  std::uint64_t published{0}, ring_full{0};
  std::uint64_t other_sources{0};          // frames of other systems or components (filtered out)
  std::uint64_t reordered{0};              // time_boot_ms older than the last published (UDP reordering): dropped
  std::uint64_t duplicates{0};             // time_boot_ms equal to the last published: dropped
  std::uint64_t resets{0};                 // time_boot_ms went back by more than 2 s: the autopilot rebooted
  std::uint64_t bad_payloads{0};           // a decodable id whose payload did not decode
  std::uint64_t rate_requests{0}, rate_accepted{0}, rate_refused{0};
  std::uint64_t read_errors{0}, write_errors{0}, device_errors{0};
  double frames_hz{0}, attitude_hz{0};     // [Hz] over the last whole second
  std::uint8_t autopilot{0};               // MAV_AUTOPILOT of the last heartbeat (12 PX4, 3 ArduPilot)
};

class AutopilotStage final : public Stage {
 public:
  static constexpr std::span<const ParamSpec> kParams{kAutopilotStageParams};
  static std::unique_ptr<Stage> make() { return std::make_unique<AutopilotStage>(); }

  Status init(StageContext& ctx) override;
  void step(TimeNs now) noexcept override;

  [[nodiscard]] const AutopilotCounters& counters() const noexcept { return c_; }
  [[nodiscard]] const ParserCounters& parser_counters() const noexcept { return parser_.counters(); }
  [[nodiscard]] const AttitudeMsg& last_attitude() const noexcept { return last_; }
  [[nodiscard]] bool active() const noexcept { return link_ != nullptr; }
  [[nodiscard]] Link* link() noexcept { return link_.get(); }

 private:
  struct Pending {
    AttitudeMsg msg;
    std::uint32_t boot_ms;
    TimeNs arrival;
  };
  void drain(TimeNs arrival) noexcept;
  void on_frame(const Frame& f, TimeNs arrival) noexcept;
  void on_attitude(std::uint32_t boot_ms, double roll, double pitch, double yaw, double p, double q, double r, TimeNs arrival) noexcept;
  void flush(TimeNs now) noexcept;
  void request_rate(TimeNs now) noexcept;
  void update_rates(TimeNs now) noexcept;

  std::unique_ptr<Link> link_;
  FrameParser parser_;
  std::vector<std::uint8_t> buf_;
  RingWriter<AttitudeMsg, kAttitudeRing> out_;
  std::array<Pending, 64> pending_{};
  std::size_t n_pending_{0};
  std::array<std::uint8_t, kMaxFrame> request_frame_{};
  bool replay_{false}, pace_{true};
  int max_bytes_{16384};
  int want_sysid_{1}, want_compid_{1};
  TimeNs latency_{0};
  double request_hz_{50};
  TimeNs log_every_{10 * kNsPerS};
  // The autopilot heard in heartbeats (where requests go).
  int target_sysid_{-1}, target_compid_{-1};
  bool seen_attitude_{false};
  bool have_boot_{false};
  std::uint32_t last_boot_ms_{0};
  TimeNs last_stamp_{0};
  bool have_offset_{false};
  TimeNs replay_offset_{0};  // this clock minus the recording's
  TimeNs next_request_{0};
  std::uint8_t tx_seq_{0};
  TimeNs window_start_{-1}, next_log_{0};
  std::uint64_t window_frames_{0}, window_attitude_{0};
  bool finished_logged_{false}, read_error_logged_{false}, refused_logged_{false}, first_heartbeat_logged_{false};
  AttitudeMsg last_{};
  AutopilotCounters c_;
};

}  // namespace ag::mavlink
