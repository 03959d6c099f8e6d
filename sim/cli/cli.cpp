// The airground-sim command line's option parsing and checks, shared by every command.
#include "cli.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>

namespace ag::sim::cli {

[[noreturn]] void usage_error(const std::string& msg) {
  // A message that already names the command's --help does not get the general one as well.
  std::fprintf(stderr, "airground-sim: %s%s\n", msg.c_str(), msg.find("--help)") == std::string::npos ? " (see --help)" : "");
  std::exit(2);
}

bool record_mcap(const Args& a) {
  const std::string r = a.get("record", "mcap");
  if (r != "none" && r != "mcap") usage_error("--record must be none or mcap, got '" + r + "'");
  return r == "mcap";
}

Args parse(int argc, char** argv, int first) {
  Args a;
  std::string cur;
  for (int i = first; i < argc; ++i) {
    std::string s = argv[i];
    const bool is_opt = s.rfind("--", 0) == 0 && !(s.size() > 2 && (std::isdigit(static_cast<unsigned char>(s[2])) != 0 || s[2] == '.'));
    if (is_opt) {
      cur = s.substr(2);
      a.opt[cur];
    } else if (!cur.empty()) {
      a.opt[cur].push_back(s);
    } else {
      a.pos.push_back(s);
    }
  }
  return a;
}

std::vector<std::string> oracles_from(const Args& a) {
  std::vector<std::string> out;
  if (!a.has("oracle")) return out;
  for (const std::string& v : a.opt.at("oracle")) {
    std::size_t b = 0;
    while (b <= v.size()) {
      const std::size_t e = std::min(v.find(',', b), v.size());
      const std::string name = v.substr(b, e - b);
      if (name != "vo" && name != "labels") {
        std::fprintf(stderr, "airground-sim: --oracle: unknown oracle '%s' (known: labels, vo) (see --help)\n", name.c_str());
        std::exit(2);
      }
      if (std::find(out.begin(), out.end(), name) == out.end()) out.push_back(name);
      b = e + 1;
    }
  }
  return out;
}

double number(const Args& a, const std::string& k, double def) {
  if (!a.has(k)) return def;
  const std::string v = a.get(k);
  char* end = nullptr;
  const double d = std::strtod(v.c_str(), &end);
  if (v.empty() || *end != '\0' || !std::isfinite(d)) usage_error("--" + k + " needs a number, got '" + v + "'");
  return d;
}

std::vector<double> numbers(const Args& a, const std::string& k, std::size_t n) {
  auto it = a.opt.find(k);
  if (it == a.opt.end() || it->second.size() != n) usage_error("--" + k + " needs " + std::to_string(n) + " numbers");
  std::vector<double> out;
  for (const auto& v : it->second) {
    char* end = nullptr;
    out.push_back(std::strtod(v.c_str(), &end));
    if (*end != '\0') usage_error("--" + k + ": '" + v + "' is not a number");
  }
  return out;
}

std::string required(const Args& a, const std::string& k) {
  if (!a.has(k) || a.get(k).empty()) usage_error("--" + k + " is required");
  return a.get(k);
}

int fail(const Error& e) {
  std::fprintf(stderr, "airground-sim: %s\n", e.message.c_str());
  return 1;
}

}  // namespace ag::sim::cli
