// Test helper: reads an MCAP file back with the official readers (read_mcap.mjs on node: @mcap/core,
// @mcap/support) and returns what they saw as JSON ({"ok": false, "error": ...} when they refuse it).
#pragma once

#include <nlohmann/json.hpp>

#include <array>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

namespace ag::test {

// Where the reader lives (the source tree's tests/mcap_reader); "" with the reason in `why` if node or
// the npm packages are missing.
inline std::string mcap_reader_script(const std::string& source_dir, std::string* why) {
  const std::string dir = source_dir + "/tests/mcap_reader";
  if (std::system("node --version >/dev/null 2>&1") != 0) {
    *why = "node is not installed (apt-get install nodejs; tools/install-deps.sh does it)";
    return {};
  }
  if (!std::filesystem::exists(dir + "/node_modules/@mcap/core/package.json") ||
      !std::filesystem::exists(dir + "/node_modules/@mcap/support/package.json")) {
    *why = "@mcap/core and @mcap/support are not installed in " + dir + "/node_modules: run tools/install-mcap-reader.sh";
    return {};
  }
  return dir + "/read_mcap.mjs";
}

inline std::string shell_quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

// Runs the reader; `extra` are more arguments (--dump TOPIC, --max N).
inline nlohmann::json read_mcap(const std::string& script, const std::string& file, const std::vector<std::string>& extra = {}) {
  std::string cmd = "node " + shell_quote(script) + " " + shell_quote(file);
  for (const std::string& e : extra) cmd += " " + shell_quote(e);
  std::FILE* p = ::popen(cmd.c_str(), "r");
  if (!p) return {{"ok", false}, {"error", "popen failed"}};
  std::string out;
  std::array<char, 65536> buf{};
  for (std::size_t n; (n = std::fread(buf.data(), 1, buf.size(), p)) > 0;) out.append(buf.data(), n);
  const int rc = ::pclose(p);
  nlohmann::json j = nlohmann::json::parse(out, nullptr, false);
  if (j.is_discarded()) return {{"ok", false}, {"error", "reader printed no JSON (exit " + std::to_string(rc) + "): " + out}};
  j["exit_status"] = rc;
  return j;
}

}  // namespace ag::test
