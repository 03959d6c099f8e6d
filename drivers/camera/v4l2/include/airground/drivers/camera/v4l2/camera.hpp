// A V4L2 camera streaming through mmap buffers: QUERYCAP, S_FMT (the driver's stride and image size
// read back), S_PARM (frame interval), REQBUFS/QUERYBUF/mmap, QBUF, STREAMON, then epoll + DQBUF.
// Buffers the driver flags V4L2_BUF_FLAG_ERROR are requeued and counted, gaps in the sequence numbers
// are counted as dropped frames, and stamps are moved to mid-exposure on CLOCK_MONOTONIC.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "airground/drivers/camera/v4l2/syscalls.hpp"
#include "airground/platform/result.hpp"
#include "airground/platform/time.hpp"

namespace ag::v4l2 {

enum class PixelFormat : std::uint8_t { kGrey = 0, kYuyv = 1, kBayerRggb8 = 2, kBayerGrbg8 = 3 };
const char* to_string(PixelFormat f) noexcept;
Result<PixelFormat> parse_pixel_format(const std::string& text);  // "GREY", "YUYV", "RGGB8", "GRBG8"
[[nodiscard]] std::uint32_t fourcc(PixelFormat f) noexcept;        // V4L2_PIX_FMT_*

struct CameraConfig {
  std::string device{"/dev/video0"};
  std::uint32_t width{1280}, height{720};
  PixelFormat format{PixelFormat::kYuyv};
  std::uint32_t fps{30};
  std::uint32_t buffers{4};          // mmap buffers requested (the driver may grant more)
  TimeNs exposure{0};                // [ns] when the device has no V4L2_CID_EXPOSURE_ABSOLUTE; 0 = none
  TimeNs readout{0};                 // [ns] sensor readout, for end-of-frame stamps
};

struct Frame {
  std::span<const std::uint8_t> data;   // the mmap buffer, bytesused long; valid until release()
  std::uint32_t width{0}, height{0}, stride{0};
  PixelFormat format{PixelFormat::kGrey};
  std::uint32_t sequence{0};
  TimeNs stamp{0};                      // [ns] CLOCK_MONOTONIC, mid-exposure
  std::uint32_t index{0};               // buffer index (for release)
};

enum class CaptureResult : std::uint8_t { kFrame = 0, kTimeout = 1, kError = 2 };

struct CameraCounters {
  std::uint64_t frames{0};
  std::uint64_t dropped{0};          // frames missing from the sequence numbers
  std::uint64_t error_buffers{0};    // V4L2_BUF_FLAG_ERROR: discarded
  std::uint64_t short_buffers{0};    // bytesused below the image size: discarded
  std::uint64_t would_block{0};      // DQBUF EAGAIN after a wake-up
  std::uint64_t timeouts{0};
  std::uint64_t stamp_backwards{0};  // a stamp before the previous one (kept, counted)
  std::uint64_t restamped{0};        // the driver's stamps are not CLOCK_MONOTONIC: dequeue time used
};

class Camera {
 public:
  enum class State : std::uint8_t { kStreaming = 0, kFailed = 1 };
  static constexpr std::uint32_t kMaxBuffers = 16;

  // Opens, configures and starts streaming; the error names the device and the ioctl that failed.
  static Result<std::unique_ptr<Camera>> open(const CameraConfig& cfg, Syscalls& sys = linux_syscalls());
  ~Camera();
  Camera(const Camera&) = delete;
  Camera& operator=(const Camera&) = delete;

  // Waits up to `timeout` for the next good frame. Never allocates.
  CaptureResult next(TimeNs timeout, Frame& out) noexcept;
  // Gives the frame's buffer back to the driver.
  void release(const Frame& f) noexcept;

  [[nodiscard]] const CameraCounters& counters() const noexcept { return c_; }
  [[nodiscard]] State state() const noexcept { return state_; }
  [[nodiscard]] const std::string& error() const noexcept { return error_; }
  [[nodiscard]] std::uint32_t width() const noexcept { return width_; }
  [[nodiscard]] std::uint32_t height() const noexcept { return height_; }
  [[nodiscard]] std::uint32_t stride() const noexcept { return stride_; }
  [[nodiscard]] std::uint32_t image_size() const noexcept { return size_; }
  [[nodiscard]] std::uint32_t buffer_count() const noexcept { return nbuf_; }
  [[nodiscard]] double frame_interval_s() const noexcept { return interval_s_; }
  [[nodiscard]] TimeNs exposure() const noexcept { return exposure_; }
  [[nodiscard]] int epoll_fd() const noexcept { return epfd_; }

 private:
  explicit Camera(Syscalls& sys) : sys_(sys) {}
  void fail(const char* what, int err) noexcept;
  Syscalls& sys_;
  int fd_{-1}, epfd_{-1};
  State state_{State::kFailed};
  PixelFormat format_{PixelFormat::kGrey};
  std::uint32_t width_{0}, height_{0}, stride_{0}, size_{0}, nbuf_{0};
  double interval_s_{0};
  TimeNs exposure_{0}, readout_{0}, last_stamp_{0};
  std::array<void*, kMaxBuffers> maps_{};
  std::array<std::size_t, kMaxBuffers> lengths_{};
  bool have_seq_{false};
  std::uint32_t next_seq_{0};
  bool streaming_{false};
  CameraCounters c_;
  std::string error_;
};

// Pixel conversion (OpenCV's conventions: BGR byte order, BT.601 limited range for YUYV, bilinear
// demosaic). out must hold width*height*3 (BGR) or width*height (grey) bytes.
void to_bgr(const Frame& f, std::uint8_t* bgr) noexcept;
void to_grey(const Frame& f, std::uint8_t* grey) noexcept;

}  // namespace ag::v4l2
