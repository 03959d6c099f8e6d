// A V4L2 capture device in memory behind the system-call seam: it answers the ioctls the driver makes,
// owns the "mmap" buffers, and plays a script of dequeue events (frames with a counter pattern, EAGAIN,
// error-flagged buffers, sequence gaps, short buffers, a failing device) so the driver can be tested
// without /dev/video.
#pragma once

#include <linux/videodev2.h>
#include <sys/mman.h>

#include <cerrno>
#include <cstdint>
#include <cstring>
#include <deque>
#include <string>
#include <vector>

#include "airground/drivers/camera/v4l2/syscalls.hpp"

namespace ag::v4l2::testing {

struct FakeEvent {
  enum class Kind { kFrame, kEagain, kError } kind{Kind::kFrame};  // kError: DQBUF fails with EIO (unplugged)
  std::uint32_t sequence{0};
  std::int64_t stamp_us{0};
  std::uint32_t flags{V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC | V4L2_BUF_FLAG_TSTAMP_SRC_SOE};
  bool short_buffer{false};
};

class FakeDevice final : public Syscalls {
 public:
  std::string path{"/dev/video0"};
  std::uint32_t caps{V4L2_CAP_VIDEO_CAPTURE | V4L2_CAP_STREAMING};
  std::uint32_t supported_fourcc{V4L2_PIX_FMT_YUYV};
  std::uint32_t line_padding{64};     // the driver pads each line (stride > width * bpp)
  std::uint32_t granted_buffers{0};   // 0 = as requested
  std::int32_t exposure_100us{50};    // 5 ms; 0 = no exposure control
  std::vector<std::uint8_t> line;     // non-empty: every line of every frame starts with these bytes (a known picture)
  std::deque<FakeEvent> script;
  // Observations.
  int streamon{0}, streamoff{0}, closes{0}, unmaps{0}, qbufs{0};
  std::uint32_t width{0}, height{0}, stride{0}, fourcc{0};
  std::vector<std::vector<std::uint8_t>> buffers;
  std::deque<std::uint32_t> queued;

  static constexpr int kFd = 42, kEpfd = 43;

  int open(const char* p, int) noexcept override {
    if (path != p) {
      errno = ENOENT;
      return -1;
    }
    return kFd;
  }
  int close(int) noexcept override {
    ++closes;
    return 0;
  }
  void* mmap(std::size_t length, int, int, int fd, off_t offset) noexcept override {
    const auto i = static_cast<std::size_t>(offset) / 4096;
    if (fd != kFd || i >= buffers.size() || length != buffers[i].size()) {
      errno = EINVAL;
      return MAP_FAILED;
    }
    return buffers[i].data();
  }
  int munmap(void*, std::size_t) noexcept override {
    ++unmaps;
    return 0;
  }
  int epoll_create1(int) noexcept override { return kEpfd; }
  int epoll_ctl(int, int, int, epoll_event*) noexcept override { return 0; }
  int epoll_wait(int, epoll_event* ev, int, int) noexcept override {
    if (script.empty()) return 0;  // nothing more: a timeout
    ev->events = EPOLLIN;
    ev->data.fd = kFd;
    return 1;
  }
  int ioctl(int fd, unsigned long req, void* arg) noexcept override {
    if (fd != kFd) {
      errno = EBADF;
      return -1;
    }
    switch (req) {
      case VIDIOC_QUERYCAP: {
        auto* c = static_cast<v4l2_capability*>(arg);
        std::memcpy(c->driver, "fake", 5);
        c->capabilities = caps | V4L2_CAP_DEVICE_CAPS;
        c->device_caps = caps;
        return 0;
      }
      case VIDIOC_S_FMT: {
        auto* f = static_cast<v4l2_format*>(arg);
        if (f->fmt.pix.pixelformat != supported_fourcc) f->fmt.pix.pixelformat = supported_fourcc;  // drivers substitute
        width = f->fmt.pix.width & ~15u;  // and round the size
        height = f->fmt.pix.height;
        fourcc = f->fmt.pix.pixelformat;
        const std::uint32_t bpp = fourcc == V4L2_PIX_FMT_YUYV ? 2 : 1;
        stride = width * bpp + line_padding;
        f->fmt.pix.width = width;
        f->fmt.pix.bytesperline = stride;
        f->fmt.pix.sizeimage = stride * height;
        return 0;
      }
      case VIDIOC_S_PARM: {
        auto* p = static_cast<v4l2_streamparm*>(arg);
        p->parm.capture.timeperframe = {1, 25};  // the device runs at 25 fps whatever was asked
        return 0;
      }
      case VIDIOC_G_CTRL: {
        auto* c = static_cast<v4l2_control*>(arg);
        if (c->id != V4L2_CID_EXPOSURE_ABSOLUTE || exposure_100us == 0) {
          errno = EINVAL;
          return -1;
        }
        c->value = exposure_100us;
        return 0;
      }
      case VIDIOC_REQBUFS: {
        auto* r = static_cast<v4l2_requestbuffers*>(arg);
        if (r->memory != V4L2_MEMORY_MMAP) {
          errno = EINVAL;
          return -1;
        }
        if (granted_buffers != 0) r->count = granted_buffers;
        buffers.assign(r->count, std::vector<std::uint8_t>(static_cast<std::size_t>(stride) * height));
        return 0;
      }
      case VIDIOC_QUERYBUF: {
        auto* b = static_cast<v4l2_buffer*>(arg);
        if (b->index >= buffers.size()) {
          errno = EINVAL;
          return -1;
        }
        b->length = static_cast<std::uint32_t>(buffers[b->index].size());
        b->m.offset = b->index * 4096;
        return 0;
      }
      case VIDIOC_QBUF: {
        auto* b = static_cast<v4l2_buffer*>(arg);
        for (std::uint32_t q : queued)
          if (q == b->index) {
            errno = EINVAL;  // queued twice: a driver bug the test must catch
            return -1;
          }
        queued.push_back(b->index);
        ++qbufs;
        return 0;
      }
      case VIDIOC_DQBUF: {
        if (script.empty() || queued.empty()) {
          errno = EAGAIN;
          return -1;
        }
        const FakeEvent e = script.front();
        script.pop_front();
        if (e.kind == FakeEvent::Kind::kEagain || e.kind == FakeEvent::Kind::kError) {
          errno = e.kind == FakeEvent::Kind::kError ? EIO : EAGAIN;
          return -1;
        }
        auto* b = static_cast<v4l2_buffer*>(arg);
        b->index = queued.front();
        queued.pop_front();
        fill(buffers[b->index], e.sequence);
        b->sequence = e.sequence;
        b->flags = e.flags;
        b->bytesused = e.short_buffer ? stride * height / 2 : stride * height;
        b->timestamp.tv_sec = e.stamp_us / 1'000'000;
        b->timestamp.tv_usec = e.stamp_us % 1'000'000;
        return 0;
      }
      case VIDIOC_STREAMON: ++streamon; return 0;
      case VIDIOC_STREAMOFF:  // as in V4L2: every buffer leaves the queue
        ++streamoff;
        queued.clear();
        return 0;
      default: errno = ENOTTY; return -1;
    }
  }

  // The frame counter in the first 4 bytes of every line, the rest a ramp.
  void fill(std::vector<std::uint8_t>& b, std::uint32_t seq) const noexcept {
    for (std::uint32_t y = 0; y < height; ++y) {
      std::uint8_t* row = b.data() + static_cast<std::size_t>(y) * stride;
      if (!line.empty()) {
        std::memcpy(row, line.data(), line.size() < stride ? line.size() : stride);
        continue;
      }
      std::memcpy(row, &seq, 4);
      for (std::uint32_t x = 4; x < stride; ++x) row[x] = static_cast<std::uint8_t>(x + y);
    }
  }
};

}  // namespace ag::v4l2::testing
