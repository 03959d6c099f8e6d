// Single-producer single-consumer ring: fixed capacity, lock-free, used in place through front()/pop().
#pragma once

#include <atomic>
#include <cassert>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <type_traits>
#include <utility>

#include "airground/platform/cacheline.hpp"

namespace ag {

// Capacity is exact: that many elements fit. Indices run free (64-bit, they never wrap in practice)
// and each side caches the other's index so the common case touches only its own cache line. The
// slot array is the next power of two above Capacity plus a slack of two cache lines, so that even a
// full ring never has the producer writing into the line the consumer is reading. Storage is
// allocated once in the constructor (start-up), never after. Only the lockstep simulator holds a ring:
// between hold() and release() pushes fill slots the consumer cannot see yet (a stage's outputs become
// visible when its modelled compute time has passed); the robot's executor never holds.
template <typename T, std::size_t Capacity>
class SpscRing {
  static_assert(Capacity >= 1, "capacity must be at least 1");
  static_assert(std::is_nothrow_destructible_v<T>);

 public:
  using value_type = T;

  SpscRing() : slots_(static_cast<Slot*>(::operator new(sizeof(Slot) * kSlots, std::align_val_t{alignof(Slot)}))) {}
  SpscRing(const SpscRing&) = delete;
  SpscRing& operator=(const SpscRing&) = delete;
  ~SpscRing() {
    while (front() != nullptr) pop();
    ::operator delete(slots_, std::align_val_t{alignof(Slot)});
  }

  static constexpr std::size_t capacity() noexcept { return Capacity; }

  // Producer side. Returns false (and leaves the ring untouched) when full.
  template <typename... Args>
  [[nodiscard]] bool try_emplace(Args&&... args) noexcept(std::is_nothrow_constructible_v<T, Args&&...>) {
    const std::uint64_t w = prod_.pushed;
    if (w - prod_.cached_read >= Capacity) {
      prod_.cached_read = cons_.read.load(std::memory_order_acquire);
      if (w - prod_.cached_read >= Capacity) return false;
    }
    ::new (static_cast<void*>(&slots_[w & kMask])) T(std::forward<Args>(args)...);
    prod_.pushed = w + 1;
    if (!prod_.held) prod_.write.store(w + 1, std::memory_order_release);
    return true;
  }
  [[nodiscard]] bool try_push(const T& v) noexcept(std::is_nothrow_copy_constructible_v<T>) { return try_emplace(v); }
  [[nodiscard]] bool try_push(T&& v) noexcept(std::is_nothrow_move_constructible_v<T>) { return try_emplace(std::move(v)); }

  // Producer side: pushes from now on stay invisible to the consumer until release().
  void hold() noexcept { prod_.held = true; }
  // Producer side: what was pushed while held becomes visible, in order; pushes are visible again.
  void release() noexcept {
    prod_.held = false;
    prod_.write.store(prod_.pushed, std::memory_order_release);
  }
  // Producer side, exact: elements pushed (held ones included) and not yet popped, as far as it knows.
  [[nodiscard]] std::size_t unread_from_producer() const noexcept {
    return static_cast<std::size_t>(prod_.pushed - cons_.read.load(std::memory_order_acquire));
  }

  // Consumer side: the oldest element, or nullptr when empty. Valid until pop().
  [[nodiscard]] T* front() noexcept {
    const std::uint64_t r = cons_.read.load(std::memory_order_relaxed);
    if (r == cons_.cached_write) {
      cons_.cached_write = prod_.write.load(std::memory_order_acquire);
      if (r == cons_.cached_write) return nullptr;
    }
    return std::launder(reinterpret_cast<T*>(&slots_[r & kMask]));
  }
  // Destroys the front element; only call after front() returned non-null.
  void pop() noexcept {
    const std::uint64_t r = cons_.read.load(std::memory_order_relaxed);
    assert(r != cons_.cached_write && "pop() without a successful front()");
    std::launder(reinterpret_cast<T*>(&slots_[r & kMask]))->~T();
    cons_.read.store(r + 1, std::memory_order_release);
  }

  // Approximate from any thread; exact from either side when the other is idle.
  [[nodiscard]] std::size_t size() const noexcept {
    const std::uint64_t r = cons_.read.load(std::memory_order_acquire);
    const std::uint64_t w = prod_.write.load(std::memory_order_acquire);
    return static_cast<std::size_t>(w - r);
  }
  [[nodiscard]] bool empty() const noexcept { return size() == 0; }

 private:
  struct Slot {
    alignas(T) std::byte bytes[sizeof(T)];
  };
  static constexpr std::size_t kSlack = (2 * kFalseSharingRange + sizeof(Slot) - 1) / sizeof(Slot);
  static constexpr std::size_t kSlots = std::bit_ceil(Capacity + kSlack);
  static constexpr std::uint64_t kMask = kSlots - 1;
  struct alignas(kFalseSharingRange) ProducerSide {
    std::atomic<std::uint64_t> write{0};  // published: what the consumer may read
    std::uint64_t pushed{0};              // producer-private: == write unless held
    std::uint64_t cached_read{0};
    bool held{false};
  };
  struct alignas(kFalseSharingRange) ConsumerSide {
    std::atomic<std::uint64_t> read{0};
    std::uint64_t cached_write{0};
  };

  ProducerSide prod_;
  ConsumerSide cons_;
  Slot* const slots_;
};

}  // namespace ag
