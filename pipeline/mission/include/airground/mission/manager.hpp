// The mission manager of one ground robot (ALGORITHMS.md §5, docs/missions.md): pure logic, no I/O, no
// allocation after construction. It hears the quadrotor's regions and the team's claims, visited and
// failure records (decoded from gossip payloads), the others' liveness and its own localization and
// route status; it chooses the nearest region not visited by anyone, not claimed by a live robot and not
// recently failed by itself, claims it, sends the goal, resolves clashes by the fixed priority (the lower
// number keeps the region; equal priorities: the lower robot id), marks a region visited only when it is
// within visit_radius_m of the goal while tracking with a pose sigma below max_sigma_m, reports failures
// (no route max_no_route times, no progress for no_progress_timeout_s), takes over the claims of robots
// not heard for claim_timeout_s, waits for new regions when nothing is left and returns to its start
// after idle_return_s without new regions, not before the survey's expected end (or at mission_end_s).
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <span>

#include "airground/comms/messages.hpp"
#include "airground/messages/drive_messages.hpp"
#include "airground/messages/messages.hpp"
#include "airground/mission/messages.hpp"
#include "airground/mission/records.hpp"

namespace ag::mission {

inline constexpr std::size_t kMaxWaypoints = 64;

struct ManagerParams {
  comms::RobotId self{1};
  std::uint8_t priority{1};            // lower number wins a clash
  double start_x{0}, start_y{0};       // [m] where it returns at the end
  double visit_radius_m{3.0};
  // [m] a visit is marked only within visit_radius_m - visit_margin_m (at least half the radius) of the
  // goal: the pose's own error must not carry a mark made at the circle's edge outside it.
  double visit_margin_m{1.5};
  // [m] A region's goal moves as the map grows it (a long row of parked cars is found one part at a time):
  // a mark made farther than this from the goal it has now no longer counts, and the region is visited
  // again. 0 = a mark counts for ever.
  double revisit_moved_m{10.0};
  double max_sigma_m{1.5};             // [m] a pose less certain than this marks nothing visited
  int max_no_route{5};                 // failed plans in a row for the current goal: failure
  double no_progress_timeout_s{90.0};  // no progress_min_m closer in this long: failure
  double progress_min_m{2.0};
  // A region this robot failed is not chosen by it again before this; one it had no route to (no free
  // cell near it, or none on the way: unmapped ground) not before new map data has come either. With
  // nothing else left the robot goes idle and returns to its start, where the map comes from (the
  // quadrotor hovers over it after its survey; out of radio range the robot would otherwise retry forever).
  double retry_after_s{120.0};
  // The team gives a region up after this many failures to reach it (no_progress or lost_localization,
  // by any robot, at goals within revisit_moved_m of its goal now; no_route has the map-data rule above):
  // no robot chooses it again unless its goal moves. nav2's bounded retries; without it a region the
  // aerial map got wrong (gen6's pond read as parked vehicles, its goal on a shore no robot can reach)
  // was retried every retry_after_s to the mission's time cap. 0 = never.
  int give_up_failures{5};
  double claim_timeout_s{20.0};        // a robot not heard this long: its claim is void
  double idle_return_s{60.0};          // nothing left and no new region this long: return to start
  double mission_end_s{0.0};           // > 0: return to start this long after the first tick regardless
  // > 0: the quadrotor's survey should end this long after the first tick; until then a robot with nothing
  // to do keeps waiting for regions (a team out of radio range of the quadrotor hears of them late), and
  // idle_return_s counts from then at the earliest.
  double survey_end_s{0.0};
  double republish_s{2.0};             // own claim and visited records re-sent this often
  // No route while the map is still growing (a tile within map_growing_s) is not a failure: the unknown
  // ground between here and there may still be mapped. The region is dropped quietly and not chosen by
  // this robot again for defer_s.
  double map_growing_s{20.0};
  double defer_s{20.0};
  // Waypoints mission (target mapping): when waypoint_count > 0 the robot drives these in order (each
  // reached within visit_radius_m while tracking; one it cannot plan to max_no_route times is skipped),
  // then returns to its start. Regions are not chosen.
  std::array<double, kMaxWaypoints> waypoint_x{}, waypoint_y{};
  std::size_t waypoint_count{0};
};

struct GoalCommand {
  std::uint32_t id{0};     // grows with every new goal or cancel
  double x{0}, y{0};       // [m]
  bool cancel{false};
};

struct OutRecord {
  comms::Topic topic{0};
  std::uint32_t size{0};
  std::array<std::uint8_t, comms::kGossipPayloadMax> payload{};
};

struct ManagerCounters {
  std::uint64_t records_in{0}, records_bad{0}, records_ignored{0};
  std::uint64_t regions_overflow{0}, failures_overflow{0}, visited_overflow{0};
  std::uint64_t deferred_no_route{0};  // no route while the map still grows: dropped for defer_s, not failed
  std::uint64_t regions_given_up{0};   // known regions not visited that the team gave up (give_up_failures), now
};

class MissionManager {
 public:
  static constexpr std::size_t kMaxRegions = kMaxRegionsMsg;
  static constexpr std::size_t kMaxBatches = kMaxRegionsMsg / kRegionsPerBatch;
  static constexpr std::size_t kMaxPeers = comms::kTeamMax;
  static constexpr std::size_t kMaxFailures = 128;
  static constexpr std::size_t kOutboxCapacity = 4;

  explicit MissionManager(const ManagerParams& p);

  // ---- inputs
  // A gossip record of another robot (regions, claims, visited, failures); malformed ones are counted.
  DecodeError on_record(comms::RobotId origin, comms::Topic topic, std::span<const std::uint8_t> payload, TimeNs now) noexcept;
  // The robot was heard (a newer pose on team_poses).
  void on_peer_heard(comms::RobotId robot, TimeNs now) noexcept;
  // New map data arrived (a tile): the quadrotor is still mapping, so waiting for regions starts again.
  void on_map_data(TimeNs now) noexcept {
    idle_since_ = now;
    last_map_data_ = now;
  }
  void on_localization(const LocalizationMsg& m) noexcept;
  void on_route(std::uint32_t goal_id, std::uint32_t seq, RouteStatus status) noexcept;
  void tick(TimeNs now) noexcept;

  // ---- outputs
  [[nodiscard]] const GoalCommand& goal() const noexcept { return goal_; }
  [[nodiscard]] std::span<const OutRecord> outbox() const noexcept { return {outbox_.data(), n_out_}; }
  void clear_outbox() noexcept { n_out_ = 0; }
  [[nodiscard]] const MissionStatusMsg& status() const noexcept { return status_; }
  [[nodiscard]] ClaimState state() const noexcept { return state_; }
  [[nodiscard]] std::uint32_t current_region() const noexcept { return region_; }
  [[nodiscard]] const VisitedRecord& own_visited() const noexcept { return visited_; }
  // Someone's visit mark counts for region `id` (within revisit_moved_m of its goal, when it is known).
  [[nodiscard]] bool visited_by_anyone(std::uint32_t id) const noexcept;
  [[nodiscard]] const ManagerCounters& counters() const noexcept { return c_; }
  [[nodiscard]] const ManagerParams& params() const noexcept { return p_; }
  [[nodiscard]] std::size_t regions_known() const noexcept { return n_regions_; }
  [[nodiscard]] std::size_t waypoints_reached() const noexcept { return wp_reached_; }
  [[nodiscard]] std::size_t waypoints_skipped() const noexcept { return wp_skipped_; }

 private:
  // Where a visit is marked: visit_radius_m - visit_margin_m, never below half the radius.
  [[nodiscard]] double mark_radius() const noexcept { return std::max(p_.visit_radius_m - p_.visit_margin_m, 0.5 * p_.visit_radius_m); }
  struct KnownRegion {
    std::uint32_t id{0};
    double x{0}, y{0};  // [m] its goal
    bool valid{false};
  };
  [[nodiscard]] bool visited_by_anyone(const KnownRegion& r) const noexcept;
  [[nodiscard]] bool given_up(const KnownRegion& r) const noexcept;
  struct Peer {
    comms::RobotId id{comms::kNoRobot};
    TimeNs last_heard{0};
    bool has_claim{false};
    ClaimRecord claim;
    VisitedRecord visited;
  };
  struct Failure {
    comms::RobotId origin{comms::kNoRobot};
    std::uint32_t region{0};
    TimeNs at{0};
    FailureReason reason{FailureReason::kNoRoute};
    std::uint16_t attempts{1};  // another robot's: its own count so far (its latest record); own: one per entry
    float x{0}, y{0};           // [m] the goal it failed to reach
  };
  Peer* peer(comms::RobotId id, bool create) noexcept;
  [[nodiscard]] bool alive(const Peer& p, TimeNs now) const noexcept;
  [[nodiscard]] bool peer_wins(const Peer& p) const noexcept;
  [[nodiscard]] const KnownRegion* region(std::uint32_t id) const noexcept;
  void rebuild_regions(TimeNs now) noexcept;
  bool choose(TimeNs now) noexcept;
  void go_to(double x, double y) noexcept;
  void cancel_goal() noexcept;
  void release(ClaimState next, TimeNs now) noexcept;
  void fail(FailureReason why, TimeNs now) noexcept;
  void begin_return(TimeNs now) noexcept;
  void publish_claim(TimeNs now) noexcept;
  void publish_visited() noexcept;
  OutRecord* out_slot() noexcept;
  void update_status(TimeNs now) noexcept;
  void tick_waypoints(TimeNs now, bool tracking) noexcept;
  std::size_t wp_next_{0}, wp_reached_{0}, wp_skipped_{0};

  ManagerParams p_;
  std::array<RegionBatch, kMaxBatches> batches_{};
  std::array<bool, kMaxBatches> have_batch_{};
  std::uint16_t batch_count_{0};
  std::array<KnownRegion, kMaxRegions> regions_{};
  std::size_t n_regions_{0};
  bool regions_dirty_{false};
  std::array<Peer, kMaxPeers> peers_{};
  std::array<Failure, kMaxFailures> failures_{};
  std::size_t n_failures_{0}, next_failure_{0};
  VisitedRecord visited_{};
  bool visited_dirty_{false};
  std::array<OutRecord, kOutboxCapacity> outbox_{};
  std::size_t n_out_{0};

  LocalizationMsg loc_{};
  bool have_loc_{false};
  double sigma_{0};
  GoalCommand goal_{};
  ClaimState state_{ClaimState::kIdle};
  std::uint32_t region_{kNoRegion};
  double goal_x_{0}, goal_y_{0};
  int no_route_{0};
  std::uint32_t last_route_seq_{0};
  double best_dist_{0};
  TimeNs progress_at_{0}, idle_since_{0}, t0_{0}, last_claim_pub_{0};
  TimeNs last_map_data_{-1};
  struct Deferred {
    std::uint32_t region{kNoRegion};
    TimeNs until{0};
  };
  std::array<Deferred, 16> deferred_{};
  bool started_{false}, claim_dirty_{true}, ended_{false};
  std::uint32_t failed_own_{0}, clashes_lost_{0}, takeovers_{0}, refused_visits_{0};
  ClaimRecord last_claim_{};
  MissionStatusMsg status_{};
  ManagerCounters c_;
};

// sqrt of the largest eigenvalue of the xy block of a row-major 3x3 covariance [m].
double pose_sigma_m(const std::array<double, 9>& cov) noexcept;

}  // namespace ag::mission
