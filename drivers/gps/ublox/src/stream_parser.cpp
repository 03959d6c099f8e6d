// UBX / NMEA stream cutting with resynchronisation.
#include "airground/drivers/gps/ublox/stream_parser.hpp"

#include <cstring>

#include "airground/drivers/gps/ublox/nmea.hpp"
#include "airground/drivers/gps/ublox/ubx.hpp"

namespace ag::ublox {

void StreamParser::fail() noexcept {
  // The frame's bytes after its first sync byte, then whatever was still pending, are scanned again.
  const std::size_t rest = pend_len_ - pend_pos_;
  const std::size_t keep = n_ > 1 ? n_ - 1 : 0;
  if (keep + rest <= pend_.size()) {
    std::memmove(pend_.data() + keep, pend_.data() + pend_pos_, rest);
    std::memcpy(pend_.data(), buf_.data() + 1, keep);
    pend_pos_ = 0;
    pend_len_ = keep + rest;
  } else {
    c_.garbage_bytes += keep;  // cannot happen (see the bound in the header); counted if it ever does
  }
  ++c_.garbage_bytes;  // the false sync byte
  n_ = 0;
  st_ = State::kHunt;
}

bool StreamParser::step(std::uint8_t b, StreamMessage& out) noexcept {
  switch (st_) {
    case State::kHunt:
      if (b == kSync1) {
        buf_[0] = b;
        n_ = 1;
        st_ = State::kSync2;
      } else if (b == '$') {
        buf_[0] = b;
        n_ = 1;
        st_ = State::kNmea;
      } else if (b != '\r' && b != '\n') {  // line ends between sentences are not garbage
        ++c_.garbage_bytes;
      }
      return false;
    case State::kSync2:
      if (b != kSync2) {
        buf_[n_++] = b;
        fail();
        return false;
      }
      buf_[n_++] = b;
      st_ = State::kClass;
      return false;
    case State::kClass: buf_[n_++] = b; st_ = State::kId; return false;
    case State::kId: buf_[n_++] = b; st_ = State::kLen1; return false;
    case State::kLen1: buf_[n_++] = b; st_ = State::kLen2; return false;
    case State::kLen2:
      buf_[n_++] = b;
      len_ = static_cast<std::size_t>(buf_[4]) | (static_cast<std::size_t>(b) << 8);
      if (len_ > kMaxUbxPayload) {
        ++c_.ubx_oversize;
        fail();
        return false;
      }
      st_ = len_ == 0 ? State::kCkA : State::kPayload;
      return false;
    case State::kPayload:
      buf_[n_++] = b;
      if (n_ == 6 + len_) st_ = State::kCkA;
      return false;
    case State::kCkA: buf_[n_++] = b; ck_a_ = b; st_ = State::kCkB; return false;
    case State::kCkB: {
      buf_[n_++] = b;
      const Fletcher8 f = ubx_checksum(buf_[2], buf_[3], std::span<const std::uint8_t>(buf_.data() + 6, len_));
      if (f.a != ck_a_ || f.b != b) {
        ++c_.ubx_bad_checksum;
        fail();
        return false;
      }
      ++c_.ubx_frames;
      out.kind = StreamMessage::Kind::kUbx;
      out.cls = buf_[2];
      out.id = buf_[3];
      out.payload = std::span<const std::uint8_t>(buf_.data() + 6, len_);
      st_ = State::kHunt;
      n_ = 0;
      return true;
    }
    case State::kNmea:
      if (b == '\n' || b == '\r') {
        std::size_t end = n_;
        const std::string_view s(reinterpret_cast<const char*>(buf_.data()), end);
        if (n_ < 4) {  // "$" then a line break: not a sentence
          ++c_.nmea_malformed;
          fail();
          return false;
        }
        if (!nmea_checksum_ok(s)) {
          if (s.rfind('*') == std::string_view::npos || s.rfind('*') + 3 != s.size()) ++c_.nmea_malformed;
          else ++c_.nmea_bad_checksum;
          fail();
          return false;
        }
        ++c_.nmea_sentences;
        out.kind = StreamMessage::Kind::kNmea;
        out.sentence = s;
        st_ = State::kHunt;
        n_ = 0;
        return true;
      }
      if (b < 0x20 || b > 0x7E || n_ >= kMaxNmeaLength) {
        buf_[n_++] = b;
        ++c_.nmea_malformed;
        fail();
        return false;
      }
      buf_[n_++] = b;
      return false;
  }
  return false;
}

std::size_t StreamParser::feed(std::span<const std::uint8_t> in, StreamMessage& out) noexcept {
  out.kind = StreamMessage::Kind::kNone;
  while (pend_pos_ < pend_len_) {
    if (step(pend_[pend_pos_++], out)) return 0;
  }
  pend_pos_ = pend_len_ = 0;
  for (std::size_t i = 0; i < in.size(); ++i) {
    if (step(in[i], out)) return i + 1;
    if (pend_pos_ < pend_len_) {  // a failure queued bytes to rescan: they come before the rest of `in`
      while (pend_pos_ < pend_len_) {
        if (step(pend_[pend_pos_++], out)) return i + 1;
      }
      pend_pos_ = pend_len_ = 0;
    }
  }
  return in.size();
}

}  // namespace ag::ublox
