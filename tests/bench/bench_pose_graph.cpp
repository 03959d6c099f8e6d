// bench_pose_graph: one-thread CPU time of an ASOOM pose-graph solve after 500 keyframes' worth of flight
// (keyframes every 2 m at 5 m/s = 0.4 s, camera frames at 10 Hz: ~2000 frames, 200 s of a lawnmower
// survey at 40 m), with the default parameters (window of 600 free frames, a solve every 30 frames).
// Reference in the same process: the same stream solved as one full batch (window_frames = 0).
// The stream comes from the simulator's quadrotor, visual odometry (random scale and yaw per segment,
// drifting) and GPS (5 Hz, 0.5 m, dropouts), recorded once and replayed into each graph.
// Accuracy figures of the windowed graph, and of the same graph with one scale per segment (ASOOM,
// scale_knot_s = 0) for comparison: the current scale error after every frame's update (rms from 30 s
// on, and at the end), and the relative distance between the newest node and the node 0.4 s / 2 s
// before it right after that update (what a stereo pair of keyframes 2 m / 10 m apart gets): bias and rms.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include "airground/aerial_mapping/pose_graph.hpp"
#include "airground/messages/pose_math.hpp"
#include "airground/sim/gps.hpp"
#include "airground/sim/quadrotor.hpp"
#include "airground/sim/survey.hpp"
#include "airground/sim/visual_odometry.hpp"
#include "airground/sim/world.hpp"
#include "bench_common.hpp"

namespace {

struct Event {
  bool frame{false};
  ag::TimeNs stamp{0};
  std::uint32_t segment{0};
  ag::Pose3 pose;       // frame: odometry pose; GPS: unused
  Eigen::Vector3d enu;  // GPS
  double sigma{0};
  ag::Pose3 truth;      // frame: true body pose
  double vo_scale{1};   // frame: the VO's true scale [VO units per metre]
};

std::vector<Event> record_flight(double duration_s) {
  auto route = ag::sim::survey_lawnmower(-150.0, -100.0, 150.0, 100.0, 40.0, 0.3, 1.2);
  if (!route) return {};
  ag::sim::Quadrotor quad(ag::sim::QuadrotorConfig{}, ag::Pose3{route.value()[0].x, route.value()[0].y, 40.0, 0, 0, 0});
  quad.set_waypoints(route.value());
  ag::sim::VoConfig vc;
  vc.tracking_loss_rate_per_s = 0.0;  // one segment: the solve being timed covers all 2000 frames' history
  ag::sim::VisualOdometrySimulator vo(vc, 11);
  ag::sim::GpsSimulator gps(ag::sim::GpsConfig{}, ag::sim::Datum{}, 12);
  std::vector<Event> ev;
  const ag::TimeNs dt = ag::period_from_hz(50.0);
  const auto steps = static_cast<std::int64_t>(duration_s * 50.0);
  for (std::int64_t k = 0; k <= steps; ++k) {
    if (k > 0) quad.step(0.02);
    const ag::TimeNs t = k * dt;
    ag::sim::VoSample vs;
    if (vo.sample(t, quad.pose(), vs) && vs.tracking) {
      Event e;
      e.frame = true;
      e.stamp = vs.stamp;
      e.segment = vs.segment;
      e.pose = vs.pose;
      e.truth = quad.pose();
      e.vo_scale = vo.scale();
      ev.push_back(e);
    }
    ag::sim::GpsFix fix;
    if (gps.sample(t, quad.pose(), fix) && fix.fix_type != ag::sim::GpsFixType::kNoFix) {
      Event e;
      e.stamp = fix.stamp;
      e.enu = Eigen::Vector3d(fix.east_m, fix.north_m, fix.up_m);
      e.sigma = fix.h_accuracy_m;
      ev.push_back(e);
    }
  }
  return ev;
}

struct Run {
  std::vector<double> solve_ms;  // every regular solve, in order
  double median_tail_ms{0};      // median of the last 10 regular solves (at ~1700-2000 frames)
  double max_tail_ms{0};
  double total_ms{0};            // sum over the run
  double rms_m{0};               // position error of all nodes after a final solve
  std::size_t frames{0};
  std::uint64_t solves{0};
  bool initialised{false};
  double scale_rms{0};           // current scale error after each update, from 30 s on
  double scale_final{0};         // ... after the last frame
  double base_bias[2]{}, base_rms[2]{};  // newest node vs 4 / 20 frames before: distance ratio - 1
};

constexpr std::size_t kBaseLags[2] = {4, 20};

Run replay(const std::vector<Event>& ev, const ag::mapping::PoseGraphParams& p) {
  ag::mapping::PoseGraph g(p);
  Run r;
  std::vector<ag::Pose3> truth;
  double se = 0;
  std::size_t ns = 0, nb[2] = {0, 0};
  const ag::TimeNs t_first = ev.empty() ? 0 : ev.front().stamp;
  for (const Event& e : ev) {
    if (e.frame) {
      const ag::mapping::NodeId id = g.add_frame(e.stamp, e.segment, e.pose);
      if (id != ag::mapping::kNoNode) truth.push_back(e.truth);
      if (g.update()) r.solve_ms.push_back(g.stats().last_solve_ms);
      if (id == ag::mapping::kNoNode || !g.initialised() || ag::to_seconds(e.stamp - t_first) < 30.0) continue;
      r.scale_final = g.scale(e.segment) * e.vo_scale - 1.0;
      se += r.scale_final * r.scale_final;
      ++ns;
      const auto j = static_cast<std::size_t>(id);
      for (std::size_t k = 0; k < 2; ++k) {
        if (j < kBaseLags[k]) continue;
        const auto i = static_cast<ag::mapping::NodeId>(j - kBaseLags[k]);
        if (g.segment_of(i) != e.segment) continue;
        const ag::Pose3& ti = truth[j - kBaseLags[k]];
        const double true_d = std::hypot(e.truth.x - ti.x, e.truth.y - ti.y, e.truth.z - ti.z);
        if (true_d < 1.0) continue;  // hover, turns
        const double d = (g.pose(id).translation() - g.pose(i).translation()).norm() / true_d - 1.0;
        r.base_bias[k] += d;
        r.base_rms[k] += d * d;
        ++nb[k];
      }
    } else {
      g.add_gps(e.stamp, e.enu, e.sigma);
    }
  }
  const std::size_t n = std::min<std::size_t>(10, r.solve_ms.size());
  std::vector<double> tail(r.solve_ms.end() - static_cast<std::ptrdiff_t>(n), r.solve_ms.end());
  std::sort(tail.begin(), tail.end());
  if (!tail.empty()) {
    r.median_tail_ms = tail[tail.size() / 2];
    r.max_tail_ms = tail.back();
  }
  for (const double ms : r.solve_ms) r.total_ms += ms;
  if (ns > 0) r.scale_rms = std::sqrt(se / static_cast<double>(ns));
  for (std::size_t k = 0; k < 2; ++k) {
    if (nb[k] == 0) continue;
    r.base_bias[k] /= static_cast<double>(nb[k]);
    r.base_rms[k] = std::sqrt(r.base_rms[k] / static_cast<double>(nb[k]));
  }
  g.update(true);
  double sp = 0;
  for (std::size_t i = 0; i < truth.size(); ++i) {
    const Eigen::Vector3d d = g.pose(static_cast<ag::mapping::NodeId>(i)).translation() - Eigen::Vector3d(truth[i].x, truth[i].y, truth[i].z);
    sp += d.squaredNorm();
  }
  r.rms_m = truth.empty() ? 0.0 : std::sqrt(sp / static_cast<double>(truth.size()));
  r.frames = g.size();
  r.solves = g.stats().solves;
  r.initialised = g.initialised();
  return r;
}

}  // namespace

int main() {
  const auto cpus = ag::bench::allowed_cpus();
  const bool pinned = !cpus.empty() && ag::bench::pin_this_thread(cpus.back());
  std::printf("bench_pose_graph: one thread%s\n", pinned ? (" (pinned to CPU " + std::to_string(cpus.back()) + ")").c_str() : "");

  const std::vector<Event> ev = record_flight(200.0);  // 500 keyframes at 0.4 s
  const ag::mapping::PoseGraphParams def;
  const Run w = replay(ev, def);
  ag::mapping::PoseGraphParams batch = def;
  batch.window_frames = 0;
  const Run b = replay(ev, batch);
  ag::mapping::PoseGraphParams one = def;
  one.scale_knot_s = 0.0;
  const Run o = replay(ev, one);
  if (w.solve_ms.empty() || b.solve_ms.empty()) {
    std::fprintf(stderr, "no solve ran\n");
    return 1;
  }
  std::printf("flight: 200 s survey, %zu frames (10 Hz), solve every %d frames, %d LM iterations max\n", w.frames,
              def.solve_every_frames, def.max_iterations);
  std::printf("window %4d frames: solve at ~2000 frames %7.1f ms (median of last 10, max %.1f); %llu solves, %8.0f ms in all; rms %.3f m%s\n",
              def.window_frames, w.median_tail_ms, w.max_tail_ms, static_cast<unsigned long long>(w.solves), w.total_ms, w.rms_m,
              w.initialised ? "" : " (NOT initialised)");
  std::printf("full batch       : solve at ~2000 frames %7.1f ms (median of last 10, max %.1f); %llu solves, %8.0f ms in all; rms %.3f m%s\n",
              b.median_tail_ms, b.max_tail_ms, static_cast<unsigned long long>(b.solves), b.total_ms, b.rms_m,
              b.initialised ? "" : " (NOT initialised)");
  const double ratio = w.median_tail_ms > 0 ? b.median_tail_ms / w.median_tail_ms : 0.0;
  std::printf("full batch / window: x%.1f; goal <= 200 ms per solve: %s\n", ratio, w.max_tail_ms <= 200.0 ? "met" : "MISSED");
  const auto accuracy = [](const char* what, const Run& r) {
    std::printf("%s: current scale error rms %.4f, at the end %+.4f; baselines 0.4 s: bias %+.4f rms %.4f, 2 s: bias %+.4f rms %.4f\n", what,
                r.scale_rms, r.scale_final, r.base_bias[0], r.base_rms[0], r.base_bias[1], r.base_rms[1]);
  };
  std::printf("scale knots every %.1f s (random walk %.4f/sqrt(s)); figures from 30 s on, right after each frame's update:\n", def.scale_knot_s,
              def.scale_drift_per_sqrt_s);
  accuracy("scale knots          ", w);
  accuracy("one scale per segment", o);
  std::printf("one scale per segment: solve at ~2000 frames %.1f ms (median of last 10)\n", o.median_tail_ms);

  char buf[768];
  std::snprintf(buf, sizeof buf,
                "{\"bench\":\"pose_graph\",\"frames\":%zu,\"window\":%d,\"solve_ms\":%.3f,\"solve_max_ms\":%.3f,\"batch_solve_ms\":%.3f,"
                "\"batch_ratio\":%.2f,\"rms_m\":%.4f,\"batch_rms_m\":%.4f,\"scale_knot_s\":%.2f,\"scale_err_rms\":%.5f,"
                "\"scale_err_final\":%.5f,\"base2s_bias\":%.5f,\"base2s_rms\":%.5f,\"one_scale_err_rms\":%.5f,\"one_scale_base2s_bias\":%.5f}",
                w.frames, def.window_frames, w.median_tail_ms, w.max_tail_ms, b.median_tail_ms, ratio, w.rms_m, b.rms_m, def.scale_knot_s,
                w.scale_rms, w.scale_final, w.base_bias[1], w.base_rms[1], o.scale_rms, o.base_bias[1]);
  const std::string written = ag::bench::append_result_line(buf);
  if (!written.empty()) std::printf("results appended to %s\n", written.c_str());
  return 0;
}
