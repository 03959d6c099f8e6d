// The mission manager: choose, claim, go, visit, fail, take over, wait, return.
#include "airground/mission/manager.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace ag::mission {

double pose_sigma_m(const std::array<double, 9>& cov) noexcept {
  const double a = cov[0], b = 0.5 * (cov[1] + cov[3]), d = cov[4];
  if (!std::isfinite(a) || !std::isfinite(b) || !std::isfinite(d)) return std::numeric_limits<double>::infinity();
  const double tr = 0.5 * (a + d), det = std::sqrt(std::max(0.0, 0.25 * (a - d) * (a - d) + b * b));
  return std::sqrt(std::max(0.0, tr + det));
}

MissionManager::MissionManager(const ManagerParams& p) : p_(p) {
  status_.state = ClaimState::kIdle;
}

MissionManager::Peer* MissionManager::peer(comms::RobotId id, bool create) noexcept {
  if (id == comms::kNoRobot || id == p_.self) return nullptr;
  Peer* free_slot = nullptr;
  for (Peer& q : peers_) {
    if (q.id == id) return &q;
    if (q.id == comms::kNoRobot && free_slot == nullptr) free_slot = &q;
  }
  if (!create || free_slot == nullptr) return nullptr;
  *free_slot = Peer{};
  free_slot->id = id;
  return free_slot;
}

bool MissionManager::alive(const Peer& q, TimeNs now) const noexcept {
  return q.id != comms::kNoRobot && now - q.last_heard <= from_seconds(p_.claim_timeout_s);
}

bool MissionManager::peer_wins(const Peer& q) const noexcept {
  return q.claim.priority != p_.priority ? q.claim.priority < p_.priority : q.id < p_.self;
}

const MissionManager::KnownRegion* MissionManager::region(std::uint32_t id) const noexcept {
  for (std::size_t i = 0; i < n_regions_; ++i)
    if (regions_[i].id == id) return &regions_[i];
  return nullptr;
}

bool MissionManager::visited_by_anyone(std::uint32_t id) const noexcept {
  const KnownRegion* r = region(id);
  return visited_by_anyone(r != nullptr ? *r : KnownRegion{id, 0.0, 0.0, false});
}

bool MissionManager::visited_by_anyone(const KnownRegion& r) const noexcept {
  // A mark counts while the region's goal (when it has one) stays within revisit_moved_m of where it was made.
  const bool by_goal = r.valid && p_.revisit_moved_m > 0.0;
  const double lim2 = p_.revisit_moved_m * p_.revisit_moved_m;
  auto covers = [&](const VisitedEntry& e) noexcept {
    if (e.region_id != r.id) return false;
    const double dx = static_cast<double>(e.x) - r.x, dy = static_cast<double>(e.y) - r.y;
    return !by_goal || dx * dx + dy * dy <= lim2;
  };
  for (std::size_t i = 0; i < visited_.count; ++i)
    if (covers(visited_.entries[i])) return true;
  for (const Peer& q : peers_) {
    if (q.id == comms::kNoRobot) continue;
    for (std::size_t i = 0; i < q.visited.count; ++i)
      if (covers(q.visited.entries[i])) return true;
  }
  return false;
}

bool MissionManager::given_up(const KnownRegion& r) const noexcept {
  if (p_.give_up_failures <= 0) return false;
  const bool by_goal = r.valid && p_.revisit_moved_m > 0.0;
  const double lim2 = p_.revisit_moved_m * p_.revisit_moved_m;
  int n = 0;
  for (std::size_t k = 0; k < n_failures_; ++k) {
    const Failure& f = failures_[k];
    if (f.region != r.id || f.reason == FailureReason::kNoRoute) continue;
    const double dx = static_cast<double>(f.x) - r.x, dy = static_cast<double>(f.y) - r.y;
    if (by_goal && dx * dx + dy * dy > lim2) continue;  // failed at a goal the region has since moved away from
    n += f.origin == p_.self ? 1 : f.attempts;
  }
  return n >= p_.give_up_failures;
}

DecodeError MissionManager::on_record(comms::RobotId origin, comms::Topic topic, std::span<const std::uint8_t> payload, TimeNs now) noexcept {
  ++c_.records_in;
  const comms::TopicKind kind = comms::topic_kind(topic);
  DecodeError e = DecodeError::kOk;
  if (kind == comms::TopicKind::kRegions) {
    RegionBatch b;
    e = decode(payload, b);
    const std::uint32_t idx = comms::topic_index(topic);
    if (e == DecodeError::kOk) {
      if (idx >= kMaxBatches) {
        ++c_.regions_overflow;
        return e;
      }
      // a newer version resets the batch count; batches of older versions are kept until replaced
      if (!have_batch_[idx] || b.regions_version >= batches_[idx].regions_version) {
        batches_[idx] = b;
        have_batch_[idx] = true;
      }
      std::uint32_t newest = 0;
      for (std::size_t i = 0; i < kMaxBatches; ++i)
        if (have_batch_[i] && batches_[i].regions_version >= newest) {
          newest = batches_[i].regions_version;
          batch_count_ = batches_[i].batches;
        }
      rebuild_regions(now);
    }
  } else if (kind == comms::TopicKind::kClaims && comms::topic_index(topic) == 0) {
    ClaimRecord cr;
    e = decode(payload, cr);
    if (e == DecodeError::kOk) {
      if (Peer* q = peer(origin, true)) {
        q->claim = cr;
        q->has_claim = true;
        q->last_heard = std::max(q->last_heard, now);
      }
    }
  } else if (kind == comms::TopicKind::kClaims && comms::topic_index(topic) == 1) {
    VisitedRecord v;
    e = decode(payload, v);
    if (e == DecodeError::kOk)
      if (Peer* q = peer(origin, true)) q->visited = v;
  } else if (kind == comms::TopicKind::kFailures) {
    FailureRecord f;
    e = decode(payload, f);
    if (e == DecodeError::kOk && (f.region_id & 0xFFFFFFu) != comms::topic_index(topic)) e = DecodeError::kValue;
    if (e == DecodeError::kOk && origin != p_.self) {
      bool known = false;
      for (std::size_t i = 0; i < n_failures_; ++i)
        if (failures_[i].origin == origin && failures_[i].region == f.region_id) {
          failures_[i].at = now;
          failures_[i].reason = f.reason;
          failures_[i].attempts = std::max<std::uint16_t>(failures_[i].attempts, std::max<std::uint16_t>(f.attempts, 1));
          failures_[i].x = f.x;
          failures_[i].y = f.y;
          known = true;
        }
      if (!known) {
        if (n_failures_ == kMaxFailures) ++c_.failures_overflow;
        failures_[next_failure_] = Failure{origin, f.region_id, now, f.reason, std::max<std::uint16_t>(f.attempts, 1), f.x, f.y};
        next_failure_ = (next_failure_ + 1) % kMaxFailures;
        n_failures_ = std::min(kMaxFailures, n_failures_ + 1);
      }
    }
  } else {
    ++c_.records_ignored;
    return DecodeError::kOk;
  }
  if (e != DecodeError::kOk) ++c_.records_bad;
  return e;
}

void MissionManager::rebuild_regions(TimeNs now) noexcept {
  bool new_region = false;
  std::array<KnownRegion, kMaxRegions> old_ids{};
  const std::size_t n_old = n_regions_;
  std::copy_n(regions_.begin(), n_old, old_ids.begin());
  n_regions_ = 0;
  for (std::size_t b = 0; b < kMaxBatches && b < batch_count_; ++b) {
    if (!have_batch_[b]) continue;
    for (std::size_t i = 0; i < batches_[b].count; ++i) {
      const RegionRecord& r = batches_[b].regions[i];
      bool dup = false;
      for (std::size_t k = 0; k < n_regions_ && !dup; ++k) dup = regions_[k].id == r.id;
      if (dup) continue;
      if (n_regions_ == kMaxRegions) {
        ++c_.regions_overflow;
        continue;
      }
      regions_[n_regions_++] = KnownRegion{r.id, r.goal_x, r.goal_y, r.goal_valid};
      bool seen = false;
      for (std::size_t k = 0; k < n_old && !seen; ++k) seen = old_ids[k].id == r.id;
      if (!seen && r.goal_valid) new_region = true;
    }
  }
  if (new_region) idle_since_ = now;  // new map data: waiting starts again
  regions_dirty_ = true;
}

void MissionManager::on_peer_heard(comms::RobotId robot, TimeNs now) noexcept {
  if (Peer* q = peer(robot, true)) q->last_heard = std::max(q->last_heard, now);
}

void MissionManager::on_localization(const LocalizationMsg& m) noexcept {
  loc_ = m;
  have_loc_ = true;
  sigma_ = pose_sigma_m(m.covariance);
}

void MissionManager::on_route(std::uint32_t goal_id, std::uint32_t seq, RouteStatus st) noexcept {
  if (goal_id != goal_.id || seq == last_route_seq_ || state_ != ClaimState::kGoing) return;
  last_route_seq_ = seq;
  if (st == RouteStatus::kNoRoute || st == RouteStatus::kBadEnds)
    ++no_route_;
  else if (st == RouteStatus::kOk)
    no_route_ = 0;
}

OutRecord* MissionManager::out_slot() noexcept { return n_out_ < kOutboxCapacity ? &outbox_[n_out_++] : nullptr; }

void MissionManager::go_to(double x, double y) noexcept {
  goal_.id += 1;
  goal_.x = x;
  goal_.y = y;
  goal_.cancel = false;
  goal_x_ = x;
  goal_y_ = y;
  no_route_ = 0;
}

void MissionManager::cancel_goal() noexcept {
  if (goal_.cancel) return;
  goal_.id += 1;
  goal_.cancel = true;
}

void MissionManager::release(ClaimState next, TimeNs now) noexcept {
  region_ = kNoRegion;
  state_ = next;
  idle_since_ = now;
  claim_dirty_ = true;
}

bool MissionManager::choose(TimeNs now) noexcept {
  // Also while the localizer converges: it needs the robot to move (the drive stage goes slowly until it tracks).
  if (!have_loc_ || (loc_.status != LocalizationStatus::kTracking && loc_.status != LocalizationStatus::kInitialising)) return false;
  const KnownRegion* best = nullptr;
  double best_d = std::numeric_limits<double>::infinity();
  bool best_takeover = false;
  for (std::size_t i = 0; i < n_regions_; ++i) {
    const KnownRegion& r = regions_[i];
    if (!r.valid || visited_by_anyone(r)) continue;
    bool taken = false, takeover = false;
    for (const Peer& q : peers_) {
      if (q.id == comms::kNoRobot || !q.has_claim || q.claim.region_id != r.id || q.claim.state != ClaimState::kGoing) continue;
      if (alive(q, now))
        taken = true;
      else
        takeover = true;
    }
    if (taken) continue;
    bool failed_recently = false;
    for (std::size_t k = 0; k < n_failures_ && !failed_recently; ++k) {
      const Failure& f = failures_[k];
      if (f.origin != p_.self || f.region != r.id) continue;
      const bool no_new_map = f.reason == FailureReason::kNoRoute && last_map_data_ <= f.at;
      failed_recently = now - f.at < from_seconds(p_.retry_after_s) || no_new_map;
    }
    if (failed_recently || given_up(r)) continue;
    bool deferred = false;
    for (const Deferred& df : deferred_) deferred = deferred || (df.region == r.id && now < df.until);
    if (deferred) continue;
    const double d = std::hypot(r.x - loc_.pose.x, r.y - loc_.pose.y);
    if (d < best_d) {
      best_d = d;
      best = &r;
      best_takeover = takeover;
    }
  }
  if (best == nullptr) return false;
  region_ = best->id;
  state_ = ClaimState::kGoing;
  if (best_takeover) ++takeovers_;
  go_to(best->x, best->y);
  best_dist_ = best_d;
  progress_at_ = now;
  claim_dirty_ = true;
  return true;
}

void MissionManager::fail(FailureReason why, TimeNs now) noexcept {
  ++failed_own_;
  if (OutRecord* o = out_slot()) {
    FailureRecord f;
    f.reason = why;
    f.region_id = region_;
    f.x = static_cast<float>(goal_x_);
    f.y = static_cast<float>(goal_y_);
    std::uint16_t attempts = 1;
    for (std::size_t k = 0; k < n_failures_; ++k)
      if (failures_[k].origin == p_.self && failures_[k].region == region_) ++attempts;
    f.attempts = attempts;
    o->topic = failure_topic(region_);
    o->size = static_cast<std::uint32_t>(encode(f, o->payload));
  }
  if (n_failures_ == kMaxFailures) ++c_.failures_overflow;
  failures_[next_failure_] = Failure{p_.self, region_, now, why, 1, static_cast<float>(goal_x_), static_cast<float>(goal_y_)};
  next_failure_ = (next_failure_ + 1) % kMaxFailures;
  n_failures_ = std::min(kMaxFailures, n_failures_ + 1);
  cancel_goal();
  release(ClaimState::kFailedRetrying, now);
}

void MissionManager::begin_return(TimeNs now) noexcept {
  region_ = kNoRegion;
  state_ = ClaimState::kReturning;
  go_to(p_.start_x, p_.start_y);
  progress_at_ = now;
  claim_dirty_ = true;
}

void MissionManager::publish_claim(TimeNs now) noexcept {
  ClaimRecord c;
  c.state = state_;
  c.priority = p_.priority;
  c.region_id = region_;
  c.goal_x = static_cast<float>(state_ == ClaimState::kGoing || state_ == ClaimState::kReturning ? goal_x_ : 0.0);
  c.goal_y = static_cast<float>(state_ == ClaimState::kGoing || state_ == ClaimState::kReturning ? goal_y_ : 0.0);
  c.pose_sigma_m = static_cast<float>(std::isfinite(sigma_) ? std::min(sigma_, 1e6) : 1e6);
  const bool changed = !(c.state == last_claim_.state && c.region_id == last_claim_.region_id && c.goal_x == last_claim_.goal_x &&
                         c.goal_y == last_claim_.goal_y);
  if (!(claim_dirty_ || changed || now - last_claim_pub_ >= from_seconds(p_.republish_s))) return;
  if (OutRecord* o = out_slot()) {
    o->topic = kClaimTopic;
    o->size = static_cast<std::uint32_t>(encode(c, o->payload));
    last_claim_ = c;
    last_claim_pub_ = now;
    claim_dirty_ = false;
    if (visited_dirty_ || visited_.count > 0) publish_visited();
  }
}

void MissionManager::publish_visited() noexcept {
  if (OutRecord* o = out_slot()) {
    o->topic = kVisitedTopic;
    o->size = static_cast<std::uint32_t>(encode(visited_, o->payload));
    visited_dirty_ = false;
  }
}

void MissionManager::tick(TimeNs now) noexcept {
  if (!started_) {
    started_ = true;
    t0_ = now;
    idle_since_ = now;
  }
  const bool tracking = have_loc_ && loc_.status == LocalizationStatus::kTracking;
  if (p_.waypoint_count > 0) {
    tick_waypoints(now, tracking);
    return;
  }
  if (p_.mission_end_s > 0 && now - t0_ >= from_seconds(p_.mission_end_s) && !ended_) {
    ended_ = true;
    if (state_ != ClaimState::kDone) begin_return(now);
  }

  if (state_ == ClaimState::kGoing) {
    const KnownRegion* r = region(region_);
    bool lost_clash = false;
    bool other_visited = false;
    for (const Peer& q : peers_)
      if (q.id != comms::kNoRobot && q.has_claim && q.claim.state == ClaimState::kGoing && q.claim.region_id == region_ && alive(q, now) &&
          peer_wins(q))
        lost_clash = true;
    if (r != nullptr) other_visited = visited_by_anyone(*r);
    const double d = tracking ? std::hypot(goal_x_ - loc_.pose.x, goal_y_ - loc_.pose.y) : best_dist_;
    if (lost_clash) {
      ++clashes_lost_;
      release(ClaimState::kIdle, now);
    } else if (r == nullptr || !r->valid || other_visited) {
      release(ClaimState::kIdle, now);  // the region merged away, lost its goal, or someone else marked it
    } else if (tracking && d <= mark_radius() && sigma_ <= p_.max_sigma_m) {
      if (visited_.count < kMaxVisited) {
        visited_.entries[visited_.count++] = VisitedEntry{region_, static_cast<float>(loc_.pose.x), static_cast<float>(loc_.pose.y)};
        visited_dirty_ = true;
      } else {
        ++c_.visited_overflow;
      }
      release(ClaimState::kIdle, now);
    } else {
      if (tracking && d <= mark_radius()) ++refused_visits_;
      if (tracking && d < best_dist_ - p_.progress_min_m) {
        best_dist_ = d;
        progress_at_ = now;
      }
      if (no_route_ >= p_.max_no_route && last_map_data_ >= 0 && now - last_map_data_ <= from_seconds(p_.map_growing_s)) {
        // The map is still growing: the way there may not be mapped yet. Not a failure; try others.
        Deferred* slot = &deferred_[0];
        for (Deferred& df : deferred_)
          if (df.until < slot->until) slot = &df;
        *slot = Deferred{region_, now + from_seconds(p_.defer_s)};
        ++c_.deferred_no_route;
        no_route_ = 0;
        cancel_goal();
        release(ClaimState::kIdle, now);
      } else if (no_route_ >= p_.max_no_route) {
        fail(FailureReason::kNoRoute, now);
      }
      else if (now - progress_at_ > from_seconds(p_.no_progress_timeout_s))
        fail(!tracking || d <= p_.visit_radius_m ? FailureReason::kLostLocalization : FailureReason::kNoProgress, now);
    }
  }

  if (state_ != ClaimState::kGoing && !ended_) {
    if (choose(now)) {
      // going
    } else if (state_ == ClaimState::kIdle || state_ == ClaimState::kFailedRetrying) {
      if (state_ == ClaimState::kFailedRetrying && !claim_dirty_) state_ = ClaimState::kIdle, claim_dirty_ = true;  // after one record saying so
      cancel_goal();
      // Waiting counts from the last new region or map tile, and not from before the survey's end: more
      // regions are coming while the quadrotor still flies.
      const TimeNs since = p_.survey_end_s > 0 ? std::max(idle_since_, t0_ + from_seconds(p_.survey_end_s)) : idle_since_;
      if (now - since >= from_seconds(p_.idle_return_s)) begin_return(now);
    }
  }
  if (state_ == ClaimState::kReturning && tracking && std::hypot(p_.start_x - loc_.pose.x, p_.start_y - loc_.pose.y) <= p_.visit_radius_m) {
    state_ = ClaimState::kDone;
    cancel_goal();
    claim_dirty_ = true;
  }
  publish_claim(now);
  if (visited_dirty_) publish_visited();
  update_status(now);
}

void MissionManager::tick_waypoints(TimeNs now, bool tracking) noexcept {
  const std::size_t n = std::min(p_.waypoint_count, kMaxWaypoints);
  const bool over = p_.mission_end_s > 0 && now - t0_ >= from_seconds(p_.mission_end_s);
  // The first waypoint also while the localizer converges (as choose() does): it needs the robot to move.
  const bool converging = have_loc_ && loc_.status == LocalizationStatus::kInitialising && wp_next_ == 0;
  if (state_ == ClaimState::kIdle && (tracking || converging)) {  // start (or the next waypoint)
    if (wp_next_ < n && !over) {
      state_ = ClaimState::kGoing;
      go_to(p_.waypoint_x[wp_next_], p_.waypoint_y[wp_next_]);
      progress_at_ = now;
      best_dist_ = std::hypot(goal_x_ - loc_.pose.x, goal_y_ - loc_.pose.y);
      claim_dirty_ = true;
    } else {
      begin_return(now);
    }
  } else if (state_ == ClaimState::kGoing) {
    const double d = tracking ? std::hypot(goal_x_ - loc_.pose.x, goal_y_ - loc_.pose.y) : best_dist_;
    bool next = false;
    if (tracking && d <= p_.visit_radius_m) {
      ++wp_reached_;
      next = true;
    } else {
      if (tracking && d < best_dist_ - p_.progress_min_m) {
        best_dist_ = d;
        progress_at_ = now;
      }
      const bool map_growing = last_map_data_ >= 0 && now - last_map_data_ <= from_seconds(p_.map_growing_s);
      if (no_route_ >= p_.max_no_route && map_growing) {
        // The way there may not be mapped yet (as for regions): not a failure; the planner keeps trying.
        ++c_.deferred_no_route;
        no_route_ = 0;
      } else if (no_route_ >= p_.max_no_route || now - progress_at_ > from_seconds(p_.no_progress_timeout_s)) {
        ++wp_skipped_;
        ++failed_own_;
        next = true;
      }
    }
    if (over) {
      begin_return(now);
    } else if (next) {
      ++wp_next_;
      state_ = ClaimState::kIdle;
      if (tracking) tick_waypoints(now, tracking);  // straight on to the next one
    }
  }
  if (state_ == ClaimState::kReturning && tracking && std::hypot(p_.start_x - loc_.pose.x, p_.start_y - loc_.pose.y) <= p_.visit_radius_m) {
    state_ = ClaimState::kDone;
    cancel_goal();
    claim_dirty_ = true;
  }
  publish_claim(now);
  update_status(now);
}

void MissionManager::update_status(TimeNs now) noexcept {
  MissionStatusMsg& s = status_;
  s.stamp = now;
  s.state = state_;
  s.region_id = region_;
  s.goal_id = goal_.id;
  s.goal_x = goal_x_;
  s.goal_y = goal_y_;
  s.pose_sigma_m = sigma_;
  std::uint32_t known = 0, vis = 0, gave_up = 0;
  for (std::size_t i = 0; i < n_regions_; ++i)
    if (regions_[i].valid) {
      ++known;
      if (visited_by_anyone(regions_[i])) ++vis;
      else if (given_up(regions_[i])) ++gave_up;
    }
  c_.regions_given_up = gave_up;
  s.regions_known = known;
  s.visited_team = vis;
  s.visited_own = visited_.count;
  s.failed_own = failed_own_;
  s.clashes_lost = clashes_lost_;
  s.takeovers = takeovers_;
  s.refused_visits = refused_visits_;
  s.records_in = c_.records_in;
  s.records_bad = c_.records_bad;
  s.done = state_ == ClaimState::kDone;
}

}  // namespace ag::mission
