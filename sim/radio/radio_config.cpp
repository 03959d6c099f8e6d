// The radio's parameters (units, ranges, defaults) and the pure parts of the model: delivery curve, airtime.
#include <algorithm>
#include <cmath>

#include "airground/platform/param_binding.hpp"
#include "airground/sim/model_params.hpp"
#include "airground/sim/radio.hpp"

namespace ag::sim {

namespace {

// Defaults: 802.11a/g OFDM (20 MHz) at its lowest rate, 6 Mbit/s, timing from IEEE 802.11-2016 clause 17;
// sources and typical ranges in docs/simulator.md.
constexpr ParamField<RadioConfig> kRadioFields[] = {
    field::real("range_m", &RadioConfig::range_m, 0.0, 1e6, "m", "distance at which a frame's delivery probability falls to 50 %"),
    field::real("path_loss_exponent", &RadioConfig::path_loss_exponent, 1.5, 6.0, "", "log-distance path-loss exponent n"),
    field::real("shadowing_sigma_db", &RadioConfig::shadowing_sigma_db, 0.0, 20.0, "dB", "log-normal shadowing per frame and receiver; 0 = hard edge at range_m"),
    field::real("carrier_sense_range_m", &RadioConfig::carrier_sense_range_m, 0.0, 1e6, "m", "nodes this close defer to each other; 0 = derived from carrier_sense_margin_db"),
    field::real("carrier_sense_margin_db", &RadioConfig::carrier_sense_margin_db, 0.0, 30.0, "dB", "carrier sense threshold below the decode threshold"),
    field::real("capture_threshold_db", &RadioConfig::capture_threshold_db, 0.0, 40.0, "dB", "a frame this much stronger than an overlapping one survives"),
    field::real("loss_probability", &RadioConfig::loss_probability, 0.0, 1.0, "", "per-frame loss independent of distance"),
    field::real("latency_s", &RadioConfig::latency_s, 0.0, 60.0, "s", "fixed delay after transmission"),
    field::real("jitter_s", &RadioConfig::jitter_s, 0.0, 60.0, "s", "uniform extra delay in [0, jitter_s]"),
    field::real("phy_rate_bps", &RadioConfig::phy_rate_bps, 1.0e5, 1.0e10, "bit/s", "PHY data rate"),
    field::real("preamble_s", &RadioConfig::preamble_s, 0.0, 0.01, "s", "PLCP preamble and header per frame"),
    field::real("slot_s", &RadioConfig::slot_s, 1e-6, 0.001, "s", "backoff slot time"),
    field::real("sifs_s", &RadioConfig::sifs_s, 0.0, 0.001, "s", "short interframe space (DIFS = SIFS + 2 slots)"),
    field::integer("cw_min", &RadioConfig::cw_min, 0, 1023, "slots", "initial contention window"),
    field::integer("cw_max", &RadioConfig::cw_max, 0, 65535, "slots", "largest contention window"),
    field::integer("retry_limit", &RadioConfig::retry_limit, 0, 31, "count", "unicast retransmissions before a frame is dropped"),
    field::real("mac_overhead_bytes", &RadioConfig::mac_overhead_bytes, 0.0, 1000.0, "B", "MAC header, FCS and LLC/SNAP per frame"),
    field::real("ack_bytes", &RadioConfig::ack_bytes, 0.0, 100.0, "B", "ACK frame after a unicast"),
    field::real("overhead_bytes", &RadioConfig::overhead_bytes, 0.0, 1e4, "B", "IPv4 + UDP header per datagram"),
    field::real("queue_limit_bytes", &RadioConfig::queue_limit_bytes, 0.0, 1e10, "B", "bytes waiting per node before tail drop"),
    field::real("max_datagram_bytes", &RadioConfig::max_datagram_bytes, 1.0, 1e9, "B", "larger datagrams are refused"),
};
constexpr auto kRadioParams = param_specs(kRadioFields);
constexpr ParamSection kRadioSchema[] = {{"radio", kRadioParams, "simulated radio: one shared medium"}};

Result<RadioConfig> radio_from(const Result<Config>& c) {
  if (!c) return c.error();
  const SectionView v(c.value(), "radio");
  const RadioConfig r = load_params(v, kRadioFields);
  if (r.cw_max < r.cw_min)
    return Error::make(ErrorCode::kConfig, "config error: key 'radio.cw_max' = " + std::to_string(r.cw_max) +
                                               " is out of range [cw_min = " + std::to_string(r.cw_min) + ", 65535] slots");
  return r;
}

// Bits of one PPDU's data field: SERVICE (16) + the frame + tail (6), in 4 us OFDM symbols.
double ofdm_data_s(const RadioConfig& c, double frame_bytes) noexcept {
  constexpr double kSymbolS = 4e-6;
  const double bits_per_symbol = c.phy_rate_bps * kSymbolS;
  return std::ceil((16.0 + 8.0 * frame_bytes + 6.0) / bits_per_symbol - 1e-9) * kSymbolS;
}

}  // namespace

std::span<const ParamSection> radio_config_schema() noexcept { return kRadioSchema; }

Result<RadioConfig> load_radio_config(const YAML::Node& node, std::string_view origin) {
  return radio_from(load_model_params(kRadioSchema, node, origin));
}
Result<RadioConfig> load_radio_config(std::string_view yaml, std::string_view origin) {
  return radio_from(load_model_params(kRadioSchema, yaml, origin));
}

double delivery_probability(const RadioConfig& c, double d) noexcept {
  if (d <= 0) return 1.0;
  if (!(c.range_m > 0)) return 0.0;
  if (c.shadowing_sigma_db <= 0) return d <= c.range_m ? 1.0 : 0.0;
  // Received power exceeds the decode threshold by 10 n log10(range / d) dB on average, less the shadowing.
  const double margin_db = 10.0 * c.path_loss_exponent * std::log10(c.range_m / d);
  return 0.5 * std::erfc(-margin_db / (c.shadowing_sigma_db * std::sqrt(2.0)));
}

double reach_m(const RadioConfig& c) noexcept {
  if (c.shadowing_sigma_db <= 0) return c.range_m;
  constexpr double kZ = 3.0902;  // P(Z > z) = 1e-3
  return c.range_m * std::pow(10.0, kZ * c.shadowing_sigma_db / (10.0 * c.path_loss_exponent));
}

double carrier_sense_range_m(const RadioConfig& c) noexcept {
  if (c.carrier_sense_range_m > 0) return c.carrier_sense_range_m;
  return c.range_m * std::pow(10.0, c.carrier_sense_margin_db / (10.0 * c.path_loss_exponent));
}

double frame_airtime_s(const RadioConfig& c, std::size_t payload_bytes, bool unicast) noexcept {
  const double frame = static_cast<double>(payload_bytes) + c.overhead_bytes + c.mac_overhead_bytes;
  double t = c.preamble_s + ofdm_data_s(c, frame);
  if (unicast) t += c.sifs_s + c.preamble_s + ofdm_data_s(c, c.ack_bytes);
  return t;
}

}  // namespace ag::sim
