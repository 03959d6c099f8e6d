// candump logs both ways with Debian's python3-can: what the project writes, python-can's
// CanutilsLogReader reads back frame for frame; what python-can's CanutilsLogWriter writes, the project
// reads. Skipped (with the reason) when /usr/bin/python3 has no `can` module.
#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "airground/drivers/can/candump_log.hpp"

namespace ag::can {
namespace {

const std::string kScript = std::string(AG_SOURCE_DIR_FOR_TESTS) + "/tests/unit/drivers/python_can_log.py";

bool python_can_available() {
  static const bool ok = std::system("/usr/bin/python3 -c 'import can' >/dev/null 2>&1") == 0;
  return ok;
}

std::vector<std::string> run(const std::string& cmd) {
  std::vector<std::string> lines;
  std::FILE* p = ::popen(cmd.c_str(), "r");
  if (p == nullptr) return lines;
  char buf[512];
  while (std::fgets(buf, sizeof buf, p) != nullptr) {
    std::string s(buf);
    while (!s.empty() && (s.back() == '\n' || s.back() == '\r')) s.pop_back();
    lines.push_back(s);
  }
  EXPECT_EQ(::pclose(p), 0) << cmd;
  return lines;
}

std::string canon(const CanFrame& f, bool error) {
  char data[17] = {0};
  for (int i = 0; i < (f.rtr ? 0 : f.dlc); ++i) std::snprintf(data + 2 * i, 3, "%02x", f.data[static_cast<std::size_t>(i)]);
  char b[128];
  std::snprintf(b, sizeof b, "%lld %x %d %d %d %d %s", static_cast<long long>(f.stamp / kNsPerUs), f.id, f.extended ? 1 : 0, f.rtr ? 1 : 0,
                error ? 1 : 0, static_cast<int>(f.dlc), data);
  return b;
}

std::string temp_path(const char* name) {
  const char* dir = std::getenv("TMPDIR");
  return std::string(dir != nullptr ? dir : "/tmp") + "/ag_" + std::to_string(::getpid()) + "_" + name;
}

TEST(CandumpPythonCan, ProjectLogsReadByPythonCan) {
  if (!python_can_available()) GTEST_SKIP() << "/usr/bin/python3 cannot import can (Debian package python3-can not installed)";
  const std::string path = temp_path("ours.log");
  std::vector<CanFrame> frames;
  auto add = [&](std::uint32_t id, bool ext, std::vector<std::uint8_t> d, TimeNs t, bool rtr = false, std::uint8_t dlc = 0) {
    CanFrame f;
    f.id = id;
    f.extended = ext;
    f.rtr = rtr;
    f.dlc = rtr ? dlc : static_cast<std::uint8_t>(d.size());
    for (std::size_t i = 0; i < d.size(); ++i) f.data[i] = d[i];
    f.stamp = t;
    frames.push_back(f);
  };
  add(0x02D, false, {0x0D, 0x00, 0x00, 0x80}, 1436509052LL * kNsPerS + 249713LL * kNsPerUs);
  add(0x1F334455, true, {0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77, 0x88}, 1436509052LL * kNsPerS + 249800LL * kNsPerUs);
  add(0x7FF, false, {}, 1436509053LL * kNsPerS);
  add(0x029, false, {}, 1436509053LL * kNsPerS + 1000, true, 0);
  add(0x000, true, {0xFF}, 1436509054LL * kNsPerS + 999999LL * kNsPerUs);
  {
    auto w = CandumpWriter::create(path);
    ASSERT_TRUE(w.ok()) << w.error().message;
    for (const CanFrame& f : frames) w.value()->write(f);
  }
  const auto py = run("/usr/bin/python3 " + kScript + " read " + path);
  ASSERT_EQ(py.size(), frames.size());
  for (std::size_t i = 0; i < frames.size(); ++i) EXPECT_EQ(py[i], canon(frames[i], false)) << "frame " << i;
  std::remove(path.c_str());
}

TEST(CandumpPythonCan, PythonCanLogsReadByTheProject) {
  if (!python_can_available()) GTEST_SKIP() << "/usr/bin/python3 cannot import can (Debian package python3-can not installed)";
  const std::string path = temp_path("python.log");
  const auto py = run("/usr/bin/python3 " + kScript + " write " + path);
  ASSERT_EQ(py.size(), 6u);
  auto log = read_candump_file(path);
  ASSERT_TRUE(log.ok()) << log.error().message;
  EXPECT_EQ(log.value().bad_lines, 0u) << log.value().first_error;
  ASSERT_EQ(log.value().records.size(), py.size());
  for (std::size_t i = 0; i < py.size(); ++i) {
    EXPECT_EQ(log.value().records[i].iface, "can0");
    EXPECT_EQ(canon(log.value().records[i].frame, log.value().records[i].error), py[i]) << "line " << i + 1;
  }
  std::remove(path.c_str());
}

TEST(CandumpPythonCan, ErrorFrameLinesAreErrorFrames) {
  auto r = parse_candump_line("(1700000000.400000) can0 20000040#0000000000000000 R");  // CAN_ERR_FLAG | CAN_ERR_BUSOFF
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_TRUE(r.value().error);
  EXPECT_EQ(r.value().frame.id, 0x40u);
  // Found by fuzz_candump_line: a NUL in the interface name used to cut the formatted line short.
  EXPECT_FALSE(parse_candump_line(std::string_view("(1.000000) ca\0n0 123#", 21)).ok());
  EXPECT_FALSE(parse_candump_line("(1.000000) averyveryverylongname0 123#").ok());
}

}  // namespace
}  // namespace ag::can
