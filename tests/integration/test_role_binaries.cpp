// The role binaries as an operator and systemd see them: options, config errors, sd_notify, signals.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "process.hpp"

namespace ag::test {
namespace {

std::string role_bin(const std::string& role) { return binary_dir() + "/firmware_host/airground-" + role; }

std::string write_temp(const std::string& name, const std::string& text) {
  const std::string path = ::testing::TempDir() + name;
  std::ofstream(path) << text;
  return path;
}

class RoleBinary : public ::testing::TestWithParam<std::string> {};

TEST_P(RoleBinary, HelpAndVersionExitZero) {
  const auto help = run({role_bin(GetParam()), "--help"});
  EXPECT_EQ(help.exit_code, 0);
  EXPECT_NE(help.out.find("--config FILE"), std::string::npos);
  EXPECT_NE(help.out.find("status"), std::string::npos) << "the stage table is listed";
  const auto ver = run({role_bin(GetParam()), "--version"});
  EXPECT_EQ(ver.exit_code, 0);
  EXPECT_NE(ver.out.find("airground-" + GetParam()), std::string::npos);
}

TEST_P(RoleBinary, ShippedDefaultConfigIsValid) {
  const std::string cfg = source_dir() + "/firmware_host/" + GetParam() + "/" + GetParam() + ".yaml";
  const auto r = run({role_bin(GetParam()), "--config", cfg, "--check-config"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
}

TEST_P(RoleBinary, PrintedConfigLoadsBackWithOverrides) {
  const auto printed = run({role_bin(GetParam()), "--print-config", "--set", "status.log_every=7", "--set", "robot.id=3"});
  ASSERT_EQ(printed.exit_code, 0) << printed.err;
  EXPECT_NE(printed.out.find("# [1, 3600] reports"), std::string::npos) << "units and ranges are printed";
  const std::string path = write_temp("printed-" + GetParam() + ".yaml", printed.out);
  const auto again = run({role_bin(GetParam()), "--config", path, "--print-config"});
  ASSERT_EQ(again.exit_code, 0) << again.err;
  EXPECT_NE(again.out.find("log_every: 7 "), std::string::npos);
  EXPECT_NE(again.out.find("id: 3 "), std::string::npos);
}

INSTANTIATE_TEST_SUITE_P(AllRoles, RoleBinary, ::testing::Values("uav", "ugv", "base"));

struct BadConfig {
  const char* name;
  const char* yaml;
  std::vector<const char*> must_mention;
};

class BadConfigExits2 : public ::testing::TestWithParam<BadConfig> {};

TEST_P(BadConfigExits2, WithMessageNamingFileKeyAndRange) {
  const BadConfig& c = GetParam();
  const std::string path = write_temp(std::string("bad-") + c.name + ".yaml", c.yaml);
  const auto r = run({role_bin("ugv"), "--config", path});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find(path), std::string::npos) << "names the file: " << r.err;
  for (const char* m : c.must_mention) EXPECT_NE(r.err.find(m), std::string::npos) << "mentions '" << m << "': " << r.err;
  EXPECT_EQ(r.err.find("starting"), std::string::npos) << "nothing started";
}

INSTANTIATE_TEST_SUITE_P(
    Cases, BadConfigExits2,
    ::testing::Values(BadConfig{"unknown_key", "status:\n  log_evry: 3\n", {"unknown key", "status.log_evry", "log_every"}},
                      BadConfig{"unknown_section", "sttus:\n  log_every: 3\n", {"unknown section", "sttus", "status"}},
                      BadConfig{"wrong_type", "scheduler:\n  realtime: sometimes\n", {"scheduler.realtime", "true|false", "sometimes"}},
                      BadConfig{"not_integer", "robot:\n  id: 1.5\n", {"robot.id", "integer", "[0, 254]"}},
                      BadConfig{"out_of_range", "scheduler:\n  watchdog_silence_s: 900\n", {"scheduler.watchdog_silence_s", "out of range", "[0.1, 60] s"}},
                      BadConfig{"bad_choice", "log:\n  level: loud\n", {"log.level", "debug|info|warn|error"}},
                      BadConfig{"malformed", "status:\n  log_every: [3\n", {"malformed YAML", ":3:"}},
                      BadConfig{"list_value", "status:\n  log_every: [3, 4]\n", {"status.log_every", "single value"}}),
    [](const auto& test_case) { return std::string(test_case.param.name); });

// Classes the robot's sensors cannot give stop it at start, naming the file and the keys (issue 27).
TEST(RoleBinaryErrors, LabelsTheSensorsCannotGiveExit2NamingTheKeys) {
  const auto uav = run({role_bin("uav"), "--config", source_dir() + "/firmware_host/uav/uav.yaml", "--set", "segmentation.labels=gt"});
  EXPECT_EQ(uav.exit_code, 2) << uav.err;
  EXPECT_NE(uav.err.find("uav.yaml"), std::string::npos) << uav.err;
  EXPECT_NE(uav.err.find("segmentation.labels: gt"), std::string::npos) << uav.err;
  EXPECT_NE(uav.err.find("camera.source: v4l2"), std::string::npos) << uav.err;
  const auto mapper = run({role_bin("uav"), "--config", source_dir() + "/firmware_host/uav/uav.yaml", "--set", "ortho_map.keyframes_channel=keyframes",
                           "--check-config"});
  EXPECT_EQ(mapper.exit_code, 2) << mapper.err;
  EXPECT_NE(mapper.err.find("ortho_map.keyframes_channel: keyframes"), std::string::npos) << mapper.err;
  const auto ugv = run({role_bin("ugv"), "--config", source_dir() + "/firmware_host/ugv/ugv.yaml", "--set", "localization.labels=gt", "--check-config"});
  EXPECT_EQ(ugv.exit_code, 2) << ugv.err;
  EXPECT_NE(ugv.err.find("ugv.yaml"), std::string::npos) << ugv.err;
  EXPECT_NE(ugv.err.find("localization.labels: gt"), std::string::npos) << ugv.err;
  EXPECT_NE(ugv.err.find("lidar.classes: none"), std::string::npos) << ugv.err;
  // Point classes from the reflectivity byte: only the simulator's labels oracle writes them there, so a
  // configuration that reads them is refused unless the user names the ablation.
  const auto refl = run({role_bin("ugv"), "--config", source_dir() + "/firmware_host/ugv/ugv.yaml", "--set", "localization.labels=gt", "--set",
                         "lidar.classes=reflectivity", "--check-config"});
  EXPECT_EQ(refl.exit_code, 2) << refl.err;
  EXPECT_NE(refl.err.find("lidar.classes: reflectivity"), std::string::npos) << refl.err;
  EXPECT_NE(refl.err.find("--oracle labels"), std::string::npos) << "the error names the way to ask for the ablation: " << refl.err;
  const auto hil = run({role_bin("ugv"), "--config", source_dir() + "/firmware_host/ugv/ugv.yaml", "--set", "localization.labels=gt", "--set",
                        "lidar.classes=reflectivity", "--oracle", "labels", "--check-config"});
  EXPECT_EQ(hil.exit_code, 0) << hil.err;
  // ... named, it runs, and says at start-up that it is an ablation.
  EXPECT_NE(hil.err.find("warning: oracle labels: lidar.classes: reflectivity"), std::string::npos) << hil.err;
  const auto unknown = run({role_bin("ugv"), "--config", source_dir() + "/firmware_host/ugv/ugv.yaml", "--oracle=labels,vo", "--check-config"});
  EXPECT_EQ(unknown.exit_code, 2) << unknown.err;
  EXPECT_NE(unknown.err.find("unknown oracle 'vo'"), std::string::npos) << unknown.err;
  const auto shipped = run({role_bin("ugv"), "--config", source_dir() + "/firmware_host/ugv/ugv.yaml", "--check-config"});
  EXPECT_EQ(shipped.exit_code, 0) << shipped.err;
  EXPECT_EQ(shipped.err.find("warning"), std::string::npos) << "the shipped configuration warns of nothing: " << shipped.err;
}

// The localizer's obstacle prior models the planner's free space: a narrower level is said at start-up.
TEST(RoleBinaryErrors, ALocalizerRoomNarrowerThanThePlannersRoutesIsSaidAtStart) {
  const std::string cfg = source_dir() + "/firmware_host/ugv/ugv.yaml";
  const auto narrower = run({role_bin("ugv"), "--config", cfg, "--set", "planner.traversable=costly", "--check-config"});
  EXPECT_EQ(narrower.exit_code, 0) << narrower.err;
  EXPECT_NE(narrower.err.find("warning: localization.pf_obstacle_traversable: rough is narrower than planner.traversable: costly"),
            std::string::npos)
      << narrower.err;
  const auto equal = run({role_bin("ugv"), "--config", cfg, "--set", "planner.traversable=costly", "--set",
                          "localization.pf_obstacle_traversable=costly", "--check-config"});
  EXPECT_EQ(equal.err.find("warning"), std::string::npos) << equal.err;
  const auto no_prior = run({role_bin("ugv"), "--config", cfg, "--set", "planner.traversable=costly", "--set",
                             "localization.pf_obstacle_penalty_per_m=0", "--check-config"});
  EXPECT_EQ(no_prior.err.find("warning"), std::string::npos) << no_prior.err;
  // The planner's geofence beyond the localizer's area: the robot could be sent where it cannot localize.
  const auto wider = run({role_bin("ugv"), "--config", cfg, "--set", "localization.area_y0_m=-80", "--check-config"});
  EXPECT_EQ(wider.exit_code, 0) << wider.err;
  EXPECT_NE(wider.err.find("warning: the planner's area reaches beyond the localizer's (planner.area_y0_m -500.0 beyond localization.area_y0_m -80.0)"),
            std::string::npos)
      << wider.err;
  const auto within = run({role_bin("ugv"), "--config", cfg, "--set", "planner.area_y0_m=-80", "--check-config"});
  EXPECT_EQ(within.err.find("warning"), std::string::npos) << within.err;
}

TEST(RoleBinaryErrors, MissingConfigFileAndBadOptionsExit2) {
  const auto missing = run({role_bin("uav"), "--config", "/nonexistent/uav.yaml"});
  EXPECT_EQ(missing.exit_code, 2);
  EXPECT_NE(missing.err.find("/nonexistent/uav.yaml"), std::string::npos);
  EXPECT_EQ(run({role_bin("uav"), "--frobnicate"}).exit_code, 2);
  EXPECT_EQ(run({role_bin("uav"), "--set", "status.log_every=abc"}).exit_code, 2);
  EXPECT_EQ(run({role_bin("uav"), "--run-for", "-1"}).exit_code, 2);
}

// A datagram socket standing in for systemd's NOTIFY_SOCKET.
class NotifySocket {
 public:
  NotifySocket() {
    path_ = ::testing::TempDir() + "notify-" + std::to_string(getpid()) + "-" + std::to_string(counter_++);
    unlink(path_.c_str());
    fd_ = socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    sockaddr_un a{};
    a.sun_family = AF_UNIX;
    std::snprintf(a.sun_path, sizeof a.sun_path, "%s", path_.c_str());
    EXPECT_EQ(bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
    timeval tv{0, 100'000};
    setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  }
  ~NotifySocket() {
    close(fd_);
    unlink(path_.c_str());
  }
  const std::string& path() const { return path_; }
  // Collects messages until `until` appears or timeout.
  std::vector<std::string> collect(double timeout_s, const std::string& until) {
    std::vector<std::string> msgs;
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    char buf[512];
    while (std::chrono::steady_clock::now() < end) {
      const ssize_t n = recv(fd_, buf, sizeof buf, 0);
      if (n <= 0) continue;
      msgs.emplace_back(buf, static_cast<std::size_t>(n));
      if (msgs.back().find(until) != std::string::npos) break;
    }
    return msgs;
  }

 private:
  static inline int counter_ = 0;
  std::string path_;
  int fd_{-1};
};

int count_with(const std::vector<std::string>& msgs, const std::string& needle) {
  int n = 0;
  for (const auto& m : msgs) n += m.find(needle) != std::string::npos ? 1 : 0;
  return n;
}

TEST(RoleBinaryService, NotifiesReadyFeedsWatchdogAndStopsOnSigterm) {
  NotifySocket sock;
  // Built-in defaults label scans "gt", which an Ouster cannot give (refused at start): the field's labeller.
  Process p({role_bin("ugv"), "--set", "scheduler.realtime=false", "--set", "scheduler.lock_memory=false", "--set", "localization.labels=geometric"},
            {"NOTIFY_SOCKET=" + sock.path(), "WATCHDOG_USEC=200000"});
  auto msgs = sock.collect(10.0, "READY=1");
  ASSERT_EQ(count_with(msgs, "READY=1"), 1) << "READY=1 once the stages run";
  auto more = sock.collect(1.0, "never");
  EXPECT_GE(count_with(more, "WATCHDOG=1"), 3) << "fed at least every 100 ms for a 200 ms watchdog";
  p.send_signal(SIGTERM);
  const auto r = p.wait(5.0);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("stopped cleanly"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("final stage=status"), std::string::npos) << "counters printed at exit";
  auto last = sock.collect(0.5, "STOPPING=1");
  EXPECT_EQ(count_with(last, "STOPPING=1"), 1);
}

TEST(RoleBinaryService, SigintAlsoStopsCleanlyAndRunForEnds) {
  Process p({role_bin("base"), "--set", "scheduler.realtime=false"});
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  p.send_signal(SIGINT);
  const auto r = p.wait(5.0);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  const auto timed = run({role_bin("uav"), "--run-for", "1.2", "--set", "scheduler.realtime=false", "--set", "segmentation.labels=erfnet", "--set",
                          "segmentation.weights=" + source_dir() + "/config/erfnet/erfnet_c7.agw", "--set", "ortho_map.keyframes_channel=keyframes_labelled"},
                         10.0);
  EXPECT_EQ(timed.exit_code, 0) << timed.err;
  EXPECT_NE(timed.err.find("final stage=status runs=2"), std::string::npos) << "released at 0 s and 1 s: " << timed.err;
}

}  // namespace
}  // namespace ag::test
