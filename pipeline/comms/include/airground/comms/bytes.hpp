// Little-endian byte writer and bounds-checked reader over caller-owned buffers (wire and journal formats).
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>

namespace ag::comms {

class ByteWriter {
 public:
  explicit ByteWriter(std::span<std::uint8_t> out) noexcept : out_(out) {}
  void u8(std::uint8_t v) noexcept { put(&v, 1); }
  void u16(std::uint16_t v) noexcept { le(v, 2); }
  void u32(std::uint32_t v) noexcept { le(v, 4); }
  void u48(std::uint64_t v) noexcept { le(v, 6); }
  void u64(std::uint64_t v) noexcept { le(v, 8); }
  void i64(std::int64_t v) noexcept { le(static_cast<std::uint64_t>(v), 8); }
  void bytes(std::span<const std::uint8_t> b) noexcept { put(b.data(), b.size()); }
  [[nodiscard]] bool ok() const noexcept { return ok_; }
  [[nodiscard]] std::size_t size() const noexcept { return n_; }
  [[nodiscard]] std::size_t room() const noexcept { return out_.size() - n_; }

 private:
  void le(std::uint64_t v, int n) noexcept {
    std::uint8_t b[8];
    for (int i = 0; i < n; ++i) b[i] = static_cast<std::uint8_t>(v >> (8 * i));
    put(b, static_cast<std::size_t>(n));
  }
  void put(const std::uint8_t* p, std::size_t n) noexcept {
    if (!ok_ || n > out_.size() - n_) {
      ok_ = false;
      return;
    }
    if (n) std::memcpy(out_.data() + n_, p, n);
    n_ += n;
  }
  std::span<std::uint8_t> out_;
  std::size_t n_{0};
  bool ok_{true};
};

// Every read checks the remaining length; after the first short read all reads fail and ok() is false.
class ByteReader {
 public:
  explicit ByteReader(std::span<const std::uint8_t> in) noexcept : in_(in) {}
  bool u8(std::uint8_t& v) noexcept {
    std::uint64_t x = 0;
    const bool r = le(x, 1);
    v = static_cast<std::uint8_t>(x);
    return r;
  }
  bool u16(std::uint16_t& v) noexcept {
    std::uint64_t x = 0;
    const bool r = le(x, 2);
    v = static_cast<std::uint16_t>(x);
    return r;
  }
  bool u32(std::uint32_t& v) noexcept {
    std::uint64_t x = 0;
    const bool r = le(x, 4);
    v = static_cast<std::uint32_t>(x);
    return r;
  }
  bool u48(std::uint64_t& v) noexcept { return le(v, 6); }
  bool u64(std::uint64_t& v) noexcept { return le(v, 8); }
  bool i64(std::int64_t& v) noexcept {
    std::uint64_t x = 0;
    const bool r = le(x, 8);
    v = static_cast<std::int64_t>(x);
    return r;
  }
  // A view of the next n bytes (empty and failed if fewer remain).
  std::span<const std::uint8_t> bytes(std::size_t n) noexcept {
    if (!ok_ || n > remaining()) {
      ok_ = false;
      return {};
    }
    auto s = in_.subspan(pos_, n);
    pos_ += n;
    return s;
  }
  [[nodiscard]] bool ok() const noexcept { return ok_; }
  [[nodiscard]] std::size_t remaining() const noexcept { return in_.size() - pos_; }
  [[nodiscard]] std::size_t position() const noexcept { return pos_; }

 private:
  bool le(std::uint64_t& v, std::size_t n) noexcept {
    if (!ok_ || n > remaining()) {
      ok_ = false;
      v = 0;
      return false;
    }
    v = 0;
    for (std::size_t i = 0; i < n; ++i) v |= static_cast<std::uint64_t>(in_[pos_ + i]) << (8 * i);
    pos_ += n;
    return true;
  }
  std::span<const std::uint8_t> in_;
  std::size_t pos_{0};
  bool ok_{true};
};

// CRC-32C (Castagnoli), the journal's entry check.
std::uint32_t crc32c(std::span<const std::uint8_t> data, std::uint32_t crc = 0) noexcept;

}  // namespace ag::comms
