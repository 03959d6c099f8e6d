// The semantic cross-view particle filter (ALGORITHMS.md §2): particles (x, y, yaw) in the map frame
// move with the odometry, are weighted by how well the polar render of the labelled scan fits the aerial
// class distance fields around them, and are resampled. Deterministic for a seed; never allocates after
// construction.
//
// One update (when the robot has moved far enough since the last):
//   1. the pending odometry increment moves every particle, with noise scaled by the distance travelled
//      and the angle turned (none while standing: see OdometryGate);
//   2. each particle is scored at yaw shifts of the render (cyclic shifts of its angle bins, hill-climbed
//      from the particle's own yaw within -w..w bins, refined by a parabola; the particle takes the best
//      yaw). The cost at a shift is the paper's: sum over the render's bins and channels of
//      count x channel weight x distance at the bin's map position, divided by the weight that fell on
//      known cells (c_known, [m]); bins on unknown cells are left out. The log weight is
//        kMask:  -exponent x known_share x ln(c_known + gamma)   (their later code: mask the unknown;
//                scaling by the known share makes a bin on an unknown cell neutral, so particles are
//                neither drawn to nor pushed from the unexplored parts of a map still being built)
//        kFixed: -exponent x ln(c + gamma), where unknown bins cost unknown_cost_m in c (the paper);
//      i.e. weight = 1 / (cost + gamma) ^ exponent (theirs: exponent 1, gamma 0.2 - 0.7);
//   3. weights accumulate, a little uniform weight is mixed in, and the set is resampled (systematic)
//      when the effective sample size drops, to a KLD-sampling count between min and max;
//   4. status: converged (tracking) once the spread stays below converged_spread_m with enough of the
//      scan on known cells; lost when the spread blows up or the best known-cell cost stays far above
//      its running level, and then the particles are re-spread around the last good pose (moved by the
//      odometry since), wider at each attempt, with the widest range bins. The next render's range-bin
//      size follows the spread.
// Particles are evaluated in Morton order of their position so that neighbours share cached cells.
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <vector>

#include "airground/platform/rng.hpp"
#include "airground/messages/geometry.hpp"
#include "airground/messages/classes.hpp"
#include "airground/localization/class_distance_fields.hpp"
#include "airground/localization/polar_render.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/param_binding.hpp"

namespace ag::loc {

enum class UnknownCost : std::uint8_t {
  kMask = 0,   // bins on unknown cells are left out; the cost is normalised over known cells only (default)
  kFixed = 1,  // bins on unknown cells cost unknown_cost_m (the paper's choice)
};

struct ParticleFilterParams {
  // particle count
  int min_particles{300};            // their later code: 300 with a good initial guess
  int max_particles{4000};           // preallocated; used while uncertain
  double kld_epsilon{0.05};          // KLD sampling: bound on the KL divergence
  double kld_z{2.33};                // KLD sampling: upper standard-normal quantile (99 %)
  double kld_bin_xy_m{1.0};          // [m] KLD histogram bin
  double kld_bin_yaw_rad{0.175};     // [rad] KLD histogram bin (10 deg)
  // motion
  double motion_sigma_xy_per_m{0.15};       // [m/m] position noise per metre travelled (their 0.15 m per step)
  double motion_sigma_yaw_per_m{0.004};     // [rad/m] yaw noise per metre travelled (their 0.004 rad per step)
  double motion_sigma_yaw_per_rad{0.05};    // [rad/rad] yaw noise per radian turned
  double motion_sigma_xy_min_m{0.05};       // [m] floor of the position noise of a moving update
  double update_min_distance_m{0.5};        // [m] update once moved this far ...
  double update_min_turn_rad{0.15};         // [rad] ... or turned this much
  // measurement
  int yaw_window_bins{2};            // yaw shifts tried each side of a particle's yaw [angle bins]
  int yaw_window_bins_tracking{1};   // ... once converged
  double gamma_m{0.3};               // [m] weight = 1 / (cost + gamma) ^ exponent (theirs: 0.2 - 0.7)
  double weight_exponent{2.0};       // sharpens the weight (theirs: 1; 2 converged 4x sooner on a partial map)
  double uniform_mix{0.01};          // fraction of uniform weight mixed in
  double resample_ess_ratio{0.5};    // resample when the effective sample size falls below this x count
  UnknownCost unknown_mode{UnknownCost::kMask};
  double unknown_cost_m{1.0};        // [m] kFixed: cost of a bin on an unknown cell (1 m measured best)
  double min_known_fraction{0.25};   // a particle's cost judges convergence and divergence only with this share known
  // adaptive range bins
  double range_bin_min_m{1.0};       // [m] (paper: 0.5; 1.0 measured better on partial maps)
  double range_bin_max_m{4.0};       // [m] (paper: 4)
  double range_bin_per_spread{1.5};  // range bin = this x spread, clamped
  // convergence and divergence
  double converged_spread_m{2.5};    // [m] publish once the spread stays below this (paper: 2.5 m)
  int converged_updates{3};          // ... for this many updates
  double lost_spread_m{8.0};         // [m] tracking is lost when the spread exceeds this
  double lost_cost_ratio{2.0};       // ... or the best cost exceeds this x its running level
  double lost_cost_min_m{1.0};       // [m] ... and this
  int lost_updates{6};               // ... for this many updates in a row
  int recovery_retry_updates{40};    // not converged this many updates after a re-spread: re-spread wider
  double recovery_sigma_xy_m{6.0};   // [m] re-spread around the last good pose, first attempt
  double recovery_sigma_yaw_rad{0.3};// [rad]
  double recovery_growth{1.5};       // sigma x this at each further attempt
  double recovery_sigma_xy_max_m{25.0};
  double lost_drift_per_m{0.05};     // [m/m] the last good pose's uncertainty grows with the distance since
  // A fix is confirmed once the filter has tracked this far [m of driving] since it converged. A fix
  // lost before that (its cost, its spread, or the pose check: a pose without room, or the planner's word)
  // is dropped: the re-spreads start from the initial guess moved by the odometry since, with the guess's
  // sigma plus lost_drift_per_m per metre, not from the last good pose. On the imported world a first
  // convergence 35-70 m up the road from the pad was found again at each re-spread around it, and the
  // pose check then refused it for ever. 0 = always the last good pose.
  double confirm_distance_m{50.0};
  // A fix the planner's word lost (set_start_blocked) is remembered: the filter does not converge within
  // this of it again until a new initial pose (0 = off). On the imported world a standing robot's wrong fix
  // in a wood, which the map check let pass and the planner refused, was found again by every re-spread
  // and lost again, for 5000 s. While the filter is not tracking, its re-spreads draw no particle inside
  // such a disc and a particle that moves into one gets no weight, so a lost cloud does not gather there
  // again. A tracking filter that passes by is not affected.
  double refused_radius_m{3.0};
  // Searching from the initial guess (an unconfirmed fix, lost), a particle farther from the guess (moved by
  // the odometry) than this many of the guess's sigmas (grown by lost_drift_per_m) gets no weight, and the
  // re-spreads keep the guess's sigma instead of growing with each attempt (0 = neither). 2: the bound R of
  // "a guess within R" (initial_sigma_m = R / 2). Standing, the same scan is matched every second, and with
  // the guess only placing the particles the resampled, roughened particles wandered to whichever wood fitted
  // that one scan best: on the imported world a robot 6 m from its dead-reckoned guess (sigma 9.6 m) was
  // searched for out to 25 m, and its cloud settled 22-23 m off (2.3 sigma), again and again. A gate, not a
  // Gaussian in the weights: the standing updates would multiply a Gaussian in as often as the scan, and
  // narrow the cloud onto the guess itself where the scan tells places apart poorly.
  double guess_gate_sigmas{2.0};
  // Lost and standing: a scan is still matched this often (the caller's clock; SemanticLocalizer), so that
  // the re-spreads go on: a robot that stops when it loses track would otherwise never be matched again
  // (AMCL's no-motion update). Each such update first roughens the particles (no motion to spread them,
  // and the same scan every time: without it the set collapses onto its first best guess), and it takes
  // more converged updates to call it tracking, so the roughened set has settled. 0 s = never.
  double lost_standing_update_s{1.0};
  double lost_standing_sigma_xy_m{0.25};      // [m] roughening per standing update
  double lost_standing_sigma_yaw_rad{0.02};   // [rad]
  int lost_standing_converged_updates{15};    // converged standing updates before tracking again
  // Still converging but already driven this far since the initial guess, and standing (a robot that
  // reached its goal on the converging estimate stops there): standing updates as when lost. Not on the
  // start pad before the first drive (there the robot waits for goals, and motion converges it better).
  double converging_standing_after_m{5.0};
  // The mission area [m, map frame] (the stage: its area_*): the robot is inside it, so a particle outside
  // has no weight. Over unmapped ground a particle's score is neutral, which beats a poor match on the
  // map: without the area a guess near the area's edge converged onto the nothing beyond it.
  MapRect area{};
  // Obstacle prior: the robot stands where its planner sends it, on cells with the planner's clearance
  // (roadmap min_clearance_m) from every mapped obstacle, or within its snap radius of one. So a particle
  // farther than obstacle_margin_m from the nearest cell with obstacle_clearance_m of room (the obstacle
  // channels' distance, LocalizationChannels::obstacle_space_channels; an unknown cell counts as room)
  // loses obstacle_penalty_per_m of log weight per metre beyond the margin at each update, up to
  // obstacle_max_depth_m. On the imported world's tree block, which ErfNet's map speckles with grass, a
  // re-spread along the tree-lined road beside it otherwise settled inside the block, "tracking", where
  // the planner found no free cell near the start (docs/localization.md). Unknown cells get no prior.
  double obstacle_clearance_m{0.6};   // [m] the planner's min_clearance_m
  double obstacle_margin_m{2.0};      // [m] the planner's snap radius
  double obstacle_penalty_per_m{1.0}; // [1/m] 0 = no prior
  double obstacle_max_depth_m{6.0};   // [m] the search for room stops here (and so does the penalty)
  // ... where room is measured from the classes the planner does not route over (its `traversable`;
  // the stage adds LocalizationChannels::add_off_route for it), or with kBlocked ("any") from the
  // obstacle classes alone. The imported world's wood, whose clearings ErfNet's map labels grass, has
  // clearance enough between the crowns but no road: a pose there converged "tracking" where the planner
  // found no free cell near the start.
  Traversability obstacle_traversable{Traversability::kRough};
  // ... except for a confirmed fix (tracking, confirm_distance_m driven since it converged): its pose check
  // and its particles' prior measure room from the obstacle classes alone (trees, buildings, vehicles:
  // LocalizationChannels::blocked_space_channels). The planner itself sends a robot onto grass (its stall
  // marks widen the way round a spot it could not pass, stall_widen_radius_m), which the room from the
  // planner's classes does not know: on gen6 a robot tracking 0.5 m from the truth 2.5 m out on the grass
  // beside a parking lot was called lost, could not converge where it stood, and stood there lost until
  // the mission's cap. A new fix still needs the planner's free space (a clearing in a wood is no place).
  bool confirmed_room_obstacles_only{true};
};

inline constexpr ParamField<ParticleFilterParams> kParticleFilterFields[] = {
    field::integer("pf_min_particles", &ParticleFilterParams::min_particles, 10, 100000, "particles", "fewest particles (their later code: 300)"),
    field::integer("pf_max_particles", &ParticleFilterParams::max_particles, 10, 100000, "particles", "most particles, preallocated (paper: 20000)"),
    field::real("pf_kld_epsilon", &ParticleFilterParams::kld_epsilon, 0.001, 1.0, "", "KLD sampling: bound on the KL divergence"),
    field::real("pf_kld_z", &ParticleFilterParams::kld_z, 0.5, 5.0, "", "KLD sampling: standard-normal quantile"),
    field::real("pf_kld_bin_xy_m", &ParticleFilterParams::kld_bin_xy_m, 0.05, 10.0, "m", "KLD histogram bin, position"),
    field::real("pf_kld_bin_yaw_rad", &ParticleFilterParams::kld_bin_yaw_rad, 0.01, 1.0, "rad", "KLD histogram bin, yaw"),
    field::real("pf_motion_sigma_xy_per_m", &ParticleFilterParams::motion_sigma_xy_per_m, 0.0, 2.0, "m/m", "position noise per metre travelled (theirs: 0.15 m per step)"),
    field::real("pf_motion_sigma_yaw_per_m", &ParticleFilterParams::motion_sigma_yaw_per_m, 0.0, 0.5, "rad/m", "yaw noise per metre travelled (theirs: 0.004 rad per step)"),
    field::real("pf_motion_sigma_yaw_per_rad", &ParticleFilterParams::motion_sigma_yaw_per_rad, 0.0, 1.0, "rad/rad", "yaw noise per radian turned"),
    field::real("pf_motion_sigma_xy_min_m", &ParticleFilterParams::motion_sigma_xy_min_m, 0.0, 2.0, "m", "floor of the position noise of a moving update"),
    field::real("pf_update_min_distance_m", &ParticleFilterParams::update_min_distance_m, 0.01, 20.0, "m", "update once moved this far"),
    field::real("pf_update_min_turn_rad", &ParticleFilterParams::update_min_turn_rad, 0.01, 3.14, "rad", "... or turned this much"),
    field::integer("pf_yaw_window_bins", &ParticleFilterParams::yaw_window_bins, 0, 20, "bins", "yaw shifts tried each side of a particle's yaw"),
    field::integer("pf_yaw_window_bins_tracking", &ParticleFilterParams::yaw_window_bins_tracking, 0, 20, "bins", "... once converged"),
    field::real("pf_gamma_m", &ParticleFilterParams::gamma_m, 0.01, 10.0, "m", "weight = 1 / (cost + gamma)^exponent (theirs: 0.2-0.7)"),
    field::real("pf_weight_exponent", &ParticleFilterParams::weight_exponent, 0.1, 10.0, "", "sharpens the weight (theirs: 1)"),
    field::real("pf_uniform_mix", &ParticleFilterParams::uniform_mix, 0.0, 0.5, "", "fraction of uniform weight mixed in"),
    field::real("pf_resample_ess_ratio", &ParticleFilterParams::resample_ess_ratio, 0.0, 1.0, "", "resample below this effective sample size ratio"),
    field::choice<&ParticleFilterParams::unknown_mode>("pf_unknown_mode", "mask|fixed", {UnknownCost::kMask, UnknownCost::kFixed}, "unknown aerial cells: masked out, or a fixed cost (paper)"),
    field::real("pf_unknown_cost_m", &ParticleFilterParams::unknown_cost_m, 0.0, 60.0, "m", "fixed: cost of a bin on an unknown cell (1 m measured best)"),
    field::real("pf_min_known_fraction", &ParticleFilterParams::min_known_fraction, 0.0, 1.0, "", "a particle's cost judges convergence and divergence only with this share known"),
    field::real("pf_range_bin_min_m", &ParticleFilterParams::range_bin_min_m, 0.1, 10.0, "m", "smallest range bin (paper: 0.5; 1.0 measured better on partial maps)"),
    field::real("pf_range_bin_max_m", &ParticleFilterParams::range_bin_max_m, 0.1, 20.0, "m", "largest range bin (paper: 4)"),
    field::real("pf_range_bin_per_spread", &ParticleFilterParams::range_bin_per_spread, 0.0, 10.0, "", "range bin = this x spread, clamped"),
    field::real("pf_converged_spread_m", &ParticleFilterParams::converged_spread_m, 0.1, 50.0, "m", "publish once the spread stays below this (paper: 2.5)"),
    field::integer("pf_converged_updates", &ParticleFilterParams::converged_updates, 1, 1000, "updates", "... for this many updates"),
    field::real("pf_lost_spread_m", &ParticleFilterParams::lost_spread_m, 0.5, 200.0, "m", "lost when the spread exceeds this"),
    field::real("pf_lost_cost_ratio", &ParticleFilterParams::lost_cost_ratio, 1.0, 100.0, "", "... or the best cost exceeds this x its running level"),
    field::real("pf_lost_cost_min_m", &ParticleFilterParams::lost_cost_min_m, 0.0, 60.0, "m", "... and this"),
    field::integer("pf_lost_updates", &ParticleFilterParams::lost_updates, 1, 1000, "updates", "... for this many updates in a row"),
    field::integer("pf_recovery_retry_updates", &ParticleFilterParams::recovery_retry_updates, 1, 100000, "updates", "not converged this long after a re-spread: re-spread wider"),
    field::real("pf_recovery_sigma_xy_m", &ParticleFilterParams::recovery_sigma_xy_m, 0.1, 200.0, "m", "re-spread around the last good pose, first attempt"),
    field::real("pf_recovery_sigma_yaw_rad", &ParticleFilterParams::recovery_sigma_yaw_rad, 0.0, 3.14, "rad", "re-spread yaw sigma"),
    field::real("pf_recovery_growth", &ParticleFilterParams::recovery_growth, 1.0, 10.0, "", "sigma x this at each further attempt"),
    field::real("pf_recovery_sigma_xy_max_m", &ParticleFilterParams::recovery_sigma_xy_max_m, 0.1, 500.0, "m", "largest re-spread sigma"),
    field::real("pf_lost_drift_per_m", &ParticleFilterParams::lost_drift_per_m, 0.0, 1.0, "m/m", "last good pose uncertainty per metre since"),
    field::real("pf_confirm_distance_m", &ParticleFilterParams::confirm_distance_m, 0.0, 100000.0, "m",
                "a fix lost before tracking this far re-spreads from the initial guess, not from it (0 = never)"),
    field::real("pf_refused_radius_m", &ParticleFilterParams::refused_radius_m, 0.0, 25.0, "m",
                "no convergence this close to a fix the planner's word lost, until a new initial pose (0 = off)"),
    field::real("pf_guess_gate_sigmas", &ParticleFilterParams::guess_gate_sigmas, 0.0, 100.0, "sigma",
                "searching from the initial guess: no weight farther than this many of its sigmas, no wider re-spreads (0 = off)"),
    field::real("pf_lost_standing_update_s", &ParticleFilterParams::lost_standing_update_s, 0.0, 60.0, "s",
                "lost and standing: match a scan this often anyway, so the re-spreads go on (0 = never)"),
    field::real("pf_lost_standing_sigma_xy_m", &ParticleFilterParams::lost_standing_sigma_xy_m, 0.0, 5.0, "m",
                "... roughening the particles by this first"),
    field::real("pf_lost_standing_sigma_yaw_rad", &ParticleFilterParams::lost_standing_sigma_yaw_rad, 0.0, 0.5, "rad", "... and this"),
    field::integer("pf_lost_standing_converged_updates", &ParticleFilterParams::lost_standing_converged_updates, 1, 1000, "updates",
                   "... and tracking again only after this many converged ones"),
    field::real("pf_converging_standing_after_m", &ParticleFilterParams::converging_standing_after_m, 0.0, 10000.0, "m",
                "still converging after driving this far since the initial guess: standing updates too (0 = from the start)"),
    field::real("pf_obstacle_clearance_m", &ParticleFilterParams::obstacle_clearance_m, 0.0, 5.0, "m",
                "obstacle prior: a cell with this much room from mapped obstacles is where the robot can be (the planner's min_clearance_m)"),
    field::real("pf_obstacle_margin_m", &ParticleFilterParams::obstacle_margin_m, 0.0, 25.0, "m",
                "... and so is any point this close to one (the planner's snap radius)"),
    field::real("pf_obstacle_penalty_per_m", &ParticleFilterParams::obstacle_penalty_per_m, 0.0, 20.0, "1/m",
                "... beyond it, log weight lost per metre at each update (0 = no prior)"),
    field::real("pf_obstacle_max_depth_m", &ParticleFilterParams::obstacle_max_depth_m, 0.5, 15.0, "m",
                "... up to this distance from room (the search stops there)"),
    field::choice<&ParticleFilterParams::obstacle_traversable>(
        "pf_obstacle_traversable", "free|rough|costly|any",
        {Traversability::kFree, Traversability::kRough, Traversability::kCostly, Traversability::kBlocked},
        "... room is clearance from the classes above this level (the planner's traversable; any = from obstacles only)"),
    field::boolean("pf_confirmed_room_obstacles_only", &ParticleFilterParams::confirmed_room_obstacles_only,
                   "... but a confirmed fix's room is clearance from the obstacle classes alone (the planner's stall marks may send it onto grass)"),
};
inline constexpr auto kParticleFilterParamSpecs = param_specs(kParticleFilterFields);
ParticleFilterParams load_particle_filter_params(const SectionView& s);

enum class FilterStatus : std::uint8_t {
  kUninitialised = 0,  // no initial guess yet
  kInitialising = 1,   // spread still above converged_spread_m: nothing to publish
  kTracking = 2,       // converged
  kLost = 3,           // diverged: re-spread around the last good pose, converging again
};

struct FilterEstimate {
  Pose2 pose;                          // weighted mean [m, rad]
  std::array<double, 9> covariance{};  // row-major 3x3 over (x, y, yaw) [m^2, m rad, rad^2]
  double spread_m{0};                  // [m] sqrt of the largest eigenvalue of the xy covariance
  double yaw_spread_rad{0};            // [rad] circular standard deviation
  FilterStatus status{FilterStatus::kUninitialised};
  std::uint32_t particles{0};
  double best_cost_m{0};               // [m] lowest known-cell cost of the last update (-1: no particle saw enough known cells)
  double cost_level_m{0};              // [m] running level of the best cost while tracking
  double range_bin_m{0};               // [m] for the next render
  std::uint64_t updates{0};
  std::uint32_t recoveries{0};         // re-spreads after divergence (total)
  std::uint64_t outside_area{0};       // particles found outside the mission area at an update (total; no weight)
  std::uint64_t inside_obstacle{0};    // particles found beyond the obstacle margin from room at an update (total; penalised)
  // The pose check (obstacle prior on): [m] from the mean pose to the nearest cell with room, at the last
  // update (0 with the prior off). Beyond obstacle_margin_m the pose is one the robot cannot hold (the
  // planner cannot start from it either): it does not converge there, and tracking there is lost after
  // lost_updates such updates.
  double room_m{0};
  std::uint64_t blocked_updates{0};    // updates whose mean pose had no room (total)
  std::uint32_t refused_fixes{0};      // fixes the planner's word lost since the initial pose (remembered: refused_radius_m)
  std::uint64_t outside_guess{0};      // particles given no weight beyond the guess's gate (guess_gate_sigmas; searching)
  std::uint64_t in_refused{0};         // particles given no weight for lying in a refused fix's disc (not tracking)
};

struct UpdateReport {
  bool updated{false};      // false: standing still (or no initial guess): nothing changed
  bool resampled{false};
  bool recovered{false};    // this update declared divergence and re-spread the particles
  double moved_m{0};        // [m] odometry distance applied
  double best_cost_m{0};    // [m] lowest known-cell cost (-1: no particle saw min_known_fraction of known cells)
  double known_fraction{0}; // share of the render's weight on known cells, that particle
};

class ParticleFilter {
 public:
  // Scratch is sized for renders of `render`'s angle and range bins.
  ParticleFilter(const ParticleFilterParams& params, const PolarRenderParams& render, std::uint64_t seed);

  // Initial guesses: a Gaussian, or uniform over a disc and a yaw interval; max_particles particles.
  void initialise_gaussian(const Pose2& guess, double sigma_xy_m, double sigma_yaw_rad) noexcept;
  void initialise_disc(const Pose2& guess, double radius_m, double yaw_halfwidth_rad) noexcept;

  // The robot moved by `delta` (body frame at the previous call: dx forward, dy left, dyaw), from the
  // gated odometry (OdometryGate): accumulated until the next update.
  void add_motion(const Pose2& delta) noexcept;
  // The pending motion is large enough for an update (or none happened since initialisation).
  [[nodiscard]] bool wants_update() const noexcept;
  // Range-bin size the next render should use [m].
  [[nodiscard]] double range_bin_m() const noexcept { return range_bin_m_; }

  // Applies the pending motion and weighs the particles against `fields` with `render` (made at
  // range_bin_m()). Does nothing unless wants_update() or `force`. Never allocates.
  UpdateReport update(const ScanRenderPolar& render, const ClassDistanceFields& fields, bool force = false) noexcept;
  // Lost and standing (SemanticLocalizer, lost_standing_update_s): an update without motion whose
  // particles are roughened by lost_standing_sigma_* first. Never allocates.
  UpdateReport update_standing(const ScanRenderPolar& render, const ClassDistanceFields& fields) noexcept;

  [[nodiscard]] const FilterEstimate& estimate() const noexcept { return est_; }
  [[nodiscard]] FilterStatus status() const noexcept { return est_.status; }
  // [m] the odometry's distance applied in updates since the initial guess.
  [[nodiscard]] double driven_m() const noexcept { return driven_m_; }
  [[nodiscard]] std::size_t size() const noexcept { return n_; }
  [[nodiscard]] Pose2 particle(std::size_t i) const noexcept { return {x_[i], y_[i], yaw_[i]}; }
  [[nodiscard]] double weight(std::size_t i) const noexcept { return w_[i]; }
  [[nodiscard]] const ParticleFilterParams& params() const noexcept { return p_; }
  [[nodiscard]] std::size_t memory_bytes() const noexcept;  // everything this object holds
  // The initial guess moved by the odometry since, and its sigma grown by lost_drift_per_m [m, rad].
  [[nodiscard]] Pose2 dead_reckoned_guess() const noexcept { return prior_; }
  [[nodiscard]] double dead_reckoned_sigma_m() const noexcept { return prior_sigma_xy_ + p_.lost_drift_per_m * dist_since_prior_; }
  // The last pose judged good (tracking, cost in line), moved by the odometry since [m, rad].
  [[nodiscard]] Pose2 last_good_pose() const noexcept { return last_good_; }
  [[nodiscard]] bool has_last_good_pose() const noexcept { return has_last_good_; }

  // The known-cell cost of one pose (no yaw shifts) [m], and the share of the render on known cells:
  // for tests and diagnostics.
  // The mean pose lies farther than obstacle_margin_m from any cell with room in `fields` (as the map is
  // now; false with the obstacle prior off): SemanticLocalizer re-checks a standing, tracking robot so.
  [[nodiscard]] bool pose_blocked(const ClassDistanceFields& fields) const noexcept;
  // The planner found no free cell near the pose this filter tracks (SemanticLocalizer::set_start_blocked):
  // each update counts as one at a blocked pose until it is cleared, or until the filter is lost or
  // initialised again (the word was about the old pose).
  void set_start_blocked(bool blocked) noexcept { start_blocked_ = blocked; }
  [[nodiscard]] bool start_blocked() const noexcept { return start_blocked_; }

  [[nodiscard]] double pose_cost(const Pose2& pose, const ScanRenderPolar& render, const ClassDistanceFields& fields,
                                 double* known_fraction = nullptr) noexcept;

 private:
  // Best log-weight (score) over yaw shifts of -window..window bins for a particle at (x, y, yaw), with
  // the known share and known-cell cost at that shift; returns the yaw correction [rad] (the best
  // shift, refined by a parabola).
  double evaluate(double x, double y, double yaw, const ScanRenderPolar& render, const ClassDistanceFields& fields,
                  int window, double& score, double& known_fraction, double& known_cost) noexcept;
  void prepare_angles(const ScanRenderPolar& render) noexcept;  // also the bins' offsets: once per render
  void apply_motion(bool roughen = false) noexcept;
  UpdateReport update_impl(const ScanRenderPolar& render, const ClassDistanceFields& fields, bool force, bool roughen) noexcept;
  void resample() noexcept;
  std::size_t kld_count() noexcept;
  void compute_estimate() noexcept;
  void build_room_table();  // the constructor's: room_ (obstacle_prior.cpp)
  // Obstacle prior: [m] from (x, y) to the nearest cell with obstacle_clearance_m of room from the
  // `obstacle_mask` channels' sources, or unknown (outside the fields is unknown), obstacle_max_depth_m
  // when there is none that near. Exact on the fields' cells (the offset table, nearest first).
  [[nodiscard]] double room_distance_m(const ClassDistanceFields& f, std::uint8_t obstacle_mask, double x, double y) const noexcept;
  // The channels room is measured from now (0: the obstacle prior is off): the obstacle classes alone for a
  // confirmed fix (confirmed_room_obstacles_only), else the fields' obstacle space (the planner's classes).
  [[nodiscard]] std::uint8_t room_channels(const ClassDistanceFields& f) const noexcept;
  static constexpr int kRoomTableCells = 32;  // 16 m on 0.5 m cells, 8 m on 0.25 m
  void update_status(double best_cost, bool cost_valid, bool standing, bool blocked) noexcept;
  void respread(const Pose2& centre, double sigma_xy, double sigma_yaw) noexcept;
  void set_range_bin() noexcept;

  ParticleFilterParams p_;
  int max_angle_bins_{0}, max_range_bins_{0};
  int prepared_angle_bins_{0};
  Rng rng_{0};  // seeded in the constructor
  std::size_t n_{0};
  std::vector<double> x_, y_, yaw_, w_, score_;  // score: log weight of the last update
  std::vector<double> nx_, ny_, nyaw_;  // resampling target
  std::vector<std::uint64_t> kld_keys_;
  std::vector<std::uint64_t> order_;  // evaluation order: Morton key << 32 | particle
  std::vector<std::uint32_t> kld_stamp_;
  std::uint32_t kld_gen_{0};
  // per-particle scratch: map cell index per (angle incl. shifts, range bin); trig of the angles
  std::vector<std::int32_t> idx_;
  std::vector<std::int32_t> bin_offset_;  // per render bin: angle x padded range bins + range
  std::vector<float> base_cos_, base_sin_;
  std::vector<double> shift_cost_, shift_known_, shift_known_cost_;
  struct RoomOffset {
    std::int16_t dc, dr;  // [cells]
    std::int32_t d2;      // [cells^2]
  };
  std::vector<RoomOffset> room_;  // obstacle prior: the cell offsets within kRoomTableCells, nearest first
  Pose2 pending_{};           // accumulated motion since the last update (body frame then)
  double pending_dist_{0};    // [m] path length
  double pending_turn_{0};    // [rad] total |dyaw|
  bool first_update_done_{false};
  double driven_m_{0.0};
  double range_bin_m_{4.0};
  FilterEstimate est_{};
  int converged_count_{0};
  int bad_count_{0};
  bool cost_level_valid_{false};
  Pose2 last_good_{};
  bool has_last_good_{false};
  double dist_since_good_{0};
  std::uint32_t attempt_{0};  // recovery attempts since the last tracking
  int updates_since_respread_{0};
  bool start_blocked_{false};
  static constexpr std::size_t kMaxRefused = 8;
  static constexpr int kRespreadTries = 8;  // draws per particle to land outside every refused disc
  std::array<Pose2, kMaxRefused> refused_{};  // the fixes the planner's word lost (a ring, newest kept)
  [[nodiscard]] bool near_refused(const Pose2& p) const noexcept;
  Pose2 prior_{};                // the initial guess, moved by the odometry since
  double prior_sigma_xy_{0}, prior_sigma_yaw_{0};
  double dist_since_prior_{0};   // [m]
  double tracked_m_{0};          // [m] driven while tracking since the last convergence
  bool distrust_good_{false};    // the last good pose was an unconfirmed fix, lost
};

}  // namespace ag::loc
