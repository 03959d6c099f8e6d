#include "web_service.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>

#include "airground/base_station/json_out.hpp"
#include "airground/messages/classes.hpp"
#include "airground/platform/clock.hpp"
#include "airground/platform/log.hpp"

namespace ag::base_station {

namespace {
double secs(TimeNs t) { return static_cast<double>(t) * 1e-9; }
void put_le(std::vector<std::uint8_t>& v, std::uint64_t x, int bytes) {
  for (int i = 0; i < bytes; ++i) v.push_back(static_cast<std::uint8_t>(x >> (8 * i)));
}
const char* loc_status_name(std::uint8_t s) {
  static constexpr const char* kNames[] = {"no_map", "initialising", "tracking", "lost"};
  return s < 4 ? kNames[s] : "unknown";
}
std::string topic_hex(comms::Topic t) {
  char b[16];
  std::snprintf(b, sizeof b, "0x%08x", t);
  return b;
}
}  // namespace

WebTile::WebTile(const MapTileMsg& m, TimeNs received_at) noexcept
    : stamp(m.stamp), received(received_at), tx(m.tx), ty(m.ty), version(m.version), cls(m.cls) {
  for (std::size_t i = 0; i < kTileCellCount; ++i) {
    const float e = m.elevation[i];
    if (!std::isfinite(e)) elev_dm[i] = INT16_MIN;
    else {
      const float d = std::round(e * 10.0f);
      elev_dm[i] = static_cast<std::int16_t>(d < -32767.0f ? -32767.0f : d > 32767.0f ? 32767.0f : d);
    }
  }
}

std::vector<std::uint8_t> encode_tile_frame(const WebTile& t) {
  std::vector<std::uint8_t> v;
  v.reserve(kTileFrameHeader + kTileCellCount * 3);
  v.push_back(1);
  v.push_back(0);
  put_le(v, static_cast<std::uint64_t>(kTileCells), 2);
  put_le(v, static_cast<std::uint32_t>(t.tx), 4);
  put_le(v, static_cast<std::uint32_t>(t.ty), 4);
  put_le(v, 0, 4);
  put_le(v, t.version, 8);
  v.insert(v.end(), t.cls.begin(), t.cls.end());
  for (std::int16_t e : t.elev_dm) put_le(v, static_cast<std::uint16_t>(e), 2);
  return v;
}

WebService::WebService(const WebServiceParams& p, LatestValue<MissionModel>& snapshot, SpscRing<WebTile, kWebTileRing>& tiles,
                       SpscRing<LogItem, kLogRing>& log, SpscRing<OperatorRequest, kCommandRing>& commands, TimeNs start)
    : p_(p), snapshot_(snapshot), tiles_in_(tiles), log_in_(log), commands_out_(commands), start_(start), fox_(p.client_buffer_bytes, p.push_hz) {}

WebService::~WebService() {
  if (log_ != nullptr) std::fclose(log_);
}

Status WebService::open_log() {
  if (p_.log_path.empty()) return ok_status();
  log_ = std::fopen(p_.log_path.c_str(), "ae");
  if (log_ == nullptr)
    return Error::make(ErrorCode::kIo, "web.log_path: cannot open '" + p_.log_path + "' for appending: " + std::strerror(errno));
  return ok_status();
}

std::string WebService::hello_json() {
  std::string s;
  JsonOut j(s);
  j.begin_object().kv("type", "hello").ki("tile_cells", kTileCells).kn("resolution_m", kMapResolutionM, 3);
  j.key("classes").begin_array();
  for (const ClassInfo& c : ClassTable::builtin().all()) {
    j.begin_object().ki("id", static_cast<int>(c.id)).kv("name", c.name);
    j.key("color").begin_array().integer(c.color.r).integer(c.color.g).integer(c.color.b).end_array();
    j.end_object();
  }
  j.end_array().end_object();
  return s;
}

std::string WebService::state_json(const MissionModel& m, TimeNs start, const net::http::HttpServerCounters* http,
                                   std::uint64_t tiles_held, std::uint64_t log_lines, std::uint64_t log_errors,
                                   const std::string& foxglove) {
  std::string s;
  s.reserve(16384);
  JsonOut j(s);
  j.begin_object().kv("type", "state").ku("seq", m.seq).kn("t", secs(m.now - start), 3);
  j.key("robots").begin_array();
  for (std::size_t i = 0; i < m.robot_count; ++i) {
    const RobotView& r = m.robots[i];
    j.begin_object().ki("id", r.id).kb("has_pose", r.has_pose);
    if (r.has_pose) {
      j.kn("x", r.x, 2).kn("y", r.y, 2).kn("yaw", r.yaw, 3).kn("sx", r.sigma_x, 2).kn("sy", r.sigma_y, 2);
      j.kv("status", loc_status_name(r.loc_status));
    }
    j.kn("age_s", secs(m.now - r.heard), 1);
    j.key("trail").begin_array();
    for (std::uint32_t k = 0; k < r.trail_count; ++k) {
      const TrailPoint& p = r.trail[(r.trail_head + kTrailPoints - r.trail_count + k) % kTrailPoints];
      j.num(p.x, 2).num(p.y, 2);  // flat x, y pairs
    }
    j.end_array();
    if (r.has_claim) {
      const mission::ClaimRecord& c = r.claim;
      j.key("claim").begin_object().kv("state", mission::to_string(c.state)).ki("priority", c.priority);
      if (c.region_id == mission::kNoRegion) j.key("region").null();
      else j.ku("region", c.region_id);
      j.kn("gx", c.goal_x, 2).kn("gy", c.goal_y, 2).kn("sigma_m", c.pose_sigma_m, 2).end_object();
    }
    j.key("visited").begin_array();
    if (r.has_visited)
      for (std::size_t k = 0; k < r.visited.count; ++k)
        j.begin_object().ku("region", r.visited.entries[k].region_id).kn("x", r.visited.entries[k].x, 2).kn("y", r.visited.entries[k].y, 2).end_object();
    j.end_array();
    j.end_object();
  }
  j.end_array();
  j.key("regions").begin_object().ku("version", m.regions_version).ki("origin", m.regions_origin).key("list").begin_array();
  m.for_each_region([&](const mission::RegionRecord& e) {
    j.begin_object().ku("id", e.id).kn("cx", e.cx, 2).kn("cy", e.cy, 2).kn("gx", e.goal_x, 2).kn("gy", e.goal_y, 2);
    j.ki("cells", e.cells).kb("goal_valid", e.goal_valid).end_object();
  });
  j.end_array().end_object();
  j.key("failures").begin_array();
  for (std::size_t i = 0; i < m.failure_count; ++i) {
    const FailureView& f = m.failures[i];
    j.begin_object().ki("robot", f.origin).ku("region", f.f.region_id).kv("reason", mission::to_string(f.f.reason));
    j.ki("attempts", f.f.attempts).kn("x", f.f.x, 2).kn("y", f.f.y, 2).end_object();
  }
  j.end_array();
  j.key("objects").begin_array();
  for (std::size_t i = 0; i < m.object_count; ++i) {
    const ObjectView& o = m.objects[i];
    j.begin_object().ki("robot", o.origin).ku("id", o.o.object_id).ki("cls", o.o.cls).ki("detections", o.o.detections);
    j.kn("x", o.o.x, 2).kn("y", o.o.y, 2).kn("cxx", o.o.cxx, 3).kn("cxy", o.o.cxy, 3).kn("cyy", o.o.cyy, 3).end_object();
  }
  j.end_array();
  j.key("comms").begin_object().kb("present", m.has_comms);
  if (m.has_comms) {
    const comms::CommsStatsMsg& c = m.comms;
    j.ku("records", c.records).ku("payload_bytes", c.payload_bytes).ku("bytes_in", c.bytes_in).ku("bytes_out", c.bytes_out);
    j.ku("datagrams_in", c.datagrams_in).ku("datagrams_out", c.datagrams_out).ku("records_in", c.records_in);
    j.ku("tiles_in", c.tiles_in).ku("tiles_bad", c.tiles_bad);
    std::uint64_t drops = 0;
    for (auto d : c.drops) drops += d;
    j.ku("drops", drops);
    j.key("peers").begin_array();
    for (std::size_t i = 0; i < c.peers && i < c.peer.size(); ++i) {
      const comms::CommsPeerRow& p = c.peer[i];
      j.begin_object().ki("id", p.robot).ku("bytes_in", p.bytes_in).ku("bytes_out", p.bytes_out).ku("records_in", p.records_in);
      j.ku("records_out", p.records_out).kn("last_heard_s", p.last_heard > 0 ? secs(c.stamp - p.last_heard) : std::nan(""), 1).end_object();
    }
    j.end_array();
  }
  j.end_object();
  const ModelCounters& k = m.counters;
  j.key("counters").begin_object().ku("records_in", k.records_in).ku("poses_in", k.poses_in).ku("tiles_in", k.tiles_in);
  j.ku("decode_errors", k.decode_errors).ku("stale_regions", k.stale_regions).ku("table_full", k.table_full);
  j.ku("tiles_held_back", k.tiles_held_back).ku("log_dropped", k.log_dropped).ku("tiles_held", tiles_held).ku("commands_sent", k.commands_sent);
  j.ku("log_lines", log_lines).ku("log_errors", log_errors);
  if (k.decode_errors > 0)
    j.kv("last_error", error_name(static_cast<mission::DecodeError>(k.last_error))).kv("last_error_kind", to_string(static_cast<RecordKind>(k.last_error_kind)))
        .ki("last_error_origin", k.last_error_origin);
  j.end_object();
  if (http != nullptr) {
    j.key("server").begin_object().ku("clients", http->clients.load()).ku("ws_clients", http->ws_clients.load());
    j.ku("requests", http->requests.load()).ku("bad_requests", http->bad_requests.load()).ku("not_found", http->not_found.load());
    j.ku("rejected_full", http->rejected_full.load()).ku("slow_dropped", http->slow_dropped.load()).ku("bytes_out", http->bytes_out.load());
    j.end_object();
  }
  j.end_object();
  if (!foxglove.empty()) s.insert(s.size() - 1, ",\"foxglove\":{" + foxglove + "}");
  return s;
}

std::string WebService::log_line(const LogItem& it, TimeNs start) {
  std::string s;
  JsonOut j(s);
  timespec wall{};
  ::clock_gettime(CLOCK_REALTIME, &wall);
  j.begin_object().kn("t", secs(it.received - start), 3).kn("utc", static_cast<double>(wall.tv_sec) + static_cast<double>(wall.tv_nsec) * 1e-9, 3);
  if (it.kind == LogItem::Kind::kPose) {
    const comms::TeamPose& p = it.pose;
    j.ki("origin", p.robot).kv("kind", "pose").kn("stamp", secs(p.stamp), 3);
    j.key("fields").begin_object().kn("x", p.pose.x, 3).kn("y", p.pose.y, 3).kn("yaw", p.pose.yaw, 4).kv("status", loc_status_name(p.status));
    j.kn("sx", p.sigma_x_m, 3).kn("sy", p.sigma_y_m, 3).kn("syaw", p.sigma_yaw_rad, 4).end_object();
    j.end_object();
    return s;
  }
  const comms::GossipRecordMsg& r = it.rec;
  const RecordKind kind = record_kind(r.key.topic);
  j.ki("origin", r.key.origin).kv("kind", to_string(kind)).kv("topic", topic_hex(r.key.topic)).ku("seq", r.seq);
  j.kn("stamp", secs(r.stamp), 3).ku("size", r.size);
  const std::span<const std::uint8_t> in(r.payload.data(), std::min<std::size_t>(r.size, r.payload.size()));
  mission::DecodeError e = mission::DecodeError::kOk;
  j.key("fields").begin_object();
  switch (kind) {
    case RecordKind::kRegions: {
      mission::RegionBatch b;
      e = mission::decode_detailed(in, b);
      if (e != mission::DecodeError::kOk) break;
      j.ku("batch", comms::topic_index(r.key.topic)).ku("batches", b.batches).ku("version", b.regions_version).key("regions").begin_array();
      for (std::size_t i = 0; i < b.count; ++i) {
        const mission::RegionRecord& x = b.regions[i];
        j.begin_object().ku("id", x.id).kn("cx", x.cx, 2).kn("cy", x.cy, 2).kn("gx", x.goal_x, 2).kn("gy", x.goal_y, 2).ki("cells", x.cells);
        j.kb("goal_valid", x.goal_valid).end_object();
      }
      j.end_array();
      break;
    }
    case RecordKind::kClaim: {
      mission::ClaimRecord c;
      e = mission::decode_detailed(in, c);
      if (e != mission::DecodeError::kOk) break;
      j.kv("state", mission::to_string(c.state)).ki("priority", c.priority);
      if (c.region_id == mission::kNoRegion) j.key("region").null();
      else j.ku("region", c.region_id);
      j.kn("gx", c.goal_x, 2).kn("gy", c.goal_y, 2).kn("sigma_m", c.pose_sigma_m, 2);
      break;
    }
    case RecordKind::kVisited: {
      mission::VisitedRecord v;
      e = mission::decode_detailed(in, v);
      if (e != mission::DecodeError::kOk) break;
      j.key("visited").begin_array();
      for (std::size_t i = 0; i < v.count; ++i)
        j.begin_object().ku("region", v.entries[i].region_id).kn("x", v.entries[i].x, 2).kn("y", v.entries[i].y, 2).end_object();
      j.end_array();
      break;
    }
    case RecordKind::kFailure: {
      mission::FailureRecord f;
      e = mission::decode_detailed(in, f);
      if (e != mission::DecodeError::kOk) break;
      j.ku("region", f.region_id).kv("reason", mission::to_string(f.reason)).ki("attempts", f.attempts).kn("x", f.x, 2).kn("y", f.y, 2);
      break;
    }
    case RecordKind::kObject: {
      mission::ObjectRecord o;
      e = mission::decode_detailed(in, o);
      if (e != mission::DecodeError::kOk) break;
      j.ku("id", o.object_id).ki("cls", o.cls).ki("detections", o.detections).kn("x", o.x, 2).kn("y", o.y, 2);
      j.kn("cxx", o.cxx, 3).kn("cxy", o.cxy, 3).kn("cyy", o.cyy, 3);
      break;
    }
    case RecordKind::kStatus:
    case RecordKind::kOther: break;
  }
  j.end_object();
  if (e != mission::DecodeError::kOk) j.kv("error", error_name(e));
  j.end_object();
  return s;
}

std::string WebService::tile_log_line(const WebTile& t, TimeNs received, TimeNs start) {
  std::string s;
  JsonOut j(s);
  timespec wall{};
  ::clock_gettime(CLOCK_REALTIME, &wall);
  std::size_t known = 0;
  for (std::uint8_t c : t.cls) known += c != 255 ? 1 : 0;
  j.begin_object().kn("t", secs(received - start), 3).kn("utc", static_cast<double>(wall.tv_sec) + static_cast<double>(wall.tv_nsec) * 1e-9, 3);
  j.kv("kind", "map_tile").kn("stamp", secs(t.stamp), 3);
  j.key("fields").begin_object().ki("tx", t.tx).ki("ty", t.ty).ku("version", t.version).ku("known_cells", known).end_object();
  j.end_object();
  return s;
}

void WebService::drain_log() noexcept {
  bool wrote = false;
  while (LogItem* it = log_in_.front()) {
    if (log_ != nullptr) {
      const std::string line = log_line(*it, start_);
      if (std::fputs(line.c_str(), log_) < 0 || std::fputc('\n', log_) == EOF) ++log_errors_;
      else ++log_lines_;
      wrote = true;
    }
    log_in_.pop();
  }
  if (wrote && std::fflush(log_) != 0) ++log_errors_;
}

void WebService::take_tiles() noexcept {
  bool wrote = false;
  while (WebTile* t = tiles_in_.front()) {
    const Key k{t->tx, t->ty};
    auto it = tiles_.find(k);
    std::uint64_t held_version = 0;
    if (it != tiles_.end() && it->second.size() >= kTileFrameHeader)
      for (int b = 0; b < 8; ++b) held_version |= std::uint64_t{it->second[16 + static_cast<std::size_t>(b)]} << (8 * b);
    if (it == tiles_.end() || t->version > held_version) {
      tiles_[k] = encode_tile_frame(*t);
      if (p_.foxglove) fox_.tile(*t);
      for (auto& [id, c] : clients_)
        if (c.queued.insert(k).second) c.pending.push_back(k);
      if (log_ != nullptr) {
        const std::string line = tile_log_line(*t, t->received, start_);
        if (std::fputs(line.c_str(), log_) < 0 || std::fputc('\n', log_) == EOF) ++log_errors_;
        else ++log_lines_;
        wrote = true;
      }
    }
    tiles_in_.pop();
  }
  if (wrote) std::fflush(log_);
}

void WebService::refresh_model() noexcept {
  if (snapshot_.fresh() || model_ == nullptr) model_ = &snapshot_.read();
}

const std::string& WebService::current_state(const net::http::HttpServer* s) {
  refresh_model();
  if (s != nullptr) http_ = &s->counters();
  if (model_->seq != state_seq_ || state_.empty()) {
    state_ = state_json(*model_, start_, http_, tiles_.size(), log_lines_, log_errors_, p_.foxglove ? fox_.counters_json() : std::string());
    state_seq_ = model_->seq;
  }
  return state_;
}

void WebService::push_tiles(net::http::HttpServer& s) {
  for (auto& [id, c] : clients_) {
    std::size_t sent = 0;
    while (!c.pending.empty() && s.ws_pending(id) < p_.client_buffer_bytes / 4) {
      const Key k = c.pending.front();
      c.pending.pop_front();
      c.queued.erase(k);
      auto it = tiles_.find(k);
      if (it == tiles_.end()) continue;
      if (!s.ws_send(id, net::http::WsOpcode::kBinary, it->second)) break;
      ++sent;
    }
    (void)sent;
  }
}

void WebService::tick(net::http::HttpServer& s) {
  http_ = &s.counters();
  take_tiles();
  drain_log();
  const TimeNs now = monotonic_now();
  const auto period = static_cast<TimeNs>(1e9 / p_.push_hz);
  if (now - last_push_ >= period) {
    const std::string& st = current_state(&s);
    if (state_seq_ != pushed_seq_ || now - last_push_ >= kNsPerS) {
      for (auto id : s.ws_clients()) {
        if (fox_.has(id)) continue;  // Foxglove clients get their own messages
        if (s.ws_pending(id) > p_.client_buffer_bytes / 2) {
          ++state_skipped_;  // it still has the last one to read; the next push carries everything
          continue;
        }
        s.ws_send_text(id, st);
      }
      pushed_seq_ = state_seq_;
      last_push_ = now;
    }
  }
  push_tiles(s);
  if (p_.foxglove) {
    refresh_model();
    fox_.tick(s, *model_, [this] { return counters_members(); });
  }
}

std::string WebService::counters_members() const {
  std::string s;
  JsonOut j(s);
  j.begin_object();
  if (model_ != nullptr) {
    const ModelCounters& k = model_->counters;
    j.key("model").begin_object().ku("records_in", k.records_in).ku("poses_in", k.poses_in).ku("tiles_in", k.tiles_in);
    j.ku("decode_errors", k.decode_errors).ku("stale_regions", k.stale_regions).ku("table_full", k.table_full);
    j.ku("tiles_held_back", k.tiles_held_back).ku("log_dropped", k.log_dropped).ku("log_lines", log_lines_).ku("log_errors", log_errors_);
    j.end_object();
  }
  if (http_ != nullptr) {
    j.key("server").begin_object().ku("clients", http_->clients.load()).ku("ws_clients", http_->ws_clients.load());
    j.ku("requests", http_->requests.load()).ku("bad_requests", http_->bad_requests.load()).ku("ws_bad_frames", http_->ws_bad_frames.load());
    j.ku("slow_dropped", http_->slow_dropped.load()).ku("bytes_out", http_->bytes_out.load()).end_object();
  }
  j.end_object();
  return s.size() > 2 ? s.substr(1, s.size() - 2) : std::string("\"model\":{}");
}

std::string WebService::ws_subprotocol(const net::http::HttpRequest& req) {
  if (p_.foxglove && req.header_has_token("sec-websocket-protocol", kFoxgloveSubprotocol)) return std::string(kFoxgloveSubprotocol);
  return {};
}

void WebService::ws_message(net::http::HttpServer& s, net::http::HttpServer::ClientId id, net::http::WsOpcode op,
                            std::span<const std::uint8_t> payload) {
  if (fox_.has(id)) fox_.message(s, id, op, payload);  // the page's own clients send nothing we read
}

void WebService::ws_open(net::http::HttpServer& s, net::http::HttpServer::ClientId id) {
  if (s.ws_protocol(id) == kFoxgloveSubprotocol) {
    fox_.open(s, id);
    return;
  }
  Client& c = clients_[id];
  for (const auto& [k, v] : tiles_)
    if (c.queued.insert(k).second) c.pending.push_back(k);
  s.ws_send_text(id, hello_json());
  s.ws_send_text(id, current_state(&s));
}

void WebService::ws_close(net::http::HttpServer::ClientId id) {
  clients_.erase(id);
  fox_.close(id);
}

net::http::HttpResponse WebService::get(const net::http::HttpRequest& req) {
  std::string_view path = req.path;
  if (path == "/") path = "/index.html";
  for (const WebAsset& a : web_assets())
    if (path == a.path) return {200, a.mime, std::string(reinterpret_cast<const char*>(a.data), a.size), {}};
  if (path == "/api/state") return {200, "application/json", current_state(nullptr), {}};
  if (path == "/api/hello" || path == "/api/classes") return {200, "application/json", hello_json(), {}};
  if (path == "/api/arm" || path == "/api/disarm")
    return {405, "text/plain; charset=utf-8", "use POST " + std::string(path) + "?robot=N\n", "Allow: POST\r\n"};
  return {404, "text/plain; charset=utf-8",
          "not found: " + std::string(req.path) + "\n(try / , /api/state, the WebSocket /ws, or Foxglove's WebSocket (foxglove.websocket.v1) at /)\n", {}};
}

net::http::HttpResponse WebService::post(const net::http::HttpRequest& req) {
  const bool arm = req.path == "/api/arm";
  if (!arm && req.path != "/api/disarm")
    return {404, "text/plain; charset=utf-8", "not found: POST " + req.path + "\n(POST /api/arm?robot=N or /api/disarm?robot=N)\n", {}};
  // robot=N, 0..254, not this base station
  long id = -1;
  for (std::size_t pos = 0; pos <= req.query.size();) {
    const std::size_t end = std::min(req.query.find('&', pos), req.query.size());
    const std::string_view kv = std::string_view(req.query).substr(pos, end - pos);
    if (kv.rfind("robot=", 0) == 0) {
      const std::string v(kv.substr(6));
      char* e = nullptr;
      errno = 0;
      const long n = std::strtol(v.c_str(), &e, 10);
      id = (!v.empty() && e != nullptr && *e == '\0' && errno == 0) ? n : -2;
    }
    pos = end + 1;
  }
  if (id < 0 || id >= comms::kMaxRobots || id == p_.self)
    return {400, "text/plain; charset=utf-8",
            "bad request: " + req.path + " needs ?robot=N, a ground robot's robot.id (0..254, not the base station's own)\n", {}};
  const OperatorRequest r{static_cast<comms::RobotId>(id), arm ? comms::OperatorCommand::kArm : comms::OperatorCommand::kDisarm, requests_ + 1};
  if (!commands_out_.try_push(r)) return {503, "text/plain; charset=utf-8", "busy: the last commands are still on their way to the radio; try again\n", "Retry-After: 1\r\n"};
  ++requests_;
  AG_LOG_INFO("web", "operator: %s robot %ld (request %u)", arm ? "arm" : "disarm", id, r.request);
  char body[128];
  std::snprintf(body, sizeof body, "{\"robot\": %ld, \"command\": \"%s\", \"request\": %u}\n", id, arm ? "arm" : "disarm", r.request);
  return {202, "application/json", body, {}};
}

}  // namespace ag::base_station
