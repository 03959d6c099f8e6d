// A minimal JSON writer (appends to a std::string; the server thread's side, may allocate).
#pragma once

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <string>
#include <string_view>

namespace ag::base_station {

class JsonOut {
 public:
  explicit JsonOut(std::string& s) : s_(s) {}
  JsonOut& begin_object() { sep(); s_ += '{'; first_ = true; return *this; }
  JsonOut& end_object() { s_ += '}'; first_ = false; return *this; }
  JsonOut& begin_array() { sep(); s_ += '['; first_ = true; return *this; }
  JsonOut& end_array() { s_ += ']'; first_ = false; return *this; }
  JsonOut& key(std::string_view k) {
    sep();
    str_raw(k);
    s_ += ':';
    first_ = true;  // the value follows without a comma
    return *this;
  }
  JsonOut& str(std::string_view v) { sep(); str_raw(v); return *this; }
  JsonOut& num(double v, int decimals = 3) {
    sep();
    if (!std::isfinite(v)) {
      s_ += "null";
      return *this;
    }
    char b[48];
    std::snprintf(b, sizeof b, "%.*f", decimals, v);
    s_ += b;
    return *this;
  }
  JsonOut& integer(std::int64_t v) { sep(); s_ += std::to_string(v); return *this; }
  JsonOut& uinteger(std::uint64_t v) { sep(); s_ += std::to_string(v); return *this; }
  JsonOut& boolean(bool v) { sep(); s_ += v ? "true" : "false"; return *this; }
  JsonOut& null() { sep(); s_ += "null"; return *this; }
  // key + value shorthands
  JsonOut& kv(std::string_view k, std::string_view v) { return key(k).str(v); }
  JsonOut& kv(std::string_view k, const char* v) { return key(k).str(v); }
  JsonOut& kn(std::string_view k, double v, int decimals = 3) { return key(k).num(v, decimals); }
  JsonOut& ki(std::string_view k, std::int64_t v) { return key(k).integer(v); }
  JsonOut& ku(std::string_view k, std::uint64_t v) { return key(k).uinteger(v); }
  JsonOut& kb(std::string_view k, bool v) { return key(k).boolean(v); }

 private:
  void sep() {
    if (!first_) s_ += ',';
    first_ = false;
  }
  void str_raw(std::string_view v) {
    s_ += '"';
    for (char c : v) {
      const auto u = static_cast<unsigned char>(c);
      if (c == '"' || c == '\\') {
        s_ += '\\';
        s_ += c;
      } else if (u < 0x20) {
        char b[8];
        std::snprintf(b, sizeof b, "\\u%04x", u);
        s_ += b;
      } else {
        s_ += c;
      }
    }
    s_ += '"';
  }
  std::string& s_;
  bool first_{true};
};

}  // namespace ag::base_station
