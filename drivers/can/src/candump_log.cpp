// candump log reading, writing, recording and replay.
#include "airground/drivers/can/candump_log.hpp"

#include <cerrno>
#include <cinttypes>
#include <cstring>
#include <fstream>
#include <sstream>

namespace ag::can {

namespace {
int hex(char c) noexcept {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}
Error bad(const std::string& what) { return Error::make(ErrorCode::kMalformed, what); }
}  // namespace

Result<CandumpRecord> parse_candump_line(std::string_view line) {
  while (!line.empty() && (line.back() == '\n' || line.back() == '\r' || line.back() == ' ')) line.remove_suffix(1);
  CandumpRecord rec;
  // (sec.usec)
  if (line.size() < 4 || line[0] != '(') return bad("expected '(seconds.microseconds)' at the start");
  const std::size_t close = line.find(')');
  if (close == std::string_view::npos) return bad("no ')' after the timestamp");
  const std::string_view ts = line.substr(1, close - 1);
  const std::size_t dot = ts.find('.');
  if (dot == std::string_view::npos || dot == 0 || ts.size() - dot - 1 != 6) return bad("timestamp must be seconds.microseconds (6 digits)");
  std::int64_t sec = 0, usec = 0;
  for (std::size_t i = 0; i < dot; ++i) {
    if (ts[i] < '0' || ts[i] > '9') return bad("timestamp seconds are not a number");
    sec = sec * 10 + (ts[i] - '0');
    if (sec > 9'000'000'000LL) return bad("timestamp beyond the year 2255 (int64 nanoseconds)");
  }
  for (std::size_t i = dot + 1; i < ts.size(); ++i) {
    if (ts[i] < '0' || ts[i] > '9') return bad("timestamp microseconds are not a number");
    usec = usec * 10 + (ts[i] - '0');
  }
  rec.frame.stamp = sec * kNsPerS + usec * kNsPerUs;
  std::string_view rest = line.substr(close + 1);
  if (rest.empty() || rest[0] != ' ') return bad("expected ' interface' after the timestamp");
  rest.remove_prefix(1);
  const std::size_t sp = rest.find(' ');
  if (sp == std::string_view::npos || sp == 0) return bad("expected 'interface id#data'");
  const std::string_view ifname = rest.substr(0, sp);
  if (ifname.size() > 15) return bad("interface name longer than 15 characters (IFNAMSIZ)");
  for (char ch : ifname)
    if (ch < 0x21 || ch > 0x7E) return bad("interface name has a control or non-ASCII character");
  rec.iface = std::string(ifname);
  std::string_view fr = rest.substr(sp + 1);
  const std::size_t end = fr.find(' ');  // newer candump may append a direction flag
  if (end != std::string_view::npos) fr = fr.substr(0, end);
  const std::size_t hash = fr.find('#');
  if (hash == std::string_view::npos) return bad("no '#' between id and data");
  if (hash + 1 < fr.size() && fr[hash + 1] == '#') return bad("CAN FD frame ('##'): only classic CAN is supported");
  if (hash != 3 && hash != 8) return bad("id must be 3 (standard) or 8 (extended) hex digits");
  std::uint32_t id = 0;
  for (std::size_t i = 0; i < hash; ++i) {
    const int h = hex(fr[i]);
    if (h < 0) return bad("id is not hexadecimal");
    id = (id << 4) | static_cast<std::uint32_t>(h);
  }
  rec.frame.extended = hash == 8;
  if (rec.frame.extended && (id & 0xE0000000U) == 0x20000000U) {  // CAN_ERR_FLAG: an error frame (candump, python-can)
    rec.error = true;
    id &= kExtendedIdMask;
  }
  if (id > (rec.frame.extended ? kExtendedIdMask : kStandardIdMask)) return bad("id beyond its format");
  rec.frame.id = id;
  std::string_view data = fr.substr(hash + 1);
  if (!data.empty() && (data[0] == 'R' || data[0] == 'r')) {
    rec.frame.rtr = true;
    if (data.size() == 2 && data[1] >= '0' && data[1] <= '8') rec.frame.dlc = static_cast<std::uint8_t>(data[1] - '0');
    else if (data.size() != 1) return bad("remote request must be 'R' or 'R<0-8>'");
    return rec;
  }
  std::uint8_t n = 0;
  for (std::size_t i = 0; i < data.size();) {
    if (data[i] == '.') {
      ++i;
      continue;
    }
    if (i + 1 >= data.size()) return bad("odd number of data hex digits");
    const int a = hex(data[i]), b = hex(data[i + 1]);
    if (a < 0 || b < 0) return bad("data is not hexadecimal");
    if (n >= 8) return bad("more than 8 data bytes");
    rec.frame.data[n++] = static_cast<std::uint8_t>(a * 16 + b);
    i += 2;
  }
  rec.frame.dlc = n;
  return rec;
}

std::size_t format_candump_line(const CanFrame& f, std::string_view iface, char* buf, std::size_t cap) noexcept {
  const TimeNs s = f.stamp >= 0 ? f.stamp / kNsPerS : 0;
  const TimeNs us = f.stamp >= 0 ? (f.stamp % kNsPerS) / kNsPerUs : 0;
  int n = std::snprintf(buf, cap, "(%" PRId64 ".%06" PRId64 ") %.*s ", s, us, static_cast<int>(iface.size()), iface.data());
  if (n < 0 || static_cast<std::size_t>(n) >= cap) return 0;
  auto len = static_cast<std::size_t>(n);
  n = f.extended ? std::snprintf(buf + len, cap - len, "%08" PRIX32 "#", f.id) : std::snprintf(buf + len, cap - len, "%03" PRIX32 "#", f.id);
  if (n < 0 || len + static_cast<std::size_t>(n) >= cap) return 0;
  len += static_cast<std::size_t>(n);
  if (f.rtr) {
    n = f.dlc > 0 ? std::snprintf(buf + len, cap - len, "R%u", static_cast<unsigned>(f.dlc)) : std::snprintf(buf + len, cap - len, "R");
    if (n < 0 || len + static_cast<std::size_t>(n) >= cap) return 0;
    return len + static_cast<std::size_t>(n);
  }
  for (std::uint8_t i = 0; i < f.dlc && i < 8; ++i) {
    n = std::snprintf(buf + len, cap - len, "%02X", static_cast<unsigned>(f.data[i]));
    if (n < 0 || len + static_cast<std::size_t>(n) >= cap) return 0;
    len += static_cast<std::size_t>(n);
  }
  return len;
}

std::string format_candump_line(const CanFrame& f, std::string_view iface) {
  char buf[128];
  const std::size_t n = format_candump_line(f, iface, buf, sizeof buf);
  return std::string(buf, n);
}

CandumpLog parse_candump_text(std::string_view text, std::string_view origin) {
  CandumpLog log;
  std::size_t line_no = 0;
  while (!text.empty()) {
    const std::size_t nl = text.find('\n');
    const std::string_view line = text.substr(0, nl);
    text = nl == std::string_view::npos ? std::string_view{} : text.substr(nl + 1);
    ++line_no;
    std::string_view trimmed = line;
    while (!trimmed.empty() && (trimmed.back() == '\r' || trimmed.back() == ' ')) trimmed.remove_suffix(1);
    if (trimmed.empty() || trimmed[0] == '#') continue;
    auto r = parse_candump_line(trimmed);
    if (!r) {
      if (log.bad_lines++ == 0) log.first_error = std::string(origin) + ":" + std::to_string(line_no) + ": " + r.error().message;
      continue;
    }
    log.records.push_back(std::move(r).value());
  }
  return log;
}

Result<CandumpLog> read_candump_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error::make(ErrorCode::kIo, "candump log " + path + ": cannot open: " + std::strerror(errno));
  std::ostringstream ss;
  ss << in.rdbuf();
  return parse_candump_text(ss.str(), path);
}

Result<std::unique_ptr<CandumpWriter>> CandumpWriter::create(const std::string& path, std::string iface) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (f == nullptr) return Error::make(ErrorCode::kIo, "candump log " + path + ": cannot create: " + std::strerror(errno));
  return std::unique_ptr<CandumpWriter>(new CandumpWriter(f, std::move(iface)));
}

CandumpWriter::~CandumpWriter() {
  if (f_ != nullptr) std::fclose(f_);
}

void CandumpWriter::write(const CanFrame& f) noexcept {
  char buf[128];
  const std::size_t n = format_candump_line(f, iface_, buf, sizeof buf);
  if (n == 0) return;
  buf[n] = '\n';
  (void)std::fwrite(buf, 1, n + 1, f_);
  ++lines_;
}

void CandumpWriter::flush() noexcept { (void)std::fflush(f_); }

CanResult RecordingCanBus::send(const CanFrame& f) noexcept {
  const CanResult r = inner_.send(f);
  if (r == CanResult::kOk) {
    CanFrame s = f;
    s.stamp = clock_.now();
    log_.write(s);
  }
  return r;
}

CanResult RecordingCanBus::receive(CanFrame& out) noexcept {
  const CanResult r = inner_.receive(out);
  if (r == CanResult::kOk) log_.write(out);
  return r;
}

CandumpReplayBus::CandumpReplayBus(std::vector<CandumpRecord> records, const Clock& clock, TimeNs start, Filter accept)
    : records_(std::move(records)), clock_(clock), start_(start), accept_(accept) {
  t0_ = records_.empty() ? 0 : records_.front().frame.stamp;
}

CanResult CandumpReplayBus::send(const CanFrame& f) noexcept {
  if (!valid(f)) return CanResult::kInvalid;
  ++c_.tx;
  return CanResult::kOk;
}

CanResult CandumpReplayBus::receive(CanFrame& out) noexcept {
  const TimeNs now = clock_.now();
  while (next_ < records_.size()) {
    const CanFrame& f = records_[next_].frame;
    const TimeNs at = f.stamp - t0_ + start_;
    if (at > now) return CanResult::kWouldBlock;
    const bool error_frame = records_[next_].error;
    ++next_;
    if (error_frame) {  // a recorded error frame: the bus state follows it, nothing is delivered
      errors_.apply(decode_error_frame(f.id, f.data), c_);
      ++c_.rx_errors;
      continue;
    }
    if (accept_ != nullptr && !accept_(f)) continue;
    if (!accepts(f)) {
      ++c_.rx_filtered;
      continue;
    }
    out = f;
    out.stamp = at;
    ++c_.rx;
    return CanResult::kOk;
  }
  return CanResult::kWouldBlock;
}

}  // namespace ag::can
