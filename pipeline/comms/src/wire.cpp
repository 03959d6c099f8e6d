// Sealing, opening and replay checks of gossip datagrams.
#include "airground/comms/wire.hpp"

#include <sodium.h>

#include <cctype>
#include <fstream>
#include <sstream>

#include "airground/comms/bytes.hpp"

namespace ag::comms {

namespace {
void nonce_of(const DatagramHeader& h, std::uint8_t (&n)[crypto_aead_chacha20poly1305_IETF_NPUBBYTES]) noexcept {
  static_assert(crypto_aead_chacha20poly1305_IETF_NPUBBYTES == 12);
  ByteWriter w(n);
  w.u8(h.sender);
  w.u8(0);
  w.u32(h.epoch);
  w.u48(h.counter);
}
int hexval(char c) noexcept {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}
}  // namespace

const char* drop_reason_name(DropReason r) noexcept {
  switch (r) {
    case DropReason::kTooShort: return "too_short";
    case DropReason::kTooLong: return "too_long";
    case DropReason::kBadMagic: return "bad_magic";
    case DropReason::kBadVersion: return "bad_version";
    case DropReason::kBadType: return "bad_type";
    case DropReason::kBadSender: return "bad_sender";
    case DropReason::kOwnEcho: return "own_echo";
    case DropReason::kNotForUs: return "not_for_us";
    case DropReason::kForged: return "forged";
    case DropReason::kReplayed: return "replayed";
    case DropReason::kMalformed: return "malformed";
    case DropReason::kRecordTooLarge: return "record_too_large";
    case DropReason::kStoreFull: return "store_full";
    case DropReason::kReassemblyEvicted: return "reassembly_evicted";
    case DropReason::kIdClash: return "id_clash";
    case DropReason::kCount: break;
  }
  return "?";
}

Result<TeamKey> TeamKey::from_hex(std::string_view hex, std::string_view origin) {
  while (!hex.empty() && std::isspace(static_cast<unsigned char>(hex.front()))) hex.remove_prefix(1);
  while (!hex.empty() && std::isspace(static_cast<unsigned char>(hex.back()))) hex.remove_suffix(1);
  if (hex.size() != 2 * kKeyBytes)
    return Error::make(ErrorCode::kConfig, std::string(origin) + ": team key must be " + std::to_string(2 * kKeyBytes) +
                                               " hex digits, found " + std::to_string(hex.size()) + " characters");
  TeamKey k;
  for (std::size_t i = 0; i < kKeyBytes; ++i) {
    const int a = hexval(hex[2 * i]), b = hexval(hex[2 * i + 1]);
    if (a < 0 || b < 0)
      return Error::make(ErrorCode::kConfig, std::string(origin) + ": team key has a non-hex character at position " +
                                                 std::to_string(a < 0 ? 2 * i : 2 * i + 1));
    k.bytes[i] = static_cast<std::uint8_t>(a * 16 + b);
  }
  return k;
}

Result<TeamKey> TeamKey::load_file(const std::string& path) {
  std::ifstream f(path);
  if (!f) return Error::make(ErrorCode::kIo, "team key file " + path + ": cannot open");
  std::stringstream ss;
  ss << f.rdbuf();
  return from_hex(ss.str(), "team key file " + path);
}

bool ReplayGuard::accept(RobotId sender, std::uint32_t epoch, std::uint64_t counter) noexcept {
  Window& w = peers_[sender];
  if (!w.any || epoch > w.epoch) {
    w = Window{epoch, counter, 1, true};
    return true;
  }
  if (epoch < w.epoch) return false;
  if (counter > w.top) {
    const std::uint64_t shift = counter - w.top;
    w.bits = shift >= kWindow ? 1 : (w.bits << shift) | 1;
    w.top = counter;
    return true;
  }
  const std::uint64_t back = w.top - counter;
  if (back >= kWindow) return false;
  const std::uint64_t bit = std::uint64_t{1} << back;
  if (w.bits & bit) return false;
  w.bits |= bit;
  return true;
}

DatagramCodec::DatagramCodec(const TeamKey& key) : key_(key.bytes) {
  if (sodium_init() < 0) std::abort();  // only if the system has no usable entropy source
}

std::size_t DatagramCodec::seal(const DatagramHeader& h, std::span<const std::uint8_t> body,
                                std::span<std::uint8_t> out) const noexcept {
  if (out.size() < kSealOverhead || body.size() > out.size() - kSealOverhead) return 0;
  ByteWriter w(out.first(kHeaderBytes));
  w.u16(kWireMagic);
  w.u8(kWireVersion);
  w.u8(static_cast<std::uint8_t>(h.type));
  w.u8(h.sender);
  w.u8(h.dest);
  w.u32(h.epoch);
  w.u48(h.counter & 0xFFFFFFFFFFFFULL);
  std::uint8_t nonce[crypto_aead_chacha20poly1305_IETF_NPUBBYTES];
  nonce_of(h, nonce);
  unsigned long long clen = 0;
  crypto_aead_chacha20poly1305_ietf_encrypt(out.data() + kHeaderBytes, &clen, body.data(), body.size(), out.data(),
                                            kHeaderBytes, nullptr, nonce, key_.data());
  return kHeaderBytes + static_cast<std::size_t>(clen);
}

bool DatagramCodec::open(std::span<const std::uint8_t> in, RobotId self, ReplayGuard& guard, DatagramHeader& h,
                         std::span<std::uint8_t> body_out, std::size_t& body_len, DropReason& why) const noexcept {
  body_len = 0;
  if (in.size() < kSealOverhead) {
    why = DropReason::kTooShort;
    return false;
  }
  if (in.size() > body_out.size() + kSealOverhead || in.size() > kMaxDatagramBytes) {
    why = DropReason::kTooLong;
    return false;
  }
  ByteReader r(in.first(kHeaderBytes));
  std::uint16_t magic = 0;
  std::uint8_t version = 0, type = 0;
  r.u16(magic);
  r.u8(version);
  r.u8(type);
  r.u8(h.sender);
  r.u8(h.dest);
  r.u32(h.epoch);
  r.u48(h.counter);
  if (magic != kWireMagic) {
    why = DropReason::kBadMagic;
    return false;
  }
  if (version != kWireVersion) {
    why = DropReason::kBadVersion;
    return false;
  }
  if (type < 1 || type > 3) {
    why = DropReason::kBadType;
    return false;
  }
  h.type = static_cast<MsgType>(type);
  if (h.sender == kNoRobot) {
    why = DropReason::kBadSender;
    return false;
  }
  if (h.dest != kNoRobot && h.dest != self) {
    why = DropReason::kNotForUs;
    return false;
  }
  std::uint8_t nonce[crypto_aead_chacha20poly1305_IETF_NPUBBYTES];
  nonce_of(h, nonce);
  unsigned long long mlen = 0;
  if (crypto_aead_chacha20poly1305_ietf_decrypt(body_out.data(), &mlen, nullptr, in.data() + kHeaderBytes,
                                                in.size() - kHeaderBytes, in.data(), kHeaderBytes, nonce,
                                                key_.data()) != 0) {
    why = DropReason::kForged;
    return false;
  }
  if (h.sender == self) {
    why = DropReason::kOwnEcho;
    return false;
  }
  if (!guard.accept(h.sender, h.epoch, h.counter)) {
    why = DropReason::kReplayed;
    return false;
  }
  body_len = static_cast<std::size_t>(mlen);
  return true;
}

}  // namespace ag::comms
