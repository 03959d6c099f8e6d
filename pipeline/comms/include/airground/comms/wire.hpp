// The gossip datagram: a 16-byte clear header, the body sealed with the team key (ChaCha20-Poly1305,
// libsodium), and per-sender replay protection.
//
//   0  magic u16 0x4741 ("AG")    2 version u8 (1)    3 type u8 (1 digest, 2 have, 3 records)
//   4  sender u8 (robot id)       5 dest u8 (255 = everyone)
//   6  epoch u32 (sender's boot epoch)   10 counter u48 (sender's datagram number within the epoch)
//  16  ciphertext of the body ... then the 16-byte Poly1305 tag
// The header is the AEAD's associated data; the nonce is sender | 0 | epoch | counter, unique per key
// because every robot has its own id and its epoch grows with every start (Journal::open).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>

#include "airground/comms/topics.hpp"
#include "airground/platform/result.hpp"

namespace ag::comms {

inline constexpr std::size_t kKeyBytes = 32;
inline constexpr std::size_t kHeaderBytes = 16;
inline constexpr std::size_t kTagBytes = 16;
inline constexpr std::size_t kSealOverhead = kHeaderBytes + kTagBytes;
inline constexpr std::size_t kMaxDatagramBytes = 65507;  // UDP over IPv4
inline constexpr std::uint16_t kWireMagic = 0x4741;
inline constexpr std::uint8_t kWireVersion = 1;

struct TeamKey {
  std::array<std::uint8_t, kKeyBytes> bytes{};
  // 64 hex digits (whitespace around them ignored).
  static Result<TeamKey> from_hex(std::string_view hex, std::string_view origin);
  static Result<TeamKey> load_file(const std::string& path);
};

enum class MsgType : std::uint8_t { kDigest = 1, kHave = 2, kRecords = 3 };

struct DatagramHeader {
  MsgType type{MsgType::kDigest};
  RobotId sender{kNoRobot};
  RobotId dest{kNoRobot};
  std::uint32_t epoch{0};
  std::uint64_t counter{0};  // 48 bits used
};

// Why a datagram (or a part of one) was refused. Counted per reason; names are in the stats.
enum class DropReason : std::uint8_t {
  kTooShort,      // below header + tag
  kTooLong,       // above the receive buffer / MTU
  kBadMagic,      // not ours at all
  kBadVersion,
  kBadType,
  kBadSender,     // sender id 255
  kOwnEcho,       // our own broadcast coming back (expected on a broadcast link; not an attack)
  kNotForUs,      // unicast to another robot
  kForged,        // authentication failed: wrong key, altered bytes, truncated tag
  kReplayed,      // counter already seen, too old for the window, or an older epoch
  kMalformed,     // authentic but its body breaks the format's bounds (a bug or a rogue team member)
  kRecordTooLarge,
  kStoreFull,
  kReassemblyEvicted,  // a partly received record pushed out of the reassembly pool
  kIdClash,       // an authentic datagram with our id that we did not send: two robots share robot.id
  kCount
};
const char* drop_reason_name(DropReason r) noexcept;

// Per sender: the newest epoch, the highest counter in it and a 64-datagram window below it (RFC 6479
// style), so reordered datagrams pass and repeats do not.
class ReplayGuard {
 public:
  static constexpr std::uint64_t kWindow = 64;
  // True if (epoch, counter) was not seen and is not too old; records it. Call only after authentication.
  bool accept(RobotId sender, std::uint32_t epoch, std::uint64_t counter) noexcept;
  void reset() noexcept { peers_ = {}; }

 private:
  struct Window {
    std::uint32_t epoch{0};
    std::uint64_t top{0};
    std::uint64_t bits{0};  // bit i: counter top - i seen
    bool any{false};
  };
  std::array<Window, 256> peers_{};
};

class DatagramCodec {
 public:
  explicit DatagramCodec(const TeamKey& key);
  // Writes header + sealed body into out; returns the datagram size, 0 if it does not fit.
  std::size_t seal(const DatagramHeader& h, std::span<const std::uint8_t> body, std::span<std::uint8_t> out) const noexcept;
  // Checks, authenticates and decrypts `in` into body_out (>= in.size() bytes). On success returns true
  // with h and body_len set; else false with `why`. The replay guard is consulted only for authentic
  // datagrams, so forged ones cannot move its windows. Our own id is checked after authentication
  // (kOwnEcho, h filled in), so the caller can tell its echo from another robot using the same id.
  bool open(std::span<const std::uint8_t> in, RobotId self, ReplayGuard& guard, DatagramHeader& h,
            std::span<std::uint8_t> body_out, std::size_t& body_len, DropReason& why) const noexcept;

 private:
  std::array<std::uint8_t, kKeyBytes> key_{};
};

}  // namespace ag::comms
