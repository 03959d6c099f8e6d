// V4L2 mmap streaming.
#include "airground/drivers/camera/v4l2/camera.hpp"

#include <fcntl.h>
#include <linux/videodev2.h>
#include <sys/mman.h>

#include <cerrno>
#include <cstring>

#include "airground/platform/clock.hpp"

namespace ag::v4l2 {

const char* to_string(PixelFormat f) noexcept {
  switch (f) {
    case PixelFormat::kGrey: return "GREY";
    case PixelFormat::kYuyv: return "YUYV";
    case PixelFormat::kBayerRggb8: return "RGGB8";
    case PixelFormat::kBayerGrbg8: return "GRBG8";
  }
  return "?";
}

Result<PixelFormat> parse_pixel_format(const std::string& t) {
  for (PixelFormat f : {PixelFormat::kGrey, PixelFormat::kYuyv, PixelFormat::kBayerRggb8, PixelFormat::kBayerGrbg8})
    if (t == to_string(f)) return f;
  return Error::make(ErrorCode::kConfig, "camera pixel format '" + t + "' is not one of GREY, YUYV, RGGB8, GRBG8");
}

std::uint32_t fourcc(PixelFormat f) noexcept {
  switch (f) {
    case PixelFormat::kGrey: return V4L2_PIX_FMT_GREY;
    case PixelFormat::kYuyv: return V4L2_PIX_FMT_YUYV;
    case PixelFormat::kBayerRggb8: return V4L2_PIX_FMT_SRGGB8;
    case PixelFormat::kBayerGrbg8: return V4L2_PIX_FMT_SGRBG8;
  }
  return 0;
}

namespace {
std::uint32_t bytes_per_pixel(PixelFormat f) noexcept { return f == PixelFormat::kYuyv ? 2 : 1; }
}  // namespace

Result<std::unique_ptr<Camera>> Camera::open(const CameraConfig& cfg, Syscalls& sys) {
  std::unique_ptr<Camera> cam(new Camera(sys));
  const std::string& dev = cfg.device;
  auto err = [&](const std::string& what, int e) {
    return Error::make(e == EACCES || e == EPERM ? ErrorCode::kPermission : ErrorCode::kUnavailable,
                       "camera " + dev + ": " + what + (e != 0 ? std::string(": ") + std::strerror(e) : std::string()));
  };
  if (cfg.buffers < 2 || cfg.buffers > kMaxBuffers) return Error::make(ErrorCode::kConfig, "camera " + dev + ": buffers must be 2..16");
  if (cfg.fps == 0) return Error::make(ErrorCode::kConfig, "camera " + dev + ": fps must be > 0");
  cam->fd_ = sys.open(dev.c_str(), O_RDWR | O_NONBLOCK | O_CLOEXEC);
  if (cam->fd_ < 0) return err("open", errno);

  v4l2_capability cap{};
  if (sys.ioctl(cam->fd_, VIDIOC_QUERYCAP, &cap) != 0) return err("VIDIOC_QUERYCAP (not a V4L2 device?)", errno);
  const std::uint32_t caps = (cap.capabilities & V4L2_CAP_DEVICE_CAPS) != 0 ? cap.device_caps : cap.capabilities;
  if ((caps & V4L2_CAP_VIDEO_CAPTURE) == 0) return err("not a single-planar video capture device", 0);
  if ((caps & V4L2_CAP_STREAMING) == 0) return err("no streaming I/O (mmap)", 0);

  v4l2_format fmt{};
  fmt.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  fmt.fmt.pix.width = cfg.width;
  fmt.fmt.pix.height = cfg.height;
  fmt.fmt.pix.pixelformat = fourcc(cfg.format);
  fmt.fmt.pix.field = V4L2_FIELD_NONE;
  if (sys.ioctl(cam->fd_, VIDIOC_S_FMT, &fmt) != 0) return err("VIDIOC_S_FMT", errno);
  if (fmt.fmt.pix.pixelformat != fourcc(cfg.format)) return err(std::string("pixel format ") + to_string(cfg.format) + " not supported", 0);
  // The driver's values rule: it may round the size and pad the lines.
  cam->format_ = cfg.format;
  cam->width_ = fmt.fmt.pix.width;
  cam->height_ = fmt.fmt.pix.height;
  const std::uint32_t min_stride = cam->width_ * bytes_per_pixel(cfg.format);
  cam->stride_ = fmt.fmt.pix.bytesperline >= min_stride ? fmt.fmt.pix.bytesperline : min_stride;
  cam->size_ = fmt.fmt.pix.sizeimage >= cam->stride_ * cam->height_ ? fmt.fmt.pix.sizeimage : cam->stride_ * cam->height_;
  if (cam->width_ == 0 || cam->height_ == 0) return err("VIDIOC_S_FMT gave a 0 x 0 image", 0);

  v4l2_streamparm parm{};
  parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  parm.parm.capture.timeperframe.numerator = 1;
  parm.parm.capture.timeperframe.denominator = cfg.fps;
  if (sys.ioctl(cam->fd_, VIDIOC_S_PARM, &parm) == 0 && parm.parm.capture.timeperframe.denominator != 0)
    cam->interval_s_ = static_cast<double>(parm.parm.capture.timeperframe.numerator) / parm.parm.capture.timeperframe.denominator;
  else
    cam->interval_s_ = 1.0 / cfg.fps;  // devices without frame-interval control run at their own rate

  cam->exposure_ = cfg.exposure;
  v4l2_control ctrl{};
  ctrl.id = V4L2_CID_EXPOSURE_ABSOLUTE;  // [100 us]
  if (sys.ioctl(cam->fd_, VIDIOC_G_CTRL, &ctrl) == 0 && ctrl.value > 0) cam->exposure_ = static_cast<TimeNs>(ctrl.value) * 100 * kNsPerUs;
  cam->readout_ = cfg.readout;

  v4l2_requestbuffers req{};
  req.count = cfg.buffers;
  req.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  req.memory = V4L2_MEMORY_MMAP;
  if (sys.ioctl(cam->fd_, VIDIOC_REQBUFS, &req) != 0) return err("VIDIOC_REQBUFS", errno);
  if (req.count < 2) return err("the driver granted fewer than 2 buffers", 0);
  cam->nbuf_ = req.count > kMaxBuffers ? kMaxBuffers : req.count;
  for (std::uint32_t i = 0; i < cam->nbuf_; ++i) {
    v4l2_buffer b{};
    b.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    b.memory = V4L2_MEMORY_MMAP;
    b.index = i;
    if (sys.ioctl(cam->fd_, VIDIOC_QUERYBUF, &b) != 0) return err("VIDIOC_QUERYBUF " + std::to_string(i), errno);
    void* p = sys.mmap(b.length, PROT_READ | PROT_WRITE, MAP_SHARED, cam->fd_, static_cast<off_t>(b.m.offset));
    if (p == MAP_FAILED) return err("mmap buffer " + std::to_string(i), errno);
    cam->maps_[i] = p;
    cam->lengths_[i] = b.length;
    if (sys.ioctl(cam->fd_, VIDIOC_QBUF, &b) != 0) return err("VIDIOC_QBUF " + std::to_string(i), errno);
  }
  int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  if (sys.ioctl(cam->fd_, VIDIOC_STREAMON, &type) != 0) return err("VIDIOC_STREAMON", errno);
  cam->streaming_ = true;
  cam->epfd_ = sys.epoll_create1(EPOLL_CLOEXEC);
  if (cam->epfd_ < 0) return err("epoll_create1", errno);
  epoll_event ev{};
  ev.events = EPOLLIN;
  ev.data.fd = cam->fd_;
  if (sys.epoll_ctl(cam->epfd_, EPOLL_CTL_ADD, cam->fd_, &ev) != 0) return err("epoll_ctl", errno);
  cam->state_ = State::kStreaming;
  return cam;
}

Camera::~Camera() {
  if (streaming_) {
    int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    (void)sys_.ioctl(fd_, VIDIOC_STREAMOFF, &type);
  }
  for (std::uint32_t i = 0; i < kMaxBuffers; ++i)
    if (maps_[i] != nullptr) (void)sys_.munmap(maps_[i], lengths_[i]);
  if (epfd_ >= 0) (void)sys_.close(epfd_);
  if (fd_ >= 0) (void)sys_.close(fd_);
}

void Camera::fail(const char* what, int e) noexcept {
  state_ = State::kFailed;
  if (error_.empty()) {
    try {
      error_ = std::string("camera: ") + what + ": " + std::strerror(e);
    } catch (...) {
    }
  }
}

CaptureResult Camera::next(TimeNs timeout, Frame& out) noexcept {
  if (state_ != State::kStreaming) return CaptureResult::kError;
  const int ms = timeout <= 0 ? 0 : static_cast<int>((timeout + kNsPerMs - 1) / kNsPerMs);
  for (int rounds = 0; rounds < static_cast<int>(kMaxBuffers) + 2; ++rounds) {
    epoll_event ev{};
    const int n = sys_.epoll_wait(epfd_, &ev, 1, rounds == 0 ? ms : 0);
    if (n < 0) {
      if (errno == EINTR) continue;
      fail("epoll_wait", errno);
      return CaptureResult::kError;
    }
    if (n == 0) {
      if (rounds == 0) ++c_.timeouts;
      return CaptureResult::kTimeout;
    }
    v4l2_buffer b{};
    b.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    b.memory = V4L2_MEMORY_MMAP;
    if (sys_.ioctl(fd_, VIDIOC_DQBUF, &b) != 0) {
      if (errno == EAGAIN) {
        ++c_.would_block;
        continue;
      }
      fail("VIDIOC_DQBUF", errno);
      return CaptureResult::kError;
    }
    if (b.index >= nbuf_) {
      fail("VIDIOC_DQBUF returned a buffer index out of range", EINVAL);
      return CaptureResult::kError;
    }
    // Sequence numbers count every frame the sensor made, good or not: gaps are frames dropped.
    if (have_seq_ && b.sequence != next_seq_) c_.dropped += static_cast<std::uint32_t>(b.sequence - next_seq_);
    have_seq_ = true;
    next_seq_ = b.sequence + 1;
    if ((b.flags & V4L2_BUF_FLAG_ERROR) != 0 || b.bytesused < size_) {
      if ((b.flags & V4L2_BUF_FLAG_ERROR) != 0) ++c_.error_buffers;
      else ++c_.short_buffers;
      if (sys_.ioctl(fd_, VIDIOC_QBUF, &b) != 0) {
        fail("VIDIOC_QBUF", errno);
        return CaptureResult::kError;
      }
      continue;
    }
    TimeNs t = static_cast<TimeNs>(b.timestamp.tv_sec) * kNsPerS + static_cast<TimeNs>(b.timestamp.tv_usec) * kNsPerUs;
    if ((b.flags & V4L2_BUF_FLAG_TIMESTAMP_MASK) != V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC) {
      t = monotonic_now();  // a driver without monotonic stamps: the dequeue time (end of frame at best)
      ++c_.restamped;
      b.flags &= ~static_cast<std::uint32_t>(V4L2_BUF_FLAG_TSTAMP_SRC_MASK);
    }
    // Drivers stamp start of exposure (SOE) or end of frame (EOF, the default): move it to mid-exposure.
    if ((b.flags & V4L2_BUF_FLAG_TSTAMP_SRC_MASK) == V4L2_BUF_FLAG_TSTAMP_SRC_SOE) t += exposure_ / 2;
    else t -= readout_ + exposure_ / 2;
    if (t < last_stamp_) ++c_.stamp_backwards;
    last_stamp_ = t;
    out.data = std::span<const std::uint8_t>(static_cast<const std::uint8_t*>(maps_[b.index]), b.bytesused);
    out.width = width_;
    out.height = height_;
    out.stride = stride_;
    out.format = format_;
    out.sequence = b.sequence;
    out.stamp = t;
    out.index = b.index;
    ++c_.frames;
    return CaptureResult::kFrame;
  }
  return CaptureResult::kTimeout;
}

void Camera::release(const Frame& f) noexcept {
  if (state_ != State::kStreaming || f.index >= nbuf_) return;
  v4l2_buffer b{};
  b.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  b.memory = V4L2_MEMORY_MMAP;
  b.index = f.index;
  if (sys_.ioctl(fd_, VIDIOC_QBUF, &b) != 0) fail("VIDIOC_QBUF", errno);
}

}  // namespace ag::v4l2
