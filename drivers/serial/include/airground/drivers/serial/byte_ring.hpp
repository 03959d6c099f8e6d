// A simulated UART's FIFO, for the simulator's in-process device links (the GNSS receiver, the autopilot):
// bytes one side writes and the other reads. The ring is allocated once, at construction; write() takes
// what fits and counts the rest dropped (an overrun); read() hands out what is there. Neither allocates
// nor blocks. One writer and one reader that never run at once (the simulator's lockstep executor).
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace ag::serial {

class ByteRing {
 public:
  explicit ByteRing(std::size_t capacity) : ring_(capacity == 0 ? 1 : capacity, 0) {}
  // Appends what fits of `bytes`; returns how many did (the rest is counted in dropped()).
  std::size_t write(std::span<const std::uint8_t> bytes) noexcept {
    const std::size_t n = std::min(bytes.size(), ring_.size() - size_);
    for (std::size_t i = 0; i < n; ++i) ring_[(head_ + size_ + i) % ring_.size()] = bytes[i];
    size_ += n;
    dropped_ += bytes.size() - n;
    return n;
  }
  // Moves up to buf.size() of the oldest bytes into buf; returns how many.
  std::size_t read(std::span<std::uint8_t> buf) noexcept {
    const std::size_t n = std::min(buf.size(), size_);
    for (std::size_t i = 0; i < n; ++i) buf[i] = ring_[(head_ + i) % ring_.size()];
    head_ = (head_ + n) % ring_.size();
    size_ -= n;
    return n;
  }
  [[nodiscard]] std::size_t size() const noexcept { return size_; }
  [[nodiscard]] std::uint64_t dropped() const noexcept { return dropped_; }

 private:
  std::vector<std::uint8_t> ring_;
  std::size_t head_{0}, size_{0};
  std::uint64_t dropped_{0};
};

}  // namespace ag::serial
