// airground-ugv fed a recorded candump log instead of a live bus (base.can_backend=replay): the real
// binary, configured only by its parameters, reproduces the recorded run's wheel odometry and records
// its own CAN traffic as a candump log. Without a CAN interface or GPIO chip it keeps running with the
// wheels stopped and names what is missing; an unreadable replay log stops it at start-up.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "airground/drivers/base/base_stage.hpp"
#include "airground/drivers/can/candump_log.hpp"
#include "process.hpp"

namespace ag::test {
namespace {

std::string ugv_bin() { return binary_dir() + "/firmware_host/airground-ugv"; }
std::string data(const std::string& f) { return source_dir() + "/tests/data/can/" + f; }

struct Row {
  long long stamp{0};
  double x{0}, y{0}, yaw{0}, v{0}, w{0};
};
std::vector<Row> read_odometry_csv(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  std::vector<Row> rows;
  std::getline(in, line);  // header
  while (std::getline(in, line)) {
    Row r;
    if (std::sscanf(line.c_str(), "%lld,%lf,%lf,%lf,%lf,%lf", &r.stamp, &r.x, &r.y, &r.yaw, &r.v, &r.w) == 6) rows.push_back(r);
  }
  return rows;
}

const std::vector<std::string> kNoDevices = {"--set", "scheduler.realtime=false", "--set", "scheduler.lock_memory=false",
                                             "--set", "base.estop_backend=none",   "--set", "base.led_backend=none",
                                             "--set", "localization.labels=geometric"};  // built-in "gt" needs classes an Ouster lacks

TEST(UgvCanReplay, TheRecordedLogReproducesItsOdometryAndTheTrafficIsRecorded) {
  const std::string dir = ::testing::TempDir() + "ugv_can_replay/";
  std::remove((dir + "odom.csv").c_str());
  (void)std::system(("mkdir -p " + dir).c_str());
  auto log = can::read_candump_file(data("base-run.log"));
  ASSERT_TRUE(log.ok()) << log.error().message;
  const double log_s = 1e-9 * static_cast<double>(log.value().records.back().frame.stamp - log.value().records.front().frame.stamp);
  ASSERT_GT(log_s, 5.0);

  std::vector<std::string> argv{ugv_bin()};
  argv.insert(argv.end(), kNoDevices.begin(), kNoDevices.end());
  for (const std::string& s : {std::string("base.can_backend=replay"), "base.can_replay_path=" + data("base-run.log"), "base.odometry_log_path=" + dir + "odom.csv",
                               "base.can_record_path=" + dir + "rec.log"}) {
    argv.emplace_back("--set");
    argv.push_back(s);
  }
  argv.emplace_back("--run-for");
  argv.push_back(std::to_string(log_s + 1.5));
  const ProcessResult r = run(argv, log_s + 30.0);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("replay finished"), std::string::npos) << r.err;

  // The odometry: every sample of the recorded run, the same values, the same spacing in time.
  const std::vector<Row> want = read_odometry_csv(data("base-run.odom.csv"));
  const std::vector<Row> got = read_odometry_csv(dir + "odom.csv");
  ASSERT_GT(want.size(), 400U);
  ASSERT_EQ(got.size(), want.size());
  double worst = 0;
  for (std::size_t i = 0; i < got.size(); ++i) {
    ASSERT_EQ(got[i].stamp - got[0].stamp, want[i].stamp - want[0].stamp) << "sample " << i;
    worst = std::max({worst, std::fabs(got[i].x - want[i].x), std::fabs(got[i].y - want[i].y), std::fabs(got[i].yaw - want[i].yaw),
                      std::fabs(got[i].v - want[i].v), std::fabs(got[i].w - want[i].w)});
  }
  EXPECT_LT(worst, 1e-9);
  EXPECT_GT(std::hypot(got.back().x, got.back().y), 2.5) << "the run went somewhere";

  // The recording: a candump log (read by the same reader python-can agrees with) holding every
  // controller frame the log fed in, in order, with the same identifiers and bytes.
  auto rec = can::read_candump_file(dir + "rec.log");
  ASSERT_TRUE(rec.ok()) << rec.error().message;
  EXPECT_EQ(rec.value().bad_lines, 0U) << rec.value().first_error;
  std::vector<can::CanFrame> fed, recorded;
  for (const auto& x : log.value().records)
    if (!x.error && base::frame_from_controller(x.frame)) fed.push_back(x.frame);
  for (const auto& x : rec.value().records)
    if (base::frame_from_controller(x.frame)) recorded.push_back(x.frame);
  ASSERT_EQ(recorded.size(), fed.size());
  for (std::size_t i = 0; i < fed.size(); ++i) {
    ASSERT_EQ(recorded[i].id, fed[i].id) << i;
    ASSERT_EQ(recorded[i].dlc, fed[i].dlc) << i;
    ASSERT_EQ(recorded[i].data, fed[i].data) << i;
  }
}

TEST(UgvCanReplay, WithoutACanInterfaceTheRobotRunsWithTheWheelsStoppedAndSaysWhy) {
  std::vector<std::string> argv{ugv_bin(), "--set", "scheduler.realtime=false", "--set", "scheduler.lock_memory=false", "--set",
                                "base.can_interface=agnocan7", "--set", "base.estop_chip=/dev/agnochip", "--set", "localization.labels=geometric",
                                "--run-for", "1.5"};
  const ProcessResult r = run(argv, 20.0);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("base.can_interface"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("agnocan7"), std::string::npos) << "the missing interface is named: " << r.err;
  EXPECT_NE(r.err.find("e-stop reads as unreadable"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("final stage=localization"), std::string::npos) << "the rest of the robot ran";
}

TEST(UgvCanReplay, AMissingOrEmptyReplayLogStopsItAtStartUpNamingThePath) {
  const std::string empty = ::testing::TempDir() + "empty.candump";
  std::ofstream(empty) << "this is not a candump line\n";
  for (const std::string& path : {std::string("/nonexistent/run.log"), empty}) {
    std::vector<std::string> argv{ugv_bin()};
    argv.insert(argv.end(), kNoDevices.begin(), kNoDevices.end());
    for (const std::string& s : {std::string("base.can_backend=replay"), "base.can_replay_path=" + path}) {
      argv.emplace_back("--set");
      argv.push_back(s);
    }
    argv.emplace_back("--run-for");
    argv.emplace_back("5");
    const ProcessResult r = run(argv, 20.0);
    EXPECT_NE(r.exit_code, 0) << path;
    EXPECT_NE(r.err.find(path), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("base.can_replay_path"), std::string::npos) << r.err;
  }
}

}  // namespace
}  // namespace ag::test
