// An HTTP/1.1 request head (RFC 9112): request line and header fields, parsed from the bytes received.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace ag::net::http {

struct HttpRequest {
  std::string method;
  std::string target;  // as sent: path and optional query
  std::string path;    // target up to '?'
  std::string query;
  int version_minor{1};  // HTTP/1.<minor>
  std::vector<std::pair<std::string, std::string>> headers;  // names lower-cased, values trimmed

  // The value of the first header with this (lower-case) name, or empty.
  [[nodiscard]] std::string_view header(std::string_view lower_name) const noexcept;
  // Whether a comma-separated header holds this token (case-insensitive), e.g. Connection: keep-alive, Upgrade.
  [[nodiscard]] bool header_has_token(std::string_view lower_name, std::string_view token) const noexcept;
  [[nodiscard]] bool keep_alive() const noexcept;
};

enum class HttpParse { kNeedMore, kOk, kBad };

// Parses the head at the start of `in`. kOk sets `consumed` (the head's length; requests with a body
// are refused as kBad since the server serves GET only). kNeedMore while no blank line arrived and
// the bytes are fewer than `max_head`; beyond that kBad. `why` names the fault for kBad.
HttpParse parse_http_request(std::string_view in, std::size_t max_head, HttpRequest& out, std::size_t& consumed,
                             std::string& why);

}  // namespace ag::net::http
