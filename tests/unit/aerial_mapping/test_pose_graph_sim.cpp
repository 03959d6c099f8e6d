// The ASOOM pose graph against the simulator's own models: a quadrotor flying a lawnmower survey at 40 m
// and 5 m/s, stepped at 50 Hz; its monocular visual odometry (10 Hz frames, unknown scale and yaw, per
// segment) goes to add_frame and its GPS (5 Hz, 0.5 m) to add_gps; update() after every frame.
// The PoseGraph tests keep the VO scale constant within a segment; the PoseGraphDrift tests give it the
// VO model's default random walk (0.002/sqrt(s)) and measure the current scale, the relative distances
// and the relative roll/pitch that the stereo pairs get.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <initializer_list>
#include <iterator>
#include <map>
#include <random>
#include <vector>

#include "airground/aerial_mapping/pose_graph.hpp"
#include "airground/messages/pose_math.hpp"
#include "airground/sim/gps.hpp"
#include "airground/sim/quadrotor.hpp"
#include "airground/sim/survey.hpp"
#include "airground/sim/visual_odometry.hpp"
#include "airground/sim/world.hpp"

namespace {

using ag::Pose3;
using ag::TimeNs;
using ag::mapping::kNoNode;
using ag::mapping::NodeId;
using ag::mapping::PoseGraph;
using ag::mapping::PoseGraphParams;

// The simulated VO's rotation noise is 0.001 rad per frame: ASOOM's 0.05 rad between-factor leaves
// yaw to the noisy direction of travel (about 0.03 rad rms); 0.005 keeps what the odometry knows.
PoseGraphParams test_params() {
  PoseGraphParams p;
  p.between_sigma_rad = 0.005;
  return p;
}

struct Flight {
  double duration_s{70.0};
  std::uint64_t seed{1};
  double vo_scale{1.0};            // forced VO scale (VO units per metre) of the first segment
  double vo_scale_after_loss{1.0}; // ... and of the segment after the forced loss
  double loss_at_s{-1.0};          // a forced tracking loss starts here (< 0: none) ...
  double loss_length_s{2.0};       // ... and lasts this long; odometry restarts as segment 1
  double outlier_at_s{-1.0};       // the first fix at or after this time is moved 50 m east (< 0: none)
  double vo_loss_rate_per_s{0.0};  // the VO model's own random tracking losses (and then random scales)
  bool gps{true};
  double vo_drift_per_s{0.0};      // the VO model's log-scale random walk [1/sqrt(s)] (its default: 0.002)
  PoseGraphParams params{test_params()};
};

// Lags (frames at 10 Hz) at which the relative poses the stereo pairs use are measured.
constexpr std::size_t kLags[] = {4, 12, 20};
constexpr std::size_t kNumLags = std::size(kLags);

// Error of node j's pose relative to node j - lag: distance ratio - 1 and the rotation error vector
// (in j's body frame: x, y = roll, pitch; z = yaw).
struct RelativeError {
  bool valid{false};
  double dist{0};
  Eigen::Vector3d rot{Eigen::Vector3d::Zero()};
};

RelativeError relative_error(const Eigen::Isometry3d& ei, const Eigen::Isometry3d& ej, const Eigen::Isometry3d& ti,
                             const Eigen::Isometry3d& tj) {
  RelativeError r;
  const double true_d = (tj.translation() - ti.translation()).norm();
  if (true_d < 1.0) return r;  // hover, turns: no baseline to speak of
  r.valid = true;
  r.dist = (ej.translation() - ei.translation()).norm() / true_d - 1.0;
  const Eigen::Matrix3d est = ei.linear().transpose() * ej.linear();
  const Eigen::Matrix3d tru = ti.linear().transpose() * tj.linear();
  const Eigen::AngleAxisd aa(Eigen::Matrix3d(tru.transpose() * est));
  r.rot = aa.angle() * aa.axis();
  return r;
}

struct NodeTruth {
  Pose3 truth;
  Pose3 vo;                                         // the odometry pose given to add_frame
  double vo_scale{1};                               // the VO's true scale then [VO units per metre]
  double t_s{0};
  std::uint32_t segment{0};
  Eigen::Vector3d at_add{Eigen::Vector3d::Zero()};  // pose() right after add_frame (the prediction)
  bool initialised_at_add{false};                   // graph.initialised() then
  // After the update() that followed add_frame (what the mapper sees when the frame is the newest):
  double scale_error_now{0};                        // current scale x true VO scale - 1 (if initialised)
  bool initialised_now{false};
  RelativeError rel_now[kNumLags];                  // to the node kLags[k] frames earlier
};

struct FlightResult {
  std::vector<NodeTruth> nodes;          // by node id
  std::map<std::uint32_t, double> vo_scale;  // true VO units per metre, per segment
  int outliers_injected{0};
};

ag::sim::VoConfig vo_config(double scale, double loss_rate, double drift) {
  ag::sim::VoConfig c;
  if (loss_rate <= 0) c.scale_min = c.scale_max = scale;  // else the model's random scale per segment
  c.scale_drift_per_s = drift;
  c.tracking_loss_rate_per_s = loss_rate;
  return c;
}

// Flies the survey and feeds the graph; returns the truth of every node.
FlightResult fly(const Flight& f, PoseGraph& graph) {
  ag::sim::QuadrotorConfig qc;
  auto route = ag::sim::survey_lawnmower(-120.0, -80.0, 120.0, 80.0, 40.0, 0.3, 1.2);
  EXPECT_TRUE(route.ok());
  ag::sim::Quadrotor quad(qc, Pose3{route.value()[0].x, route.value()[0].y, 40.0, 0, 0, 0.3});
  quad.set_waypoints(route.value());
  ag::sim::VisualOdometrySimulator vo0(vo_config(f.vo_scale, f.vo_loss_rate_per_s, f.vo_drift_per_s), f.seed);
  ag::sim::VisualOdometrySimulator vo1(vo_config(f.vo_scale_after_loss, 0.0, f.vo_drift_per_s), f.seed + 100);
  ag::sim::GpsConfig gc;
  gc.sigma_m = 0.5;
  gc.dropout_rate_per_s = 0.0;
  ag::sim::GpsSimulator gps(gc, ag::sim::Datum{}, f.seed + 7);

  FlightResult r;
  const TimeNs dt = ag::period_from_hz(50.0);
  const auto steps = static_cast<std::int64_t>(f.duration_s * 50.0);
  bool outlier_done = false;
  for (std::int64_t k = 0; k <= steps; ++k) {
    const TimeNs t = k * dt;
    const double ts = ag::to_seconds(t);
    if (k > 0) quad.step(0.02);
    const Pose3 truth = quad.pose();
    const bool lost = f.loss_at_s >= 0 && ts >= f.loss_at_s && ts < f.loss_at_s + f.loss_length_s;
    const bool second = f.loss_at_s >= 0 && ts >= f.loss_at_s + f.loss_length_s;
    ag::sim::VoSample vs;
    ag::sim::VisualOdometrySimulator& vo = second ? vo1 : vo0;
    if (!lost && vo.sample(t, truth, vs) && vs.tracking) {
      const std::uint32_t seg = second ? 1U : vs.segment;
      const NodeId id = graph.add_frame(vs.stamp, seg, vs.pose);
      EXPECT_NE(id, kNoNode);
      if (id != kNoNode) {
        const auto j = static_cast<std::size_t>(id);
        r.nodes.resize(j + 1);
        NodeTruth& nt = r.nodes[j];
        nt.truth = truth;
        nt.vo = vs.pose;
        nt.t_s = ts;
        nt.segment = seg;
        nt.at_add = graph.pose(id).translation();
        nt.initialised_at_add = graph.initialised();
        r.vo_scale[seg] = vo.scale();
        nt.vo_scale = vo.scale();
        graph.update();
        nt.initialised_now = graph.initialised();
        if (nt.initialised_now) {
          nt.scale_error_now = graph.scale(seg) * vo.scale() - 1.0;
          for (std::size_t l = 0; l < kNumLags; ++l) {
            if (j < kLags[l] || r.nodes[j - kLags[l]].segment != seg) continue;
            const auto i = static_cast<NodeId>(j - kLags[l]);
            nt.rel_now[l] = relative_error(graph.pose(i), graph.pose(id), ag::to_isometry(r.nodes[j - kLags[l]].truth),
                                           ag::to_isometry(truth));
          }
        }
      } else {
        graph.update();
      }
    }
    ag::sim::GpsFix fix;
    if (f.gps && gps.sample(t, truth, fix) && fix.fix_type != ag::sim::GpsFixType::kNoFix) {
      Eigen::Vector3d enu(fix.east_m, fix.north_m, fix.up_m);
      if (f.outlier_at_s >= 0 && !outlier_done && ts >= f.outlier_at_s) {
        enu.x() += 50.0;
        outlier_done = true;
        ++r.outliers_injected;
      }
      graph.add_gps(fix.stamp, enu, fix.h_accuracy_m);
    }
  }
  graph.update(true);
  return r;
}

struct Errors {
  double rms_m{0};
  double max_m{0};
  double rms_yaw{0};
  double max_yaw{0};
  double max_tilt{0};
  std::size_t n{0};
};

// Position and yaw errors of the nodes with t in [t0, t1] (and of segment `seg` if >= 0).
Errors errors(const PoseGraph& g, const FlightResult& r, double t0, double t1, int seg = -1) {
  Errors e;
  double se = 0, sy = 0;
  for (std::size_t i = 0; i < r.nodes.size(); ++i) {
    const NodeTruth& nt = r.nodes[i];
    if (nt.t_s < t0 || nt.t_s > t1 || (seg >= 0 && nt.segment != static_cast<std::uint32_t>(seg))) continue;
    const Eigen::Isometry3d p = g.pose(static_cast<NodeId>(i));
    const Eigen::Isometry3d t = ag::to_isometry(nt.truth);
    const double d = (p.translation() - t.translation()).norm();
    const Pose3 pe = ag::to_pose3(p);
    const double dy = std::abs(ag::wrap_angle(pe.yaw - nt.truth.yaw));
    const double tilt = Eigen::AngleAxisd(Eigen::Quaterniond(p.linear() * t.linear().transpose())).angle();
    se += d * d;
    sy += dy * dy;
    e.max_m = std::max(e.max_m, d);
    e.max_yaw = std::max(e.max_yaw, dy);
    e.max_tilt = std::max(e.max_tilt, tilt);
    ++e.n;
  }
  if (e.n > 0) {
    e.rms_m = std::sqrt(se / static_cast<double>(e.n));
    e.rms_yaw = std::sqrt(sy / static_cast<double>(e.n));
  }
  return e;
}

void print(const char* what, const Errors& e, const PoseGraph& g) {
  std::printf("%s: %zu nodes, position rms %.3f max %.3f m, yaw rms %.4f max %.4f rad, rotation max %.4f rad; "
              "%llu solves, last %.1f ms\n",
              what, e.n, e.rms_m, e.max_m, e.rms_yaw, e.max_yaw, e.max_tilt,
              static_cast<unsigned long long>(g.stats().solves), g.stats().last_solve_ms);
}

// Largest error of pose() right after add_frame (the prediction the mapper gets at once), over the
// frames added while the graph was initialised, and over those added >= 10 s after their segment was.
struct Prediction {
  double max_m{0};
  double max_settled_m{0};
  std::size_t n{0};
  std::size_t n_settled{0};
};

Prediction prediction_errors(const FlightResult& r) {
  Prediction p;
  std::map<std::uint32_t, double> init_at;
  for (const NodeTruth& nt : r.nodes) {
    if (!nt.initialised_at_add) continue;
    if (init_at.count(nt.segment) == 0) init_at[nt.segment] = nt.t_s;
    const double d = (nt.at_add - Eigen::Vector3d(nt.truth.x, nt.truth.y, nt.truth.z)).norm();
    p.max_m = std::max(p.max_m, d);
    ++p.n;
    if (nt.t_s >= init_at[nt.segment] + 10.0) {
      p.max_settled_m = std::max(p.max_settled_m, d);
      ++p.n_settled;
    }
  }
  return p;
}

// |metres per VO unit x VO units per metre - 1|
double scale_error(const PoseGraph& g, const FlightResult& r, std::uint32_t seg) {
  return std::abs(g.scale(seg) * r.vo_scale.at(seg) - 1.0);
}

// What a drifting VO scale and the VO's rotation noise do to the relative poses the stereo pairs use,
// over the nodes from t0 on.
struct LagFigures {
  double dist_bias{0}, dist_rms{0};    // distance ratio - 1: mean and rms
  double tilt_rms{0}, yaw_rms{0};      // rotation error: roll/pitch (rms per axis) and yaw [rad]
  std::size_t n{0};
};
struct DriftFigures {
  double scale_now_rms{0};             // current scale error after each update (causal)
  double scale_now_final{0};           // ... at the last frame
  double scale_smoothed_rms{0};        // scale_at(node) after the final solve, nodes >= 10 s before the end
  LagFigures now[kNumLags];            // relative poses right after the newer node's update (causal)
  LagFigures smoothed[kNumLags];       // relative poses after the final solve
  LagFigures vo[kNumLags];             // the raw odometry's relative poses
};

void add_to(LagFigures& f, const RelativeError& e) {
  if (!e.valid) return;
  f.dist_bias += e.dist;
  f.dist_rms += e.dist * e.dist;
  f.tilt_rms += 0.5 * (e.rot.x() * e.rot.x() + e.rot.y() * e.rot.y());
  f.yaw_rms += e.rot.z() * e.rot.z();
  ++f.n;
}
void finish(LagFigures& f) {
  if (f.n == 0) return;
  const auto n = static_cast<double>(f.n);
  f.dist_bias /= n;
  f.dist_rms = std::sqrt(f.dist_rms / n);
  f.tilt_rms = std::sqrt(f.tilt_rms / n);
  f.yaw_rms = std::sqrt(f.yaw_rms / n);
}

DriftFigures drift_figures(const PoseGraph& g, const FlightResult& r, double t0) {
  DriftFigures d;
  double se = 0, ss = 0;
  std::size_t ns = 0, nss = 0;
  const double t_end = r.nodes.empty() ? 0.0 : r.nodes.back().t_s;
  for (std::size_t j = 0; j < r.nodes.size(); ++j) {
    const NodeTruth& nt = r.nodes[j];
    if (nt.t_s < t0) continue;
    if (nt.t_s <= t_end - 10.0) {
      const double e = g.scale_at(static_cast<NodeId>(j)) * nt.vo_scale - 1.0;
      ss += e * e;
      ++nss;
    }
    if (nt.initialised_now) {
      se += nt.scale_error_now * nt.scale_error_now;
      ++ns;
      d.scale_now_final = nt.scale_error_now;
    }
    for (std::size_t k = 0; k < kNumLags; ++k) {
      add_to(d.now[k], nt.rel_now[k]);
      if (j < kLags[k] || r.nodes[j - kLags[k]].segment != nt.segment) continue;
      const NodeTruth& ni = r.nodes[j - kLags[k]];
      const Eigen::Isometry3d ti = ag::to_isometry(ni.truth), tj = ag::to_isometry(nt.truth);
      add_to(d.smoothed[k], relative_error(g.pose(static_cast<NodeId>(j - kLags[k])), g.pose(static_cast<NodeId>(j)), ti, tj));
      // The odometry's own relative pose (rotation; its translation is in VO units, scaled to metres
      // with the true scale of the newer frame).
      Eigen::Isometry3d vi = ag::to_isometry(ni.vo), vj = ag::to_isometry(nt.vo);
      vi.translation() /= nt.vo_scale;
      vj.translation() /= nt.vo_scale;
      add_to(d.vo[k], relative_error(ti, ti * vi.inverse() * vj, ti, tj));
    }
  }
  if (ns > 0) d.scale_now_rms = std::sqrt(se / static_cast<double>(ns));
  if (nss > 0) d.scale_smoothed_rms = std::sqrt(ss / static_cast<double>(nss));
  for (std::size_t k = 0; k < kNumLags; ++k) {
    finish(d.now[k]);
    finish(d.smoothed[k]);
    finish(d.vo[k]);
  }
  return d;
}

void print(const DriftFigures& d) {
  std::printf("  current scale error: rms %.4f, final %+.4f; smoothed scale error rms %.4f\n", d.scale_now_rms, d.scale_now_final,
              d.scale_smoothed_rms);
  for (std::size_t k = 0; k < kNumLags; ++k) {
    std::printf("  lag %2zu frames: distance bias/rms now %+.4f/%.4f smoothed %+.4f/%.4f; roll-pitch rms now %.5f smoothed %.5f vo %.5f; "
                "yaw rms now %.5f smoothed %.5f vo %.5f rad\n",
                kLags[k], d.now[k].dist_bias, d.now[k].dist_rms, d.smoothed[k].dist_bias, d.smoothed[k].dist_rms, d.now[k].tilt_rms,
                d.smoothed[k].tilt_rms, d.vo[k].tilt_rms, d.now[k].yaw_rms, d.smoothed[k].yaw_rms, d.vo[k].yaw_rms);
  }
}

// Reference for the current scale: a Kalman filter that knows everything but the scale (VO without
// noise, yaw known: its steps are the true ones times the true VO scale), fed 0.5 m GPS at 5 Hz and told
// the true random-walk rate. Returns the rms of its current scale error over the nodes from t0 on.
double oracle_scale_rms(const FlightResult& r, double drift_per_sqrt_s, double gps_sigma, std::uint64_t seed, double t0,
                        double vel_sigma = 0.0) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> gauss(0.0, gps_sigma);
  Eigen::Vector3d x(r.nodes[0].truth.x, r.nodes[0].truth.y, 1.0 / r.nodes[0].vo_scale);  // p, metres per VO unit
  Eigen::Matrix3d P = Eigen::Matrix3d::Zero();
  P(0, 0) = P(1, 1) = gps_sigma * gps_sigma;
  P(2, 2) = 1e-4 * x(2) * x(2);
  double se = 0;
  std::size_t n = 0;
  for (std::size_t k = 1; k < r.nodes.size(); ++k) {
    const NodeTruth& a = r.nodes[k - 1];
    const NodeTruth& b = r.nodes[k];
    const Eigen::Vector2d u = Eigen::Vector2d(b.truth.x - a.truth.x, b.truth.y - a.truth.y) * b.vo_scale;  // VO units
    const double qw = std::pow(drift_per_sqrt_s * x(2), 2) * (b.t_s - a.t_s);
    Eigen::Matrix3d F = Eigen::Matrix3d::Identity();
    F(0, 2) = u.x();
    F(1, 2) = u.y();
    const Eigen::Vector3d g(u.x(), u.y(), 1.0);
    x.head<2>() += x(2) * u;
    P = F * P * F.transpose() + g * g.transpose() * qw;
    if (k % 2 == 0) {  // a fix every other frame
      const Eigen::Vector2d z(b.truth.x + gauss(rng), b.truth.y + gauss(rng));
      Eigen::Matrix<double, 2, 3> H = Eigen::Matrix<double, 2, 3>::Zero();
      H(0, 0) = H(1, 1) = 1.0;
      const Eigen::Matrix2d S = H * P * H.transpose() + Eigen::Matrix2d::Identity() * gps_sigma * gps_sigma;
      const Eigen::Matrix<double, 3, 2> K = P * H.transpose() * S.inverse();
      x += K * (z - x.head<2>());
      P = (Eigen::Matrix3d::Identity() - K * H) * P;
      if (vel_sigma > 0) {  // GPS velocity: v = c u / dt
        const double dt = b.t_s - a.t_s;
        const Eigen::Vector2d zv = Eigen::Vector2d(b.truth.x - a.truth.x, b.truth.y - a.truth.y) / dt +
                                   Eigen::Vector2d(gauss(rng), gauss(rng)) * (vel_sigma / gps_sigma);
        Eigen::Matrix<double, 2, 3> Hv = Eigen::Matrix<double, 2, 3>::Zero();
        Hv.col(2) = u / dt;
        const Eigen::Matrix2d Sv = Hv * P * Hv.transpose() + Eigen::Matrix2d::Identity() * vel_sigma * vel_sigma;
        const Eigen::Matrix<double, 3, 2> Kv = P * Hv.transpose() * Sv.inverse();
        x += Kv * (zv - x(2) * u / dt);
        P = (Eigen::Matrix3d::Identity() - Kv * Hv) * P;
      }
    }
    if (b.t_s >= t0) {
      const double e = x(2) * b.vo_scale - 1.0;
      se += e * e;
      ++n;
    }
  }
  return n > 0 ? std::sqrt(se / static_cast<double>(n)) : 0.0;
}

double env_or(const char* name, double fallback) {
  const char* v = std::getenv(name);
  return v != nullptr ? std::atof(v) : fallback;
}

// A 3-minute survey with the VO model's default scale drift (0.002 / sqrt(s)) and noise.
Flight drift_flight(std::uint64_t seed, const PoseGraphParams& params) {
  Flight f;
  f.duration_s = 180.0;
  f.seed = seed;
  f.vo_scale = 1.3;
  f.vo_drift_per_s = 0.002;
  f.params = params;
  return f;
}

// Figures pooled over seeds (rms of rms values, mean of |bias|), nodes from 30 s on.
struct Pooled {
  double scale_now_rms{0}, scale_smoothed_rms{0}, final_abs_mean{0};
  double bias_abs[kNumLags]{}, dist_rms[kNumLags]{};
  double tilt_now_over_vo{0}, tilt_smoothed_over_vo{0};  // worst ratio over lags and seeds
  double oracle_rms{0};                                  // oracle_scale_rms() on the same flights
  double tilt[3][kNumLags]{}, yaw[3][kNumLags]{};        // [now, smoothed, vo][lag] rms
  int n{0};
};

Pooled pooled_drift_figures(const PoseGraphParams& params, std::initializer_list<std::uint64_t> seeds, bool verbose) {
  Pooled p;
  for (const std::uint64_t seed : seeds) {
    const Flight f = drift_flight(seed, params);
    PoseGraph g(f.params);
    const FlightResult r = fly(f, g);
    const DriftFigures d = drift_figures(g, r, 30.0);
    const double oracle = oracle_scale_rms(r, 0.002, 0.5, seed, 30.0);
    if (verbose) {
      std::printf("seed %llu: %llu knots, last solve %.1f ms over %llu nodes and %llu knots; oracle filter's current scale rms %.4f\n",
                  static_cast<unsigned long long>(seed), static_cast<unsigned long long>(g.stats().scale_knots), g.stats().last_solve_ms,
                  static_cast<unsigned long long>(g.stats().last_free_nodes), static_cast<unsigned long long>(g.stats().last_free_knots),
                  oracle);
      print(d);
      if (const double vs = env_or("AG_PG_ORACLE_VEL", 0.0); vs > 0)
        std::printf("  oracle filter with GPS velocity (sigma %.3f m/s) too: current scale rms %.4f\n", vs,
                    oracle_scale_rms(r, 0.002, 0.5, seed, 30.0, vs));
    }
    p.scale_now_rms += d.scale_now_rms * d.scale_now_rms;
    p.scale_smoothed_rms += d.scale_smoothed_rms * d.scale_smoothed_rms;
    p.final_abs_mean += std::abs(d.scale_now_final);
    p.oracle_rms += oracle * oracle;
    for (std::size_t k = 0; k < kNumLags; ++k) {
      p.bias_abs[k] += std::abs(d.now[k].dist_bias);
      p.dist_rms[k] += d.now[k].dist_rms * d.now[k].dist_rms;
      p.tilt_now_over_vo = std::max(p.tilt_now_over_vo, d.now[k].tilt_rms / d.vo[k].tilt_rms);
      p.tilt_smoothed_over_vo = std::max(p.tilt_smoothed_over_vo, d.smoothed[k].tilt_rms / d.vo[k].tilt_rms);
      const LagFigures* src[3] = {&d.now[k], &d.smoothed[k], &d.vo[k]};
      for (int m = 0; m < 3; ++m) {
        p.tilt[m][k] += src[m]->tilt_rms * src[m]->tilt_rms;
        p.yaw[m][k] += src[m]->yaw_rms * src[m]->yaw_rms;
      }
    }
    ++p.n;
  }
  const double n = std::max(p.n, 1);
  p.scale_now_rms = std::sqrt(p.scale_now_rms / n);
  p.scale_smoothed_rms = std::sqrt(p.scale_smoothed_rms / n);
  p.final_abs_mean /= n;
  p.oracle_rms = std::sqrt(p.oracle_rms / n);
  for (std::size_t k = 0; k < kNumLags; ++k) {
    p.bias_abs[k] /= n;
    p.dist_rms[k] = std::sqrt(p.dist_rms[k] / n);
    for (int m = 0; m < 3; ++m) {
      p.tilt[m][k] = std::sqrt(p.tilt[m][k] / n);
      p.yaw[m][k] = std::sqrt(p.yaw[m][k] / n);
    }
  }
  return p;
}

void print(const char* what, const Pooled& p) {
  std::printf("%s, %d flights: current scale error rms %.4f (oracle filter %.4f), final |error| mean %.4f; smoothed scale error rms %.4f\n", what,
              p.n, p.scale_now_rms, p.oracle_rms, p.final_abs_mean, p.scale_smoothed_rms);
  for (std::size_t k = 0; k < kNumLags; ++k)
    std::printf("  lag %2zu frames: distance |bias| %.4f rms %.4f; roll/pitch rms now %.5f smoothed %.5f VO %.5f; "
                "yaw rms now %.5f smoothed %.5f VO %.5f\n",
                kLags[k], p.bias_abs[k], p.dist_rms[k], p.tilt[0][k], p.tilt[1][k], p.tilt[2][k], p.yaw[0][k], p.yaw[1][k], p.yaw[2][k]);
  std::printf("  relative roll/pitch rms / the VO's: now %.3f, smoothed %.3f (worst lag)\n", p.tilt_now_over_vo, p.tilt_smoothed_over_vo);
}

// A monocular VO's scale drifts: one scale per segment (ASOOM) is wrong by the drift since the window's
// mean, knots every scale_knot_s follow it. The current scale is a filter's estimate: with 0.5 m GPS at
// 5 Hz and a 0.002/sqrt(s) random walk even a filter that knows everything else (oracle_scale_rms) is
// off by ~0.005 rms, so the bounds below are what the information allows, measured with margin.
TEST(PoseGraphDrift, ScaleKnotsFollowADriftingVoScale) {
  const PoseGraphParams knots = test_params();
  PoseGraphParams one = knots;
  one.scale_knot_s = 0.0;  // one scale per segment: the old model
  const Pooled pk = pooled_drift_figures(knots, {1, 2, 3}, false);
  const Pooled p1 = pooled_drift_figures(one, {1, 2, 3}, false);
  print("scale knots", pk);
  print("one scale per segment", p1);
  constexpr std::size_t kLag2s = 2;  // kLags[2] = 20 frames = 2 s
  // Measured (3 flights): knots 0.0061 / 0.0040 / 0.0011, one scale 0.0081 / 0.0064 / 0.0038.
  EXPECT_LE(pk.scale_now_rms, 0.0070);
  EXPECT_LE(pk.scale_smoothed_rms, 0.0050);
  EXPECT_LE(pk.bias_abs[kLag2s], 0.0020);
  // ... and the old model fails each of those bounds.
  EXPECT_GT(p1.scale_now_rms, 0.0070);
  EXPECT_GT(p1.scale_smoothed_rms, 0.0050);
  EXPECT_GT(p1.bias_abs[kLag2s], 0.0020);
  // Close to what the information allows: within 1.5x of the oracle filter (measured 1.2x).
  EXPECT_LE(pk.scale_now_rms, 1.5 * pk.oracle_rms);
  // Relative roll/pitch: the VO's white rotation noise is all there is to know (GPS does not see
  // attitude), the graph must keep it, not add to it (measured ratio 1.00-1.04).
  EXPECT_LE(pk.tilt_now_over_vo, 1.1);
  EXPECT_LE(pk.tilt_smoothed_over_vo, 1.1);
}

TEST(PoseGraphDrift, KnotsAndScaleAt) {
  Flight f = drift_flight(4, test_params());
  f.duration_s = 60.0;
  PoseGraph g(f.params);
  const FlightResult r = fly(f, g);
  ASSERT_TRUE(g.initialised());
  // 600 frames at 10 Hz: a knot per scale_knot_s (the first step lies half a frame after the first knot).
  const double expected = f.duration_s / f.params.scale_knot_s;
  EXPECT_NEAR(static_cast<double>(g.stats().scale_knots), expected, 1.0);
  EXPECT_GE(g.stats().last_free_knots, 2U);
  EXPECT_DOUBLE_EQ(g.scale_at(g.last()), g.scale(0));
  EXPECT_EQ(g.scale_at(kNoNode), 0.0);
  EXPECT_EQ(g.scale_at(static_cast<NodeId>(g.size())), 0.0);
  // The scale varies along the segment, as the truth does, and follows it.
  double lo = 1e9, hi = 0, se = 0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < r.nodes.size(); ++i) {
    if (r.nodes[i].t_s < 20.0 || r.nodes[i].t_s > f.duration_s - 10.0) continue;
    const double s = g.scale_at(static_cast<NodeId>(i));
    lo = std::min(lo, s);
    hi = std::max(hi, s);
    se += std::pow(s * r.nodes[i].vo_scale - 1.0, 2);
    ++n;
  }
  ASSERT_GT(n, 200U);
  std::printf("scale over 20-50 s: %.5f-%.5f m per VO unit, error rms %.4f\n", lo, hi, std::sqrt(se / static_cast<double>(n)));
  EXPECT_GT(hi / lo, 1.001);  // exactly 1 with one scale per segment
  EXPECT_LE(std::sqrt(se / static_cast<double>(n)), 0.006);  // measured 0.0034
}

// Measurement tool, not a check: the figures of ScaleKnotsFollowADriftingVoScale over AG_PG_SEEDS seeds
// (default 8) with parameters from AG_PG_KNOT_S, AG_PG_DRIFT, AG_PG_BETWEEN_M, AG_PG_BETWEEN_RAD,
// AG_PG_GRAVITY_RAD, AG_PG_WINDOW, AG_PG_EVERY (AG_PG_ORACLE_VEL > 0: also the oracle filter given GPS
// velocity of that sigma, m/s). Run with
//   --gtest_also_run_disabled_tests --gtest_filter='*DISABLED_Measure*'
TEST(PoseGraphDrift, DISABLED_Measure) {
  PoseGraphParams p = test_params();
  p.scale_knot_s = env_or("AG_PG_KNOT_S", p.scale_knot_s);
  p.scale_drift_per_sqrt_s = env_or("AG_PG_DRIFT", p.scale_drift_per_sqrt_s);
  p.between_sigma_m = env_or("AG_PG_BETWEEN_M", p.between_sigma_m);
  p.between_sigma_rad = env_or("AG_PG_BETWEEN_RAD", p.between_sigma_rad);
  p.gravity_sigma_rad = env_or("AG_PG_GRAVITY_RAD", p.gravity_sigma_rad);
  p.window_frames = static_cast<int>(env_or("AG_PG_WINDOW", p.window_frames));
  p.solve_every_frames = static_cast<int>(env_or("AG_PG_EVERY", p.solve_every_frames));
  const auto seeds = static_cast<std::uint64_t>(env_or("AG_PG_SEEDS", 8));
  Pooled all;
  double sum_now = 0, sum_sm = 0, sum_final = 0, sum_oracle = 0, sum_bias[kNumLags] = {}, sum_rms[kNumLags] = {};
  for (std::uint64_t seed = 1; seed <= seeds; ++seed) {
    const Pooled q = pooled_drift_figures(p, {seed}, true);
    sum_now += q.scale_now_rms * q.scale_now_rms;
    sum_sm += q.scale_smoothed_rms * q.scale_smoothed_rms;
    sum_final += q.final_abs_mean;
    sum_oracle += q.oracle_rms * q.oracle_rms;
    for (std::size_t k = 0; k < kNumLags; ++k) {
      sum_bias[k] += q.bias_abs[k];
      sum_rms[k] += q.dist_rms[k] * q.dist_rms[k];
    }
    for (std::size_t k = 0; k < kNumLags; ++k)
      for (int m = 0; m < 3; ++m) {
        all.tilt[m][k] += q.tilt[m][k] * q.tilt[m][k];
        all.yaw[m][k] += q.yaw[m][k] * q.yaw[m][k];
      }
    all.tilt_now_over_vo = std::max(all.tilt_now_over_vo, q.tilt_now_over_vo);
    all.tilt_smoothed_over_vo = std::max(all.tilt_smoothed_over_vo, q.tilt_smoothed_over_vo);
  }
  const auto n = static_cast<double>(seeds);
  all.n = static_cast<int>(seeds);
  all.scale_now_rms = std::sqrt(sum_now / n);
  all.scale_smoothed_rms = std::sqrt(sum_sm / n);
  all.final_abs_mean = sum_final / n;
  all.oracle_rms = std::sqrt(sum_oracle / n);
  for (std::size_t k = 0; k < kNumLags; ++k) {
    all.bias_abs[k] = sum_bias[k] / n;
    all.dist_rms[k] = std::sqrt(sum_rms[k] / n);
    for (int m = 0; m < 3; ++m) {
      all.tilt[m][k] = std::sqrt(all.tilt[m][k] / n);
      all.yaw[m][k] = std::sqrt(all.yaw[m][k] / n);
    }
  }
  std::printf("knot %.2f s, drift %.4f, between %.3f m %.4f rad, gravity %.4f rad, window %d, solve every %d:\n", p.scale_knot_s,
              p.scale_drift_per_sqrt_s, p.between_sigma_m, p.between_sigma_rad, p.gravity_sigma_rad, p.window_frames, p.solve_every_frames);
  print("all", all);
}

class PoseGraphScale : public ::testing::TestWithParam<double> {};

TEST_P(PoseGraphScale, RecoversScaleYawAndPositions) {
  Flight f;
  f.vo_scale = GetParam();
  f.duration_s = 70.0;
  PoseGraph g(f.params);
  const FlightResult r = fly(f, g);
  ASSERT_TRUE(g.initialised());
  EXPECT_EQ(g.stats().segments, 1U);
  EXPECT_EQ(g.stats().frames_rejected, 0U);
  EXPECT_EQ(g.stats().scale_flips, 0U);
  EXPECT_GT(g.stats().gps_factors, 0U);
  const Errors e = errors(g, r, f.duration_s - 30.0, f.duration_s);
  print(GetParam() < 1 ? "scale 0.3" : "scale 3.0", e, g);
  std::printf("  scale error %.5f\n", scale_error(g, r, 0));
  EXPECT_LE(scale_error(g, r, 0), 0.01);
  EXPECT_GT(e.n, 250U);
  EXPECT_LE(e.rms_m, 0.3);
  EXPECT_LE(e.rms_yaw, 0.01);
  EXPECT_LE(e.max_tilt, 0.05);
  const Prediction pred = prediction_errors(r);
  std::printf("  prediction at add_frame: max error %.3f m over %zu frames, %.3f m from 10 s after initialisation\n", pred.max_m,
              pred.n, pred.max_settled_m);
  EXPECT_GT(pred.n_settled, 500U);
  EXPECT_LE(pred.max_m, 2.0);
  EXPECT_LE(pred.max_settled_m, 1.0);
}

INSTANTIATE_TEST_SUITE_P(ForcedVoScale, PoseGraphScale, ::testing::Values(0.3, 3.0));

TEST(PoseGraph, TrackingLossStartsASegmentThatGpsPlaces) {
  Flight f;
  f.duration_s = 80.0;
  f.vo_scale = 0.5;
  f.vo_scale_after_loss = 2.0;
  f.loss_at_s = 40.0;
  f.loss_length_s = 2.0;
  PoseGraph g(f.params);
  const FlightResult r = fly(f, g);
  EXPECT_EQ(g.stats().segments, 2U);
  EXPECT_TRUE(g.segment_initialised(0));
  EXPECT_TRUE(g.segment_initialised(1));
  EXPECT_TRUE(g.initialised());
  std::printf("scale errors: segment 0 %.5f, segment 1 %.5f\n", scale_error(g, r, 0), scale_error(g, r, 1));
  EXPECT_LE(scale_error(g, r, 1), 0.01);
  const Errors e1 = errors(g, r, f.loss_at_s + f.loss_length_s + 5.0, f.duration_s, 1);
  print("segment 1", e1, g);
  EXPECT_GT(e1.n, 250U);
  EXPECT_LE(e1.rms_m, 0.3);
  EXPECT_LE(e1.rms_yaw, 0.01);
}

TEST(PoseGraph, RandomTrackingLossesOfTheVoModel) {
  Flight f;
  f.duration_s = 90.0;
  f.seed = 3;
  f.vo_loss_rate_per_s = 1.0 / 15.0;
  PoseGraph g(f.params);
  const FlightResult r = fly(f, g);
  std::printf("%llu segments\n", static_cast<unsigned long long>(g.stats().segments));
  EXPECT_GE(g.stats().segments, 4U);
  EXPECT_EQ(g.stats().segments, r.vo_scale.size());
  for (const auto& [seg, vo_scale] : r.vo_scale) {
    double t0 = 1e9, t1 = -1;
    for (const NodeTruth& nt : r.nodes) {
      if (nt.segment != seg) continue;
      t0 = std::min(t0, nt.t_s);
      t1 = std::max(t1, nt.t_s);
    }
    const Errors e = errors(g, r, t0 + 2.0, t1, static_cast<int>(seg));
    std::printf("segment %u: %.1f-%.1f s, VO scale %.3f, initialised %d, scale error %.4f, position rms %.3f max %.3f m, yaw rms %.4f\n", seg,
                t0, t1, vo_scale, g.segment_initialised(seg) ? 1 : 0, scale_error(g, r, seg), e.rms_m, e.max_m, e.rms_yaw);
    if (t1 - t0 < 5.0) continue;  // too short to judge
    EXPECT_TRUE(g.segment_initialised(seg)) << seg;
    EXPECT_LE(scale_error(g, r, seg), 0.02) << seg;
    EXPECT_LE(e.rms_m, 0.4) << seg;
    EXPECT_LE(e.max_m, 1.0) << seg;
  }
}

TEST(PoseGraph, GpsOutlierBeforeInitialisationIsTrimmed) {
  for (const double at : {0.0, 0.4}) {
    Flight f;
    f.duration_s = 30.0;
    f.vo_scale = 0.6;
    f.outlier_at_s = at;
    PoseGraph g(f.params);
    const FlightResult r = fly(f, g);
    ASSERT_EQ(r.outliers_injected, 1);
    EXPECT_TRUE(g.initialised());
    EXPECT_GE(g.stats().gps_rejected_gate, 1U) << at;
    const Errors e = errors(g, r, 0.0, f.duration_s);
    print("outlier before initialisation", e, g);
    EXPECT_LE(e.max_m, 1.0) << at;
    EXPECT_LE(scale_error(g, r, 0), 0.01) << at;
  }
}

TEST(PoseGraph, GpsOutlierIsGatedAndDoesNotMoveTheMap) {
  Flight f;
  f.duration_s = 60.0;
  f.vo_scale = 1.7;
  f.outlier_at_s = 35.0;
  PoseGraph g(f.params);
  const FlightResult r = fly(f, g);
  ASSERT_EQ(r.outliers_injected, 1);
  EXPECT_GE(g.stats().gps_rejected_gate, 1U);
  const Errors e = errors(g, r, 25.0, f.duration_s);
  print("outlier", e, g);
  EXPECT_LE(e.max_m, 0.5);
}

TEST(PoseGraph, RefusesOutOfOrderInputAndStaysUninitialisedWithoutGps) {
  PoseGraph g;
  const Pose3 p{1, 2, 3, 0, 0, 0.5};
  EXPECT_EQ(g.last(), kNoNode);
  EXPECT_EQ(g.add_frame(ag::kNsPerS, 0, p), 0);
  EXPECT_EQ(g.add_frame(ag::kNsPerS, 0, p), kNoNode);      // same stamp
  EXPECT_EQ(g.add_frame(ag::kNsPerS / 2, 0, p), kNoNode);  // earlier
  EXPECT_EQ(g.stats().frames_rejected, 2U);
  EXPECT_EQ(g.stats().frames, 1U);
  EXPECT_TRUE(g.add_gps(ag::kNsPerS, Eigen::Vector3d(5, 5, 40), 0.5));
  EXPECT_FALSE(g.add_gps(ag::kNsPerS, Eigen::Vector3d(5, 5, 40), 0.5));
  EXPECT_FALSE(g.add_gps(ag::kNsPerS - 1, Eigen::Vector3d(5, 5, 40), 0.5));
  EXPECT_EQ(g.stats().gps_rejected_order, 2U);
  EXPECT_EQ(g.stats().gps_fixes, 3U);

  // A whole flight with no GPS: nothing crashes, poses stay finite, never initialised.
  Flight f;
  f.duration_s = 20.0;
  f.gps = false;
  f.vo_scale = 0.8;
  PoseGraph h(f.params);
  const FlightResult r = fly(f, h);
  EXPECT_FALSE(h.initialised());
  EXPECT_FALSE(h.segment_initialised(0));
  EXPECT_EQ(h.size(), r.nodes.size());
  EXPECT_GT(h.size(), 150U);
  for (std::size_t i = 0; i < h.size(); ++i) ASSERT_TRUE(h.pose(static_cast<NodeId>(i)).matrix().allFinite());
  EXPECT_TRUE(h.pose(12345678).isApprox(Eigen::Isometry3d::Identity()));
}

TEST(PoseGraph, WindowBoundsTheSolve) {
  Flight f;
  f.duration_s = 300.5;  // 3000 frames at 10 Hz
  f.vo_scale = 1.3;
  f.params.window_frames = 300;
  PoseGraph g(f.params);
  const FlightResult r = fly(f, g);
  EXPECT_GE(g.size(), 3000U);
  EXPECT_TRUE(g.initialised());
  EXPECT_GT(g.stats().solves, 90U);
  EXPECT_GT(g.stats().last_solve_ms, 0.0);
  EXPECT_EQ(g.stats().last_free_nodes, 300U);
  EXPECT_GE(g.stats().last_iterations, 1U);
  const Errors e = errors(g, r, f.duration_s - 30.0, f.duration_s);
  print("window 300", e, g);
  EXPECT_LE(e.rms_m, 0.3);
  EXPECT_LE(scale_error(g, r, 0), 0.01);
}

}  // namespace
