// Simulated GNSS receiver: noise, Gauss-Markov bias, Poisson dropouts, ENU -> WGS84 via GeographicLib.
#include "airground/sim/gps.hpp"

#include <GeographicLib/LocalCartesian.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

#include "airground/platform/param_binding.hpp"
#include "airground/sim/model_params.hpp"

namespace ag::sim {

namespace {

constexpr ParamField<GpsConfig> kGpsFields[] = {
    field::real("sigma_m", &GpsConfig::sigma_m, 0.0, 100.0, "m", "white noise per horizontal axis per fix"),
    field::real("sigma_vertical_m", &GpsConfig::sigma_vertical_m, 0.0, 100.0, "m", "white noise, up, per fix"),
    field::real("rate_hz", &GpsConfig::rate_hz, 0.1, 100.0, "Hz", "fix rate"),
    field::real("dropout_rate_per_s", &GpsConfig::dropout_rate_per_s, 0.0, 10.0, "1/s", "mean rate of dropout events, 0 = never"),
    field::real("dropout_mean_s", &GpsConfig::dropout_mean_s, 0.0, 3600.0, "s", "mean length of a dropout (exponential)"),
    field::real("bias_sigma_m", &GpsConfig::bias_sigma_m, 0.0, 100.0, "m", "stationary std of the horizontal bias per axis, 0 = off"),
    field::real("bias_sigma_vertical_m", &GpsConfig::bias_sigma_vertical_m, 0.0, 100.0, "m", "stationary std of the vertical bias"),
    field::real("bias_tau_s", &GpsConfig::bias_tau_s, 0.1, 1e6, "s", "correlation time of the bias"),
    field::real("velocity_sigma_mps", &GpsConfig::velocity_sigma_mps, 0.0, 10.0, "m/s", "white noise per velocity component"),
    field::boolean("report_no_fix", &GpsConfig::report_no_fix, "emit no-fix reports during dropouts instead of nothing"),
    field::real("outlier_at_s", &GpsConfig::outlier_at_s, -1.0, 1e7, "s", "fault injection: one fix this long after the start is off by outlier_m; -1 = never"),
    field::real("outlier_m", &GpsConfig::outlier_m, 0.0, 1e4, "m", "fault injection: size of that jump"),
};
constexpr auto kGpsParams = param_specs(kGpsFields);
constexpr ParamSection kGpsSchema[] = {{"gps", kGpsParams, "simulated GNSS receiver"}};

}  // namespace

std::span<const ParamSection> gps_config_schema() noexcept { return kGpsSchema; }

namespace {
Result<GpsConfig> gps_from(const Result<Config>& c) {
  if (!c) return c.error();
  const SectionView v(c.value(), "gps");
  return load_params(v, kGpsFields);
}
}  // namespace

Result<GpsConfig> load_gps_config(const YAML::Node& node, std::string_view origin) {
  return gps_from(load_model_params(kGpsSchema, node, origin));
}
Result<GpsConfig> load_gps_config(std::string_view yaml, std::string_view origin) {
  return gps_from(load_model_params(kGpsSchema, yaml, origin));
}

struct GpsSimulator::Geodesy {
  GeographicLib::LocalCartesian lc;
};

GpsSimulator::GpsSimulator(const GpsConfig& cfg, const Datum& datum, std::uint64_t seed)
    : cfg_(cfg),
      datum_(datum),
      geo_(std::make_unique<Geodesy>(Geodesy{GeographicLib::LocalCartesian(datum.lat_deg, datum.lon_deg, datum.height_m)})),
      noise_rng_(derive_seed(seed, 0)),
      dropout_rng_(derive_seed(seed, 1)),
      period_(period_from_hz(cfg.rate_hz > 0 ? cfg.rate_hz : 1.0)) {
  // The bias starts from its stationary distribution, so the first fix is as wrong as any other.
  bias_e_ = noise_rng_.gaussian(0.0, cfg_.bias_sigma_m);
  bias_n_ = noise_rng_.gaussian(0.0, cfg_.bias_sigma_m);
  bias_u_ = noise_rng_.gaussian(0.0, cfg_.bias_sigma_vertical_m);
}

GpsSimulator::~GpsSimulator() = default;
GpsSimulator::GpsSimulator(GpsSimulator&&) noexcept = default;
GpsSimulator& GpsSimulator::operator=(GpsSimulator&&) noexcept = default;

void GpsSimulator::advance_dropouts(TimeNs t) {
  // Dropouts come from their own random stream in event order, so when they happen does not depend on
  // how often sample() is called.
  while (t >= dropout_end_) {
    dropout_start_ = time_after(dropout_end_, dropout_rng_.exponential(cfg_.dropout_rate_per_s));
    if (dropout_start_ == std::numeric_limits<TimeNs>::max()) {
      dropout_end_ = dropout_start_;
      return;
    }
    const double len = cfg_.dropout_mean_s > 0 ? dropout_rng_.exponential(1.0 / cfg_.dropout_mean_s) : 0.0;
    dropout_end_ = time_after(dropout_start_, len);
    if (dropout_end_ > dropout_start_) ++dropouts_started_;  // zero-length dropouts never show
  }
}

bool GpsSimulator::in_dropout(TimeNs t) const noexcept { return started_ && t >= dropout_start_ && t < dropout_end_; }

bool GpsSimulator::sample(TimeNs t, const Pose3& truth, GpsFix& out) {
  if (!started_) {
    started_ = true;
    start_t_ = t;
    next_fix_ = t;
    dropout_end_ = t;  // the first dropout is drawn from here
    dropout_start_ = t;
  }
  advance_dropouts(t);
  if (t < next_fix_) return false;
  // The next fix is on the fixed grid after t: a caller stepping slower than the rate gets one fix per call.
  next_fix_ += period_ * ((t - next_fix_) / period_ + 1);

  const double dt = have_last_ ? to_seconds(t - last_fix_t_) : 0.0;
  if (have_last_ && cfg_.bias_tau_s > 0) {
    const double a = std::exp(-dt / cfg_.bias_tau_s);
    const double q = std::sqrt(std::max(0.0, 1.0 - a * a));
    bias_e_ = a * bias_e_ + q * noise_rng_.gaussian(0.0, cfg_.bias_sigma_m);
    bias_n_ = a * bias_n_ + q * noise_rng_.gaussian(0.0, cfg_.bias_sigma_m);
    bias_u_ = a * bias_u_ + q * noise_rng_.gaussian(0.0, cfg_.bias_sigma_vertical_m);
  }
  double ve = 0, vn = 0, vu = 0;
  if (have_last_ && dt > 0) {
    ve = (truth.x - last_truth_.x) / dt;
    vn = (truth.y - last_truth_.y) / dt;
    vu = (truth.z - last_truth_.z) / dt;
  }
  last_truth_ = truth;
  last_fix_t_ = t;
  have_last_ = true;

  out = GpsFix{};
  out.stamp = t;
  out.h_accuracy_m = std::sqrt(cfg_.sigma_m * cfg_.sigma_m + cfg_.bias_sigma_m * cfg_.bias_sigma_m);
  out.v_accuracy_m = std::sqrt(cfg_.sigma_vertical_m * cfg_.sigma_vertical_m +
                               cfg_.bias_sigma_vertical_m * cfg_.bias_sigma_vertical_m);
  if (in_dropout(t)) {
    if (!cfg_.report_no_fix) return false;
    out.fix_type = GpsFixType::kNoFix;
    out.h_accuracy_m = out.v_accuracy_m = 1e4;  // what a receiver without a fix reports, roughly
    return true;
  }
  // Noise draws happen in a fixed order per fix, so a run is repeatable for a given seed and call pattern.
  out.east_m = truth.x + bias_e_ + noise_rng_.gaussian(0.0, cfg_.sigma_m);
  out.north_m = truth.y + bias_n_ + noise_rng_.gaussian(0.0, cfg_.sigma_m);
  out.up_m = truth.z + bias_u_ + noise_rng_.gaussian(0.0, cfg_.sigma_vertical_m);
  if (!outlier_done_ && cfg_.outlier_at_s >= 0 && to_seconds(t - start_t_) >= cfg_.outlier_at_s) {
    outlier_done_ = true;
    out.east_m += cfg_.outlier_m / std::sqrt(2.0);
    out.north_m += cfg_.outlier_m / std::sqrt(2.0);
  }
  out.vel_east_mps = ve + noise_rng_.gaussian(0.0, cfg_.velocity_sigma_mps);
  out.vel_north_mps = vn + noise_rng_.gaussian(0.0, cfg_.velocity_sigma_mps);
  out.vel_up_mps = vu + noise_rng_.gaussian(0.0, cfg_.velocity_sigma_mps);
  geo_->lc.Reverse(out.east_m, out.north_m, out.up_m, out.lat_deg, out.lon_deg, out.height_m);
  out.fix_type = GpsFixType::kFix3D;
  return true;
}

}  // namespace ag::sim
