// The semantic cross-view particle filter: motion, cost of the polar render against the distance fields
// with yaw by cyclic shift, weights, KLD-sized systematic resampling, convergence and recovery.
#include "airground/localization/particle_filter.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

namespace ag::loc {

namespace {

// Map cells (row-major index, or `outside`) of kCellBlock consecutive range-bin centres r0, r0 + 1, ...
// along the direction (ux, uy) [cells per range bin] from (fx0, fy0) [cells], in GCC vector types
// (AVX2 on the robots' x86, NEON on the Xavier's ARM).
constexpr std::size_t kCellBlock = 8;
using F8 = float __attribute__((vector_size(32)));
using I8 = std::int32_t __attribute__((vector_size(32)));
std::size_t padded_range_bins(int n) noexcept {
  return (static_cast<std::size_t>(n) + kCellBlock - 1) / kCellBlock * kCellBlock;
}
void cells_along(float fx0, float fy0, float ux, float uy, float r0, std::int32_t w, std::int32_t h, std::int32_t outside,
                 std::int32_t* out) noexcept {
  const F8 k = F8{0, 1, 2, 3, 4, 5, 6, 7} + r0;
  // +1 then -1: truncation is the floor down to -1; the clamp keeps the conversion defined
  F8 fx = fx0 + k * ux + 1.0F, fy = fy0 + k * uy + 1.0F;
  const float wf = static_cast<float>(w) + 2.0F, hf = static_cast<float>(h) + 2.0F;
  fx = fx < 0.0F ? F8{} : fx;
  fy = fy < 0.0F ? F8{} : fy;
  fx = fx > wf ? F8{} + wf : fx;
  fy = fy > hf ? F8{} + hf : fy;
  const I8 c = __builtin_convertvector(fx, I8) - 1, r = __builtin_convertvector(fy, I8) - 1;
  const I8 in = (c >= 0) & (r >= 0) & (c < w) & (r < h);
  const I8 idx = in ? r * w + c : I8{} + outside;
  std::memcpy(out, &idx, sizeof idx);
}

std::uint64_t interleave16(std::uint32_t v) noexcept {  // bit k -> bit 2k
  std::uint64_t x = v & 0xFFFFU;
  x = (x | (x << 8U)) & 0x00FF00FFULL;
  x = (x | (x << 4U)) & 0x0F0F0F0FULL;
  x = (x | (x << 2U)) & 0x33333333ULL;
  x = (x | (x << 1U)) & 0x55555555ULL;
  return x;
}

std::size_t next_pow2(std::size_t v) noexcept {
  std::size_t p = 1;
  while (p < v) p <<= 1U;
  return p;
}

}  // namespace

ParticleFilterParams load_particle_filter_params(const SectionView& s) {
  return load_params(s, kParticleFilterFields);
}

// ------------------------------------------------------------------------------------------- set-up

ParticleFilter::ParticleFilter(const ParticleFilterParams& params, const PolarRenderParams& render, std::uint64_t seed)
    : p_(params), max_angle_bins_(render.angle_bins), max_range_bins_(render.range_bins) {
  if (p_.min_particles < 1 || p_.max_particles < p_.min_particles)
    throw std::invalid_argument("ParticleFilter: need 1 <= min_particles <= max_particles");
  if (p_.yaw_window_bins < 0 || p_.yaw_window_bins > 20 || p_.yaw_window_bins_tracking < 0 ||
      p_.yaw_window_bins_tracking > p_.yaw_window_bins)
    throw std::invalid_argument("ParticleFilter: need 0 <= yaw_window_bins_tracking <= yaw_window_bins <= 20");
  if (max_angle_bins_ < 1 || max_range_bins_ < 1) throw std::invalid_argument("ParticleFilter: render bins must be positive");
  if (p_.range_bin_min_m <= 0.0 || p_.range_bin_max_m < p_.range_bin_min_m)
    throw std::invalid_argument("ParticleFilter: need 0 < range_bin_min_m <= range_bin_max_m");
  rng_ = Rng(seed);
  const auto n = static_cast<std::size_t>(p_.max_particles);
  for (auto* v : {&x_, &y_, &yaw_, &w_, &score_, &nx_, &ny_, &nyaw_}) v->assign(n, 0.0);
  const std::size_t table = next_pow2(2 * n);
  kld_keys_.assign(table, 0);
  order_.assign(n, 0);
  bin_offset_.assign(static_cast<std::size_t>(max_angle_bins_) * static_cast<std::size_t>(max_range_bins_), 0);
  kld_stamp_.assign(table, 0);
  const auto angles = static_cast<std::size_t>(max_angle_bins_ + 2 * p_.yaw_window_bins);
  base_cos_.assign(angles, 0.0F);
  base_sin_.assign(angles, 0.0F);
  idx_.assign(angles * padded_range_bins(max_range_bins_), 0);
  const auto shifts = static_cast<std::size_t>(2 * p_.yaw_window_bins + 1);
  shift_cost_.assign(shifts, 0.0);
  shift_known_.assign(shifts, 0.0);
  shift_known_cost_.assign(shifts, 0.0);
  range_bin_m_ = p_.range_bin_max_m;
  build_room_table();
}

std::size_t ParticleFilter::memory_bytes() const noexcept {
  std::size_t b = sizeof(*this);
  for (const auto* v : {&x_, &y_, &yaw_, &w_, &score_, &nx_, &ny_, &nyaw_, &shift_cost_, &shift_known_, &shift_known_cost_})
    b += v->capacity() * sizeof(double);
  for (const auto* v : {&base_cos_, &base_sin_}) b += v->capacity() * sizeof(float);
  return b + (kld_keys_.capacity() + order_.capacity()) * sizeof(std::uint64_t) + kld_stamp_.capacity() * sizeof(std::uint32_t) +
         (idx_.capacity() + bin_offset_.capacity()) * sizeof(std::int32_t) + room_.capacity() * sizeof(RoomOffset);
}

void ParticleFilter::respread(const Pose2& centre, double sigma_xy, double sigma_yaw) noexcept {
  n_ = static_cast<std::size_t>(p_.max_particles);
  const double w = 1.0 / static_cast<double>(n_);
  for (std::size_t i = 0; i < n_; ++i) {
    // Not inside a refused fix's disc (a few tries: the discs are small beside any re-spread's sigma).
    for (int attempt = 0; attempt < kRespreadTries; ++attempt) {
      x_[i] = centre.x + sigma_xy * rng_.gaussian();
      y_[i] = centre.y + sigma_xy * rng_.gaussian();
      if (!near_refused(Pose2{x_[i], y_[i], 0.0})) break;
    }
    yaw_[i] = wrap_angle(centre.yaw + sigma_yaw * rng_.gaussian());
    w_[i] = w;
    score_[i] = 0.0;
  }
  range_bin_m_ = p_.range_bin_max_m;
  converged_count_ = 0;
  bad_count_ = 0;
  updates_since_respread_ = 0;
  compute_estimate();
}

void ParticleFilter::initialise_gaussian(const Pose2& guess, double sigma_xy_m, double sigma_yaw_rad) noexcept {
  respread(guess, sigma_xy_m, sigma_yaw_rad);
  est_.status = FilterStatus::kInitialising;
  start_blocked_ = false;
  est_.refused_fixes = 0;
  prior_ = guess;
  prior_sigma_xy_ = sigma_xy_m;
  prior_sigma_yaw_ = sigma_yaw_rad;
  dist_since_prior_ = tracked_m_ = 0.0;
  distrust_good_ = false;
  est_.updates = 0;
  pending_ = {};
  pending_dist_ = pending_turn_ = 0.0;
  first_update_done_ = false;
  driven_m_ = 0.0;
  has_last_good_ = false;
  cost_level_valid_ = false;
  attempt_ = 0;
}

void ParticleFilter::initialise_disc(const Pose2& guess, double radius_m, double yaw_halfwidth_rad) noexcept {
  initialise_gaussian(guess, 0.0, 0.0);
  prior_sigma_xy_ = 0.5 * radius_m;                             // a uniform disc's standard deviation per axis
  prior_sigma_yaw_ = yaw_halfwidth_rad / 1.7320508075688772;  // ... and a uniform interval's
  for (std::size_t i = 0; i < n_; ++i) {
    const double r = radius_m * std::sqrt(rng_.uniform()), a = 2.0 * kPi * rng_.uniform();
    x_[i] = guess.x + r * std::cos(a);
    y_[i] = guess.y + r * std::sin(a);
    yaw_[i] = wrap_angle(guess.yaw + yaw_halfwidth_rad * (2.0 * rng_.uniform() - 1.0));
  }
  compute_estimate();
}

// ------------------------------------------------------------------------------------------- motion

namespace {
// `p` moved by `d` (body frame at p: dx forward, dy left, dyaw).
void move_by(Pose2& p, const Pose2& d) noexcept {
  const double c = std::cos(p.yaw), s = std::sin(p.yaw);
  p.x += c * d.x - s * d.y;
  p.y += s * d.x + c * d.y;
  p.yaw = wrap_angle(p.yaw + d.yaw);
}
}  // namespace

void ParticleFilter::add_motion(const Pose2& d) noexcept {
  if (!std::isfinite(d.x) || !std::isfinite(d.y) || !std::isfinite(d.yaw)) return;  // a broken odometry sample
  const double c = std::cos(pending_.yaw), s = std::sin(pending_.yaw);
  pending_.x += c * d.x - s * d.y;
  pending_.y += s * d.x + c * d.y;
  pending_.yaw = wrap_angle(pending_.yaw + d.yaw);
  const double step = std::hypot(d.x, d.y);
  pending_dist_ += step;
  pending_turn_ += std::fabs(d.yaw);
  if (has_last_good_) {
    move_by(last_good_, d);
    dist_since_good_ += step;
  }
  move_by(prior_, d);
  dist_since_prior_ += step;
}

bool ParticleFilter::wants_update() const noexcept {
  if (est_.status == FilterStatus::kUninitialised) return false;
  return !first_update_done_ || pending_dist_ >= p_.update_min_distance_m || pending_turn_ >= p_.update_min_turn_rad;
}

void ParticleFilter::apply_motion(bool roughen) noexcept {
  const bool moved = pending_dist_ > 0.0 || pending_turn_ > 0.0 || roughen;
  double sxy = moved ? std::max(p_.motion_sigma_xy_min_m, p_.motion_sigma_xy_per_m * pending_dist_) : 0.0;
  double syaw = p_.motion_sigma_yaw_per_m * pending_dist_ + p_.motion_sigma_yaw_per_rad * pending_turn_;
  if (roughen) {
    sxy = std::max(sxy, p_.lost_standing_sigma_xy_m);
    syaw = std::max(syaw, p_.lost_standing_sigma_yaw_rad);
  }
  for (std::size_t i = 0; i < n_; ++i) {
    const double c = std::cos(yaw_[i]), s = std::sin(yaw_[i]);
    x_[i] += c * pending_.x - s * pending_.y;
    y_[i] += s * pending_.x + c * pending_.y;
    yaw_[i] += pending_.yaw;
    if (moved) {
      x_[i] += sxy * rng_.gaussian();
      y_[i] += sxy * rng_.gaussian();
      yaw_[i] += syaw * rng_.gaussian();
    }
    yaw_[i] = wrap_angle(yaw_[i]);
  }
  pending_ = {};
  pending_dist_ = pending_turn_ = 0.0;
}

// -------------------------------------------------------------------------------------- measurement

void ParticleFilter::prepare_angles(const ScanRenderPolar& render) noexcept {
  // each bin's offset in the cell table of a particle (angle-major, padded range bins)
  const auto n_r = padded_range_bins(render.used_range_bins());
  const std::span<const ScanRenderPolar::Bin> bins = render.bins();
  for (std::size_t b = 0; b < bins.size(); ++b)
    bin_offset_[b] = static_cast<std::int32_t>(static_cast<std::size_t>(bins[b].angle) * n_r + bins[b].range);
  if (prepared_angle_bins_ == render.angle_bins()) return;
  prepared_angle_bins_ = render.angle_bins();
  const int w = p_.yaw_window_bins;
  const double da = render.angle_bin_rad();
  for (int j = 0; j < render.angle_bins() + 2 * w; ++j) {
    const double a = (j - w + 0.5) * da;
    base_cos_[static_cast<std::size_t>(j)] = static_cast<float>(std::cos(a));
    base_sin_[static_cast<std::size_t>(j)] = static_cast<float>(std::sin(a));
  }
}

double ParticleFilter::evaluate(double x, double y, double yaw, const ScanRenderPolar& render,
                                const ClassDistanceFields& fields, int window, double& score, double& known_fraction,
                                double& known_cost) noexcept {
  const int wmax = p_.yaw_window_bins;
  const auto n_r = padded_range_bins(render.used_range_bins());
  const auto cy = static_cast<float>(std::cos(yaw)), sy = static_cast<float>(std::sin(yaw));
  const double inv_res = 1.0 / fields.resolution_m();
  const auto fx0 = static_cast<float>((x - fields.origin_x()) * inv_res);
  const auto fy0 = static_cast<float>((y - fields.origin_y()) * inv_res);
  const auto scale = static_cast<float>(render.range_bin_m() * inv_res);
  const std::int32_t w_cells = fields.width(), h_cells = fields.height();
  const auto outside = static_cast<std::int32_t>(fields.outside_index());

  // Map cell of every (angle incl. the shift margin, range bin) centre around this particle.
  const int j0 = wmax - window, j1 = render.angle_bins() + wmax + window;
  for (int j = j0; j < j1; ++j) {
    const auto uj = static_cast<std::size_t>(j);
    const float ux = (cy * base_cos_[uj] - sy * base_sin_[uj]) * scale;
    const float uy = (sy * base_cos_[uj] + cy * base_sin_[uj]) * scale;
    std::int32_t* row = &idx_[uj * n_r];
    for (std::size_t r = 0; r < n_r; r += kCellBlock)
      cells_along(fx0, fy0, ux, uy, static_cast<float>(r) + 0.5F, w_cells, h_cells, outside, row + r);
  }

  // Score (log weight) of one shift; bins whose cell is unknown are left out of the cost and counted
  // in the known share. Shift-major with register accumulators: the bins' lookups are independent.
  const std::uint8_t* cells = fields.cells();
  constexpr auto stride = static_cast<std::size_t>(ClassDistanceFields::kStride);
  const std::span<const ScanRenderPolar::Bin> bins = render.bins();
  const std::span<const ScanRenderPolar::Entry> entries = render.entries();
  const std::int32_t* off = bin_offset_.data();
  const double total = render.total_weight();
  const double q = fields.quantum_m();
  auto score_of = [&](int s) noexcept {
    const std::int32_t* col = &idx_[static_cast<std::size_t>(j0 + s) * n_r];
    float sum = 0.0F, kn = 0.0F;
    for (std::size_t b = 0; b < bins.size(); ++b) {
      const std::uint8_t* rec = cells + static_cast<std::size_t>(col[off[b]]) * stride;
      const float is_known = rec[stride - 1] != 255 ? 1.0F : 0.0F;
      const ScanRenderPolar::Entry* e = &entries[bins[b].first];
      float c = 0.0F;
      for (std::uint32_t k = 0; k < bins[b].entries; ++k) c += e[k].value * static_cast<float>(rec[e[k].channel]);
      sum += is_known * c;
      kn += is_known * bins[b].weight;
    }
    const auto us = static_cast<std::size_t>(s);
    const double kd = static_cast<double>(kn), cost = q * static_cast<double>(sum);
    const double kf = total > 0.0 ? kd / total : 0.0;
    const double ck = kd > 0.0 ? cost / kd : 0.0;
    shift_known_[us] = kf;
    shift_known_cost_[us] = ck;
    if (p_.unknown_mode == UnknownCost::kFixed) {
      const double c = total > 0.0 ? (cost + (total - kd) * p_.unknown_cost_m) / total : p_.unknown_cost_m;
      shift_cost_[us] = -p_.weight_exponent * std::log(c + p_.gamma_m);
    } else {
      shift_cost_[us] = -p_.weight_exponent * kf * std::log(ck + p_.gamma_m);
    }
    return shift_cost_[us];
  };

  // Hill-climb over the shifts from the particle's own yaw (ties keep it): -1, 0, +1 first, further
  // out only while the best is at an edge of what was tried.
  const int n_shift = 2 * window + 1;
  int lo = window, hi = window, best_s = window;
  double best = score_of(window);
  for (;;) {
    bool grew = false;
    if (best_s == lo && lo > 0) {
      const double v = score_of(--lo);
      grew = true;
      if (v > best) {
        best = v;
        best_s = lo;
      }
    }
    if (best_s == hi && hi < n_shift - 1) {
      const double v = score_of(++hi);
      grew = true;
      if (v > best) {
        best = v;
        best_s = hi;
      }
    }
    if (!grew) break;
  }
  double offset = 0.0;
  if (best_s > lo && best_s < hi) {
    const double cm = shift_cost_[static_cast<std::size_t>(best_s) - 1], cp = shift_cost_[static_cast<std::size_t>(best_s) + 1];
    const double den = cm - 2.0 * best + cp;
    if (den < -1e-12) {
      offset = std::clamp(0.5 * (cm - cp) / den, -0.5, 0.5);
      best -= 0.25 * (cm - cp) * offset;
    }
  }
  score = best;
  known_fraction = shift_known_[static_cast<std::size_t>(best_s)];
  known_cost = shift_known_cost_[static_cast<std::size_t>(best_s)];
  return (best_s - window + offset) * render.angle_bin_rad();
}

double ParticleFilter::pose_cost(const Pose2& pose, const ScanRenderPolar& render, const ClassDistanceFields& fields,
                                 double* known_fraction) noexcept {
  if (render.angle_bins() > max_angle_bins_ || render.range_bins() > max_range_bins_) return p_.unknown_cost_m;
  prepare_angles(render);
  double score = 0.0, kf = 0.0, cost = 0.0;
  evaluate(pose.x, pose.y, pose.yaw, render, fields, 0, score, kf, cost);
  if (known_fraction != nullptr) *known_fraction = kf;
  return cost;
}

UpdateReport ParticleFilter::update(const ScanRenderPolar& render, const ClassDistanceFields& fields, bool force) noexcept {
  return update_impl(render, fields, force, false);
}

UpdateReport ParticleFilter::update_standing(const ScanRenderPolar& render, const ClassDistanceFields& fields) noexcept {
  return update_impl(render, fields, true, true);
}

UpdateReport ParticleFilter::update_impl(const ScanRenderPolar& render, const ClassDistanceFields& fields, bool force, bool roughen) noexcept {
  UpdateReport rep;
  if (est_.status == FilterStatus::kUninitialised || (!force && !wants_update())) return rep;
  if (render.angle_bins() > max_angle_bins_ || render.range_bins() > max_range_bins_) return rep;
  rep.updated = true;
  rep.moved_m = pending_dist_;
  driven_m_ += pending_dist_;
  if (est_.status == FilterStatus::kTracking) tracked_m_ += pending_dist_;
  apply_motion(roughen);
  first_update_done_ = true;
  ++est_.updates;
  ++updates_since_respread_;
  if (render.bins().empty() || render.total_weight() <= 0.0) {  // nothing seen: motion only
    compute_estimate();
    set_range_bin();
    return rep;
  }
  prepare_angles(render);
  const int window = est_.status == FilterStatus::kTracking ? p_.yaw_window_bins_tracking : p_.yaw_window_bins;
  // Best known-cell cost among the particles that see enough of the map (for the status checks).
  double best = std::numeric_limits<double>::infinity();
  double top = -std::numeric_limits<double>::infinity();
  // Particles in Morton order of 2 m cells: neighbours look up the same field cells, which stay in cache.
  for (std::size_t i = 0; i < n_; ++i) {
    const auto cx = static_cast<std::uint32_t>(static_cast<std::int64_t>(std::floor(x_[i] * 0.5)) & 0xFFFF);
    const auto cyy = static_cast<std::uint32_t>(static_cast<std::int64_t>(std::floor(y_[i] * 0.5)) & 0xFFFF);
    order_[i] = (interleave16(cx) | (interleave16(cyy) << 1U)) << 32U | i;
  }
  std::sort(order_.begin(), order_.begin() + static_cast<std::ptrdiff_t>(n_));
  const std::uint8_t obstacle_mask = room_channels(fields);
  const bool searching = est_.status != FilterStatus::kTracking && est_.refused_fixes > 0;
  // Searching from the initial guess: nothing beyond its gate, the guess moved by the odometry.
  const double gate = est_.status == FilterStatus::kLost && distrust_good_ ? p_.guess_gate_sigmas * dead_reckoned_sigma_m() : 0.0;
  const double gate2 = gate * gate;
  for (std::size_t k = 0; k < n_; ++k) {
    const std::size_t i = order_[k] & 0xFFFFFFFFULL;
    // No weight, counted: outside the mission area (not where the robot can be); searching from the guess,
    // beyond its gate; not tracking, in a fix the planner's word lost.
    const double gx = x_[i] - prior_.x, gy = y_[i] - prior_.y;
    std::uint64_t* excluded = !p_.area.contains(x_[i], y_[i])                        ? &est_.outside_area
                              : gate2 > 0.0 && gx * gx + gy * gy > gate2                ? &est_.outside_guess
                              : searching && near_refused(Pose2{x_[i], y_[i], 0.0}) ? &est_.in_refused
                                                                                      : nullptr;
    if (excluded != nullptr) {
      score_[i] = -std::numeric_limits<double>::infinity();
      ++*excluded;
      continue;
    }
    double score = 0.0, kf = 0.0, ck = 0.0;
    yaw_[i] = wrap_angle(yaw_[i] + evaluate(x_[i], y_[i], yaw_[i], render, fields, window, score, kf, ck));
    if (obstacle_mask != 0U) {
      const double deep = room_distance_m(fields, obstacle_mask, x_[i], y_[i]) - p_.obstacle_margin_m;
      if (deep > 0.0) {
        score -= p_.obstacle_penalty_per_m * deep;
        ++est_.inside_obstacle;
      }
    }
    score_[i] = score;
    top = std::max(top, score);
    if (kf >= p_.min_known_fraction && ck < best) {
      best = ck;
      rep.known_fraction = kf;
    }
  }
  if (!std::isfinite(top))  // every particle outside the area: they keep their weights (the uniform case below)
    for (std::size_t i = 0; i < n_; ++i) score_[i] = top = 0.0;
  double sum = 0.0;
  for (std::size_t i = 0; i < n_; ++i) {
    w_[i] *= std::exp(score_[i] - top);
    sum += w_[i];
  }
  const double uni = 1.0 / static_cast<double>(n_);
  double sq = 0.0;
  for (std::size_t i = 0; i < n_; ++i) {
    const double w = sum > 0.0 && std::isfinite(sum) ? w_[i] / sum : uni;
    w_[i] = (1.0 - p_.uniform_mix) * w + p_.uniform_mix * uni;
    sq += w_[i] * w_[i];
  }
  const bool cost_valid = std::isfinite(best);
  if (!cost_valid) best = -1.0;
  rep.best_cost_m = best;
  const double ess = 1.0 / sq;
  if (ess < p_.resample_ess_ratio * static_cast<double>(n_)) {
    resample();
    rep.resampled = true;
  }
  compute_estimate();
  est_.best_cost_m = best;
  est_.room_m = obstacle_mask != 0U ? room_distance_m(fields, obstacle_mask, est_.pose.x, est_.pose.y) : 0.0;
  const bool blocked = (obstacle_mask != 0U && est_.room_m > p_.obstacle_margin_m) || start_blocked_;
  if (blocked) ++est_.blocked_updates;
  const std::uint32_t before = est_.recoveries;
  update_status(best, cost_valid, roughen, blocked);
  rep.recovered = est_.recoveries != before;
  set_range_bin();
  return rep;
}

// ------------------------------------------------------------------------------------- resampling

std::size_t ParticleFilter::kld_count() noexcept {
  // Distinct (x, y, yaw) bins among a systematic draw of max_particles from the current weights.
  ++kld_gen_;
  if (kld_gen_ == 0) {
    std::fill(kld_stamp_.begin(), kld_stamp_.end(), 0U);
    kld_gen_ = 1;
  }
  const std::size_t mask = kld_keys_.size() - 1;
  const std::size_t m = static_cast<std::size_t>(p_.max_particles);
  const double step = 1.0 / static_cast<double>(m);
  double u = rng_.uniform() * step;
  std::size_t i = 0, k = 0;
  double c = w_[0];
  std::uint64_t last_key = std::numeric_limits<std::uint64_t>::max();
  for (std::size_t j = 0; j < m; ++j, u += step) {
    while (u > c && i + 1 < n_) c += w_[++i];
    const auto bx = static_cast<std::int64_t>(std::floor(x_[i] / p_.kld_bin_xy_m));
    const auto by = static_cast<std::int64_t>(std::floor(y_[i] / p_.kld_bin_xy_m));
    const auto bt = static_cast<std::int64_t>(std::floor((yaw_[i] + kPi) / p_.kld_bin_yaw_rad));
    const std::uint64_t key = ((static_cast<std::uint64_t>(bx) & 0x1FFFFFULL) << 42U) |
                              ((static_cast<std::uint64_t>(by) & 0x1FFFFFULL) << 21U) | (static_cast<std::uint64_t>(bt) & 0x1FFFFFULL);
    if (key == last_key) continue;
    last_key = key;
    std::size_t h = static_cast<std::size_t>((key * 0x9E3779B97F4A7C15ULL) >> 20U) & mask;
    while (kld_stamp_[h] == kld_gen_ && kld_keys_[h] != key) h = (h + 1) & mask;
    if (kld_stamp_[h] != kld_gen_) {
      kld_stamp_[h] = kld_gen_;
      kld_keys_[h] = key;
      ++k;
    }
  }
  double n = static_cast<double>(p_.min_particles);
  if (k > 1) {
    const double km = static_cast<double>(k - 1);
    const double a = 2.0 / (9.0 * km);
    const double t = 1.0 - a + std::sqrt(a) * p_.kld_z;
    n = km / (2.0 * p_.kld_epsilon) * t * t * t;
  }
  return static_cast<std::size_t>(std::clamp(n, static_cast<double>(p_.min_particles), static_cast<double>(p_.max_particles)));
}

void ParticleFilter::resample() noexcept {
  const std::size_t m = kld_count();
  const double step = 1.0 / static_cast<double>(m);
  double u = rng_.uniform() * step;
  std::size_t i = 0;
  double c = w_[0];
  for (std::size_t j = 0; j < m; ++j, u += step) {
    while (u > c && i + 1 < n_) c += w_[++i];
    nx_[j] = x_[i];
    ny_[j] = y_[i];
    nyaw_[j] = yaw_[i];
  }
  std::swap(x_, nx_);
  std::swap(y_, ny_);
  std::swap(yaw_, nyaw_);
  n_ = m;
  const double w = 1.0 / static_cast<double>(n_);
  std::fill_n(w_.begin(), n_, w);
}

// --------------------------------------------------------------------------------- estimate, status

void ParticleFilter::compute_estimate() noexcept {
  double sw = 0.0, mx = 0.0, my = 0.0, sc = 0.0, ss = 0.0;
  for (std::size_t i = 0; i < n_; ++i) {
    sw += w_[i];
    mx += w_[i] * x_[i];
    my += w_[i] * y_[i];
    sc += w_[i] * std::cos(yaw_[i]);
    ss += w_[i] * std::sin(yaw_[i]);
  }
  if (!(sw > 0.0)) return;
  mx /= sw;
  my /= sw;
  const double myaw = std::atan2(ss, sc);
  double cxx = 0, cxy = 0, cyy = 0, cxt = 0, cyt = 0, ctt = 0;
  for (std::size_t i = 0; i < n_; ++i) {
    const double w = w_[i] / sw, dx = x_[i] - mx, dy = y_[i] - my, dt = wrap_angle(yaw_[i] - myaw);
    cxx += w * dx * dx;
    cxy += w * dx * dy;
    cyy += w * dy * dy;
    cxt += w * dx * dt;
    cyt += w * dy * dt;
    ctt += w * dt * dt;
  }
  est_.pose = Pose2{mx, my, myaw};
  est_.covariance = {cxx, cxy, cxt, cxy, cyy, cyt, cxt, cyt, ctt};
  const double tr = 0.5 * (cxx + cyy), det = cxx * cyy - cxy * cxy;
  est_.spread_m = std::sqrt(std::max(0.0, tr + std::sqrt(std::max(0.0, tr * tr - det))));
  const double r = std::hypot(sc, ss) / sw;
  est_.yaw_spread_rad = r > 0.0 ? std::sqrt(std::max(0.0, -2.0 * std::log(std::min(r, 1.0)))) : kPi;
  est_.particles = static_cast<std::uint32_t>(n_);
}

void ParticleFilter::set_range_bin() noexcept {
  range_bin_m_ = std::clamp(p_.range_bin_per_spread * est_.spread_m, p_.range_bin_min_m, p_.range_bin_max_m);
  est_.range_bin_m = range_bin_m_;
}

bool ParticleFilter::near_refused(const Pose2& p) const noexcept {
  const std::size_t n = std::min<std::size_t>(est_.refused_fixes, kMaxRefused);
  for (std::size_t i = 0; i < n; ++i)
    if (std::hypot(p.x - refused_[i].x, p.y - refused_[i].y) < p_.refused_radius_m) return true;
  return false;
}

void ParticleFilter::update_status(double best_cost, bool cost_valid, bool standing, bool blocked) noexcept {
  if (est_.status == FilterStatus::kTracking) {
    const bool bad = blocked || est_.spread_m > p_.lost_spread_m ||
                     (cost_valid && cost_level_valid_ &&
                      best_cost > std::max(p_.lost_cost_min_m, p_.lost_cost_ratio * est_.cost_level_m));
    if (!bad) {
      bad_count_ = 0;
      if (cost_valid && cost_level_valid_) est_.cost_level_m = 0.9 * est_.cost_level_m + 0.1 * best_cost;
      if (cost_valid && !cost_level_valid_) {
        est_.cost_level_m = best_cost;
        cost_level_valid_ = true;
      }
      last_good_ = est_.pose;
      has_last_good_ = true;
      dist_since_good_ = 0.0;
      return;
    }
    if (++bad_count_ < p_.lost_updates) return;
    est_.status = FilterStatus::kLost;
    if (start_blocked_) refused_[est_.refused_fixes++ % kMaxRefused] = est_.pose;
    start_blocked_ = false;
    distrust_good_ = tracked_m_ < p_.confirm_distance_m;
    attempt_ = 0;
  } else {
    const bool refused = near_refused(est_.pose);
    converged_count_ = est_.spread_m < p_.converged_spread_m && cost_valid && !blocked && !refused ? converged_count_ + 1 : 0;
    if (converged_count_ >= (standing ? p_.lost_standing_converged_updates : p_.converged_updates)) {
      est_.status = FilterStatus::kTracking;
      tracked_m_ = 0.0;
      distrust_good_ = false;
      est_.cost_level_m = best_cost;
      cost_level_valid_ = true;
      bad_count_ = 0;
      attempt_ = 0;
      last_good_ = est_.pose;
      has_last_good_ = true;
      dist_since_good_ = 0.0;
      return;
    }
    if (est_.status != FilterStatus::kLost || updates_since_respread_ < p_.recovery_retry_updates || !has_last_good_) return;
    ++attempt_;  // still lost after a re-spread: wider
  }
  // Re-spread around the last good pose (moved by the odometry since).
  const double growth = std::pow(p_.recovery_growth, static_cast<double>(attempt_));
  const double sxy = std::min(p_.recovery_sigma_xy_max_m, p_.recovery_sigma_xy_m * growth + p_.lost_drift_per_m * dist_since_good_);
  const double syaw = std::min(kPi, p_.recovery_sigma_yaw_rad * growth);
  const Pose2 centre = has_last_good_ ? last_good_ : est_.pose;
  ++est_.recoveries;
  if (distrust_good_) {  // an unconfirmed fix, lost: search from the initial guess again
    const double guess_sxy = p_.guess_gate_sigmas > 0.0 ? std::max(p_.recovery_sigma_xy_m, dead_reckoned_sigma_m())  // the guess's own
                                                         : std::max(sxy, dead_reckoned_sigma_m());
    respread(prior_, guess_sxy, std::min(kPi, std::max(syaw, prior_sigma_yaw_)));
    return;
  }
  respread(centre, sxy, syaw);
}

}  // namespace ag::loc
