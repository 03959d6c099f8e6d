// pcap / pcapng reading (formats: tcpdump.org pcap(5) and the pcapng IETF draft).
#include "airground/drivers/lidar/ouster/pcap_reader.hpp"

#include <cstring>
#include <fstream>
#include <iterator>

namespace ag::ouster {

namespace {
std::uint32_t rd32(const std::uint8_t* p, bool swap) noexcept {
  std::uint32_t v;
  std::memcpy(&v, p, 4);
  return swap ? __builtin_bswap32(v) : v;
}
std::uint16_t rd16(const std::uint8_t* p, bool swap) noexcept {
  std::uint16_t v;
  std::memcpy(&v, p, 2);
  return swap ? __builtin_bswap16(v) : v;
}
std::uint16_t be16(const std::uint8_t* p) noexcept { return static_cast<std::uint16_t>((p[0] << 8) | p[1]); }
std::uint32_t be32(const std::uint8_t* p) noexcept {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) | p[3];
}
constexpr std::uint32_t kPcapMagicUs = 0xA1B2C3D4, kPcapMagicNs = 0xA1B23C4D, kNgShb = 0x0A0D0D0A, kNgBom = 0x1A2B3C4D;
}  // namespace

Result<PcapReader> PcapReader::open(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error::make(ErrorCode::kIo, "cannot open capture " + path);
  std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  return from_bytes(std::move(bytes), path);
}

Result<PcapReader> PcapReader::from_bytes(std::vector<std::uint8_t> bytes, std::string origin) {
  PcapReader r;
  r.data_ = std::move(bytes);
  r.origin_ = std::move(origin);
  if (r.data_.size() < 24) return Error::make(ErrorCode::kMalformed, r.origin_ + ": shorter than a pcap header");
  std::uint32_t magic;
  std::memcpy(&magic, r.data_.data(), 4);
  if (magic == kNgShb) {
    r.ng_ = true;
    std::uint32_t bom;
    std::memcpy(&bom, r.data_.data() + 8, 4);
    if (bom == kNgBom) r.swap_ = false;
    else if (__builtin_bswap32(bom) == kNgBom) r.swap_ = true;
    else return Error::make(ErrorCode::kMalformed, r.origin_ + ": pcapng section header with a bad byte-order magic");
    r.start_ = 0;
  } else {
    if (magic == kPcapMagicUs || magic == kPcapMagicNs) r.swap_ = false;
    else if (__builtin_bswap32(magic) == kPcapMagicUs || __builtin_bswap32(magic) == kPcapMagicNs) r.swap_ = true;
    else return Error::make(ErrorCode::kMalformed, r.origin_ + ": not a pcap or pcapng file (magic " + std::to_string(magic) + ")");
    const std::uint32_t m = r.swap_ ? __builtin_bswap32(magic) : magic;
    r.nanos_ = m == kPcapMagicNs;
    const std::uint16_t major = rd16(r.data_.data() + 4, r.swap_);
    if (major != 2) return Error::make(ErrorCode::kMalformed, r.origin_ + ": pcap version " + std::to_string(major) + " (expected 2)");
    r.link_ = rd32(r.data_.data() + 20, r.swap_) & 0x0FFFFFFFu;
    r.start_ = 24;
  }
  r.pos_ = r.start_;
  return r;
}

void PcapReader::rewind() noexcept {
  pos_ = start_;
  error_.clear();
  ng_links_.clear();
  ng_tsres_.clear();
}

void PcapReader::fail(const char* what) noexcept {
  if (error_.empty()) {
    try {
      error_ = origin_ + ": " + what + " at byte " + std::to_string(pos_);
    } catch (...) {
    }
  }
  pos_ = data_.size();
}

bool PcapReader::next_classic(std::span<const std::uint8_t>& frame, TimeNs& stamp) noexcept {
  if (pos_ >= data_.size()) return false;
  if (data_.size() - pos_ < 16) {
    fail("truncated record header");
    return false;
  }
  const std::uint8_t* h = data_.data() + pos_;
  const std::uint32_t sec = rd32(h, swap_), frac = rd32(h + 4, swap_), incl = rd32(h + 8, swap_);
  if (incl > data_.size() - pos_ - 16) {
    fail("record longer than the rest of the file");
    return false;
  }
  stamp = static_cast<TimeNs>(sec) * kNsPerS + static_cast<TimeNs>(frac) * (nanos_ ? 1 : kNsPerUs);
  frame = std::span<const std::uint8_t>(h + 16, incl);
  pos_ += 16 + incl;
  return true;
}

bool PcapReader::next_ng(std::span<const std::uint8_t>& frame, TimeNs& stamp, std::uint32_t& link) noexcept {
  while (pos_ < data_.size()) {
    if (data_.size() - pos_ < 12) {
      fail("truncated pcapng block");
      return false;
    }
    const std::uint8_t* b = data_.data() + pos_;
    std::uint32_t type;
    std::memcpy(&type, b, 4);
    if (type == kNgShb) {  // a new section may change byte order
      std::uint32_t bom;
      std::memcpy(&bom, b + 8, 4);
      if (bom == kNgBom) swap_ = false;
      else if (__builtin_bswap32(bom) == kNgBom) swap_ = true;
      else {
        fail("bad pcapng byte-order magic");
        return false;
      }
      ng_links_.clear();
      ng_tsres_.clear();
    } else {
      type = rd32(b, swap_);
    }
    const std::uint32_t len = rd32(b + 4, swap_);
    if (len < 12 || len % 4 != 0 || len > data_.size() - pos_) {
      fail("pcapng block with a bad length");
      return false;
    }
    pos_ += len;
    if (type == 1 && len >= 20) {  // interface description
      ng_links_.push_back(rd16(b + 8, swap_));
      std::uint64_t res = 1'000'000;
      for (std::size_t o = 16; o + 4 <= len - 4;) {  // options: if_tsresol (9)
        const std::uint16_t code = rd16(b + o, swap_), olen = rd16(b + o + 2, swap_);
        if (code == 0) break;
        if (code == 9 && olen >= 1 && o + 4 < len - 4) {
          const std::uint8_t v = b[o + 4];
          res = 1;
          const std::uint64_t base = (v & 0x80) ? 2 : 10;
          for (int i = 0; i < (v & 0x7F) && res < (1ull << 62) / base; ++i) res *= base;
        }
        o += 4 + ((olen + 3u) & ~3u);
      }
      ng_tsres_.push_back(res);
    } else if (type == 6 && len >= 32) {  // enhanced packet
      const std::uint32_t iface = rd32(b + 8, swap_);
      const std::uint64_t ts = (std::uint64_t{rd32(b + 12, swap_)} << 32) | rd32(b + 16, swap_);
      const std::uint32_t cap = rd32(b + 20, swap_);
      if (iface >= ng_links_.size() || cap > len - 32) {
        fail("enhanced packet block with a bad interface or length");
        return false;
      }
      link = ng_links_[iface];
      const std::uint64_t res = ng_tsres_[iface];
      stamp = static_cast<TimeNs>(ts / res) * kNsPerS + static_cast<TimeNs>((ts % res) * 1'000'000'000ull / res);
      frame = std::span<const std::uint8_t>(b + 28, cap);
      return true;
    } else if (type == 3 && len >= 16) {  // simple packet
      if (ng_links_.empty()) {
        fail("simple packet block before an interface");
        return false;
      }
      link = ng_links_[0];
      stamp = 0;
      const std::uint32_t orig = rd32(b + 8, swap_);
      frame = std::span<const std::uint8_t>(b + 12, std::min<std::size_t>(orig, len - 16));
      return true;
    }
  }
  return false;
}

bool PcapReader::parse_frame(std::span<const std::uint8_t> f, std::uint32_t link, TimeNs stamp, UdpDatagram& out) noexcept {
  std::size_t ip = 0;
  std::uint16_t ethertype = 0x0800;
  if (link == 1) {  // Ethernet, with up to two VLAN tags
    if (f.size() < 14) return false;
    ethertype = be16(f.data() + 12);
    ip = 14;
    for (int i = 0; i < 2 && (ethertype == 0x8100 || ethertype == 0x88A8) && f.size() >= ip + 4; ++i) {
      ethertype = be16(f.data() + ip + 2);
      ip += 4;
    }
  } else if (link == 113) {  // Linux cooked v1
    if (f.size() < 16) return false;
    ethertype = be16(f.data() + 14);
    ip = 16;
  } else if (link != 101 && link != 228) {
    return false;
  }
  if (ethertype != 0x0800 || f.size() < ip + 20) return false;
  const std::uint8_t* h = f.data() + ip;
  if ((h[0] >> 4) != 4) return false;
  const std::size_t ihl = static_cast<std::size_t>(h[0] & 0x0F) * 4;
  if (ihl < 20 || f.size() < ip + ihl + 8) return false;
  if (h[9] != 17) return false;
  const std::uint16_t frag = be16(h + 6);
  if ((frag & 0x3FFF) != 0) {  // more-fragments flag or an offset
    ++c_.fragments;
    return false;
  }
  const std::uint8_t* u = h + ihl;
  const std::uint16_t ulen = be16(u + 4);
  if (ulen < 8) return false;
  const std::size_t avail = f.size() - ip - ihl;
  if (ulen > avail) {
    ++c_.truncated;
    return false;
  }
  out.stamp = stamp;
  out.src_ip = be32(h + 12);
  out.dst_ip = be32(h + 16);
  out.src_port = be16(u);
  out.dst_port = be16(u + 2);
  out.payload = std::span<const std::uint8_t>(u + 8, ulen - 8u);
  return true;
}

bool PcapReader::next(UdpDatagram& out) noexcept {
  for (;;) {
    std::span<const std::uint8_t> frame;
    TimeNs stamp = 0;
    std::uint32_t link = link_;
    const bool got = ng_ ? next_ng(frame, stamp, link) : next_classic(frame, stamp);
    if (!got) return false;
    ++c_.records;
    const auto before = c_.fragments + c_.truncated;
    if (parse_frame(frame, link, stamp, out)) {
      ++c_.udp;
      return true;
    }
    if (c_.fragments + c_.truncated == before) ++c_.not_udp;
  }
}

}  // namespace ag::ouster
