// The base's live Foxglove connection: the Foxglove WebSocket protocol (subprotocol foxglove.websocket.v1,
// github.com/foxglove/ws-protocol docs/spec.md) on the web stage's server, beside the page's own /ws.
// It advertises what the base station model holds, JSON-encoded with Foxglove's schemas (the recording's
// encoders, drivers/recording/mcap foxglove_json.hpp):
//   /tf (FrameTransforms map -> robot<id>), /robot<id>/pose (PoseInFrame, advertised when the robot is
//   first heard), /map_tiles (Grid: elevation, class, class colour), /regions, /claims, /visits,
//   /failures, /objects (SceneUpdate), /comms and /base/counters (JSON with our own JSON schemas).
// A subscriber gets the newest message of each channel at once (all held tiles for /map_tiles), then
// every change. Message timestamps are the base's wall clock. Runs on the server thread only.
// Refused client messages (not JSON, unknown op, an op needing a capability we lack, unknown channel,
// a subscription id in use, binary messages) get a status (level 2) naming the fault and are counted;
// the connection stays. A client that does not read loses messages (counted), never blocks anything.
#pragma once

#include <atomic>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <set>
#include <span>
#include <string>
#include <string_view>
#include <unordered_map>
#include <utility>
#include <vector>

#include "airground/base_station/model.hpp"
#include "airground/base_station/web_stage.hpp"
#include "airground/drivers/net/http/server.hpp"

namespace ag::base_station {

inline constexpr std::string_view kFoxgloveSubprotocol = "foxglove.websocket.v1";

// Fixed channel ids; a robot's pose channel is kFoxglovePoseChannelBase + its id.
enum FoxgloveChannel : std::uint32_t {
  kFgTf = 1, kFgMapTiles, kFgRegions, kFgClaims, kFgVisits, kFgFailures, kFgObjects, kFgComms, kFgCounters
};
inline constexpr std::uint32_t kFoxglovePoseChannelBase = 100;

class FoxgloveService {
 public:
  using ClientId = net::http::HttpServer::ClientId;
  // client_buffer_bytes: the server's per-client output bound; messages are dropped for a client with
  // more than half of it waiting (tiles wait in its queue while more than a quarter is waiting).
  FoxgloveService(std::size_t client_buffer_bytes, double push_hz);

  // Whether a WebSocket client speaks this protocol (it was accepted with kFoxgloveSubprotocol).
  [[nodiscard]] bool has(ClientId id) const noexcept { return clients_.count(id) != 0; }
  // A new client: serverInfo, then the advertise of every channel.
  void open(net::http::HttpServer& s, ClientId id);
  void close(ClientId id);
  // A client message: subscribe / unsubscribe, or a refusal (status, counted).
  void message(net::http::HttpServer& s, ClientId id, net::http::WsOpcode op, std::span<const std::uint8_t> payload);
  // A tile version newer than the one held (from the web service's tile hand-over).
  void tile(const WebTile& t);
  // Every server tick: advertises new robots, publishes what changed in the model (at most push_hz) and
  // the counters (1 Hz), sends queued tiles.
  // `counters_extra()`: JSON object members ("model":{…},"server":{…}) for /base/counters, called once a second.
  void tick(net::http::HttpServer& s, const MissionModel& m, const std::function<std::string()>& counters_extra);

  struct Counters {
    std::atomic<std::uint64_t> clients_opened{0}, subscriptions{0}, unsubscriptions{0};
    std::atomic<std::uint64_t> messages_out{0}, bytes_out{0};
    std::atomic<std::uint64_t> client_errors{0};   // refused client messages (each got a status)
    std::atomic<std::uint64_t> dropped_slow{0};    // messages not sent to a client that was not reading
    std::atomic<std::uint32_t> clients{0}, channels{0};
  };
  [[nodiscard]] const Counters& counters() const noexcept { return c_; }
  // The counters as one JSON object's members (no braces), for /api/state.
  [[nodiscard]] std::string counters_json() const;

  // The JSON schemas of our own two channels (airground.CommsStats, airground.BaseCounters).
  static const std::string& comms_schema();
  static const std::string& counters_schema();

 private:
  using Key = std::pair<std::int32_t, std::int32_t>;
  struct Channel {
    std::uint32_t id{0};
    std::string topic, schema_name, schema;
    std::string latest;  // newest message JSON ("" none yet): sent at subscribe
    std::string key;     // the newest message built with timestamp 0: what decides whether it changed
  };
  struct Client {
    std::map<std::uint32_t, std::uint32_t> subs;      // subscription id -> channel id
    std::map<std::uint32_t, std::uint32_t> by_channel;  // channel id -> subscription id
    std::deque<Key> tiles;                              // tiles to send on /map_tiles
    std::set<Key> tiles_queued;
  };
  Channel& add_channel(std::uint32_t id, std::string topic, std::string_view schema_name, std::string schema);
  [[nodiscard]] std::string advertise_json(const std::vector<const Channel*>& chans) const;
  void refuse(net::http::HttpServer& s, ClientId id, const std::string& why);
  void subscribe(net::http::HttpServer& s, ClientId id, Client& c, std::string_view text);
  void unsubscribe(net::http::HttpServer& s, ClientId id, Client& c, std::string_view text);
  // build(t_ns) -> message JSON. Sends it to every subscriber of the channel and keeps it as the
  // channel's newest, unless it equals the newest but for the timestamp.
  template <typename Build>
  void publish(net::http::HttpServer& s, Channel& ch, std::uint64_t t_ns, Build&& build) {
    std::string key = build(std::uint64_t{0});
    if (key == ch.key) return;
    ch.key = std::move(key);
    send_all(s, ch, t_ns, build(t_ns));
  }
  void send_all(net::http::HttpServer& s, Channel& ch, std::uint64_t t_ns, std::string json);
  bool send_data(net::http::HttpServer& s, ClientId id, std::uint32_t sub, std::uint64_t t_ns, std::string_view json, bool queue_limit);
  void send_tiles(net::http::HttpServer& s);
  void publish_model(net::http::HttpServer& s, const MissionModel& m, std::uint64_t t_ns);

  std::size_t buffer_;
  std::int64_t push_period_ns_;
  Counters c_;
  std::map<std::uint32_t, Channel> channels_;
  std::unordered_map<ClientId, Client> clients_;
  struct HeldTile {
    WebTile tile;
    std::string json;  // its Grid message, built when first sent ("" not yet: no cost without a subscriber)
  };
  std::map<Key, HeldTile> tiles_;
  std::map<comms::RobotId, TimeNs> pose_sent_;
  std::vector<std::uint8_t> frame_;  // scratch: one binary message
  std::uint64_t model_seq_{~std::uint64_t{0}};
  std::int64_t last_model_ns_{0}, last_counters_ns_{0};
};

}  // namespace ag::base_station
