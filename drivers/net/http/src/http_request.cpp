#include "airground/drivers/net/http/http_request.hpp"

#include <cctype>

namespace ag::net::http {
namespace {
bool iequal(std::string_view a, std::string_view b) noexcept {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (std::tolower(static_cast<unsigned char>(a[i])) != std::tolower(static_cast<unsigned char>(b[i]))) return false;
  return true;
}
std::string_view trim(std::string_view s) noexcept {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
  return s;
}
bool token_char(char c) noexcept {
  const auto u = static_cast<unsigned char>(c);
  if (std::isalnum(u) != 0) return true;
  return std::string_view("!#$%&'*+-.^_`|~").find(c) != std::string_view::npos;
}
}  // namespace

std::string_view HttpRequest::header(std::string_view name) const noexcept {
  for (const auto& [k, v] : headers)
    if (k == name) return v;
  return {};
}

bool HttpRequest::header_has_token(std::string_view name, std::string_view token) const noexcept {
  for (const auto& [k, v] : headers) {
    if (k != name) continue;
    std::string_view rest = v;
    while (!rest.empty()) {
      const std::size_t c = rest.find(',');
      if (iequal(trim(rest.substr(0, c)), token)) return true;
      if (c == std::string_view::npos) break;
      rest.remove_prefix(c + 1);
    }
  }
  return false;
}

bool HttpRequest::keep_alive() const noexcept {
  if (header_has_token("connection", "close")) return false;
  if (version_minor == 0) return header_has_token("connection", "keep-alive");
  return true;
}

HttpParse parse_http_request(std::string_view in, std::size_t max_head, HttpRequest& out, std::size_t& consumed,
                             std::string& why) {
  const std::size_t end = in.find("\r\n\r\n");
  if (end == std::string_view::npos) {
    if (in.size() >= max_head) {
      why = "request head longer than " + std::to_string(max_head) + " B";
      return HttpParse::kBad;
    }
    // A request line that is already malformed need not wait for the rest.
    const std::size_t nl = in.find('\n');
    if (nl != std::string_view::npos && (nl == 0 || in[nl - 1] != '\r')) {
      why = "line not ended by CRLF";
      return HttpParse::kBad;
    }
    return HttpParse::kNeedMore;
  }
  if (end + 4 > max_head) {
    why = "request head longer than " + std::to_string(max_head) + " B";
    return HttpParse::kBad;
  }
  out = HttpRequest{};
  std::string_view head = in.substr(0, end);
  const std::size_t le = head.find("\r\n");
  const std::string_view line = head.substr(0, le);
  head = le == std::string_view::npos ? std::string_view{} : head.substr(le + 2);
  const std::size_t s1 = line.find(' ');
  const std::size_t s2 = s1 == std::string_view::npos ? s1 : line.find(' ', s1 + 1);
  if (s1 == std::string_view::npos || s2 == std::string_view::npos || line.find(' ', s2 + 1) != std::string_view::npos) {
    why = "request line is not 'METHOD TARGET HTTP/1.x'";
    return HttpParse::kBad;
  }
  const std::string_view method = line.substr(0, s1), target = line.substr(s1 + 1, s2 - s1 - 1), version = line.substr(s2 + 1);
  if (method.empty()) {
    why = "empty method";
    return HttpParse::kBad;
  }
  for (char c : method)
    if (!token_char(c)) {
      why = "bad character in method";
      return HttpParse::kBad;
    }
  if (target.empty() || target.front() != '/') {
    why = "request target is not an absolute path";
    return HttpParse::kBad;
  }
  for (char c : target)
    if (static_cast<unsigned char>(c) <= 0x20 || static_cast<unsigned char>(c) >= 0x7F) {
      why = "control or non-ASCII byte in target";
      return HttpParse::kBad;
    }
  if (version == "HTTP/1.1") out.version_minor = 1;
  else if (version == "HTTP/1.0") out.version_minor = 0;
  else {
    why = "unsupported version '" + std::string(version.substr(0, 16)) + "'";
    return HttpParse::kBad;
  }
  out.method = std::string(method);
  out.target = std::string(target);
  const std::size_t q = target.find('?');
  out.path = std::string(target.substr(0, q));
  if (q != std::string_view::npos) out.query = std::string(target.substr(q + 1));
  while (!head.empty()) {
    const std::size_t e = head.find("\r\n");
    const std::string_view h = head.substr(0, e);
    head = e == std::string_view::npos ? std::string_view{} : head.substr(e + 2);
    const std::size_t colon = h.find(':');
    if (colon == std::string_view::npos || colon == 0) {
      why = "header line without a name and ':'";
      return HttpParse::kBad;
    }
    std::string name(h.substr(0, colon));
    for (char& c : name) {
      if (!token_char(c)) {
        why = "bad character in header name";
        return HttpParse::kBad;
      }
      c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    }
    out.headers.emplace_back(std::move(name), std::string(trim(h.substr(colon + 1))));
  }
  if (out.version_minor == 1 && out.header("host").empty()) {
    why = "HTTP/1.1 request without Host";
    return HttpParse::kBad;
  }
  const std::string_view cl = out.header("content-length");
  if ((!cl.empty() && cl != "0") || !out.header("transfer-encoding").empty()) {
    why = "request with a body (only GET is served)";
    return HttpParse::kBad;
  }
  consumed = end + 4;
  return HttpParse::kOk;
}

}  // namespace ag::net::http
