// The server-thread side of the web stage: the tiles held, the state JSON, the WebSocket pushes and the
// mission log writer. Everything here runs on the HttpServer's thread (it may allocate and write files).
#pragma once

#include <cstdio>
#include <deque>
#include <map>
#include <set>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "airground/base_station/model.hpp"
#include "airground/base_station/web_stage.hpp"
#include "airground/drivers/net/http/server.hpp"
#include "foxglove_service.hpp"

namespace ag::base_station {

// The embedded page (generated from pipeline/base_station/web/ at build time).
struct WebAsset {
  const char* path;
  const char* mime;
  const unsigned char* data;
  std::size_t size;
};
std::span<const WebAsset> web_assets() noexcept;

// Binary tile frame: u8 type=1, u8 reserved, u16 cells per side (64), i32 tx, i32 ty, u32 reserved,
// u64 version, then cells*cells class bytes (row-major from the south-west corner), then cells*cells
// i16 elevations in decimetres (-32768 unknown). Little-endian.
inline constexpr std::size_t kTileFrameHeader = 24;
std::vector<std::uint8_t> encode_tile_frame(const WebTile& t);

struct WebServiceParams {
  std::string log_path;
  double push_hz{4.0};
  std::size_t client_buffer_bytes{4u << 20};
  bool foxglove{true};  // answer WebSocket clients that offer foxglove.websocket.v1 (at any path)
  comms::RobotId self{comms::kNoRobot};  // the base station's robot.id (no command to itself)
};

class WebService final : public net::http::HttpServer::Handler {
 public:
  WebService(const WebServiceParams& p, LatestValue<MissionModel>& snapshot, SpscRing<WebTile, kWebTileRing>& tiles,
             SpscRing<LogItem, kLogRing>& log, SpscRing<OperatorRequest, kCommandRing>& commands, TimeNs start);
  ~WebService() override;
  // Opens (appends to) the log file; an error names the path.
  Status open_log();

  net::http::HttpResponse get(const net::http::HttpRequest& req) override;
  // POST /api/arm?robot=N, /api/disarm?robot=N: 202 and the command on its way to the team (the stage
  // publishes it), 400 for a missing or bad robot id, 503 while the hand-over is full, 404 otherwise.
  net::http::HttpResponse post(const net::http::HttpRequest& req) override;
  void ws_open(net::http::HttpServer& s, net::http::HttpServer::ClientId id) override;
  void ws_close(net::http::HttpServer::ClientId id) override;
  void ws_message(net::http::HttpServer& s, net::http::HttpServer::ClientId id, net::http::WsOpcode op,
                  std::span<const std::uint8_t> payload) override;
  std::string ws_subprotocol(const net::http::HttpRequest& req) override;
  void tick(net::http::HttpServer& s) override;
  // Any thread (atomics).
  [[nodiscard]] std::string foxglove_counters_json() const { return fox_.counters_json(); }
  // Writes what waits in the log ring.
  void drain_log() noexcept;
  // At stop (server thread joined): takes and logs the tiles handed over, then the log ring.
  void flush() noexcept {
    take_tiles();
    drain_log();
  }

  // JSON of the model (what /api/state and the "state" WebSocket messages carry).
  // `foxglove`: FoxgloveService::counters_json() ("" = none).
  static std::string state_json(const MissionModel& m, TimeNs start, const net::http::HttpServerCounters* http,
                                std::uint64_t tiles_held, std::uint64_t log_lines, std::uint64_t log_errors,
                                const std::string& foxglove = {});
  static std::string hello_json();
  // One mission-log line (no newline) for a record or a pose.
  static std::string log_line(const LogItem& item, TimeNs start);
  static std::string tile_log_line(const WebTile& t, TimeNs received, TimeNs start);

 private:
  using Key = std::pair<std::int32_t, std::int32_t>;
  struct Client {
    std::deque<Key> pending;  // tiles to send (newest version at send time)
    std::set<Key> queued;
  };
  void take_tiles() noexcept;
  void push_tiles(net::http::HttpServer& s);
  const std::string& current_state(const net::http::HttpServer* s);
  void refresh_model() noexcept;
  // The model, server and Foxglove counters as JSON object members (the /base/counters channel).
  [[nodiscard]] std::string counters_members() const;

  WebServiceParams p_;
  LatestValue<MissionModel>& snapshot_;
  SpscRing<WebTile, kWebTileRing>& tiles_in_;
  SpscRing<LogItem, kLogRing>& log_in_;
  SpscRing<OperatorRequest, kCommandRing>& commands_out_;
  std::uint32_t requests_{0};
  TimeNs start_;
  std::FILE* log_{nullptr};
  std::uint64_t log_lines_{0}, log_errors_{0};
  std::map<Key, std::vector<std::uint8_t>> tiles_;
  std::unordered_map<net::http::HttpServer::ClientId, Client> clients_;
  const MissionModel* model_{nullptr};
  std::uint64_t state_seq_{~std::uint64_t{0}};
  std::string state_;
  TimeNs last_push_{0};
  std::uint64_t pushed_seq_{~std::uint64_t{0}};
  const net::http::HttpServerCounters* http_{nullptr};
  std::uint64_t state_skipped_{0};
  FoxgloveService fox_;
};

}  // namespace ag::base_station
