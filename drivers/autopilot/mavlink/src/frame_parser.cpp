// MAVLink frame cutting with resynchronisation.
#include "airground/drivers/autopilot/mavlink/frame_parser.hpp"

#include <algorithm>
#include <cstring>

namespace ag::mavlink {

std::size_t FrameParser::feed(std::span<const std::uint8_t> in) noexcept {
  if (head_ > 0) {  // keep the unread bytes at the front so a whole frame always fits
    std::memmove(buf_.data(), buf_.data() + head_, tail_ - head_);
    tail_ -= head_;
    boundary_ = boundary_ > head_ ? boundary_ - head_ : 0;
    head_ = 0;
  }
  const std::size_t n = std::min(in.size(), buf_.size() - tail_);
  if (n > 0) std::memcpy(buf_.data() + tail_, in.data(), n);
  tail_ += n;
  return n;
}

void FrameParser::end_of_packet() noexcept { boundary_ = tail_; }

bool FrameParser::next(Frame& out) noexcept {
  for (;;) {
    while (head_ < tail_ && buf_[head_] != kMagicV1 && buf_[head_] != kMagicV2) {
      ++c_.garbage_bytes;
      ++head_;
    }
    if (head_ >= tail_) return false;
    const std::uint8_t* p = buf_.data() + head_;
    const std::size_t avail = tail_ - head_;
    const bool v2 = p[0] == kMagicV2;
    const std::size_t hdr = v2 ? kHeaderV2 : kHeaderV1;
    // A frame that cannot be complete before the end of its packet is cut off.
    const std::size_t limit = boundary_ > head_ ? boundary_ - head_ : 0;
    auto cut_off = [&](std::size_t need) {
      if (limit == 0 || need <= limit) return false;
      ++c_.truncated;
      ++head_;
      return true;
    };
    if (avail < hdr) {
      if (cut_off(hdr)) continue;
      return false;
    }
    const std::size_t len = p[1];
    std::uint8_t incompat = 0;
    std::uint32_t msgid = p[5];
    if (v2) {
      incompat = p[2];
      if ((incompat & ~kIncompatSigned) != 0) {
        ++c_.unsupported_flags;
        ++head_;
        continue;
      }
      msgid = static_cast<std::uint32_t>(p[7]) | static_cast<std::uint32_t>(p[8]) << 8 | static_cast<std::uint32_t>(p[9]) << 16;
    }
    const std::size_t sig = (incompat & kIncompatSigned) != 0 ? kSignatureBytes : 0;
    const std::size_t total = hdr + len + kChecksumBytes + sig;
    if (avail < total) {
      if (cut_off(total)) continue;
      return false;
    }
    const MessageInfo* info = find_message(msgid);
    if (info == nullptr) {
      ++c_.unknown_id;
      ++head_;
      continue;
    }
    std::uint16_t crc = crc_x25(std::span<const std::uint8_t>(p + 1, hdr - 1 + len));
    crc = crc_accumulate(info->crc_extra, crc);
    const std::uint16_t got = static_cast<std::uint16_t>(p[hdr + len] | p[hdr + len + 1] << 8);
    if (crc != got) {
      ++c_.bad_crc;
      ++head_;
      continue;
    }
    head_ += total;  // a CRC-valid frame is real: whatever follows is read after it
    if (len > info->max_length || (!v2 && len < info->min_length)) {
      ++c_.bad_length;
      continue;
    }
    ++c_.frames;
    ++(v2 ? c_.v2_frames : c_.v1_frames);
    if (sig != 0) ++c_.signed_frames;
    if (v2 && len < info->max_length) ++c_.truncated_payloads;
    out.header.version = v2 ? 2 : 1;
    out.header.incompat_flags = incompat;
    out.header.compat_flags = v2 ? p[3] : 0;
    out.header.seq = v2 ? p[4] : p[2];
    out.header.sysid = v2 ? p[5] : p[3];
    out.header.compid = v2 ? p[6] : p[4];
    out.header.msgid = msgid;
    out.payload = std::span<const std::uint8_t>(p + hdr, len);
    out.signature = std::span<const std::uint8_t>(p + hdr + len + kChecksumBytes, sig);
    out.wire_bytes = total;
    return true;
  }
}

}  // namespace ag::mavlink
