// A recorded candump log of a drive (tests/data/can/base-run.log, made by base_run_log) replays through
// the base's odometry and reproduces the odometry the driver published during that run.
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "airground/drivers/base/base_stage.hpp"
#include "airground/drivers/base/diff_drive_base.hpp"
#include "airground/drivers/can/candump_log.hpp"

namespace ag::base {
namespace {

struct OdomRow {
  TimeNs stamp;
  double x, y, yaw, v, w;
};

std::vector<OdomRow> read_csv(const std::string& path) {
  std::vector<OdomRow> rows;
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);  // header
  while (std::getline(in, line)) {
    OdomRow r{};
    long long s = 0;
    if (std::sscanf(line.c_str(), "%lld,%lf,%lf,%lf,%lf,%lf", &s, &r.x, &r.y, &r.yaw, &r.v, &r.w) == 6) {
      r.stamp = s;
      rows.push_back(r);
    }
  }
  return rows;
}

TEST(BaseReplay, TheRecordedLogReproducesTheLoggedOdometry) {
  const std::string dir = std::string(AG_TEST_DATA_DIR) + "/can";
  auto log = can::read_candump_file(dir + "/base-run.log");
  ASSERT_TRUE(log.ok()) << log.error().message;
  ASSERT_EQ(log.value().bad_lines, 0U) << log.value().first_error;
  const std::vector<OdomRow> want = read_csv(dir + "/base-run.odom.csv");
  ASSERT_GT(want.size(), 400U);
  std::size_t commands = 0;
  for (const auto& r : log.value().records) commands += odrive::cmd_of(r.frame.id) == static_cast<std::uint8_t>(odrive::Cmd::kSetInputVel) ? 1U : 0U;
  EXPECT_GT(commands, 1000U) << "the log holds the driver's commands too";

  const TimeNs t0 = log.value().records.front().frame.stamp;
  SimClock clock(t0);
  can::CandumpReplayBus bus(log.value().records, clock, t0, &frame_from_controller);
  DiffDriveBase base(BaseParams{}, bus);
  std::vector<WheelOdometryMsg> got;
  for (TimeNs t = t0; t <= bus.log_end() + 10 * kNsPerMs; t += 10 * kNsPerMs) {
    clock.set(t);
    base.receive_only(t);
    WheelOdometryMsg m;
    while (base.take_odometry(m)) got.push_back(m);
  }
  ASSERT_EQ(got.size(), want.size());
  double worst = 0;
  for (std::size_t i = 0; i < got.size(); ++i) {
    ASSERT_EQ(got[i].stamp, want[i].stamp) << i;
    worst = std::max({worst, std::fabs(got[i].pose.x - want[i].x), std::fabs(got[i].pose.y - want[i].y),
                      std::fabs(got[i].pose.yaw - want[i].yaw), std::fabs(got[i].v_mps - want[i].v)});
  }
  EXPECT_LT(worst, 1e-9) << "replayed odometry differs from the logged run";
  EXPECT_GT(std::hypot(want.back().x, want.back().y), 2.5) << "the logged run went somewhere";
  EXPECT_EQ(base.counters().heartbeats, 2 * 120U) << "12 s of 10 Hz heartbeats from two controllers";
}

TEST(BaseReplay, ATruncatedLogIsCountedNotFatal) {
  std::ifstream in(std::string(AG_TEST_DATA_DIR) + "/can/base-run.log");
  std::ostringstream ss;
  ss << in.rdbuf();
  std::string text = ss.str();
  ASSERT_GT(text.size(), 1000U);
  text.resize(text.size() / 2 + 7);  // cut mid-line
  const can::CandumpLog log = can::parse_candump_text(text, "base-run.log");
  EXPECT_GT(log.records.size(), 100U);
  EXPECT_EQ(log.bad_lines, 1U) << "the cut line";
  EXPECT_NE(log.first_error.find("base-run.log:"), std::string::npos);
}

}  // namespace
}  // namespace ag::base
