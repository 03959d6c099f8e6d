// The browser test: the real base role (comms over an in-process link to a played mission) serves its
// page; Debian's chromium, headless, driven by Playwright (tests/browser/check_base_page.mjs), loads it
// while the robots move and checks that the map, the robots, the regions and the goals are drawn —
// canvas pixels where a water tile and each robot's arrow are known to be. The screenshot is kept in
// <build>/tests/browser/artifacts/base_station_page.png.
#include <gtest/gtest.h>
#include <fcntl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "../unit/base_station/base_rig.hpp"

namespace ag::base_station::test {
namespace {

std::string env_or(const char* name, const std::string& fallback) {
  const char* v = std::getenv(name);
  return v != nullptr && *v != '\0' ? std::string(v) : fallback;
}
std::string find_in_path(const std::string& exe) {
  std::stringstream path(env_or("PATH", "/usr/bin:/bin"));
  std::string dir;
  while (std::getline(path, dir, ':'))
    if (::access((dir + "/" + exe).c_str(), X_OK) == 0) return dir + "/" + exe;
  return {};
}
std::string slurp(const std::string& p) {
  std::ifstream f(p);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

TEST(BaseStationBrowser, ChromiumDrawsTheMapRobotsRegionsAndGoalsOfALiveMission) {
  const std::string src = env_or("AG_SOURCE_DIR", AG_TEST_SOURCE_DIR);
  const std::string out_dir = env_or("AG_BINARY_DIR", AG_TEST_BINARY_DIR) + "/tests/browser/artifacts";
  const std::string node = find_in_path("node");
  const std::string chromium = env_or("AG_CHROMIUM", find_in_path("chromium"));
  const std::string script = src + "/tests/browser/check_base_page.mjs";
  if (node.empty()) GTEST_SKIP() << "node is not installed (apt-get install nodejs; tools/install-deps.sh does it)";
  if (chromium.empty()) GTEST_SKIP() << "chromium is not installed (apt-get install chromium; tools/install-deps.sh does it)";
  if (!std::filesystem::exists(src + "/tests/browser/node_modules/playwright-core/package.json"))
    GTEST_SKIP() << "playwright-core is not installed: run tools/install-browser-test.sh";

  TempDir dir;
  MissionPlayer player;
  auto rig = BaseRig::make(dir);
  ASSERT_NE(rig, nullptr);
  ASSERT_GT(rig->web->port(), 0);
  const std::string url = "http://127.0.0.1:" + std::to_string(rig->web->port()) + "/";
  std::filesystem::remove(out_dir + "/base_station_page.png");

  // The mission's first second: the whole map and the records, before the browser starts.
  const TimeNs t0 = monotonic_now();
  for (std::int32_t tx = 0; tx < 3; ++tx)
    for (std::int32_t ty = 0; ty < 2; ++ty) player.tile(tx, ty, 1, kNsPerS);
  player.publish_mission_records(kNsPerS);

  const std::string log_out = dir.file("browser.log");
  // Everything exec needs is built before fork(): the child of a threaded process may only make
  // async-signal-safe calls.
  const std::vector<std::string> args = {node, script, "--url", url, "--out", out_dir, "--tiles", "6", "--robots", "2", "--regions", "3",
                                         "--visited", "1", "--failed", "1", "--objects", "1",
                                         // water tile (2, 1) near its centre (off the grid lines); grass in tile (1, 0)
                                         "--probe", "83,51,40,110,210", "--probe", "57,3,110,190,60",
                                         // the vehicle block in tile (0, 1): rows 20..27 (north of the tile's south edge), cols 16..27
                                         "--probe", "11,44,230,40,40",
                                         // inside each robot's arrow: its colour
                                         "--robot-probe", "1,255,210,74", "--robot-probe", "2,74,217,255", "--timeout-s", "30"};
  std::vector<std::string> envs;
  for (char** e = environ; *e != nullptr; ++e)
    if (std::strncmp(*e, "AG_CHROMIUM=", 12) != 0) envs.emplace_back(*e);
  envs.push_back("AG_CHROMIUM=" + chromium);
  std::vector<char*> argv, envp;
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  for (const auto& e : envs) envp.push_back(const_cast<char*>(e.c_str()));
  envp.push_back(nullptr);
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    const int fd = ::open(log_out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ::dup2(fd, 1);
    ::dup2(fd, 2);
    ::execve(node.c_str(), argv.data(), envp.data());
    ::_exit(127);
  }
  int status = 0;
  bool exited = false;
  for (int k = 0; !exited; ++k) {
    const TimeNs now = monotonic_now() - t0 + kNsPerS;
    const double t = static_cast<double>(now - kNsPerS) * 1e-9;
    if (k % 4 == 0)
      for (int r = 1; r <= 2; ++r) {
        const Pose2 p = MissionPlayer::robot_pose(r, t);
        player.pose(r, p.x, p.y, p.yaw, now);
      }
    player.tick(now);
    rig->step(now);
    if (t > 60.0) {
      ::kill(pid, SIGKILL);
      ADD_FAILURE() << "the browser check did not finish in 60 s";
    }
    exited = ::waitpid(pid, &status, WNOHANG) == pid;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  const std::string out = slurp(log_out);
  std::printf("%s", out.c_str());
  ASSERT_TRUE(WIFEXITED(status)) << out;
  EXPECT_EQ(WEXITSTATUS(status), 0) << "the page check failed:\n" << out;
  EXPECT_TRUE(std::filesystem::exists(out_dir + "/base_station_page.png")) << "screenshot kept as an artefact";
  if (std::filesystem::exists(out_dir + "/base_station_page.png"))
    std::printf("screenshot: %s/base_station_page.png (%ju B)\n", out_dir.c_str(),
                static_cast<std::uintmax_t>(std::filesystem::file_size(out_dir + "/base_station_page.png")));
  const auto* c = rig->web->server_counters();
  ASSERT_NE(c, nullptr);
  EXPECT_GE(c->ws_opened.load(), 1U) << "the page used the WebSocket";
  EXPECT_EQ(c->bad_requests.load(), 0U);

  // The mission log holds every kind the page showed.
  rig->role->stop_all();
  const std::string log = slurp(dir.file("mission.jsonl"));
  for (const char* kind : {"\"kind\":\"map_tile\"", "\"kind\":\"pose\"", "\"kind\":\"regions\"", "\"kind\":\"claim\"", "\"kind\":\"visited\"",
                           "\"kind\":\"failure\"", "\"kind\":\"object\""})
    EXPECT_NE(log.find(kind), std::string::npos) << kind << " missing from the mission log";
}

}  // namespace
}  // namespace ag::base_station::test
