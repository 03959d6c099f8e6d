// base_run_log: records a simulated 12 s drive of the base as a candump log plus the wheel odometry the
// driver published, the pair test_base_replay checks a replay against.
//   base_run_log --out DIR      writes DIR/base-run.log and DIR/base-run.odom.csv
#include <cstdio>
#include <cstring>
#include <string>

#include "airground/drivers/can/candump_log.hpp"
#include "base_rig.hpp"

int main(int argc, char** argv) {
  std::string out = ".";
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--help") == 0 || std::strcmp(argv[i], "-h") == 0) {
      std::printf("usage: base_run_log [--out DIR]\n  records a simulated 12 s drive of the base (two ODrive controllers over CAN)\n"
                  "  as DIR/base-run.log (candump -l format) and DIR/base-run.odom.csv (the driver's wheel odometry)\n");
      return 0;
    }
    if (std::strcmp(argv[i], "--out") == 0 && i + 1 < argc) out = argv[++i];
    else {
      std::fprintf(stderr, "base_run_log: unknown argument '%s' (try --help)\n", argv[i]);
      return 2;
    }
  }
  using namespace ag;
  SimClock clock(1'764'633'600LL * kNsPerS);
  can::InProcessCanLink link(clock);
  auto w = can::CandumpWriter::create(out + "/base-run.log");
  if (!w) {
    std::fprintf(stderr, "base_run_log: %s\n", w.error().message.c_str());
    return 1;
  }
  can::RecordingCanBus rec(link.robot(), *w.value(), clock);
  base::BaseParams bp;
  base::DiffDriveBase drv(bp, rec);
  base::OdriveSimParams sp;
  sp.encoder_period_s = 0.02;
  base::OdriveSimulator sim(link.device(), {bp.left_node, bp.right_node}, sp);
  std::FILE* csv = std::fopen((out + "/base-run.odom.csv").c_str(), "w");
  if (csv == nullptr) {
    std::fprintf(stderr, "base_run_log: cannot create %s/base-run.odom.csv\n", out.c_str());
    return 1;
  }
  std::fprintf(csv, "stamp_ns,x_m,y_m,yaw_rad,v_mps,w_radps\n");
  const TimeNs t0 = clock.now();
  drv.arm(t0);
  std::size_t samples = 0;
  for (TimeNs t = t0 + base::test::kTick; t <= t0 + 12 * kNsPerS; t += base::test::kTick) {
    clock.set(t);
    sim.step(t);
    double l = 0, r = 0;
    base::test::scripted_wheels(to_seconds(t - t0), l, r);
    drv.command(l, r, t);
    drv.step(t);
    WheelOdometryMsg m;
    while (drv.take_odometry(m)) {
      std::fprintf(csv, "%lld,%.17g,%.17g,%.17g,%.17g,%.17g\n", static_cast<long long>(m.stamp), m.pose.x, m.pose.y, m.pose.yaw, m.v_mps, m.w_radps);
      ++samples;
    }
  }
  std::fclose(csv);
  w.value()->flush();
  std::printf("base_run_log: %zu frames in %s/base-run.log, %zu odometry samples in %s/base-run.odom.csv; final pose (%.3f, %.3f, %.3f rad)\n",
              w.value()->lines(), out.c_str(), samples, out.c_str(), drv.odometry().pose.x, drv.odometry().pose.y, drv.odometry().pose.yaw);
  return 0;
}
