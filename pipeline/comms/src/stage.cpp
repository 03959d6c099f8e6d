// The comms stage: channels in, GossipNode over the configured link, channels and stats out.
#include "airground/comms/stage.hpp"

#include <sys/stat.h>

#include <cmath>
#include <cstring>
#include <ctime>
#include <map>
#include <mutex>
#include <string>

#include "airground/comms/bytes.hpp"
#include "airground/comms/messages.hpp"
#include "airground/drivers/net/udp/udp_link.hpp"
#include "airground/messages/channels.hpp"
#include "airground/platform/log.hpp"

namespace ag::comms {

namespace {
std::mutex g_links_mutex;
std::map<std::string, DatagramLink*, std::less<>>& links() {
  static std::map<std::string, DatagramLink*, std::less<>> m;
  return m;
}
std::uint64_t bits(double v) noexcept {
  std::uint64_t b = 0;
  std::memcpy(&b, &v, 8);
  return b;
}
std::uint32_t bits(float v) noexcept {
  std::uint32_t b = 0;
  std::memcpy(&b, &v, 4);
  return b;
}
template <typename T, typename U>
T from_bits(U b) noexcept {
  T v;
  std::memcpy(&v, &b, sizeof v);
  return v;
}
std::vector<std::string> split_commas(const std::string& s) {
  std::vector<std::string> out;
  std::size_t a = 0;
  while (a <= s.size()) {
    std::size_t b = s.find(',', a);
    if (b == std::string::npos) b = s.size();
    std::string item = s.substr(a, b - a);
    while (!item.empty() && item.front() == ' ') item.erase(item.begin());
    while (!item.empty() && item.back() == ' ') item.pop_back();
    if (!item.empty()) out.push_back(item);
    a = b + 1;
  }
  return out;
}
}  // namespace

void register_inproc_link(std::string_view instance, DatagramLink* link) {
  std::lock_guard<std::mutex> lock(g_links_mutex);
  if (link == nullptr) {
    const auto it = links().find(instance);
    if (it != links().end()) links().erase(it);
  } else {
    links()[std::string(instance)] = link;
  }
}

DatagramLink* find_inproc_link(std::string_view instance) {
  std::lock_guard<std::mutex> lock(g_links_mutex);
  const auto it = links().find(instance);
  return it == links().end() ? nullptr : it->second;
}

std::size_t CommsStage::encode_pose(const LocalizationMsg& m, std::span<std::uint8_t> out) noexcept {
  ByteWriter w(out);
  w.u64(bits(m.pose.x));
  w.u64(bits(m.pose.y));
  w.u64(bits(m.pose.yaw));
  w.u8(static_cast<std::uint8_t>(m.status));
  w.u32(bits(static_cast<float>(std::sqrt(std::max(0.0, m.covariance[0])))));
  w.u32(bits(static_cast<float>(std::sqrt(std::max(0.0, m.covariance[4])))));
  w.u32(bits(static_cast<float>(std::sqrt(std::max(0.0, m.covariance[8])))));
  return w.ok() ? w.size() : 0;
}

bool CommsStage::decode_pose(std::span<const std::uint8_t> in, TeamPose& out) noexcept {
  if (in.size() != kPosePayloadBytes) return false;
  ByteReader r(in);
  std::uint64_t x = 0, y = 0, yaw = 0;
  std::uint32_t sx = 0, sy = 0, syaw = 0;
  r.u64(x);
  r.u64(y);
  r.u64(yaw);
  r.u8(out.status);
  r.u32(sx);
  r.u32(sy);
  r.u32(syaw);
  out.pose = Pose2{from_bits<double>(x), from_bits<double>(y), from_bits<double>(yaw)};
  out.sigma_x_m = from_bits<float>(sx);
  out.sigma_y_m = from_bits<float>(sy);
  out.sigma_yaw_rad = from_bits<float>(syaw);
  return r.ok() && std::isfinite(out.pose.x) && std::isfinite(out.pose.y) && std::isfinite(out.pose.yaw);
}

Status CommsStage::init(StageContext& ctx) {
  const CommsSettings cfg = load_params(ctx.params(), kCommsStageFields);
  const std::string where = "config error: " + std::string(ctx.stage_name) + ".";
  self_ = static_cast<RobotId>(ctx.config.get_int("robot.id"));
  send_pose_ = cfg.send_pose;
  send_tiles_ = cfg.send_map_tiles;
  deliver_tiles_ = cfg.deliver_map_tiles;
  deliver_commands_ = cfg.deliver_commands;
  if (send_tiles_ && deliver_tiles_)
    return Error::make(ErrorCode::kConfig, where + "send_map_tiles and deliver_map_tiles: a robot either makes the map or receives it, not both");
  tiles_per_step_ = static_cast<std::size_t>(cfg.tiles_per_step);
  pose_period_ = from_seconds(cfg.pose_period_s);

  StoreLimits lim;
  lim.max_records = static_cast<std::size_t>(cfg.max_records);
  lim.arena_bytes = static_cast<std::size_t>(cfg.store_mb * 1024.0 * 1024.0);
  lim.max_payload_bytes = std::max<std::size_t>(TileCodec::max_payload_bytes(), kGossipPayloadMax);
  store_ = std::make_unique<RecordStore>(lim);

  std::uint32_t min_epoch = 1;
  if (cfg.epoch_from_clock) {
    const std::time_t t = std::time(nullptr);
    if (t > 1577836800) min_epoch = static_cast<std::uint32_t>(t - 1577836800);  // seconds since 2020
  }
  std::uint32_t epoch = min_epoch;
  const std::string& journal_path = cfg.journal;
  if (!journal_path.empty()) {
    auto j = Journal::open(journal_path, *store_, min_epoch, report_);
    if (!j) return j.error();
    journal_ = std::move(j.value());
    epoch = journal_->epoch();
    if (report_.bad_regions > 0)
      AG_LOG_WARN("comms", "journal %s: %zu damaged region(s), %zu bytes skipped (counted); first: %s", journal_path.c_str(),
                  report_.bad_regions, report_.bad_bytes, report_.problems.substr(0, report_.problems.find('\n')).c_str());
    AG_LOG_INFO("comms", "journal %s: %zu records restored (%zu bytes read), boot epoch %u", journal_path.c_str(),
                report_.records_loaded, report_.bytes, epoch);
  }

  const std::string& transport = cfg.transport;
  TeamKey key{};
  if (transport != "none") {
    auto k = TeamKey::load_file(cfg.key_file);
    if (!k) return Error::make(k.error().code, where + "key_file: " + k.error().message);
    key = k.value();
    struct stat st{};
    if (::stat(cfg.key_file.c_str(), &st) == 0 && (st.st_mode & S_IROTH) != 0)
      AG_LOG_WARN("comms", "team key %s is readable by every user: chmod o-r it (anyone holding it can speak for the team)",
                  cfg.key_file.c_str());
  }
  GossipParams gp;
  gp.self = self_;
  gp.mtu_bytes = static_cast<std::size_t>(cfg.mtu_bytes);
  gp.digest_period_s = cfg.digest_period_s;
  gp.budget_bytes_per_s = cfg.budget_bytes_per_s;
  gp.broadcast_budget_bytes_per_s = cfg.broadcast_budget_bytes_per_s;
  gp.peer_timeout_s = cfg.peer_timeout_s;
  gp.seed = 0x636F6D6DULL + self_;
  if (transport == "udp") {
    net::UdpLinkConfig uc;
    uc.bind_address = cfg.bind;
    uc.port = cfg.port;
    uc.broadcast_address = cfg.broadcast;
    uc.peers = split_commas(cfg.peers);
    uc.device = cfg.device;
    uc.mtu = gp.mtu_bytes;
    auto link = net::UdpLink::open(uc);
    if (!link) return Error::make(link.error().code, std::string(ctx.stage_name) + ": " + link.error().message);
    owned_link_ = std::move(link.value());
    link_ = owned_link_.get();
    AG_LOG_INFO("comms", "robot %u gossiping on udp %s:%u (broadcast '%s', %zu unicast peers)", self_, uc.bind_address.c_str(),
                static_cast<unsigned>(uc.port), uc.broadcast_address.c_str(), uc.peers.size());
  } else if (transport == "inproc") {
    link_ = find_inproc_link(ctx.instance);
    if (link_ == nullptr)
      return Error::make(ErrorCode::kConfig, where + "transport: inproc, but no link is registered for robot '" + std::string(ctx.instance) + "'");
    gp.mtu_bytes = std::min(gp.mtu_bytes, link_->mtu());
  }
  // Operator commands the journal restored were given before this start: they never act again.
  for (RecordStore::Slot s = 0; s < store_->size(); ++s) {
    const RecordMeta& m = store_->meta(s);
    if (m.key.topic == command_topic(self_) && m.key.origin < kMaxRobots) command_seen_[m.key.origin] = std::max(command_seen_[m.key.origin], m.seq);
  }
  node_ = std::make_unique<GossipNode>(gp, key, *store_, epoch, journal_.get());
  node_->announce_all();  // what the journal restored reaches this robot's stages too

  codec_ = std::make_unique<TileCodec>();
  tile_ = std::make_unique<MapTileMsg>();
  buf_.resize(std::max<std::size_t>(TileCodec::max_payload_bytes(), kGossipPayloadMax));
  rec_ = std::make_unique<GossipRecordMsg>();
  team_ = std::make_unique<TeamPosesMsg>();
  stats_ = std::make_unique<CommsStatsMsg>();

  auto out_in = ctx.channels.ring_reader(chan::kGossipOut);
  if (!out_in) return out_in.error();
  out_in_ = out_in.value();
  ctx.channels.allow_unwritten(chan::kGossipOut);  // the base station publishes no records: it only relays
  auto gin = ctx.channels.ring_writer(chan::kGossipIn);
  if (!gin) return gin.error();
  gossip_in_ = gin.value();
  if (send_pose_) {
    auto r = ctx.channels.latest_reader(chan::kLocalization);
    if (!r) return r.error();
    pose_in_ = r.value();
  }
  if (send_tiles_) {
    auto r = ctx.channels.ring_reader(chan::kMapTiles);
    if (!r) return r.error();
    tiles_in_ = r.value();
  }
  if (deliver_tiles_) {
    auto w = ctx.channels.ring_writer(chan::kMapTiles);
    if (!w) return w.error();
    tiles_out_ = w.value();
  }
  auto team = ctx.channels.latest_writer(chan::kTeamPoses);
  if (!team) return team.error();
  team_out_ = team.value();
  auto st = ctx.channels.latest_writer(chan::kCommsStats);
  if (!st) return st.error();
  stats_out_ = st.value();
  if (deliver_commands_) {
    auto arm = ctx.channels.latest_writer(chan::kRadioArm);
    if (!arm) return arm.error();
    arm_out_ = arm.value();
  }

  return ok_status();
}

void CommsStage::take_own(TimeNs now) noexcept {
  for (GossipPublishMsg* m = out_in_.front(); m != nullptr; m = out_in_.front()) {
    const std::size_t n = std::min<std::size_t>(m->size, m->payload.size());
    const std::uint8_t prio = m->priority != 0 ? m->priority : default_priority(topic_kind(m->topic));
    if (topic_kind_known(m->topic)) (void)node_->publish(m->topic, prio, m->stamp != 0 ? m->stamp : now, std::span<const std::uint8_t>(m->payload.data(), n));
    out_in_.pop();
  }
  if (send_pose_ && pose_in_.connected() && (last_pose_ < 0 || now - last_pose_ >= pose_period_)) {
    const LocalizationMsg& lm = pose_in_.read();
    if (lm.stamp != last_pose_stamp_ && lm.status != LocalizationStatus::kNoMap) {
      const std::size_t n = encode_pose(lm, buf_);
      (void)node_->publish(make_topic(TopicKind::kPose, 0), default_priority(TopicKind::kPose), lm.stamp,
                           std::span<const std::uint8_t>(buf_.data(), n));
      last_pose_ = now;
      last_pose_stamp_ = lm.stamp;
    }
  }
  if (send_tiles_) {
    for (std::size_t k = 0; k < tiles_per_step_; ++k) {
      MapTileMsg* t = tiles_in_.front();
      if (t == nullptr) break;
      if (tile_index_ok(t->tx, t->ty)) {
        const std::size_t n = codec_->encode(*t, buf_);
        if (n > 0 && node_->publish(tile_topic(t->tx, t->ty), default_priority(TopicKind::kMapTile), t->stamp,
                                    std::span<const std::uint8_t>(buf_.data(), n)) != PutResult::kFull)
          ++tiles_out_n_;
      } else {
        ++tiles_bad_;
      }
      tiles_in_.pop();
    }
  }
}

void CommsStage::take_command(const RecordMeta& m, std::span<const std::uint8_t> payload, TimeNs now) noexcept {
  OperatorCommand c{};
  std::uint32_t request = 0;
  if (!decode_command(payload, c, request)) {
    if (commands_bad_++ == 0) AG_LOG_WARN("comms", "an operator command from robot %u is malformed (%u bytes): ignored (counted)", m.key.origin, m.size);
    return;
  }
  if (m.key.origin >= kMaxRobots || m.seq <= command_seen_[m.key.origin]) {
    ++commands_stale_;
    return;
  }
  command_seen_[m.key.origin] = m.seq;
  ++commands_in_;
  AG_LOG_INFO("comms", "operator command from robot %u: %s (request %u)", m.key.origin, c == OperatorCommand::kArm ? "arm" : "disarm", request);
  arm_out_.publish(BaseArmMsg{now, now, c == OperatorCommand::kArm});
}

void CommsStage::deliver(TimeNs now) noexcept {
  std::size_t tiles = 0;
  RecordStore::Slot s;
  bool team_changed = false;
  while (node_->pending_change(s)) {
    const RecordMeta& m = store_->meta(s);
    const auto payload = store_->payload(s);
    const TopicKind kind = topic_kind(m.key.topic);
    if (m.key.origin == self_) {
      node_->pop_change();
      continue;
    }
    if (kind == TopicKind::kMapTile) {
      if (deliver_tiles_) {
        if (tiles >= tiles_per_step_ || tiles_out_.free_slots() == 0) break;  // the rest next step
        if (codec_->decode(payload, *tile_) && tile_topic(tile_->tx, tile_->ty) == m.key.topic) {
          tile_->published = now;
          (void)tiles_out_.push(*tile_);
          ++tiles_in_n_;
        } else {
          ++tiles_bad_;
        }
        ++tiles;
      }
    } else if (kind == TopicKind::kCommand) {
      if (deliver_commands_ && m.key.topic == command_topic(self_)) take_command(m, payload, now);
    } else if (kind == TopicKind::kPose) {
      TeamPose p;
      if (decode_pose(payload, p)) {
        p.robot = m.key.origin;
        p.stamp = m.stamp;
        std::uint32_t i = 0;
        while (i < team_->count && team_->robots[i].robot != p.robot) ++i;
        if (i < kTeamMax) {
          team_->robots[i] = p;
          if (i == team_->count) ++team_->count;
          team_changed = true;
        }
      }
    } else if (m.size <= kGossipPayloadMax) {
      rec_->stamp = m.stamp;
      rec_->published = now;
      rec_->key = m.key;
      rec_->seq = m.seq;
      rec_->priority = m.priority;
      rec_->size = m.size;
      std::memcpy(rec_->payload.data(), payload.data(), m.size);
      (void)gossip_in_.push(*rec_);
    } else {
      ++undeliverable_;
    }
    node_->pop_change();
  }
  if (team_changed) {
    team_->stamp = now;
    team_->published = now;
    team_out_.publish(*team_);
  }
}

void CommsStage::publish_stats(TimeNs now) noexcept {
  const GossipStats& g = node_->stats();
  CommsStatsMsg& s = *stats_;
  s.stamp = now;
  s.published = now;
  s.records = static_cast<std::uint32_t>(store_->size());
  s.payload_bytes = store_->payload_bytes();
  s.datagrams_in = g.datagrams_in;
  s.bytes_in = g.bytes_in;
  s.datagrams_out = g.datagrams_out;
  s.bytes_out = g.bytes_out;
  s.records_in = g.records_in;
  s.records_out = g.records_out;
  s.own_records = g.own_records;
  s.journal_appends = journal_ ? journal_->appended() : 0;
  s.journal_errors = g.journal_errors;
  s.link_send_failures = g.send_failures;
  s.budget_waits = g.budget_waits;
  s.tiles_out = tiles_out_n_;
  s.tiles_in = tiles_in_n_;
  s.tiles_bad = tiles_bad_;
  s.commands_in = commands_in_;
  s.commands_stale = commands_stale_;
  s.commands_bad = commands_bad_;
  s.drops = g.drops;
  s.peers = 0;
  for (int r = 0; r < kMaxRobots && s.peers < kTeamMax; ++r) {
    const PeerStats& p = node_->peer_stats(static_cast<RobotId>(r));
    if (!p.seen && p.datagrams_out == 0) continue;
    CommsPeerRow& row = s.peer[s.peers++];
    row.robot = static_cast<RobotId>(r);
    row.datagrams_in = p.datagrams_in;
    row.bytes_in = p.bytes_in;
    row.records_in = p.records_in;
    row.datagrams_out = p.datagrams_out;
    row.bytes_out = p.bytes_out;
    row.records_out = p.records_out;
    row.duplicates_in = p.duplicates_in;
    row.last_heard = p.last_heard;
  }
  stats_out_.publish(s);
  // One warning the first time each reason shows up; the counts are in comms_stats.
  for (std::size_t i = 0; i < g.drops.size(); ++i) {
    if (g.drops[i] != 0 && logged_drops_[i] == 0 && static_cast<DropReason>(i) != DropReason::kOwnEcho)
      AG_LOG_WARN("comms", "dropped a datagram: %s (counted in comms_stats, logged once)%s", drop_reason_name(static_cast<DropReason>(i)),
                  static_cast<DropReason>(i) == DropReason::kIdClash ? ": another robot uses this robot.id; give each robot its own" : "");
    logged_drops_[i] = g.drops[i];
  }
}

void CommsStage::step(TimeNs now) noexcept {
  take_own(now);
  if (link_ != nullptr) node_->tick(now, *link_);
  deliver(now);
  publish_stats(now);
}

void CommsStage::stop() noexcept {
  if (journal_ && !journal_->sync()) AG_LOG_WARN("comms", "journal %s: fdatasync failed at stop", journal_->path().c_str());
}

}  // namespace ag::comms
