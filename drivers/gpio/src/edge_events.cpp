// Fake edge line (eventfd) and the e-stop edge reader.
#include "airground/drivers/gpio/edge_events.hpp"

#include <sys/eventfd.h>
#include <unistd.h>

namespace ag::gpio {

FakeEdgeLine::FakeEdgeLine() : efd_(::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC)) {}

FakeEdgeLine::~FakeEdgeLine() {
  if (efd_ >= 0) ::close(efd_);
}

void FakeEdgeLine::press(bool active, TimeNs stamp) noexcept {
  if (active == level_) return;  // no edge
  level_ = active;
  if (size_ == kQueue) {  // the kernel's event buffer overflows the same way: oldest lost
    head_ = (head_ + 1) % kQueue;
    --size_;
    ++overruns_;
  }
  q_[(head_ + size_) % kQueue] = EdgeEvent{active ? Edge::kRising : Edge::kFalling, stamp};
  ++size_;
  const std::uint64_t one = 1;
  (void)!::write(efd_, &one, sizeof one);
}

int FakeEdgeLine::read_events(std::span<EdgeEvent> out) noexcept {
  std::uint64_t n = 0;
  (void)!::read(efd_, &n, sizeof n);  // clears the fd's readiness (EAGAIN when already clear)
  std::size_t k = 0;
  while (k < out.size() && size_ > 0) {
    out[k++] = q_[head_];
    head_ = (head_ + 1) % kQueue;
    --size_;
  }
  if (size_ > 0) {  // more than fit: stay readable
    const std::uint64_t one = 1;
    (void)!::write(efd_, &one, sizeof one);
  }
  return static_cast<int>(k);
}

bool EStopEdges::drain() noexcept {
  tapped_ = pressed_;
  std::array<EdgeEvent, 16> ev{};
  for (;;) {
    const int n = src_.read_events(ev);
    if (n < 0) {
      pressed_ = true;
      tapped_ = true;
      return false;
    }
    for (int i = 0; i < n; ++i) {
      const EdgeEvent& e = ev[static_cast<std::size_t>(i)];
      pressed_ = e.edge == Edge::kRising;
      tapped_ = tapped_ || pressed_;
      last_ = e.stamp;
      ++edges_;
    }
    if (n < static_cast<int>(ev.size())) return true;
  }
}

}  // namespace ag::gpio
