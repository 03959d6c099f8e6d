#include "foxglove_service.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <ctime>

#include "airground/messages/classes.hpp"
#include "airground/drivers/recording/mcap/foxglove_json.hpp"
#include "airground/platform/clock.hpp"
#include "airground/platform/log.hpp"

namespace ag::base_station {
namespace fg = ag::foxglove;

namespace {
constexpr std::uint8_t kMessageData = 0x01;  // server binary opcode (spec: Message Data)
constexpr std::size_t kDataHeader = 1 + 4 + 8;
constexpr std::size_t kMaxRefusalText = 120;  // bytes of a refused message quoted back

std::uint64_t wall_ns() {
  timespec t{};
  ::clock_gettime(CLOCK_REALTIME, &t);
  return static_cast<std::uint64_t>(t.tv_sec) * 1'000'000'000u + static_cast<std::uint64_t>(t.tv_nsec);
}
std::string robot_frame(comms::RobotId id) { return "robot" + std::to_string(id); }
fg::Pose planar(double x, double y, double yaw) { return fg::Pose{{x, y, 0}, fg::quat_from_rpy(0, 0, yaw)}; }
// A client's JSON id: an unsigned 32-bit integer, or false.
bool u32_of(const nlohmann::json& j, std::uint32_t& out) {
  if (!j.is_number_unsigned()) return false;
  const auto v = j.get<std::uint64_t>();
  if (v > 0xFFFFFFFFu) return false;
  out = static_cast<std::uint32_t>(v);
  return true;
}
std::string excerpt(std::string_view text) {
  std::string s(text.substr(0, kMaxRefusalText));
  for (char& ch : s)
    if (static_cast<unsigned char>(ch) < 0x20) ch = ' ';
  return "'" + s + (text.size() > kMaxRefusalText ? "...'" : "'");
}
}  // namespace

const std::string& FoxgloveService::comms_schema() {
  static const std::string s =
      R"J({"title":"airground.CommsStats","description":"The base's gossip counters (pipeline/comms CommsStatsMsg)","type":"object",)J"
      R"J("properties":{"records":{"type":"integer"},"payload_bytes":{"type":"integer"},"datagrams_in":{"type":"integer"},)J"
      R"J("datagrams_out":{"type":"integer"},"bytes_in":{"type":"integer"},"bytes_out":{"type":"integer"},"records_in":{"type":"integer"},)J"
      R"J("records_out":{"type":"integer"},"tiles_in":{"type":"integer"},"tiles_bad":{"type":"integer"},"drops":{"type":"integer"},)J"
      R"J("peers":{"type":"array","items":{"type":"object","properties":{"robot":{"type":"integer"},"bytes_in":{"type":"integer"},)J"
      R"J("bytes_out":{"type":"integer"},"records_in":{"type":"integer"},"records_out":{"type":"integer"}}}}}})J";
  return s;
}

const std::string& FoxgloveService::counters_schema() {
  static const std::string s =
      R"J({"title":"airground.BaseCounters","description":"The base station's model, page server and Foxglove counters","type":"object",)J"
      R"J("properties":{"model":{"type":"object","additionalProperties":{"type":"integer"}},)J"
      R"J("server":{"type":"object","additionalProperties":{"type":"integer"}},)J"
      R"J("foxglove":{"type":"object","additionalProperties":{"type":"integer"}}}})J";
  return s;
}

FoxgloveService::FoxgloveService(std::size_t client_buffer_bytes, double push_hz)
    : buffer_(client_buffer_bytes), push_period_ns_(static_cast<std::int64_t>(1e9 / std::max(push_hz, 0.1))) {
  add_channel(kFgTf, "/tf", "foxglove.FrameTransforms", fg::schema("foxglove.FrameTransforms"));
  add_channel(kFgMapTiles, "/map_tiles", "foxglove.Grid", fg::schema("foxglove.Grid"));
  add_channel(kFgRegions, "/regions", "foxglove.SceneUpdate", fg::schema("foxglove.SceneUpdate"));
  add_channel(kFgClaims, "/claims", "foxglove.SceneUpdate", fg::schema("foxglove.SceneUpdate"));
  add_channel(kFgVisits, "/visits", "foxglove.SceneUpdate", fg::schema("foxglove.SceneUpdate"));
  add_channel(kFgFailures, "/failures", "foxglove.SceneUpdate", fg::schema("foxglove.SceneUpdate"));
  add_channel(kFgObjects, "/objects", "foxglove.SceneUpdate", fg::schema("foxglove.SceneUpdate"));
  add_channel(kFgComms, "/comms", "airground.CommsStats", comms_schema());
  add_channel(kFgCounters, "/base/counters", "airground.BaseCounters", counters_schema());
}

FoxgloveService::Channel& FoxgloveService::add_channel(std::uint32_t id, std::string topic, std::string_view schema_name, std::string schema) {
  Channel& ch = channels_[id];
  ch.id = id;
  ch.topic = std::move(topic);
  ch.schema_name = schema_name;
  ch.schema = std::move(schema);
  c_.channels.store(static_cast<std::uint32_t>(channels_.size()), std::memory_order_relaxed);
  return ch;
}

std::string FoxgloveService::advertise_json(const std::vector<const Channel*>& chans) const {
  std::string s = R"({"op":"advertise","channels":[)";
  for (std::size_t i = 0; i < chans.size(); ++i) {
    const Channel& c = *chans[i];
    s += (i ? "," : "") + std::string(R"({"id":)") + std::to_string(c.id) + R"(,"topic":)" + fg::json_string(c.topic) +
         R"(,"encoding":)" + fg::json_string(fg::kMessageEncoding) + R"(,"schemaName":)" + fg::json_string(c.schema_name) +
         R"(,"schema":)" + fg::json_string(c.schema) + R"(,"schemaEncoding":)" + fg::json_string(fg::kSchemaEncoding) + "}";
  }
  return s + "]}";
}

void FoxgloveService::open(net::http::HttpServer& s, ClientId id) {
  clients_[id];
  c_.clients_opened.fetch_add(1, std::memory_order_relaxed);
  c_.clients.store(static_cast<std::uint32_t>(clients_.size()), std::memory_order_relaxed);
  s.ws_send_text(id, R"({"op":"serverInfo","name":"airground-base","capabilities":[],"metadata":{"frames":)"
                     R"("map: the team's local ENU frame (x east, y north); robot<id>: each robot as it reports its pose",)"
                     R"("clock":"message timestamps are the base's wall clock"},"sessionId":")" +
                         std::to_string(wall_ns()) + "\"}");
  std::vector<const Channel*> all;
  for (const auto& [cid, ch] : channels_) all.push_back(&ch);
  s.ws_send_text(id, advertise_json(all));
}

void FoxgloveService::close(ClientId id) {
  clients_.erase(id);
  c_.clients.store(static_cast<std::uint32_t>(clients_.size()), std::memory_order_relaxed);
}

void FoxgloveService::refuse(net::http::HttpServer& s, ClientId id, const std::string& why) {
  const auto n = c_.client_errors.fetch_add(1, std::memory_order_relaxed) + 1;
  if (n <= 20 || n % 1000 == 0)
    AG_LOG_WARN("foxglove", "client %llu: %s client_errors=%llu", static_cast<unsigned long long>(id), why.c_str(),
                static_cast<unsigned long long>(n));
  s.ws_send_text(id, R"({"op":"status","level":2,"message":)" + fg::json_string(why) + "}");
}

void FoxgloveService::message(net::http::HttpServer& s, ClientId id, net::http::WsOpcode op, std::span<const std::uint8_t> payload) {
  auto it = clients_.find(id);
  if (it == clients_.end()) return;
  if (op != net::http::WsOpcode::kText) {
    char b[160];
    std::snprintf(b, sizeof b, "binary message refused (opcode 0x%02x, %zu bytes): this server has no clientPublish or services capability",
                  payload.empty() ? 0u : static_cast<unsigned>(payload[0]), payload.size());
    refuse(s, id, b);
    return;
  }
  const std::string_view text(reinterpret_cast<const char*>(payload.data()), payload.size());
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (j.is_discarded()) {
    refuse(s, id, "not JSON: " + excerpt(text));
    return;
  }
  if (!j.is_object() || !j.contains("op") || !j["op"].is_string()) {
    refuse(s, id, "a client message is a JSON object with a string 'op': " + excerpt(text));
    return;
  }
  const auto& opname = j["op"].get_ref<const std::string&>();
  if (opname == "subscribe") return subscribe(s, id, it->second, text);
  if (opname == "unsubscribe") return unsubscribe(s, id, it->second, text);
  static constexpr std::pair<const char*, const char*> kNeeds[] = {
      {"advertise", "clientPublish"}, {"unadvertise", "clientPublish"}, {"getParameters", "parameters"},
      {"setParameters", "parameters"}, {"subscribeParameterUpdates", "parametersSubscribe"},
      {"unsubscribeParameterUpdates", "parametersSubscribe"}, {"subscribeConnectionGraph", "connectionGraph"},
      {"unsubscribeConnectionGraph", "connectionGraph"}, {"fetchAsset", "assets"}};
  for (const auto& [name, cap] : kNeeds)
    if (opname == name) return refuse(s, id, "op '" + opname + "' needs the capability '" + cap + "', which this server does not offer");
  refuse(s, id, "unknown op " + excerpt(opname) + " (this server accepts subscribe and unsubscribe)");
}

void FoxgloveService::subscribe(net::http::HttpServer& s, ClientId id, Client& c, std::string_view text) {
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (!j.contains("subscriptions") || !j["subscriptions"].is_array())
    return refuse(s, id, "subscribe: 'subscriptions' must be an array of {id, channelId}");
  for (const nlohmann::json& e : j["subscriptions"]) {
    std::uint32_t sub = 0, chan = 0;
    if (!e.is_object() || !e.contains("id") || !e.contains("channelId") || !u32_of(e["id"], sub) || !u32_of(e["channelId"], chan)) {
      refuse(s, id, "subscribe: an entry is not {id, channelId} with unsigned 32-bit integers: " + excerpt(e.dump()));
      continue;
    }
    auto ch = channels_.find(chan);
    if (ch == channels_.end()) {
      refuse(s, id, "subscribe: channel " + std::to_string(chan) + " is not advertised (subscription " + std::to_string(sub) + ")");
      continue;
    }
    if (auto used = c.subs.find(sub); used != c.subs.end()) {
      refuse(s, id, "subscribe: subscription id " + std::to_string(sub) + " is already in use (channel " + std::to_string(used->second) + ")");
      continue;
    }
    if (auto dup = c.by_channel.find(chan); dup != c.by_channel.end()) {
      refuse(s, id, "subscribe: channel " + std::to_string(chan) + " (" + ch->second.topic + ") already has subscription " +
                        std::to_string(dup->second) + " on this connection");
      continue;
    }
    c.subs[sub] = chan;
    c.by_channel[chan] = sub;
    c_.subscriptions.fetch_add(1, std::memory_order_relaxed);
    // The newest message at once (a late subscriber sees the current state), every held tile queued.
    if (chan == kFgMapTiles) {
      for (const auto& [k, v] : tiles_)
        if (c.tiles_queued.insert(k).second) c.tiles.push_back(k);
    } else if (!ch->second.latest.empty()) {
      send_data(s, id, sub, wall_ns(), ch->second.latest, true);
    }
  }
}

void FoxgloveService::unsubscribe(net::http::HttpServer& s, ClientId id, Client& c, std::string_view text) {
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (!j.contains("subscriptionIds") || !j["subscriptionIds"].is_array())
    return refuse(s, id, "unsubscribe: 'subscriptionIds' must be an array of numbers");
  for (const nlohmann::json& e : j["subscriptionIds"]) {
    std::uint32_t sub = 0;
    if (!u32_of(e, sub)) {
      refuse(s, id, "unsubscribe: " + excerpt(e.dump()) + " is not an unsigned 32-bit subscription id");
      continue;
    }
    auto it = c.subs.find(sub);
    if (it == c.subs.end()) {
      refuse(s, id, "unsubscribe: no subscription " + std::to_string(sub) + " on this connection");
      continue;
    }
    if (it->second == kFgMapTiles) {
      c.tiles.clear();
      c.tiles_queued.clear();
    }
    c.by_channel.erase(it->second);
    c.subs.erase(it);
    c_.unsubscriptions.fetch_add(1, std::memory_order_relaxed);
  }
}

bool FoxgloveService::send_data(net::http::HttpServer& s, ClientId id, std::uint32_t sub, std::uint64_t t_ns, std::string_view json,
                                bool queue_limit) {
  if (queue_limit && s.ws_pending(id) > buffer_ / 2) {
    c_.dropped_slow.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  frame_.resize(kDataHeader + json.size());
  frame_[0] = kMessageData;
  for (int i = 0; i < 4; ++i) frame_[1 + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(sub >> (8 * i));
  for (int i = 0; i < 8; ++i) frame_[5 + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(t_ns >> (8 * i));
  std::memcpy(frame_.data() + kDataHeader, json.data(), json.size());
  if (!s.ws_send(id, net::http::WsOpcode::kBinary, frame_)) return false;
  c_.messages_out.fetch_add(1, std::memory_order_relaxed);
  c_.bytes_out.fetch_add(frame_.size(), std::memory_order_relaxed);
  return true;
}

void FoxgloveService::send_all(net::http::HttpServer& s, Channel& ch, std::uint64_t t_ns, std::string json) {
  ch.latest = std::move(json);
  for (auto& [id, c] : clients_)
    if (auto sub = c.by_channel.find(ch.id); sub != c.by_channel.end()) send_data(s, id, sub->second, t_ns, ch.latest, true);
}

namespace {
// A tile as a foxglove.Grid: per cell elevation float32 [m] (NaN unknown), class, red, green, blue (the
// class colour); rows south to north — the layout of the simulator's recording (/uav/map_tiles).
std::string grid_json(const WebTile& t, std::uint64_t t_ns) {
  static const std::array<Rgb, 256> colors = [] {
    std::array<Rgb, 256> c{};
    for (const ClassInfo& k : ClassTable::builtin().all()) c[raw(k.id)] = k.color;
    return c;
  }();
  std::vector<std::uint8_t> data(kTileCellCount * 8, 0);
  for (std::size_t k = 0; k < kTileCellCount; ++k) {
    const float e = t.elev_dm[k] == INT16_MIN ? std::nanf("") : static_cast<float>(t.elev_dm[k]) * 0.1f;
    std::memcpy(&data[k * 8], &e, 4);
    data[k * 8 + 4] = t.cls[k];
    data[k * 8 + 5] = colors[t.cls[k]].r;
    data[k * 8 + 6] = colors[t.cls[k]].g;
    data[k * 8 + 7] = colors[t.cls[k]].b;
  }
  const double tile_m = kTileCells * kMapResolutionM;
  return fg::grid(t_ns, "map", {{t.tx * tile_m, t.ty * tile_m, 0}, {}}, kTileCells, kMapResolutionM, kMapResolutionM, kTileCells * 8, 8,
                  {{"elevation", 0, fg::NumericType::kFloat32}, {"class", 4, fg::NumericType::kUint8}, {"red", 5, fg::NumericType::kUint8},
                   {"green", 6, fg::NumericType::kUint8}, {"blue", 7, fg::NumericType::kUint8}},
                  data);
}
}  // namespace

void FoxgloveService::tile(const WebTile& t) {
  const Key key{t.tx, t.ty};
  HeldTile& h = tiles_[key];
  h.tile = t;
  h.json.clear();
  for (auto& [id, c] : clients_)
    if (c.by_channel.count(kFgMapTiles) != 0 && c.tiles_queued.insert(key).second) c.tiles.push_back(key);
}

void FoxgloveService::send_tiles(net::http::HttpServer& s) {
  for (auto& [id, c] : clients_) {
    auto sub = c.by_channel.find(kFgMapTiles);
    if (sub == c.by_channel.end()) continue;
    // Tiles wait in the client's queue (newest version at send time) while its output drains.
    while (!c.tiles.empty() && s.ws_pending(id) < buffer_ / 4) {
      const Key k = c.tiles.front();
      c.tiles.pop_front();
      c.tiles_queued.erase(k);
      auto t = tiles_.find(k);
      if (t == tiles_.end()) continue;
      const std::uint64_t now = wall_ns();
      if (t->second.json.empty()) t->second.json = grid_json(t->second.tile, now);
      if (!send_data(s, id, sub->second, now, t->second.json, false)) break;
    }
  }
}

void FoxgloveService::publish_model(net::http::HttpServer& s, const MissionModel& m, std::uint64_t t) {
  // Robots: a pose channel each (advertised to every client when first heard), the frame tree.
  std::vector<const Channel*> fresh;
  std::vector<fg::FrameTransform> tf;
  for (std::size_t i = 0; i < m.robot_count; ++i) {
    const RobotView& r = m.robots[i];
    if (!r.has_pose) continue;
    tf.push_back({"map", robot_frame(r.id), {r.x, r.y, 0}, fg::quat_from_rpy(0, 0, r.yaw)});
    const std::uint32_t cid = kFoxglovePoseChannelBase + r.id;
    if (channels_.count(cid) == 0)
      fresh.push_back(&add_channel(cid, "/" + robot_frame(r.id) + "/pose", "foxglove.PoseInFrame", fg::schema("foxglove.PoseInFrame")));
  }
  if (!fresh.empty()) {
    const std::string adv = advertise_json(fresh);
    for (const auto& [id, c] : clients_) s.ws_send_text(id, adv);
  }
  for (std::size_t i = 0; i < m.robot_count; ++i) {
    const RobotView& r = m.robots[i];
    if (!r.has_pose) continue;
    auto [it, first] = pose_sent_.try_emplace(r.id, r.pose_stamp);
    if (!first && it->second == r.pose_stamp) continue;
    it->second = r.pose_stamp;
    send_all(s, channels_[kFoxglovePoseChannelBase + r.id], t, fg::pose_in_frame(t, "map", planar(r.x, r.y, r.yaw)));
  }
  if (!tf.empty()) publish(s, channels_[kFgTf], t, [&](std::uint64_t u) { return fg::frame_transforms(u, tf); });

  const fg::Color region_c{0.95, 0.75, 0.1, 0.6}, goal_c{0.1, 0.8, 0.9, 0.9}, visit_c{0.2, 0.85, 0.3, 0.9};
  const fg::Color fail_c{0.9, 0.15, 0.1, 0.9}, object_c{0.8, 0.3, 0.9, 0.5}, white{1, 1, 1, 1};
  fg::SceneEntity regions{"regions", "map", {}, {}, {}};
  m.for_each_region([&](const mission::RegionRecord& e) {
    regions.spheres.push_back({{e.cx, e.cy, 0}, std::max(1.0, std::sqrt(static_cast<double>(e.cells)) * 0.5), region_c});
    if (e.goal_valid) regions.spheres.push_back({{e.goal_x, e.goal_y, 0}, 0.6, goal_c});
    regions.texts.push_back({{e.cx, e.cy, 1.5}, "R" + std::to_string(e.id), white, 12});
  });
  if (!regions.spheres.empty()) publish(s, channels_[kFgRegions], t, [&](std::uint64_t u) { return fg::scene_update(u, {regions}); });

  std::vector<fg::SceneEntity> claims, visits;
  for (std::size_t i = 0; i < m.robot_count; ++i) {
    const RobotView& r = m.robots[i];
    const std::string name = robot_frame(r.id);
    if (r.has_claim) {
      const mission::ClaimRecord& c = r.claim;
      fg::SceneEntity e{"claim/" + name, "map", {}, {}, {}};
      const bool region = c.region_id != mission::kNoRegion;
      if (region) e.spheres.push_back({{c.goal_x, c.goal_y, 0}, 1.0, goal_c});
      if (region && r.has_pose) e.lines.push_back({{{r.x, r.y, 0.2}, {c.goal_x, c.goal_y, 0.2}}, goal_c, 0.2, false});
      e.texts.push_back({{region ? c.goal_x : r.x, region ? c.goal_y : r.y, 2.0},
                         name + " " + mission::to_string(c.state) + (region ? " R" + std::to_string(c.region_id) : std::string()), white, 12});
      claims.push_back(std::move(e));
    }
    if (r.has_visited && r.visited.count > 0) {
      fg::SceneEntity e{"visits/" + name, "map", {}, {}, {}};
      for (std::size_t k = 0; k < r.visited.count; ++k) {
        const mission::VisitedEntry& v = r.visited.entries[k];
        e.spheres.push_back({{v.x, v.y, 0}, 0.8, visit_c});
        e.texts.push_back({{v.x, v.y, 1.0}, name + " visited R" + std::to_string(v.region_id), white, 10});
      }
      visits.push_back(std::move(e));
    }
  }
  if (!claims.empty()) publish(s, channels_[kFgClaims], t, [&](std::uint64_t u) { return fg::scene_update(u, claims); });
  if (!visits.empty()) publish(s, channels_[kFgVisits], t, [&](std::uint64_t u) { return fg::scene_update(u, visits); });

  fg::SceneEntity failures{"failures", "map", {}, {}, {}};
  for (std::size_t i = 0; i < m.failure_count; ++i) {
    const FailureView& f = m.failures[i];
    failures.spheres.push_back({{f.f.x, f.f.y, 0}, 1.0, fail_c});
    failures.texts.push_back({{f.f.x, f.f.y, 1.5},
                              robot_frame(f.origin) + " R" + std::to_string(f.f.region_id) + " " + mission::to_string(f.f.reason) + " x" +
                                  std::to_string(f.f.attempts),
                              white, 11});
  }
  if (!failures.spheres.empty()) publish(s, channels_[kFgFailures], t, [&](std::uint64_t u) { return fg::scene_update(u, {failures}); });

  fg::SceneEntity objects{"objects", "map", {}, {}, {}};
  const ClassTable& classes = ClassTable::builtin();
  for (std::size_t i = 0; i < m.object_count; ++i) {
    const mission::ObjectRecord& o = m.objects[i].o;
    const double sigma = std::sqrt(std::max({static_cast<double>(o.cxx), static_cast<double>(o.cyy), 0.0}));
    objects.spheres.push_back({{o.x, o.y, 0}, std::max(0.5, 4.0 * sigma), object_c});  // the 2-sigma circle
    const std::string cls = classes.valid_id(o.cls) ? classes.info(static_cast<ClassId>(o.cls)).name : "class " + std::to_string(o.cls);
    objects.texts.push_back({{o.x, o.y, 1.5}, cls + " #" + std::to_string(o.object_id) + " (" + std::to_string(o.detections) + " detections)", white, 11});
  }
  if (!objects.spheres.empty()) publish(s, channels_[kFgObjects], t, [&](std::uint64_t u) { return fg::scene_update(u, {objects}); });

  if (m.has_comms) {
    const comms::CommsStatsMsg& c = m.comms;
    std::uint64_t drops = 0;
    for (std::uint64_t d : c.drops) drops += d;
    std::string j = "{\"records\":" + std::to_string(c.records) + ",\"payload_bytes\":" + std::to_string(c.payload_bytes) +
                    ",\"datagrams_in\":" + std::to_string(c.datagrams_in) + ",\"datagrams_out\":" + std::to_string(c.datagrams_out) +
                    ",\"bytes_in\":" + std::to_string(c.bytes_in) + ",\"bytes_out\":" + std::to_string(c.bytes_out) +
                    ",\"records_in\":" + std::to_string(c.records_in) + ",\"records_out\":" + std::to_string(c.records_out) +
                    ",\"tiles_in\":" + std::to_string(c.tiles_in) + ",\"tiles_bad\":" + std::to_string(c.tiles_bad) +
                    ",\"drops\":" + std::to_string(drops) + ",\"peers\":[";
    for (std::size_t i = 0; i < c.peers && i < c.peer.size(); ++i) {
      const comms::CommsPeerRow& p = c.peer[i];
      j += (i ? "," : "") + std::string("{\"robot\":") + std::to_string(p.robot) + ",\"bytes_in\":" + std::to_string(p.bytes_in) +
           ",\"bytes_out\":" + std::to_string(p.bytes_out) + ",\"records_in\":" + std::to_string(p.records_in) +
           ",\"records_out\":" + std::to_string(p.records_out) + "}";
    }
    j += "]}";
    publish(s, channels_[kFgComms], t, [&](std::uint64_t) { return j; });
  }
}

std::string FoxgloveService::counters_json() const {
  const auto u = [](const std::atomic<std::uint64_t>& a) { return std::to_string(a.load(std::memory_order_relaxed)); };
  return "\"clients\":" + std::to_string(c_.clients.load(std::memory_order_relaxed)) + ",\"clients_opened\":" + u(c_.clients_opened) +
         ",\"channels\":" + std::to_string(c_.channels.load(std::memory_order_relaxed)) + ",\"subscriptions\":" + u(c_.subscriptions) +
         ",\"unsubscriptions\":" + u(c_.unsubscriptions) + ",\"messages_out\":" + u(c_.messages_out) + ",\"bytes_out\":" + u(c_.bytes_out) +
         ",\"client_errors\":" + u(c_.client_errors) + ",\"dropped_slow\":" + u(c_.dropped_slow);
}

void FoxgloveService::tick(net::http::HttpServer& s, const MissionModel& m, const std::function<std::string()>& counters_extra) {
  const std::int64_t now = monotonic_now();
  if (m.seq != model_seq_ && now - last_model_ns_ >= push_period_ns_) {
    model_seq_ = m.seq;
    last_model_ns_ = now;
    publish_model(s, m, wall_ns());
  }
  if (now - last_counters_ns_ >= kNsPerS) {
    last_counters_ns_ = now;
    const std::uint64_t t = wall_ns();
    // Sent every second whether or not they changed (a live view shows they are current).
    send_all(s, channels_[kFgCounters], t, "{" + counters_extra() + ",\"foxglove\":{" + counters_json() + "}}");
  }
  send_tiles(s);
}

}  // namespace ag::base_station
