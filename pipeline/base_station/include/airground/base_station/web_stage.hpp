// The base station's web stage: the team's poses, map tiles, gossip records and comms counters ->
// a MissionModel (fixed arrays) -> the server thread (net/http) that serves the live page, /api/state
// and /ws, Foxglove's WebSocket protocol (foxglove.websocket.v1, src/foxglove_service.hpp), and writes
// the mission log (JSON lines).
//   "team_poses" (latest), "map_tiles" (ring; comms.deliver_map_tiles must be on), "gossip_in" (ring),
//   "comms_stats" (latest); out: "gossip_out" (the operator's arm / disarm for a robot, from the page's
//   buttons or POST /api/arm?robot=N, /api/disarm?robot=N).
// step() never allocates and never blocks: the model goes to the server thread through a triple
// buffer, tiles and log entries through SPSC rings; sockets and the log file live on the server thread.
#pragma once

#include <memory>
#include <span>
#include <string>

#include "airground/base_station/model.hpp"
#include "airground/comms/messages.hpp"
#include "airground/messages/messages.hpp"
#include "airground/drivers/net/http/server.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/latest_value.hpp"
#include "airground/platform/param_binding.hpp"
#include "airground/platform/spsc_ring.hpp"
#include "airground/platform/stage.hpp"

namespace ag::base_station {

// The web stage's parameters as read (the buffer's KiB are converted in init()).
struct WebSettings {
  int port{8080};
  std::string bind{"0.0.0.0"};
  int max_clients{8};
  std::string log_path;
  double push_hz{4.0};            // [Hz]
  int client_buffer_kb{4096};     // [KiB]
  double slow_client_s{5.0};      // [s]
  int tiles_per_step{16};
  bool foxglove{true};
};
inline constexpr ParamField<WebSettings> kWebStageFields[] = {
    field::integer("port", &WebSettings::port, 0, 65535, "", "TCP port of the live page (http://<base>:<port>/) and its WebSocket; 0 = any free port"),
    field::text("bind", &WebSettings::bind, "0.0.0.0", "", "IPv4 address to listen on (127.0.0.1 = this machine only)"),
    field::integer("max_clients", &WebSettings::max_clients, 1, 1024, "connections", "browsers and API clients at once; more get 503"),
    field::text("log_path", &WebSettings::log_path, "", "", "mission log, JSON lines (every record received); empty = none"),
    field::real("push_hz", &WebSettings::push_hz, 0.2, 50.0, "Hz", "state updates sent to each browser"),
    field::integer("client_buffer_kb", &WebSettings::client_buffer_kb, 64, 1 << 20, "KiB", "output held per client; a client that lets it fill is dropped"),
    field::real("slow_client_s", &WebSettings::slow_client_s, 0.5, 600.0, "s", "a client whose output has not drained for this long is dropped"),
    field::integer("tiles_per_step", &WebSettings::tiles_per_step, 1, 64, "tiles", "map tiles handed to the server per step"),
    field::boolean("foxglove", &WebSettings::foxglove, "live Foxglove connection on the same port: WebSocket subprotocol foxglove.websocket.v1 (ws://<base>:<port>/)"),
};
inline constexpr auto kWebStageParams = param_specs(kWebStageFields);

// A map tile as the server keeps and sends it: classes and elevation in decimetres (INT16_MIN unknown).
struct WebTile {
  TimeNs stamp{0};     // [ns] when the tile last changed (the mapper's clock)
  TimeNs received{0};  // [ns] base clock
  std::int32_t tx{0}, ty{0};
  std::uint64_t version{0};
  std::array<std::uint8_t, kTileCellCount> cls{};
  std::array<std::int16_t, kTileCellCount> elev_dm{};
  WebTile() = default;
  WebTile(const MapTileMsg& m, TimeNs received_at) noexcept;
};

// One mission-log entry on its way to the writer (server) thread.
struct LogItem {
  enum class Kind : std::uint8_t { kRecord, kPose } kind{Kind::kRecord};
  TimeNs received{0};  // [ns] base clock
  comms::TeamPose pose;
  comms::GossipRecordMsg rec;
  LogItem() = default;
  LogItem(TimeNs t, const comms::GossipRecordMsg& r) noexcept : kind(Kind::kRecord), received(t), rec(r) {}
  LogItem(TimeNs t, const comms::TeamPose& p) noexcept : kind(Kind::kPose), received(t), pose(p) {}
};

inline constexpr std::size_t kWebTileRing = 64;
inline constexpr std::size_t kLogRing = 1024;

// An operator's command from the page or a tool (POST /api/arm?robot=N, /api/disarm?robot=N) on its
// way from the server thread to the stage, which publishes it to the team (gossip, TopicKind::kCommand).
struct OperatorRequest {
  comms::RobotId robot{comms::kNoRobot};
  comms::OperatorCommand command{comms::OperatorCommand::kArm};
  std::uint32_t request{0};  // counted by the server from 1
};
inline constexpr std::size_t kCommandRing = 16;

class WebService;

class WebStage final : public Stage {
 public:
  static constexpr std::span<const ParamSpec> kParams{kWebStageParams};
  static std::unique_ptr<Stage> make() { return std::make_unique<WebStage>(); }
  WebStage();
  ~WebStage() override;

  Status init(StageContext& ctx) override;
  void step(TimeNs now) noexcept override;
  void stop() noexcept override;

  [[nodiscard]] const MissionModel& model() const noexcept { return *model_; }
  // The listening port (0 until bound) and the server's counters (any thread).
  [[nodiscard]] int port() const noexcept;
  [[nodiscard]] const net::http::HttpServerCounters* server_counters() const noexcept;
  // The Foxglove connection's counters as JSON object members ("" before init; any thread).
  [[nodiscard]] std::string foxglove_counters_json() const;

 private:
  std::unique_ptr<MissionModel> model_;
  std::unique_ptr<LatestValue<MissionModel>> snapshot_;
  std::unique_ptr<SpscRing<WebTile, kWebTileRing>> tiles_to_server_;
  std::unique_ptr<SpscRing<LogItem, kLogRing>> log_to_server_;
  std::unique_ptr<SpscRing<OperatorRequest, kCommandRing>> commands_from_server_;
  std::unique_ptr<WebService> service_;
  RingWriter<comms::GossipPublishMsg, comms::kGossipRing> gossip_out_;
  std::unique_ptr<comms::GossipPublishMsg> out_msg_;
  std::unique_ptr<net::http::HttpServer> server_;
  LatestReader<comms::TeamPosesMsg> team_;
  LatestReader<comms::CommsStatsMsg> stats_;
  RingReader<MapTileMsg, kMapTileRing> tiles_;
  RingReader<comms::GossipRecordMsg, comms::kGossipRing> records_;
  std::size_t tiles_per_step_{16};
  std::uint64_t published_seq_{~std::uint64_t{0}};
  TimeNs last_comms_{-kNsPerS};
};

}  // namespace ag::base_station
