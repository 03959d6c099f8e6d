// bench_pose_graph: one-thread CPU time of an ASOOM pose-graph solve after 500 keyframes' worth of flight
// (keyframes every 2 m at 5 m/s = 0.4 s, camera frames at 10 Hz: ~2000 frames, 200 s of a lawnmower
// survey at 40 m), with the default parameters (window of 600 free frames, a solve every 30 frames).
// Reference in the same process: the same stream solved as one full batch (window_frames = 0).
// The stream comes from the simulator's quadrotor, visual odometry (random scale and yaw per segment,
// drifting) and GPS (5 Hz, 0.5 m, dropouts), recorded once and replayed into each graph.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include "airground/aerial_mapping/pose_graph.hpp"
#include "airground/core/pose_math.hpp"
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
};

Run replay(const std::vector<Event>& ev, const ag::mapping::PoseGraphParams& p) {
  ag::mapping::PoseGraph g(p);
  Run r;
  std::vector<ag::Pose3> truth;
  for (const Event& e : ev) {
    if (e.frame) {
      if (g.add_frame(e.stamp, e.segment, e.pose) != ag::mapping::kNoNode) truth.push_back(e.truth);
      if (g.update()) r.solve_ms.push_back(g.stats().last_solve_ms);
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
  g.update(true);
  double se = 0;
  for (std::size_t i = 0; i < truth.size(); ++i) {
    const Eigen::Vector3d d = g.pose(static_cast<ag::mapping::NodeId>(i)).translation() - Eigen::Vector3d(truth[i].x, truth[i].y, truth[i].z);
    se += d.squaredNorm();
  }
  r.rms_m = truth.empty() ? 0.0 : std::sqrt(se / static_cast<double>(truth.size()));
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

  char buf[512];
  std::snprintf(buf, sizeof buf,
                "{\"bench\":\"pose_graph\",\"frames\":%zu,\"window\":%d,\"solve_ms\":%.3f,\"solve_max_ms\":%.3f,\"batch_solve_ms\":%.3f,"
                "\"batch_ratio\":%.2f,\"rms_m\":%.4f,\"batch_rms_m\":%.4f}",
                w.frames, def.window_frames, w.median_tail_ms, w.max_tail_ms, b.median_tail_ms, ratio, w.rms_m, b.rms_m);
  const std::string written = ag::bench::append_result_line(buf);
  if (!written.empty()) std::printf("results appended to %s\n", written.c_str());
  return 0;
}
