// DBC reader.
#include "airground/drivers/can/dbc.hpp"

#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>

namespace ag::can {

std::uint64_t DbcSignal::raw(const CanFrame& f) const noexcept {
  std::uint64_t bytes = 0;
  for (int i = 0; i < 8; ++i) bytes |= static_cast<std::uint64_t>(f.data[static_cast<std::size_t>(i)]) << (8 * i);
  const std::uint64_t v = bytes >> start_bit;
  return length >= 64 ? v : v & ((std::uint64_t{1} << length) - 1);
}

double DbcSignal::decode(const CanFrame& f) const noexcept {
  const std::uint64_t r = raw(f);
  if (float_type == 1) {
    const auto b = static_cast<std::uint32_t>(r);
    float x = 0;
    std::memcpy(&x, &b, sizeof x);
    return static_cast<double>(x);
  }
  if (float_type == 2) {
    double x = 0;
    std::memcpy(&x, &r, sizeof x);
    return x;
  }
  double v = static_cast<double>(r);
  if (is_signed && length < 64 && (r >> (length - 1) & 1) != 0) v = static_cast<double>(static_cast<std::int64_t>(r | (~std::uint64_t{0} << length)));
  return v * factor + offset;
}

const DbcSignal* DbcMessage::signal(std::string_view n) const noexcept {
  for (const auto& s : signals)
    if (s.name == n) return &s;
  return nullptr;
}
const DbcMessage* Dbc::message(std::string_view name) const noexcept {
  for (const auto& m : messages)
    if (m.name == name) return &m;
  return nullptr;
}
const DbcMessage* Dbc::message(std::uint32_t id) const noexcept {
  for (const auto& m : messages)
    if (m.id == id) return &m;
  return nullptr;
}

Result<Dbc> parse_dbc(std::string_view text, std::string_view origin) {
  Dbc dbc;
  std::istringstream in{std::string(text)};
  std::string line;
  int line_no = 0;
  auto err = [&](const std::string& what) {
    return Error::make(ErrorCode::kMalformed, "DBC " + std::string(origin) + ":" + std::to_string(line_no) + ": " + what);
  };
  while (std::getline(in, line)) {
    ++line_no;
    std::size_t p = line.find_first_not_of(" \t");
    if (p == std::string::npos) continue;
    std::string_view l(line);
    l.remove_prefix(p);
    if (l.rfind("BO_ ", 0) == 0) {
      // BO_ <id> <name>: <dlc> <sender>
      DbcMessage m;
      char name[128] = {0};
      unsigned long id = 0;
      int dlc = 0;
      if (std::sscanf(std::string(l).c_str(), "BO_ %lu %127[^:]: %d", &id, name, &dlc) != 3) return err("bad BO_ line");
      m.id = static_cast<std::uint32_t>(id);
      m.name = name;
      m.dlc = dlc;
      dbc.messages.push_back(std::move(m));
    } else if (l.rfind("SG_ ", 0) == 0) {
      // SG_ <name> [M|mN] : <start>|<len>@<order><sign> (<factor>,<offset>) [<min>|<max>] "<unit>" <receivers>
      if (dbc.messages.empty()) return err("SG_ before any BO_");
      DbcSignal s;
      const std::size_t colon = l.find(':');
      if (colon == std::string_view::npos) return err("SG_ without ':'");
      std::istringstream nm{std::string(l.substr(4, colon - 4))};
      nm >> s.name;
      int start = 0, len = 0, order = 0;
      char sign = '+';
      double factor = 1, offset = 0;
      char unit[64] = {0};
      const std::string rest(l.substr(colon + 1));
      if (std::sscanf(rest.c_str(), " %d|%d@%d%c (%lf,%lf) [%*[^]]] \"%63[^\"]", &start, &len, &order, &sign, &factor, &offset, unit) < 6)
        return err("bad SG_ layout for '" + s.name + "'");
      if (len <= 0 || len > 64 || start < 0 || start > 63 || (order == 1 && start + len > 64)) return err("signal '" + s.name + "' outside 64 bits");
      s.start_bit = start;
      s.length = len;
      s.little_endian = order == 1;
      s.is_signed = sign == '-';
      s.factor = factor;
      s.offset = offset;
      s.unit = unit;
      dbc.messages.back().signals.push_back(std::move(s));
    } else if (l.rfind("SIG_VALTYPE_ ", 0) == 0) {
      unsigned long id = 0;
      char name[128] = {0};
      int type = 0;
      if (std::sscanf(std::string(l).c_str(), "SIG_VALTYPE_ %lu %127s : %d", &id, name, &type) != 3) return err("bad SIG_VALTYPE_ line");
      bool found = false;
      for (auto& m : dbc.messages)
        if (m.id == id)
          for (auto& s : m.signals)
            if (s.name == name) {
              s.float_type = type;
              found = true;
            }
      if (!found) return err(std::string("SIG_VALTYPE_ for an unknown signal ") + name);
    }
  }
  if (dbc.messages.empty()) return Error::make(ErrorCode::kMalformed, "DBC " + std::string(origin) + ": no messages (BO_)");
  return dbc;
}

Result<Dbc> read_dbc_file(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Error::make(ErrorCode::kIo, "DBC " + path + ": cannot open: " + std::strerror(errno));
  std::ostringstream ss;
  ss << in.rdbuf();
  return parse_dbc(ss.str(), path);
}

}  // namespace ag::can
