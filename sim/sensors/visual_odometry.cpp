// Simulated monocular VO: true motion scaled and rotated into a per-segment frame, with drift and losses.
#include "airground/sim/visual_odometry.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "airground/platform/param_binding.hpp"
#include "airground/sim/model_params.hpp"

namespace ag::sim {

namespace {

constexpr ParamField<VoConfig> kVoFields[] = {
    field::real("rate_hz", &VoConfig::rate_hz, 0.0, 1000.0, "Hz", "frame rate, 0 = a frame at every call"),
    field::real("scale_min", &VoConfig::scale_min, 1e-3, 1e3, "", "smallest initial scale of a segment (VO units per metre)"),
    field::real("scale_max", &VoConfig::scale_max, 1e-3, 1e3, "", "largest initial scale of a segment"),
    field::real("scale_drift_per_s", &VoConfig::scale_drift_per_s, 0.0, 1.0, "1/sqrt(s)", "random walk of log(scale): std over 1 s"),
    field::real("yaw_drift_rad_per_s", &VoConfig::yaw_drift_rad_per_s, 0.0, 1.0, "rad/sqrt(s)", "random walk of the frame yaw: std over 1 s"),
    field::real("position_noise_m", &VoConfig::position_noise_m, 0.0, 100.0, "m", "white noise per axis per frame"),
    field::real("rotation_noise_rad", &VoConfig::rotation_noise_rad, 0.0, 1.0, "rad", "white noise per angle per frame"),
    field::real("tracking_loss_rate_per_s", &VoConfig::tracking_loss_rate_per_s, 0.0, 10.0, "1/s", "mean rate of tracking losses, 0 = never"),
    field::real("tracking_loss_duration_s", &VoConfig::tracking_loss_duration_s, 0.0, 3600.0, "s", "mean length of a tracking loss (exponential)"),
    field::real("forced_loss_at_s", &VoConfig::forced_loss_at_s, -1.0, 1e7, "s", "fault injection: one extra tracking loss this long after the start; -1 = none"),
    field::boolean("random_initial_yaw", &VoConfig::random_initial_yaw, "a new segment starts at a random yaw (false: yaw 0)"),
};
constexpr auto kVoParams = param_specs(kVoFields);
constexpr ParamSection kVoSchema[] = {{"visual_odometry", kVoParams, "simulated monocular visual odometry"}};

Result<VoConfig> vo_from(const Result<Config>& c, std::string_view origin) {
  if (!c) return c.error();
  const SectionView v(c.value(), "visual_odometry");
  const VoConfig o = load_params(v, kVoFields);
  if (o.scale_min > o.scale_max)
    return model_config_error(origin, "key 'visual_odometry.scale_min' (" + std::to_string(o.scale_min) +
                                          ") must not exceed 'visual_odometry.scale_max' (" +
                                          std::to_string(o.scale_max) + ")");
  return o;
}

}  // namespace

std::span<const ParamSection> vo_config_schema() noexcept { return kVoSchema; }

Result<VoConfig> load_vo_config(const YAML::Node& node, std::string_view origin) {
  return vo_from(load_model_params(kVoSchema, node, origin), origin);
}
Result<VoConfig> load_vo_config(std::string_view yaml, std::string_view origin) {
  return vo_from(load_model_params(kVoSchema, yaml, origin), origin);
}

VisualOdometrySimulator::VisualOdometrySimulator(const VoConfig& cfg, std::uint64_t seed)
    : cfg_(cfg),
      noise_rng_(derive_seed(seed, 0)),
      loss_rng_(derive_seed(seed, 1)),
      period_(cfg.rate_hz > 0 ? period_from_hz(cfg.rate_hz) : 0) {}

void VisualOdometrySimulator::advance_losses(TimeNs t) {
  // Losses come from their own stream in event order: when they happen does not depend on the call rate.
  while (t >= loss_end_) {
    loss_start_ = time_after(loss_end_, loss_rng_.exponential(cfg_.tracking_loss_rate_per_s));
    if (loss_start_ == std::numeric_limits<TimeNs>::max()) {
      loss_end_ = loss_start_;
      return;
    }
    const double len = cfg_.tracking_loss_duration_s > 0 ? loss_rng_.exponential(1.0 / cfg_.tracking_loss_duration_s) : 0.0;
    loss_end_ = time_after(loss_start_, len);
    if (loss_end_ > loss_start_) ++losses_;
  }
}

void VisualOdometrySimulator::start_segment(const Pose3& truth) {
  const double lmin = std::log(cfg_.scale_min), lmax = std::log(cfg_.scale_max);
  log_scale_ = noise_rng_.uniform(lmin, lmax);  // log-uniform: 0.5x is as likely as 2x
  scale_ = std::exp(log_scale_);
  const double yaw0 = cfg_.random_initial_yaw ? noise_rng_.uniform(-kPi, kPi) : 0.0;
  yaw_offset_ = wrap_angle(yaw0 - truth.yaw);
  vx_ = vy_ = vz_ = 0.0;
  tracking_ = true;
  losses_at_segment_start_ = losses_;
}

bool VisualOdometrySimulator::sample(TimeNs t, const Pose3& truth, VoSample& out) {
  bool first = false;
  if (!started_) {
    started_ = true;
    first = true;
    next_frame_ = t;
    loss_start_ = loss_end_ = t;
    start_t_ = t;
  }
  advance_losses(t);
  if (!forced_done_ && cfg_.forced_loss_at_s >= 0 && to_seconds(t - start_t_) >= cfg_.forced_loss_at_s && t < loss_start_) {
    forced_done_ = true;  // replaces the pending random loss's window; the random stream continues after it
    loss_start_ = t;
    loss_end_ = time_after(t, std::max(cfg_.tracking_loss_duration_s, 0.5));
    ++losses_;
  }
  if (t < next_frame_) return false;
  if (period_ > 0) next_frame_ += period_ * ((t - next_frame_) / period_ + 1);

  const bool lost_now = t >= loss_start_ && t < loss_end_;
  out = VoSample{};
  out.stamp = t;
  if (lost_now) {
    tracking_ = false;
    out.segment = segment_;
    out.tracking = false;
    out.pose = last_out_;
    last_truth_ = truth;
    last_t_ = t;
    return true;
  }
  // A loss that began since the last frame (even one that already ended) breaks the segment.
  const bool restart = first || !tracking_ || losses_ != losses_at_segment_start_;
  if (restart) {
    if (!first) ++segment_;
    start_segment(truth);
  } else {
    const double dt = to_seconds(t - last_t_);
    const double sq = std::sqrt(std::max(dt, 0.0));
    log_scale_ += noise_rng_.gaussian(0.0, cfg_.scale_drift_per_s * sq);
    scale_ = std::exp(log_scale_);
    yaw_offset_ = wrap_angle(yaw_offset_ + noise_rng_.gaussian(0.0, cfg_.yaw_drift_rad_per_s * sq));
    const double dx = truth.x - last_truth_.x, dy = truth.y - last_truth_.y, dz = truth.z - last_truth_.z;
    const double c = std::cos(yaw_offset_), s = std::sin(yaw_offset_);
    vx_ += scale_ * (c * dx - s * dy);
    vy_ += scale_ * (s * dx + c * dy);
    vz_ += scale_ * dz;
  }
  out.segment = segment_;
  out.tracking = true;
  out.pose.x = vx_ + scale_ * noise_rng_.gaussian(0.0, cfg_.position_noise_m);
  out.pose.y = vy_ + scale_ * noise_rng_.gaussian(0.0, cfg_.position_noise_m);
  out.pose.z = vz_ + scale_ * noise_rng_.gaussian(0.0, cfg_.position_noise_m);
  out.pose.roll = truth.roll + noise_rng_.gaussian(0.0, cfg_.rotation_noise_rad);
  out.pose.pitch = truth.pitch + noise_rng_.gaussian(0.0, cfg_.rotation_noise_rad);
  out.pose.yaw = wrap_angle(truth.yaw + yaw_offset_ + noise_rng_.gaussian(0.0, cfg_.rotation_noise_rad));
  last_out_ = out.pose;
  last_truth_ = truth;
  last_t_ = t;
  return true;
}

}  // namespace ag::sim
