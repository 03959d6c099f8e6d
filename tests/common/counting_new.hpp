// A replacement of the global operator new/delete that counts the calling thread's allocations inside
// an AllocationWindow: how the no-allocation tests prove that real-time calls never allocate. It defines
// the replacement functions, so include it from exactly one file of a test executable.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <new>

namespace ag::test_alloc {
inline std::atomic<std::uint64_t> g_allocations{0};
inline thread_local bool t_counting = false;  // only the test thread, only inside an AllocationWindow

inline void* allocate(std::size_t n) {
  if (t_counting) g_allocations.fetch_add(1, std::memory_order_relaxed);
  return std::malloc(n == 0 ? 1 : n);
}
inline void* allocate_aligned(std::size_t n, std::align_val_t al) {
  if (t_counting) g_allocations.fetch_add(1, std::memory_order_relaxed);
  const std::size_t a = std::max(static_cast<std::size_t>(al), sizeof(void*));
  void* p = nullptr;
  return posix_memalign(&p, a, n == 0 ? 1 : n) == 0 ? p : nullptr;
}

// Counts operator new calls made by this thread while it lives.
class AllocationWindow {
 public:
  AllocationWindow() noexcept : start_(g_allocations.load(std::memory_order_relaxed)) { t_counting = true; }
  ~AllocationWindow() { t_counting = false; }
  AllocationWindow(const AllocationWindow&) = delete;
  AllocationWindow& operator=(const AllocationWindow&) = delete;
  [[nodiscard]] std::uint64_t allocations() const noexcept { return g_allocations.load(std::memory_order_relaxed) - start_; }

 private:
  std::uint64_t start_{0};
};
}  // namespace ag::test_alloc

// GCC sees free() on memory from an operator new it inlined; for a replacement pair that is the point.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
void* operator new(std::size_t n) {
  if (void* p = ag::test_alloc::allocate(n)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n) {
  if (void* p = ag::test_alloc::allocate(n)) return p;
  throw std::bad_alloc();
}
void* operator new(std::size_t n, const std::nothrow_t&) noexcept { return ag::test_alloc::allocate(n); }
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept { return ag::test_alloc::allocate(n); }
void* operator new(std::size_t n, std::align_val_t al) {
  if (void* p = ag::test_alloc::allocate_aligned(n, al)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n, std::align_val_t al) {
  if (void* p = ag::test_alloc::allocate_aligned(n, al)) return p;
  throw std::bad_alloc();
}
void* operator new(std::size_t n, std::align_val_t al, const std::nothrow_t&) noexcept {
  return ag::test_alloc::allocate_aligned(n, al);
}
void* operator new[](std::size_t n, std::align_val_t al, const std::nothrow_t&) noexcept {
  return ag::test_alloc::allocate_aligned(n, al);
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t, const std::nothrow_t&) noexcept { std::free(p); }
#pragma GCC diagnostic pop
