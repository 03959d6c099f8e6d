// The regions and mission stages.
#include "airground/mission/stages.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>

#include "airground/comms/messages.hpp"
#include "airground/messages/channels.hpp"
#include "airground/mission/messages.hpp"
#include "airground/platform/log.hpp"

namespace ag::mission {

// ----------------------------------------------------------------------------------------- regions
Status RegionsStage::init(StageContext& ctx) {
  const SectionView v = ctx.params();
  const std::string where = std::string(ctx.stage_name) + ".";
  const RegionsSettings own = load_params(v, kRegionsStageFields);
  auto area = load_mission_area(v, kRegionsAreaFields, ctx.stage_name);
  if (!area) return area.error();
  RegionParams p = load_params(v, kRegionFields);
  p.resolution_m = kMapResolutionM;
  p.tile_cells = kTileCells;
  p.max_regions = static_cast<int>(kMaxRegionsMsg);
  ex_ = std::make_unique<RegionExtractor>(p, ClassTable::builtin(), tiles_covering(area.value().rect(), kMapResolutionM, kTileCells));
  msg_ = std::make_unique<RegionsMsg>();
  pub_ = std::make_unique<comms::GossipPublishMsg>();
  batch_ = std::make_unique<RegionBatch>();
  period_ = from_seconds(own.period_s);
  auto tiles = ctx.channels.ring_reader(chan::kMapTiles);
  if (!tiles) return tiles.error();
  tiles_ = tiles.value();
  auto g = ctx.channels.ring_writer(chan::kGossipOut);
  if (!g) return g.error();
  gossip_ = g.value();
  auto out = ctx.channels.latest_writer(chan::kRegions);
  if (!out) return out.error();
  out_ = out.value();
  return ok_status();
}

bool RegionsStage::publish_batches(TimeNs now) noexcept {
  const std::uint32_t n = msg_->count;
  constexpr std::uint32_t kPer = static_cast<std::uint32_t>(kRegionsPerBatch);
  const std::uint32_t batches = std::max<std::uint32_t>(1, (n + kPer - 1) / kPer);
  if (gossip_.free_slots() < batches) {
    ++c_.publish_deferred;
    return false;
  }
  for (std::uint32_t b = 0; b < batches; ++b) {
    RegionBatch& rb = *batch_;
    rb.regions_version = msg_->version;
    rb.batches = static_cast<std::uint16_t>(batches);
    rb.count = static_cast<std::uint8_t>(std::min<std::uint32_t>(kRegionsPerBatch, n - std::min(n, b * kPer)));
    for (std::uint32_t i = 0; i < rb.count; ++i) rb.regions[i] = msg_->regions[b * kPer + i];
    comms::GossipPublishMsg& m = *pub_;
    m.stamp = now;
    m.published = now;
    m.topic = regions_topic(b);
    m.priority = 0;
    m.size = static_cast<std::uint32_t>(encode(rb, m.payload));
    (void)gossip_.push(m);
    ++c_.batches_published;
  }
  msg_->batches = batches;
  ++c_.versions_published;
  return true;
}

void RegionsStage::step(TimeNs now) noexcept {
  for (MapTileMsg* t = tiles_.front(); t != nullptr; t = tiles_.front()) {
    ++c_.tiles_in;
    if (ex_->set_tile(t->tx, t->ty, t->version, std::span<const std::uint8_t>(t->cls.data(), t->cls.size())))
      ++c_.tiles_applied;
    else if (c_.tiles_rejected++ == 0)
      AG_LOG_WARN("regions", "map tile (%d, %d) v%llu outside the mission area (regions.area_*) or not newer: dropped (counted)",
                  static_cast<int>(t->tx), static_cast<int>(t->ty), static_cast<unsigned long long>(t->version));
    tiles_.pop();
  }
  if (ex_->changed() && (last_extract_ < 0 || now - last_extract_ >= period_)) {
    last_extract_ = now;
    ex_->extract();
    ++c_.extractions;
    add_work(1.0);  // one regions update (compute-time model)
    if (ex_->version() != published_version_) {
      published_version_ = ex_->version();
      RegionsMsg& m = *msg_;
      const auto regs = ex_->regions();
      m.count = static_cast<std::uint32_t>(std::min(regs.size(), kMaxRegionsMsg));
      m.dropped = regs.size() - m.count;
      c_.regions_dropped = m.dropped;
      for (std::uint32_t i = 0; i < m.count; ++i) {
        const Region& r = regs[i];
        m.regions[i] = RegionRecord{r.id, static_cast<float>(r.cx), static_cast<float>(r.cy), static_cast<float>(r.goal_x),
                                    static_cast<float>(r.goal_y), static_cast<std::uint16_t>(std::min<std::uint32_t>(r.cells, 0xFFFF)), r.goal_valid};
      }
      m.version = published_version_;
      m.stamp = now;
      m.published = now;
      m.extractions = c_.extractions;
      pending_ = true;
    }
  }
  if (pending_ && publish_batches(now)) {
    pending_ = false;
    out_.publish(*msg_);
  }
}

// ----------------------------------------------------------------------------------------- mission
Status parse_waypoints(std::string_view text, ManagerParams& p) {
  p.waypoint_count = 0;
  std::size_t pos = 0;
  int item = 0;
  while (pos < text.size()) {
    std::size_t end = text.find(';', pos);
    if (end == std::string_view::npos) end = text.size();
    const std::string part(text.substr(pos, end - pos));
    pos = end + 1;
    ++item;
    if (part.find_first_not_of(" \t") == std::string::npos) continue;
    double x = 0, y = 0;
    char tail = 0;
    if (std::sscanf(part.c_str(), " %lf , %lf %c", &x, &y, &tail) != 2 || !std::isfinite(x) || !std::isfinite(y))
      return Error::make(ErrorCode::kConfig, "config error: mission.waypoints item " + std::to_string(item) + " '" + part + "' is not 'x,y'");
    if (p.waypoint_count == kMaxWaypoints)
      return Error::make(ErrorCode::kConfig, "config error: mission.waypoints: more than " + std::to_string(kMaxWaypoints) + " waypoints");
    p.waypoint_x[p.waypoint_count] = x;
    p.waypoint_y[p.waypoint_count] = y;
    ++p.waypoint_count;
  }
  return ok_status();
}

Status MissionStage::init(StageContext& ctx) {
  const SectionView v = ctx.params();
  ManagerParams p = load_params(v, kManagerFields);
  p.self = static_cast<comms::RobotId>(ctx.config.get_int("robot.id"));
  if (Status st = parse_waypoints(v.text("waypoints"), p); !st.ok()) return st;
  mgr_ = std::make_unique<MissionManager>(p);
  pub_ = std::make_unique<comms::GossipPublishMsg>();
  heard_ = std::make_unique<std::array<TimeNs, 256>>();
  heard_->fill(-1);
  auto gin = ctx.channels.ring_reader(chan::kGossipIn);
  if (!gin) return gin.error();
  gossip_in_ = gin.value();
  auto gout = ctx.channels.ring_writer(chan::kGossipOut);
  if (!gout) return gout.error();
  gossip_out_ = gout.value();
  auto team = ctx.channels.latest_reader(chan::kTeamPoses);
  if (!team) return team.error();
  team_ = team.value();
  auto cs = ctx.channels.latest_reader(chan::kCommsStats);
  if (!cs) return cs.error();
  comms_stats_ = cs.value();
  auto loc = ctx.channels.latest_reader(chan::kLocalization);
  if (!loc) return loc.error();
  loc_ = loc.value();
  auto path = ctx.channels.latest_reader(chan::kPlannedPath);
  if (!path) return path.error();
  path_ = path.value();
  auto goal = ctx.channels.latest_writer(chan::kGoal);
  if (!goal) return goal.error();
  goal_out_ = goal.value();
  auto st = ctx.channels.latest_writer(chan::kMissionStatus);
  if (!st) return st.error();
  status_out_ = st.value();
  auto obj = ctx.channels.latest_reader(chan::kObjects);
  if (!obj) return obj.error();
  objects_in_ = obj.value();
  objects_ = std::make_unique<ObjectsMsg>();
  objects_sent_ = std::make_unique<std::array<ObjectRecord, kMaxObjectsMsg>>();
  objects_sent_at_ = std::make_unique<std::array<TimeNs, kMaxObjectsMsg>>();
  objects_sent_at_->fill(-1);
  republish_ = from_seconds(p.republish_s);
  return ok_status();
}

void MissionStage::step(TimeNs now) noexcept {
  MissionManager& m = *mgr_;
  for (comms::GossipRecordMsg* r = gossip_in_.front(); r != nullptr; r = gossip_in_.front()) {
    ++c_.records_in;
    const std::uint32_t size = std::min<std::uint32_t>(r->size, static_cast<std::uint32_t>(r->payload.size()));
    const DecodeError e = m.on_record(r->key.origin, r->key.topic, std::span<const std::uint8_t>(r->payload.data(), size), now);
    if (e != DecodeError::kOk && c_.records_bad++ % 100 == 0)
      AG_LOG_WARN("mission", "record of robot %u topic 0x%08x (%u B): %s (%llu malformed so far, dropped)", static_cast<unsigned>(r->key.origin),
                  static_cast<unsigned>(r->key.topic), static_cast<unsigned>(r->size), to_string(e),
                  static_cast<unsigned long long>(c_.records_bad));
    gossip_in_.pop();
  }
  if (team_.fresh()) {
    const comms::TeamPosesMsg& t = team_.read();
    for (std::uint32_t i = 0; i < std::min<std::uint32_t>(t.count, static_cast<std::uint32_t>(t.robots.size())); ++i) {
      const comms::TeamPose& tp = t.robots[i];
      if (tp.stamp != (*heard_)[tp.robot]) {
        (*heard_)[tp.robot] = tp.stamp;
        m.on_peer_heard(tp.robot, now);
      }
    }
  }
  if (comms_stats_.fresh()) {  // map tiles delivered: the quadrotor is still mapping, keep waiting for regions
    const std::uint64_t tiles = comms_stats_.read().tiles_in;
    if (tiles != tiles_seen_) {
      tiles_seen_ = tiles;
      m.on_map_data(now);
    }
  }
  if (loc_.fresh()) m.on_localization(loc_.read());
  if (path_.fresh()) {
    const PlannedPathMsg& pp = path_.read();
    m.on_route(pp.goal_id, pp.seq, pp.status);
  }
  m.tick(now);
  if (const std::uint64_t g = m.counters().regions_given_up; g > given_up_logged_) {
    AG_LOG_WARN("mission", "%llu region(s) given up after %d failures to reach them (mission.give_up_failures)", static_cast<unsigned long long>(g),
                m.params().give_up_failures);
    given_up_logged_ = g;
  }
  for (const OutRecord& o : m.outbox()) {
    if (o.size == 0) continue;
    comms::GossipPublishMsg& g = *pub_;
    g.stamp = now;
    g.published = now;
    g.topic = o.topic;
    g.priority = 0;
    g.size = o.size;
    std::memcpy(g.payload.data(), o.payload.data(), o.size);
    if (gossip_out_.push(g) == 0)
      ++c_.records_published;
    else
      ++c_.publish_refused;
  }
  m.clear_outbox();
  // the target mapper's confirmed objects: a record when one changed (at most every republish_s), at
  // most four per step so the claims keep their room in the ring
  if (objects_in_.fresh()) *objects_ = objects_in_.read();
  std::uint32_t sent = 0;
  for (std::uint32_t i = 0; i < std::min<std::uint32_t>(objects_->count, static_cast<std::uint32_t>(kMaxObjectsMsg)) && sent < 4; ++i) {
    const ObjectRecord& o = objects_->objects[i];
    if (!objects_->confirmed[i] || o == (*objects_sent_)[i] || ((*objects_sent_at_)[i] >= 0 && now - (*objects_sent_at_)[i] < republish_))
      continue;
    comms::GossipPublishMsg& g = *pub_;
    g.stamp = now;
    g.published = now;
    g.topic = object_topic(o.object_id);
    g.priority = 0;
    g.size = static_cast<std::uint32_t>(encode(o, g.payload));
    if (gossip_out_.push(g) == 0) {
      ++c_.records_published;
      (*objects_sent_)[i] = o;
      (*objects_sent_at_)[i] = now;
      ++sent;
    } else {
      ++c_.publish_refused;
    }
  }
  const GoalCommand& gc = m.goal();
  if (gc.id != goal_sent_) {
    goal_sent_ = gc.id;
    GoalMsg gm;
    gm.stamp = now;
    gm.published = now;
    gm.id = gc.id;
    gm.goal = RoutePoint{gc.x, gc.y};
    gm.cancel = gc.cancel;
    goal_out_.publish(gm);
    ++c_.goals_published;
  }
  MissionStatusMsg s = m.status();
  s.published = now;
  status_out_.publish(s);
}

// ----------------------------------------------------------------------------------------- targets
Status TargetsStage::init(StageContext& ctx) {
  const SectionView v = ctx.params();
  const DetectorParams dp = load_params(v, kDetectorFields);
  TrackerParams tp = load_params(v, kObjectTrackerFields);
  tp.max_objects = kMaxObjectsMsg;
  cfg_ = load_params(v, kTargetsStageFields);
  det_ = std::make_unique<VehicleDetector>(dp);
  trk_ = std::make_unique<ObjectTracker>(tp);
  msg_ = std::make_unique<ObjectsMsg>();
  auto sc = ctx.channels.ring_reader(chan::kLidarScan);
  if (!sc) return sc.error();
  scans_ = sc.value();
  auto loc = ctx.channels.latest_reader(chan::kLocalization);
  if (!loc) return loc.error();
  loc_ = loc.value();
  auto out = ctx.channels.latest_writer(chan::kObjects);
  if (!out) return out.error();
  out_ = out.value();
  return ok_status();
}

void TargetsStage::step(TimeNs now) noexcept {
  if (loc_.fresh()) {
    pose_ = loc_.read();
    have_pose_ = true;
  }
  bool changed = false;
  for (LidarScanMsg* s = scans_.front(); s != nullptr; s = scans_.front()) {
    ++c_.scans;
    const bool usable = have_pose_ && pose_.status == LocalizationStatus::kTracking && pose_sigma_m(pose_.covariance) <= cfg_.max_sigma_m &&
                        s->labels != LabelSource::kNone;
    if (!usable) {
      ++c_.scans_skipped_pose;
    } else {
      const std::size_t n = std::min<std::size_t>(s->count, s->points.size());
      for (const Detection& d : det_->detect(std::span<const ScanReturn>(s->points.data(), n), s->sensor_in_body, pose_.pose, pose_.covariance)) {
        ++c_.detections;
        (void)trk_->update(d, s->stamp);
        changed = true;
      }
    }
    scans_.pop();
  }
  if (!changed) return;
  ObjectsMsg& m = *msg_;
  const auto objs = trk_->objects();
  m.count = static_cast<std::uint32_t>(std::min(objs.size(), kMaxObjectsMsg));
  for (std::uint32_t i = 0; i < m.count; ++i) {
    m.objects[i] = trk_->record(i);
    m.confirmed[i] = trk_->confirmed(i);
  }
  m.scans = c_.scans;
  m.detections = c_.detections;
  m.dropped = trk_->dropped();
  m.stamp = now;
  m.published = now;
  out_.publish(m);
}

}  // namespace ag::mission
