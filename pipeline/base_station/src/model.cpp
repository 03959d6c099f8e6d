#include "airground/base_station/model.hpp"

#include <cmath>

namespace ag::base_station {

using mission::DecodeError;

void MissionModel::reset() noexcept {
  robot_index.fill(-1);
  robot_count = 0;
  regions_batches = 0;
  regions_version = 0;
  batch_valid.fill(false);
  failure_count = 0;
  object_count = 0;
  has_comms = false;
  counters = ModelCounters{};
}

RobotView* MissionModel::robot(comms::RobotId id) noexcept {
  if (id == comms::kNoRobot) return nullptr;
  const std::int16_t k = robot_index[id];
  if (k >= 0) return &robots[static_cast<std::size_t>(k)];
  if (robot_count >= kModelRobots) {
    ++counters.table_full;
    return nullptr;
  }
  RobotView& r = robots[robot_count];
  r = RobotView{};
  r.id = id;
  robot_index[id] = static_cast<std::int16_t>(robot_count++);
  return &r;
}

const RobotView* MissionModel::find_robot(comms::RobotId id) const noexcept {
  const std::int16_t k = robot_index[id];
  return k >= 0 ? &robots[static_cast<std::size_t>(k)] : nullptr;
}

bool MissionModel::apply_poses(const comms::TeamPosesMsg& m, TimeNs t) noexcept {
  bool changed = false;
  const std::uint32_t n = m.count < comms::kTeamMax ? m.count : static_cast<std::uint32_t>(comms::kTeamMax);
  for (std::uint32_t i = 0; i < n; ++i) {
    const comms::TeamPose& p = m.robots[i];
    if (p.robot == comms::kNoRobot) continue;
    RobotView* r = robot(p.robot);
    if (r == nullptr) continue;
    if (r->has_pose && p.stamp <= r->pose_stamp) continue;
    if (!std::isfinite(p.pose.x) || !std::isfinite(p.pose.y) || !std::isfinite(p.pose.yaw)) {
      ++counters.decode_errors;
      continue;
    }
    ++counters.poses_in;
    r->has_pose = true;
    r->pose_stamp = p.stamp;
    r->heard = t;
    r->loc_status = p.status;
    r->x = static_cast<float>(p.pose.x);
    r->y = static_cast<float>(p.pose.y);
    r->yaw = static_cast<float>(p.pose.yaw);
    r->sigma_x = p.sigma_x_m;
    r->sigma_y = p.sigma_y_m;
    bool add = r->trail_count == 0;
    if (!add) {
      const TrailPoint& last = r->trail[(r->trail_head + kTrailPoints - 1) % kTrailPoints];
      add = std::hypot(r->x - last.x, r->y - last.y) >= kTrailMinStepM;
    }
    if (add) {
      r->trail[r->trail_head] = TrailPoint{r->x, r->y};
      r->trail_head = (r->trail_head + 1) % kTrailPoints;
      if (r->trail_count < kTrailPoints) ++r->trail_count;
    }
    changed = true;
  }
  if (changed) {
    ++seq;
    now = t;
  }
  return changed;
}

RecordKind MissionModel::apply_record(const comms::GossipRecordMsg& rec, TimeNs t, DecodeError& err) noexcept {
  ++counters.records_in;
  const RecordKind kind = record_kind(rec.key.topic);
  const std::span<const std::uint8_t> in(rec.payload.data(), rec.size <= rec.payload.size() ? rec.size : rec.payload.size());
  err = DecodeError::kOk;
  const comms::RobotId origin = rec.key.origin;
  if (RobotView* r = robot(origin); r != nullptr && kind != RecordKind::kRegions) r->heard = t;
  switch (kind) {
    case RecordKind::kRegions: {
      ++counters.regions_in;
      const std::uint32_t b = comms::topic_index(rec.key.topic);
      static mission::RegionBatch scratch;  // tmp's target for a batch beyond the table (refused below)
      mission::RegionBatch& tmp = b < kRegionBatches ? batches[b] : scratch;
      mission::RegionBatch before{};
      const bool had = b < kRegionBatches && batch_valid[b];
      if (had) before = tmp;
      err = b >= kRegionBatches ? DecodeError::kValue : mission::decode_detailed(in, tmp);
      if (err != DecodeError::kOk) break;  // the codec left tmp as it was
      if (tmp.regions_version < regions_version) {
        ++counters.stale_regions;
        if (had) tmp = before;
        else batch_valid[b] = false;
        break;
      }
      if (tmp.regions_version > regions_version) {
        // A new version: batches of the older one stay shown until their replacements arrive, but
        // only up to the new batch count.
        regions_version = tmp.regions_version;
      }
      regions_batches = tmp.batches;
      regions_origin = origin;
      batch_valid[b] = true;
      break;
    }
    case RecordKind::kClaim: {
      ++counters.claims_in;
      mission::ClaimRecord c;
      err = mission::decode_detailed(in, c);
      if (err == DecodeError::kOk) {
        if (RobotView* r = robot(origin)) {
          r->claim = c;
          r->has_claim = true;
        }
      }
      break;
    }
    case RecordKind::kVisited: {
      ++counters.visited_in;
      RobotView* r = robot(origin);
      if (r == nullptr) break;
      err = mission::decode_detailed(in, r->visited);  // a bad record leaves the held one
      if (err == DecodeError::kOk) r->has_visited = true;
      break;
    }
    case RecordKind::kFailure: {
      ++counters.failures_in;
      mission::FailureRecord f;
      err = mission::decode_detailed(in, f);
      if (err != DecodeError::kOk) break;
      std::uint32_t k = 0;
      while (k < failure_count && !(failures[k].origin == origin && failures[k].f.region_id == f.region_id)) ++k;
      if (k == failure_count) {
        if (failure_count >= kModelFailures) {
          ++counters.table_full;
          break;
        }
        ++failure_count;
      }
      failures[k] = FailureView{origin, t, f};
      break;
    }
    case RecordKind::kObject: {
      ++counters.objects_in;
      mission::ObjectRecord o;
      err = mission::decode_detailed(in, o);
      if (err != DecodeError::kOk) break;
      std::uint32_t k = 0;
      while (k < object_count && !(objects[k].origin == origin && objects[k].o.object_id == o.object_id)) ++k;
      if (k == object_count) {
        if (object_count >= kModelObjects) {
          ++counters.table_full;
          break;
        }
        ++object_count;
      }
      objects[k] = ObjectView{origin, o};
      break;
    }
    case RecordKind::kStatus:
    case RecordKind::kOther: ++counters.other_in; break;
  }
  if (err != DecodeError::kOk) {
    ++counters.decode_errors;
    counters.last_error = static_cast<std::uint8_t>(err);
    counters.last_error_kind = static_cast<std::uint8_t>(kind);
    counters.last_error_origin = origin;
  }
  ++seq;
  now = t;
  return kind;
}

void MissionModel::apply_comms(const comms::CommsStatsMsg& m) noexcept {
  comms = m;
  has_comms = true;
  ++seq;
}

}  // namespace ag::base_station
