// Simulated GNSS receiver: noisy WGS84 fixes of a true ENU pose at a fixed rate, with bias and dropouts.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string_view>

#include "airground/messages/geometry.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/result.hpp"
#include "airground/platform/time.hpp"
#include "airground/platform/rng.hpp"
#include "airground/sim/world.hpp"

namespace YAML {
class Node;
}

namespace ag::sim {

struct GpsConfig {
  double sigma_m{0.5};               // [m] white noise per horizontal axis (east, north), per fix
  double sigma_vertical_m{1.0};      // [m] white noise, up
  double rate_hz{5.0};               // [Hz] fix rate
  double dropout_rate_per_s{1.0 / 120.0};  // [1/s] mean rate of dropout events (Poisson), 0 = never
  double dropout_mean_s{5.0};        // [s] mean dropout length (exponential)
  double bias_sigma_m{0.0};          // [m] stationary std of a slowly wandering horizontal bias per axis, 0 = off
  double bias_sigma_vertical_m{0.0}; // [m] the same, up
  double bias_tau_s{60.0};           // [s] correlation time of the bias (first-order Gauss-Markov)
  double velocity_sigma_mps{0.05};   // [m/s] white noise on each velocity component
  bool report_no_fix{false};         // during a dropout: false = no output, true = fixes with kNoFix at the rate
  // Fault injection: the first fix at or after outlier_at_s is off by outlier_m to the north-east
  // (a multipath jump, as receivers report them: with the normal accuracy). Negative = never.
  double outlier_at_s{-1.0};         // [s] time of the outlier, from the first sample() call
  double outlier_m{50.0};            // [m] horizontal size of the jump
};

// Parameter table (key, default, range, unit) of GpsConfig, as one section named "gps".
std::span<const ParamSection> gps_config_schema() noexcept;
// `node` is the GPS mapping itself; every key is checked (unknown / type / range -> ErrorCode::kConfig).
Result<GpsConfig> load_gps_config(const YAML::Node& node, std::string_view origin);
Result<GpsConfig> load_gps_config(std::string_view yaml, std::string_view origin);

// Fix types carry the u-blox UBX-NAV-PVT fixType values.
enum class GpsFixType : std::uint8_t { kNoFix = 0, kFix2D = 2, kFix3D = 3 };

struct GpsFix {
  TimeNs stamp{0};             // [ns] time of the true pose the fix was taken from
  GpsFixType fix_type{GpsFixType::kNoFix};  // kNoFix: the position and velocity fields are 0
  double lat_deg{0};           // WGS84 latitude [deg]
  double lon_deg{0};           // WGS84 longitude [deg]
  double height_m{0};          // [m] height above the WGS84 ellipsoid
  double east_m{0}, north_m{0}, up_m{0};  // [m] the same noisy position in the local ENU map frame
  double vel_east_mps{0}, vel_north_mps{0}, vel_up_mps{0};  // [m/s] from the truth between fixes, noisy
  double h_accuracy_m{0};      // [m] 1-sigma horizontal accuracy per axis the receiver reports
  double v_accuracy_m{0};      // [m] 1-sigma vertical accuracy
};

class GpsSimulator {
 public:
  GpsSimulator(const GpsConfig& cfg, const Datum& datum, std::uint64_t seed);
  ~GpsSimulator();
  GpsSimulator(GpsSimulator&&) noexcept;
  GpsSimulator& operator=(GpsSimulator&&) noexcept;

  // Call at every simulation step with the antenna's true pose (map frame, z above the datum height).
  // True when a fix is due (the first call, then every 1/rate_hz on a fixed grid; late calls do not
  // burst); false between fixes and during dropouts (unless report_no_fix).
  bool sample(TimeNs t, const Pose3& truth, GpsFix& out);

  [[nodiscard]] bool in_dropout(TimeNs t) const noexcept;
  [[nodiscard]] std::uint64_t dropouts_started() const noexcept { return dropouts_started_; }
  [[nodiscard]] const Datum& datum() const noexcept { return datum_; }
  [[nodiscard]] const GpsConfig& config() const noexcept { return cfg_; }

 private:
  void advance_dropouts(TimeNs t);

  struct Geodesy;  // GeographicLib::LocalCartesian, kept out of this header
  GpsConfig cfg_;
  Datum datum_;
  std::unique_ptr<Geodesy> geo_;
  Rng noise_rng_;
  Rng dropout_rng_;
  TimeNs period_{0};
  TimeNs next_fix_{0};
  bool started_{false};
  TimeNs dropout_start_{0}, dropout_end_{0};
  std::uint64_t dropouts_started_{0};
  double bias_e_{0}, bias_n_{0}, bias_u_{0};
  TimeNs last_fix_t_{0};
  Pose3 last_truth_{};
  bool have_last_{false};
  TimeNs start_t_{0};
  bool outlier_done_{false};
};

}  // namespace ag::sim
