// Latest-value (triple) buffer: one writer, one reader, only the newest value matters, never blocks.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>

#include "airground/platform/cacheline.hpp"

namespace ag {

// Three slots: the writer owns one, the reader owns one, the third is the hand-over. The writer fills
// its slot and swaps it with the hand-over, setting a "fresh" bit; the reader swaps its slot with the
// hand-over when the bit is set. T is held in place; nothing is allocated after construction.
template <typename T>
class LatestValue {
 public:
  LatestValue() = default;
  explicit LatestValue(const T& initial) : slots_{{{initial}, {initial}, {initial}}} {}
  LatestValue(const LatestValue&) = delete;
  LatestValue& operator=(const LatestValue&) = delete;

  // Writer: fill this slot in place, then publish().
  [[nodiscard]] T& write_slot() noexcept { return slots_[write_idx_].value; }
  void publish() noexcept {
    ++published_;
    if (held_) {  // lockstep compute time: handed over at release()
      pending_ = true;
      return;
    }
    hand_over();
  }
  // Writer, lockstep simulator only: publications from now on are handed over at release() (the newest).
  void hold() noexcept { held_ = true; }
  void release() noexcept {
    held_ = false;
    if (pending_) {
      pending_ = false;
      hand_over();
    }
  }
  void write(const T& v) noexcept {
    write_slot() = v;
    publish();
  }

  // Reader: the newest published value (or the initial one). Stays valid until the next read().
  [[nodiscard]] const T& read() noexcept {
    if ((handover_.load(std::memory_order_relaxed) & kFresh) != 0) {
      const std::uint8_t prev = handover_.exchange(read_idx_, std::memory_order_acq_rel);
      read_idx_ = prev & kIndexMask;
    }
    return slots_[read_idx_].value;
  }
  // Reader: true if a value newer than the last read() is waiting.
  [[nodiscard]] bool fresh() const noexcept { return (handover_.load(std::memory_order_acquire) & kFresh) != 0; }
  // Writer side count of publications (for tests and counters).
  [[nodiscard]] std::uint64_t published() const noexcept { return published_; }

 private:
  void hand_over() noexcept {
    const std::uint8_t prev = handover_.exchange(static_cast<std::uint8_t>(write_idx_ | kFresh), std::memory_order_acq_rel);
    write_idx_ = prev & kIndexMask;
  }

  static constexpr std::uint8_t kFresh = 0x4;
  static constexpr std::uint8_t kIndexMask = 0x3;
  struct alignas(kCacheLine) Slot {
    T value{};
  };
  std::array<Slot, 3> slots_{};
  alignas(kFalseSharingRange) std::atomic<std::uint8_t> handover_{1};
  alignas(kFalseSharingRange) std::uint8_t write_idx_{0};
  std::uint64_t published_{0};
  bool held_{false}, pending_{false};  // writer-private
  alignas(kFalseSharingRange) std::uint8_t read_idx_{2};
};

}  // namespace ag
