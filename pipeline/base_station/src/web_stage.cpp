#include "airground/base_station/web_stage.hpp"

#include "airground/comms/messages.hpp"
#include "airground/messages/channels.hpp"
#include "airground/platform/log.hpp"
#include "web_service.hpp"

namespace ag::base_station {

WebStage::WebStage() = default;

WebStage::~WebStage() { stop(); }

Status WebStage::init(StageContext& ctx) {
  const WebSettings cfg = load_params(ctx.params(), kWebStageFields);
  tiles_per_step_ = static_cast<std::size_t>(cfg.tiles_per_step);
  auto team = ctx.channels.latest_reader(chan::kTeamPoses);
  if (!team) return team.error();
  team_ = team.value();
  auto stats = ctx.channels.latest_reader(chan::kCommsStats);
  if (!stats) return stats.error();
  stats_ = stats.value();
  auto tiles = ctx.channels.ring_reader(chan::kMapTiles);
  if (!tiles) return tiles.error();
  tiles_ = tiles.value();
  auto recs = ctx.channels.ring_reader(chan::kGossipIn);
  if (!recs) return recs.error();
  records_ = recs.value();

  model_ = std::make_unique<MissionModel>();
  snapshot_ = std::make_unique<LatestValue<MissionModel>>();
  tiles_to_server_ = std::make_unique<SpscRing<WebTile, kWebTileRing>>();
  log_to_server_ = std::make_unique<SpscRing<LogItem, kLogRing>>();
  commands_from_server_ = std::make_unique<SpscRing<OperatorRequest, kCommandRing>>();
  out_msg_ = std::make_unique<comms::GossipPublishMsg>();
  auto gout = ctx.channels.ring_writer(chan::kGossipOut);
  if (!gout) return gout.error();
  gossip_out_ = gout.value();
  model_->now = ctx.clock.now();

  WebServiceParams sp;
  sp.log_path = cfg.log_path;
  sp.push_hz = cfg.push_hz;
  sp.client_buffer_bytes = static_cast<std::size_t>(cfg.client_buffer_kb) * 1024;
  sp.foxglove = cfg.foxglove;
  sp.self = static_cast<comms::RobotId>(ctx.config.get_int("robot.id"));
  service_ = std::make_unique<WebService>(sp, *snapshot_, *tiles_to_server_, *log_to_server_, *commands_from_server_, ctx.clock.now());
  if (auto st = service_->open_log(); !st) return st.error();

  net::http::HttpServerParams hp;
  hp.bind = cfg.bind;
  hp.port = cfg.port;
  hp.max_clients = static_cast<std::size_t>(cfg.max_clients);
  hp.client_buffer_bytes = sp.client_buffer_bytes;
  hp.slow_client_s = cfg.slow_client_s;
  hp.name = std::string(ctx.stage_name);
  auto srv = net::http::HttpServer::start(hp, *service_);
  if (!srv) return srv.error();
  server_ = std::move(srv).value();
  if (!sp.log_path.empty()) AG_LOG_INFO(hp.name.c_str(), "mission log %s", sp.log_path.c_str());
  return ok_status();
}

void WebStage::step(TimeNs now) noexcept {
  MissionModel& m = *model_;
  // The operator's commands: held in the server's ring while gossip_out is full.
  while (const OperatorRequest* r = commands_from_server_->front()) {
    if (gossip_out_.free_slots() == 0) break;
    comms::GossipPublishMsg& g = *out_msg_;
    g.stamp = now;
    g.published = now;
    g.topic = comms::command_topic(r->robot);
    g.priority = 0;  // the kind's default
    g.size = static_cast<std::uint32_t>(comms::encode_command(r->command, r->request, std::span<std::uint8_t>(g.payload.data(), g.payload.size())));
    (void)gossip_out_.push(g);
    ++m.counters.commands_sent;
    ++m.seq;
    commands_from_server_->pop();
  }
  // Tiles: held in the channel while the server's hand-over is full (nothing is lost).
  for (std::size_t k = 0; k < tiles_per_step_; ++k) {
    MapTileMsg* t = tiles_.front();
    if (t == nullptr) break;
    if (!tiles_to_server_->try_emplace(*t, now)) {
      ++m.counters.tiles_held_back;
      break;
    }
    ++m.counters.tiles_in;
    ++m.seq;
    tiles_.pop();
  }
  while (comms::GossipRecordMsg* r = records_.front()) {
    mission::DecodeError err = mission::DecodeError::kOk;
    m.apply_record(*r, now, err);
    if (!log_to_server_->try_emplace(now, *r)) ++m.counters.log_dropped;
    records_.pop();
  }
  if (team_.fresh()) {
    const comms::TeamPosesMsg& team = team_.read();
    for (std::uint32_t i = 0; i < team.count && i < team.robots.size(); ++i) {
      const comms::TeamPose& p = team.robots[i];
      const RobotView* r = m.find_robot(p.robot);
      if (r != nullptr && r->has_pose && p.stamp <= r->pose_stamp) continue;
      if (!log_to_server_->try_emplace(now, p)) ++m.counters.log_dropped;
    }
    m.apply_poses(team, now);
  }
  // Comms counters change every step: taken twice a second, so the model is not copied every step for them.
  if (stats_.fresh() && now - last_comms_ >= kNsPerS / 2) {
    m.apply_comms(stats_.read());
    last_comms_ = now;
  }
  if (m.seq != published_seq_) {
    m.now = now;
    snapshot_->write_slot() = m;
    snapshot_->publish();
    published_seq_ = m.seq;
  }
}

void WebStage::stop() noexcept {
  if (server_) {
    server_->stop();
    server_.reset();
  }
  if (service_) service_->flush();
}

int WebStage::port() const noexcept { return server_ ? server_->port() : 0; }

const net::http::HttpServerCounters* WebStage::server_counters() const noexcept { return server_ ? &server_->counters() : nullptr; }

std::string WebStage::foxglove_counters_json() const { return service_ ? service_->foxglove_counters_json() : std::string(); }

}  // namespace ag::base_station
