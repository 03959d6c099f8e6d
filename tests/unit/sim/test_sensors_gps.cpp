// Tests of the simulated GNSS receiver (noise, rate, dropouts, bias, geodesy, config) and its PRNG.
#include <gtest/gtest.h>

#include <GeographicLib/LocalCartesian.hpp>

#include <cmath>
#include <cstdint>
#include <vector>

#include "airground/sim/gps.hpp"
#include "airground/messages/geometry.hpp"
#include "airground/platform/rng.hpp"

namespace ag::sim {
namespace {

struct Moments {
  double mean{0}, sd{0};
};
Moments moments(const std::vector<double>& v) {
  double s = 0, s2 = 0;
  for (double x : v) s += x;
  const double m = s / static_cast<double>(v.size());
  for (double x : v) s2 += (x - m) * (x - m);
  return {m, std::sqrt(s2 / static_cast<double>(v.size() - 1))};
}

GpsConfig quiet() {
  GpsConfig c;
  c.dropout_rate_per_s = 0.0;
  return c;
}

TEST(Rng, SameSeedSameStreamAndKnownValues) {
  Rng a(123), b(123), c(124);
  for (int i = 0; i < 100; ++i) {
    const auto x = a.next_u64();
    EXPECT_EQ(x, b.next_u64());
    EXPECT_NE(x, c.next_u64());
  }
  // splitmix64 reference values (seed 0): pins the generator across compilers and libraries.
  std::uint64_t s = 0;
  EXPECT_EQ(splitmix64(s), 0xE220A8397B1DCDAFULL);
  EXPECT_EQ(splitmix64(s), 0x6E789E6AA1B965F4ULL);
  EXPECT_NE(derive_seed(5, 0), derive_seed(5, 1));
  EXPECT_NE(derive_seed(5, 0), derive_seed(6, 0));
}

TEST(Rng, DistributionsHaveTheirMoments) {
  Rng r(99);
  constexpr int kN = 200000;
  std::vector<double> u, g, e;
  u.reserve(kN);
  g.reserve(kN);
  e.reserve(kN);
  for (int i = 0; i < kN; ++i) {
    const double x = r.uniform();
    ASSERT_GE(x, 0.0);
    ASSERT_LT(x, 1.0);
    u.push_back(x);
    g.push_back(r.gaussian(1.0, 2.0));
    e.push_back(r.exponential(4.0));
  }
  EXPECT_NEAR(moments(u).mean, 0.5, 0.003);
  EXPECT_NEAR(moments(u).sd, std::sqrt(1.0 / 12.0), 0.003);
  EXPECT_NEAR(moments(g).mean, 1.0, 0.02);
  EXPECT_NEAR(moments(g).sd, 2.0, 0.02);
  EXPECT_NEAR(moments(e).mean, 0.25, 0.003);
  EXPECT_NEAR(moments(e).sd, 0.25, 0.005);
  EXPECT_TRUE(std::isinf(r.exponential(0.0)));
  int counts[7] = {};
  for (int i = 0; i < 70000; ++i) ++counts[r.below(7)];
  for (int k : counts) EXPECT_NEAR(k, 10000, 450);
}

TEST(GpsSimulator, NoiseHasZeroMeanAndConfiguredSigma) {
  const Datum datum;
  GpsSimulator gps(quiet(), datum, 1);
  const Pose3 truth{10.0, -5.0, 40.0, 0, 0, 0};
  std::vector<double> de, dn, du;
  GpsFix fix;
  for (int i = 0; i < 20000; ++i) {
    ASSERT_TRUE(gps.sample(i * 200 * kNsPerMs, truth, fix));
    EXPECT_EQ(fix.fix_type, GpsFixType::kFix3D);
    de.push_back(fix.east_m - truth.x);
    dn.push_back(fix.north_m - truth.y);
    du.push_back(fix.up_m - truth.z);
  }
  const double tol_mean = 4.0 * 0.5 / std::sqrt(20000.0);
  EXPECT_NEAR(moments(de).mean, 0.0, tol_mean);
  EXPECT_NEAR(moments(dn).mean, 0.0, tol_mean);
  EXPECT_NEAR(moments(du).mean, 0.0, 2 * tol_mean);
  EXPECT_NEAR(moments(de).sd, 0.5, 0.02);
  EXPECT_NEAR(moments(dn).sd, 0.5, 0.02);
  EXPECT_NEAR(moments(du).sd, 1.0, 0.04);
  EXPECT_DOUBLE_EQ(fix.h_accuracy_m, 0.5);
  EXPECT_DOUBLE_EQ(fix.v_accuracy_m, 1.0);
}

TEST(GpsSimulator, GeodeticOutputRoundTripsThroughLocalCartesian) {
  Datum datum;
  datum.lat_deg = -33.8688;
  datum.lon_deg = 151.2093;
  datum.height_m = 20.0;
  GpsSimulator gps(GpsConfig{}, datum, 5);
  const GeographicLib::LocalCartesian lc(datum.lat_deg, datum.lon_deg, datum.height_m);
  GpsFix fix;
  int checked = 0;
  for (int i = 0; i < 200; ++i) {
    const Pose3 truth{-300.0 + 3.0 * i, 150.0 - 2.0 * i, 45.0, 0, 0, 0};
    if (!gps.sample(i * 200 * kNsPerMs, truth, fix)) continue;
    double e = 0, n = 0, u = 0;
    lc.Forward(fix.lat_deg, fix.lon_deg, fix.height_m, e, n, u);
    EXPECT_NEAR(e, fix.east_m, 1e-6);
    EXPECT_NEAR(n, fix.north_m, 1e-6);
    EXPECT_NEAR(u, fix.up_m, 1e-6);
    EXPECT_NEAR(e, truth.x, 5.0);  // noise only
    ++checked;
  }
  EXPECT_GT(checked, 150);
  // Without noise the datum itself comes out.
  GpsConfig exact = quiet();
  exact.sigma_m = exact.sigma_vertical_m = 0.0;
  GpsSimulator g0(exact, datum, 5);
  ASSERT_TRUE(g0.sample(0, Pose3{}, fix));
  EXPECT_NEAR(fix.lat_deg, datum.lat_deg, 1e-12);
  EXPECT_NEAR(fix.lon_deg, datum.lon_deg, 1e-12);
  EXPECT_NEAR(fix.height_m, datum.height_m, 1e-6);
}

TEST(GpsSimulator, FixesComeAtTheConfiguredRate) {
  GpsConfig c = quiet();
  c.rate_hz = 5.0;
  for (const TimeNs step : {TimeNs{10 * kNsPerMs}, TimeNs{30 * kNsPerMs}, TimeNs{70 * kNsPerMs}}) {
    GpsSimulator gps(c, Datum{}, 2);
    std::vector<TimeNs> stamps;
    GpsFix fix;
    const TimeNs t0 = 1234 * kNsPerMs;
    for (TimeNs t = t0; t < t0 + 100 * kNsPerS; t += step)
      if (gps.sample(t, Pose3{}, fix)) stamps.push_back(fix.stamp);
    EXPECT_NEAR(static_cast<double>(stamps.size()), 500.0, 1.0) << "step " << step;
    EXPECT_EQ(stamps.front(), t0);
    for (std::size_t i = 1; i < stamps.size(); ++i) {
      EXPECT_GE(stamps[i] - stamps[i - 1], 200 * kNsPerMs - step);
      EXPECT_LE(stamps[i] - stamps[i - 1], 200 * kNsPerMs + step);
    }
  }
}

TEST(GpsSimulator, DropoutsHappenAndEnd) {
  GpsConfig c;
  c.dropout_rate_per_s = 1.0 / 20.0;
  c.dropout_mean_s = 5.0;
  GpsSimulator gps(c, Datum{}, 3);
  GpsFix fix;
  std::vector<TimeNs> stamps;
  int due = 0;
  for (TimeNs t = 0; t < 10000 * kNsPerS; t += 200 * kNsPerMs) {
    ++due;
    if (gps.sample(t, Pose3{}, fix)) stamps.push_back(fix.stamp);
    else EXPECT_TRUE(gps.in_dropout(t));
  }
  // Alternating renewal process: ~1 dropout per 25 s (400 +- 17), 20% (+- 1.1%) of the time without a fix.
  const double missing = 1.0 - static_cast<double>(stamps.size()) / due;
  EXPECT_NEAR(missing, 0.2, 0.05);
  EXPECT_GT(gps.dropouts_started(), 330u);
  EXPECT_LT(gps.dropouts_started(), 470u);
  int gaps = 0;
  for (std::size_t i = 1; i < stamps.size(); ++i) gaps += stamps[i] - stamps[i - 1] > 200 * kNsPerMs ? 1 : 0;
  EXPECT_LE(static_cast<std::uint64_t>(gaps), gps.dropouts_started());
  EXPECT_GE(static_cast<double>(gaps), 0.85 * static_cast<double>(gps.dropouts_started()));
  EXPECT_GT(stamps.back(), 9900 * kNsPerS);  // fixes always come back
}

TEST(GpsSimulator, DropoutScheduleDoesNotDependOnCallRate) {
  GpsConfig c;
  c.dropout_rate_per_s = 0.1;
  GpsSimulator fast(c, Datum{}, 8), slow(c, Datum{}, 8);
  GpsFix fix;
  int compared = 0, in_drop = 0;
  for (TimeNs t = 0; t < 600 * kNsPerS; t += 10 * kNsPerMs) {
    fast.sample(t, Pose3{}, fix);
    if (t % (100 * kNsPerMs) == 0) {
      slow.sample(t, Pose3{}, fix);
      EXPECT_EQ(fast.in_dropout(t), slow.in_dropout(t));
      ++compared;
      in_drop += slow.in_dropout(t) ? 1 : 0;
    }
  }
  EXPECT_GT(in_drop, 0);
  EXPECT_LT(in_drop, compared);
}

TEST(GpsSimulator, NoFixReportsDuringDropoutsWhenAsked) {
  GpsConfig c;
  c.dropout_rate_per_s = 0.2;
  c.report_no_fix = true;
  GpsSimulator gps(c, Datum{}, 4);
  GpsFix fix;
  int no_fix = 0, total = 0;
  for (TimeNs t = 0; t < 200 * kNsPerS; t += 200 * kNsPerMs) {
    ASSERT_TRUE(gps.sample(t, Pose3{}, fix));
    ++total;
    if (fix.fix_type == GpsFixType::kNoFix) {
      ++no_fix;
      EXPECT_TRUE(gps.in_dropout(t));
    }
  }
  EXPECT_GT(no_fix, 0);
  EXPECT_LT(no_fix, total);
}

TEST(GpsSimulator, BiasWandersSlowlyWithItsStationarySigma) {
  GpsConfig c = quiet();
  c.sigma_m = 0.01;
  c.bias_sigma_m = 2.0;
  c.bias_tau_s = 60.0;
  std::vector<double> first;
  double max_step = 0;
  for (std::uint64_t seed = 0; seed < 1000; ++seed) {
    GpsSimulator gps(c, Datum{}, seed);
    GpsFix fix;
    ASSERT_TRUE(gps.sample(0, Pose3{}, fix));
    first.push_back(fix.east_m);
    const double e0 = fix.east_m;
    ASSERT_TRUE(gps.sample(200 * kNsPerMs, Pose3{}, fix));
    max_step = std::max(max_step, std::abs(fix.east_m - e0));
  }
  EXPECT_NEAR(moments(first).sd, 2.0, 0.15);
  EXPECT_NEAR(moments(first).mean, 0.0, 0.25);
  // Over 0.2 s the bias moves by ~2 * sqrt(2 * 0.2 / 60) = 0.16 m (1 sigma): far less than its spread.
  EXPECT_LT(max_step, 0.8);
}

TEST(GpsSimulator, VelocityFollowsTheTruth) {
  GpsSimulator gps(quiet(), Datum{}, 6);
  GpsFix fix;
  std::vector<double> ve, vn;
  for (int i = 0; i < 1000; ++i) {
    const double t = 0.2 * i;
    if (gps.sample(from_seconds(t), Pose3{1.0 * t, 2.0 * t, 40.0, 0, 0, 0}, fix) && i > 0) {
      ve.push_back(fix.vel_east_mps);
      vn.push_back(fix.vel_north_mps);
    }
  }
  EXPECT_NEAR(moments(ve).mean, 1.0, 0.01);
  EXPECT_NEAR(moments(vn).mean, 2.0, 0.01);
  EXPECT_NEAR(moments(ve).sd, 0.05, 0.01);
}

TEST(GpsSimulator, DeterministicBySeed) {
  auto run = [](std::uint64_t seed) {
    GpsSimulator gps(GpsConfig{}, Datum{}, seed);
    std::vector<double> out;
    GpsFix fix;
    for (TimeNs t = 0; t < 300 * kNsPerS; t += 50 * kNsPerMs)
      if (gps.sample(t, Pose3{}, fix)) out.push_back(fix.lat_deg);
    return out;
  };
  EXPECT_EQ(run(10), run(10));
  EXPECT_NE(run(10), run(11));
}

TEST(GpsConfigYaml, LoadsAndValidatesEveryKey) {
  auto ok = load_gps_config("sigma_m: 2.5\nrate_hz: 10\nreport_no_fix: true\n", "gps.yaml");
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  EXPECT_DOUBLE_EQ(ok->sigma_m, 2.5);
  EXPECT_DOUBLE_EQ(ok->rate_hz, 10.0);
  EXPECT_TRUE(ok->report_no_fix);
  EXPECT_DOUBLE_EQ(ok->sigma_vertical_m, GpsConfig{}.sigma_vertical_m);

  auto unknown = load_gps_config("sigma: 1\n", "gps.yaml");
  ASSERT_FALSE(unknown.ok());
  EXPECT_EQ(unknown.error().code, ErrorCode::kConfig);
  EXPECT_NE(unknown.error().message.find("'gps.sigma'"), std::string::npos) << unknown.error().message;
  EXPECT_NE(unknown.error().message.find("gps.yaml:1"), std::string::npos);

  auto type = load_gps_config("report_no_fix: maybe\n", "gps.yaml");
  ASSERT_FALSE(type.ok());
  EXPECT_NE(type.error().message.find("report_no_fix"), std::string::npos);

  auto range = load_gps_config("rate_hz: 0\n", "gps.yaml");
  ASSERT_FALSE(range.ok());
  EXPECT_NE(range.error().message.find("rate_hz"), std::string::npos);
  EXPECT_NE(range.error().message.find("[0.1, 100] Hz"), std::string::npos) << range.error().message;

  EXPECT_EQ(gps_config_schema().size(), 1u);
  EXPECT_EQ(gps_config_schema()[0].name, "gps");
}

}  // namespace
}  // namespace ag::sim
