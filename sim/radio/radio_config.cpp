// The radio's parameters (units, ranges, defaults) and the pure parts of the model: delivery curve, airtime.
#include <algorithm>
#include <cmath>

#include "airground/sim/model_params.hpp"
#include "airground/sim/radio.hpp"

namespace ag::sim {

namespace {

// Defaults: 802.11a/g OFDM (20 MHz) at its lowest rate, 6 Mbit/s, timing from IEEE 802.11-2016 clause 17;
// sources and typical ranges in docs/simulator.md.
constexpr ParamSpec kRadioParams[] = {
    ParamSpec::real("range_m", 100.0, 0.0, 1e6, "m", "distance at which a frame's delivery probability falls to 50 %"),
    ParamSpec::real("path_loss_exponent", 3.0, 1.5, 6.0, "", "log-distance path-loss exponent n"),
    ParamSpec::real("shadowing_sigma_db", 6.0, 0.0, 20.0, "dB", "log-normal shadowing per frame and receiver; 0 = hard edge at range_m"),
    ParamSpec::real("carrier_sense_range_m", 0.0, 0.0, 1e6, "m", "nodes this close defer to each other; 0 = derived from carrier_sense_margin_db"),
    ParamSpec::real("carrier_sense_margin_db", 6.0, 0.0, 30.0, "dB", "carrier sense threshold below the decode threshold"),
    ParamSpec::real("capture_threshold_db", 10.0, 0.0, 40.0, "dB", "a frame this much stronger than an overlapping one survives"),
    ParamSpec::real("loss_probability", 0.01, 0.0, 1.0, "", "per-frame loss independent of distance"),
    ParamSpec::real("latency_s", 0.005, 0.0, 60.0, "s", "fixed delay after transmission"),
    ParamSpec::real("jitter_s", 0.002, 0.0, 60.0, "s", "uniform extra delay in [0, jitter_s]"),
    ParamSpec::real("phy_rate_bps", 6.0e6, 1.0e5, 1.0e10, "bit/s", "PHY data rate"),
    ParamSpec::real("preamble_s", 20e-6, 0.0, 0.01, "s", "PLCP preamble and header per frame"),
    ParamSpec::real("slot_s", 9e-6, 1e-6, 0.001, "s", "backoff slot time"),
    ParamSpec::real("sifs_s", 16e-6, 0.0, 0.001, "s", "short interframe space (DIFS = SIFS + 2 slots)"),
    ParamSpec::integer("cw_min", 15, 0, 1023, "slots", "initial contention window"),
    ParamSpec::integer("cw_max", 1023, 0, 65535, "slots", "largest contention window"),
    ParamSpec::integer("retry_limit", 7, 0, 31, "count", "unicast retransmissions before a frame is dropped"),
    ParamSpec::real("mac_overhead_bytes", 36.0, 0.0, 1000.0, "B", "MAC header, FCS and LLC/SNAP per frame"),
    ParamSpec::real("ack_bytes", 14.0, 0.0, 100.0, "B", "ACK frame after a unicast"),
    ParamSpec::real("overhead_bytes", 28.0, 0.0, 1e4, "B", "IPv4 + UDP header per datagram"),
    ParamSpec::real("queue_limit_bytes", 262144.0, 0.0, 1e10, "B", "bytes waiting per node before tail drop"),
    ParamSpec::real("max_datagram_bytes", 65507.0, 1.0, 1e9, "B", "larger datagrams are refused"),
};
constexpr ParamSection kRadioSchema[] = {{"radio", kRadioParams, "simulated radio: one shared medium"}};

Result<RadioConfig> radio_from(const Result<Config>& c) {
  if (!c) return c.error();
  const SectionView v(c.value(), "radio");
  RadioConfig r;
  r.range_m = v.real("range_m");
  r.path_loss_exponent = v.real("path_loss_exponent");
  r.shadowing_sigma_db = v.real("shadowing_sigma_db");
  r.carrier_sense_range_m = v.real("carrier_sense_range_m");
  r.carrier_sense_margin_db = v.real("carrier_sense_margin_db");
  r.capture_threshold_db = v.real("capture_threshold_db");
  r.loss_probability = v.real("loss_probability");
  r.latency_s = v.real("latency_s");
  r.jitter_s = v.real("jitter_s");
  r.phy_rate_bps = v.real("phy_rate_bps");
  r.preamble_s = v.real("preamble_s");
  r.slot_s = v.real("slot_s");
  r.sifs_s = v.real("sifs_s");
  r.cw_min = static_cast<int>(v.integer("cw_min"));
  r.cw_max = static_cast<int>(v.integer("cw_max"));
  r.retry_limit = static_cast<int>(v.integer("retry_limit"));
  r.mac_overhead_bytes = v.real("mac_overhead_bytes");
  r.ack_bytes = v.real("ack_bytes");
  r.overhead_bytes = v.real("overhead_bytes");
  r.queue_limit_bytes = v.real("queue_limit_bytes");
  r.max_datagram_bytes = v.real("max_datagram_bytes");
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
