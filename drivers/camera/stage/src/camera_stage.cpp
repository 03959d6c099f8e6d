// The camera stage: a V4L2 device or a frame-stream replay onto "camera" and "visual_odometry".
#include "airground/drivers/camera/stage/camera_stage.hpp"

#include <fcntl.h>
#include <sys/stat.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>

#include "airground/messages/channels.hpp"
#include "airground/platform/log.hpp"

namespace ag::camera {

namespace {
constexpr TimeNs kCameraRetry = 2 * kNsPerS;
constexpr TimeNs kReplayRetry = kNsPerS;
constexpr TimeNs kFaultLogEvery = kNsPerS;
v4l2::Syscalls* g_test_syscalls = nullptr;

unsigned long long ull(std::uint64_t v) noexcept { return static_cast<unsigned long long>(v); }
}  // namespace

// --- resampling -----------------------------------------------------------------------------------

void AreaResampler::taps(std::uint32_t n, std::uint32_t m, std::vector<Tap>& out, std::vector<std::uint32_t>& first) {
  out.clear();
  first.assign(m + 1, 0);
  const double s = static_cast<double>(n) / m;
  for (std::uint32_t i = 0; i < m; ++i) {
    first[i] = static_cast<std::uint32_t>(out.size());
    if (s <= 1.0) {
      // Enlarging: the two source pixels around the output pixel's centre.
      const double c = std::clamp((i + 0.5) * s - 0.5, 0.0, static_cast<double>(n - 1));
      const auto j = static_cast<std::uint32_t>(c);
      const double t = c - j;
      out.push_back({j, static_cast<float>(1.0 - t)});
      if (t > 0 && j + 1 < n) out.push_back({j + 1, static_cast<float>(t)});
      continue;
    }
    const double a = i * s, b = (i + 1) * s;
    for (auto j = static_cast<std::uint32_t>(a); j < n && j < b; ++j) {
      const double overlap = std::min(b, j + 1.0) - std::max(a, static_cast<double>(j));
      if (overlap > 1e-9) out.push_back({j, static_cast<float>(overlap / s)});
    }
  }
  first[m] = static_cast<std::uint32_t>(out.size());
}

void AreaResampler::configure(std::uint32_t src_w, std::uint32_t src_h, std::uint32_t dst_w, std::uint32_t dst_h) {
  sw_ = src_w, sh_ = src_h, dw_ = dst_w, dh_ = dst_h;
  taps(src_w, dst_w, xt_, x0_);
  taps(src_h, dst_h, yt_, y0_);
  row_.assign(static_cast<std::size_t>(dst_w) * 3, 0.0f);
  acc_.assign(static_cast<std::size_t>(dst_w) * 3, 0.0f);
}

void AreaResampler::run(const std::uint8_t* bgr, std::uint8_t* rgb) noexcept {
  const std::size_t src_row = static_cast<std::size_t>(sw_) * 3;
  for (std::uint32_t dy = 0; dy < dh_; ++dy) {
    std::fill(acc_.begin(), acc_.end(), 0.0f);
    for (std::uint32_t ty = y0_[dy]; ty < y0_[dy + 1]; ++ty) {
      const std::uint8_t* in = bgr + yt_[ty].src * src_row;
      for (std::uint32_t dx = 0; dx < dw_; ++dx) {
        float b = 0, g = 0, r = 0;
        for (std::uint32_t tx = x0_[dx]; tx < x0_[dx + 1]; ++tx) {
          const std::uint8_t* p = in + static_cast<std::size_t>(xt_[tx].src) * 3;
          const float w = xt_[tx].w;
          b += w * p[0];
          g += w * p[1];
          r += w * p[2];
        }
        float* a = acc_.data() + static_cast<std::size_t>(dx) * 3;
        const float wy = yt_[ty].w;
        a[0] += wy * b;
        a[1] += wy * g;
        a[2] += wy * r;
      }
    }
    std::uint8_t* out = rgb + static_cast<std::size_t>(dy) * dw_ * 3;
    for (std::uint32_t dx = 0; dx < dw_; ++dx) {
      const float* a = acc_.data() + static_cast<std::size_t>(dx) * 3;
      for (int k = 0; k < 3; ++k) out[dx * 3 + static_cast<std::uint32_t>(k)] = static_cast<std::uint8_t>(std::clamp(a[2 - k] + 0.5f, 0.0f, 255.0f));
    }
  }
}

// --- the stage ------------------------------------------------------------------------------------

void CameraStage::set_syscalls_for_tests(v4l2::Syscalls* sys) noexcept { g_test_syscalls = sys; }

Status CameraStage::init(StageContext& ctx) {
  const CameraSettings own = load_params(ctx.params(), kCameraStageFields);
  where_ = std::string(ctx.stage_name) + ".";
  max_frames_ = own.max_frames_per_step;
  img_ = std::make_unique<CameraImageMsg>();
  img_->cls.fill(255);  // a live camera has no labels
  auto cw = ctx.channels.ring_writer(chan::kCamera.with_name(own.camera_channel));
  if (!cw) return cw.error();
  cam_out_ = cw.value();
  auto vw = ctx.channels.ring_writer(chan::kVisualOdometry.with_name(own.vo_channel));
  if (!vw) return vw.error();
  vo_out_ = vw.value();

  const std::string& source = own.source;
  if (ctx.device != nullptr) device_ = ctx.device;
  if (source != "none") device_->describe("images", {"device", "bad_buffers", "bad_records", "ring_full"});
  if (source == "v4l2") {
    auto fmt = v4l2::parse_pixel_format(own.format);
    if (!fmt) return Error::make(ErrorCode::kConfig, "config error: " + where_ + "format: " + fmt.error().message);
    cfg_.device = own.device;
    cfg_.width = static_cast<std::uint32_t>(own.width);
    cfg_.height = static_cast<std::uint32_t>(own.height);
    cfg_.format = fmt.value();
    cfg_.fps = static_cast<std::uint32_t>(own.fps);
    sys_ = g_test_syscalls != nullptr ? g_test_syscalls : &v4l2::linux_syscalls();
    // Sized for what was asked; a device that grants more is resized at open (open allocates anyway).
    bgr_.assign(static_cast<std::size_t>(cfg_.width) * cfg_.height * 3, 0);
    resample_.configure(cfg_.width, cfg_.height, kImageWidth, kImageHeight);
    source_ = Source::kV4l2;
    (void)open_camera(ctx.clock.now(), false);
  } else if (source == "sim") {
    sim_ = find_sim_camera(ctx.instance);
    if (sim_ == nullptr)
      return Error::make(ErrorCode::kConfig, "config error: " + where_ + "source is sim but the simulator gave robot '" +
                                                 std::string(ctx.instance) + "' no camera");
    source_ = Source::kSim;
  } else if (source == "replay") {
    replay_path_ = own.replay;
    if (replay_path_.empty()) return Error::make(ErrorCode::kConfig, "config error: " + where_ + "replay is empty but source is replay: name a frame-stream file or FIFO");
    arrival_ = own.stamps == "arrival";
    pace_ = own.pace;
    source_ = Source::kReplay;
    (void)open_replay(ctx.clock.now(), false);
  } else {
    AG_LOG_INFO("camera", "%ssource: none: no images or visual odometry are published", where_.c_str());
  }
  return ok_status();
}

bool CameraStage::open_camera(TimeNs now, bool retry) {
  last_try_ = now;
  if (retry) {
    // A device still absent costs one failed open(2) and no allocation; Camera::open only once it is back.
    const int fd = sys_->open(cfg_.device.c_str(), O_RDWR | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0) return false;
    (void)sys_->close(fd);
  }
  auto c = v4l2::Camera::open(cfg_, *sys_);
  if (!c) {
    if (!fault_logged_) {
      ++c_.device_errors;
      fault_logged_ = true;
      AG_LOG_ERROR("camera", "%sdevice: %s; no images until it opens (retrying every 2 s) device_errors=%llu", where_.c_str(),
                   c.error().message.c_str(), ull(c_.device_errors));
    }
    return false;
  }
  cam_ = std::move(c).value();
  const std::size_t need = static_cast<std::size_t>(cam_->width()) * cam_->height() * 3;
  if (bgr_.size() < need) bgr_.resize(need);
  if (resample_.src_width() != cam_->width() || resample_.src_height() != cam_->height())
    resample_.configure(cam_->width(), cam_->height(), kImageWidth, kImageHeight);
  if (retry) ++c_.reopens;
  fault_logged_ = false;
  AG_LOG_INFO("camera", "%sdevice: %s streaming %ux%u %s at %.1f fps, resampled to %dx%d%s", where_.c_str(), cfg_.device.c_str(), cam_->width(),
              cam_->height(), v4l2::to_string(cfg_.format), cam_->frame_interval_s() > 0 ? 1.0 / cam_->frame_interval_s() : 0.0, kImageWidth,
              kImageHeight, retry ? " (reopened)" : "");
  return true;
}

bool CameraStage::open_replay(TimeNs now, bool retry) {
  last_try_ = now;
  struct stat st {};
  const bool exists = ::stat(replay_path_.c_str(), &st) == 0;
  if (retry && !exists) return false;  // still absent: no allocation until it appears
  auto r = FrameStreamReader::open(replay_path_);
  if (!r) {
    // Only a path that does not exist yet is waited for (the HIL simulator creates its FIFO after the
    // robot starts); one that exists and cannot be read will not get better.
    retry_replay_ = !exists;
    if (!fault_logged_ || exists) {  // (a path that appeared but cannot be read is a new fault)
      ++c_.device_errors;
      fault_logged_ = true;
      AG_LOG_ERROR("camera", "%sreplay: %s; %s device_errors=%llu", where_.c_str(), r.error().message.c_str(),
                   retry_replay_ ? "nothing is published until it appears (retrying every second)" : "nothing is published", ull(c_.device_errors));
    }
    return false;
  }
  reader_ = std::move(r).value();
  retry_replay_ = false;
  if (retry) ++c_.reopens;
  fault_logged_ = false;
  AG_LOG_INFO("camera", "%sreplay: reading %s %s (stamps %s%s)", where_.c_str(), reader_->is_fifo() ? "FIFO" : "file", replay_path_.c_str(),
              arrival_ ? "shifted to arrival" : "as recorded", pace_ && !reader_->is_fifo() ? ", paced" : "");
  return true;
}

void CameraStage::step(TimeNs now) noexcept {
  switch (source_) {
    case Source::kV4l2: step_v4l2(now); break;
    case Source::kReplay: step_replay(now); break;
    case Source::kSim: step_sim(now); break;
    case Source::kNone: return;
  }
  note_device(now);
}

// The stage's device counters, and one warning when an open source gives no image for a few seconds.
void CameraStage::note_device(TimeNs now) noexcept {
  device_->error_total(0, c_.device_errors);
  device_->error_total(3, c_.ring_full);
  if (cam_) device_->error_total(1, cam_->counters().error_buffers + cam_->counters().short_buffers);
  device_->error_total(2, c_.replay.crc_errors + c_.replay.bad_records);
  const bool open = (source_ == Source::kV4l2 && cam_) || (source_ == Source::kReplay && reader_ && !finished_) || source_ == Source::kSim;
  if (!open || !silence_.check(*device_, now)) return;
  ++c_.silence_warnings;
  const double s = static_cast<double>(silence_.silent_for(now)) * 1e-9;
  if (source_ == Source::kV4l2)
    AG_LOG_WARN("camera", "%sdevice: no image for %.0f s from %s, which is open and streaming (%llu error/short buffers, %llu dropped): "
                "no trigger, a USB bandwidth limit, or another process", where_.c_str(), s, cfg_.device.c_str(),
                ull(cam_->counters().error_buffers + cam_->counters().short_buffers), ull(cam_->counters().dropped));
  else if (source_ == Source::kSim)
    AG_LOG_WARN("camera", "%ssim: no image for %.0f s from the simulator's camera", where_.c_str(), s);
  else
    AG_LOG_WARN("camera", "%sreplay: no image for %.0f s from %s (%s)", where_.c_str(), s, replay_path_.c_str(),
                reader_->is_fifo() ? "no writer on the FIFO yet, or it stopped writing" : "a file with no image records here");
}

void CameraStage::step_v4l2(TimeNs now) noexcept {
  if (!cam_) {
    if (now - last_try_ >= kCameraRetry) {
      try {
        (void)open_camera(now, true);
      } catch (...) {  // out of memory while reopening: try again later
        cam_.reset();
      }
    }
    return;
  }
  for (int i = 0; i < max_frames_; ++i) {
    v4l2::Frame f;
    const v4l2::CaptureResult r = cam_->next(0, f);
    if (r == v4l2::CaptureResult::kTimeout) break;
    if (r == v4l2::CaptureResult::kFrame) {
      v4l2::to_bgr(f, bgr_.data());
      cam_->release(f);  // back to the driver before the resampling: it may fill it meanwhile
      resample_.run(bgr_.data(), img_->rgb.data());
      img_->stamp = f.stamp;
      img_->published = now;
      img_->seq = ++seq_;
      img_->labels = LabelSource::kNone;
      ++c_.frames_published;
      device_->unit_received(true, now);
      device_->received_bytes(f.data.size());
      if (cam_out_.push(*img_) != 0) ++c_.ring_full;
    }
    if (r == v4l2::CaptureResult::kError || cam_->state() == v4l2::Camera::State::kFailed) {
      ++c_.device_errors;
      fault_logged_ = true;
      AG_LOG_ERROR("camera", "%sdevice: %s failed: %s; reopening every 2 s device_errors=%llu", where_.c_str(), cfg_.device.c_str(),
                   cam_->error().c_str(), ull(c_.device_errors));
      cam_.reset();
      last_try_ = now;
      return;
    }
  }
}

void CameraStage::note_replay_faults(TimeNs now) noexcept {
  c_.replay = reader_->counters();
  const std::uint64_t faults = c_.replay.crc_errors + c_.replay.bad_records + c_.replay.garbage_bytes;
  if (faults == faults_logged_ || (faults_logged_ != 0 && now - last_fault_log_ < kFaultLogEvery)) return;
  faults_logged_ = faults;
  last_fault_log_ = now;
  const std::string_view e = reader_->last_error().empty() ? std::string_view("bytes outside any record skipped") : reader_->last_error();
  AG_LOG_WARN("camera", "%sreplay: %.*s crc_errors=%llu bad_records=%llu garbage_bytes=%llu", where_.c_str(), static_cast<int>(e.size()), e.data(),
              ull(c_.replay.crc_errors), ull(c_.replay.bad_records), ull(c_.replay.garbage_bytes));
}

void CameraStage::step_replay(TimeNs now) noexcept {
  if (!reader_) {
    if (retry_replay_ && now - last_try_ >= kReplayRetry) {
      try {
        (void)open_replay(now, true);
      } catch (...) {
        reader_.reset();
      }
    }
    return;
  }
  if (finished_) return;
  int images = 0;
  std::size_t vos = 0;
  for (;;) {
    if (pending_ == Pending::kNothing) {
      const ReadResult r = reader_->next(*img_, vo_);
      if (r == ReadResult::kNone) break;
      if (r == ReadResult::kEnd) {
        finished_ = true;
        note_replay_faults(now);
        if (c_.replay.read_errors > 0) {
          ++c_.device_errors;
          const std::string_view e = reader_->last_error();
          AG_LOG_ERROR("camera", "%sreplay: %.*s device_errors=%llu", where_.c_str(), static_cast<int>(e.size()), e.data(), ull(c_.device_errors));
        }
        AG_LOG_INFO("camera", "%sreplay: %s: replay finished images=%llu vo=%llu crc_errors=%llu bad_records=%llu garbage_bytes=%llu", where_.c_str(),
                    replay_path_.c_str(), ull(c_.replay.images), ull(c_.replay.vo), ull(c_.replay.crc_errors), ull(c_.replay.bad_records),
                    ull(c_.replay.garbage_bytes));
        return;
      }
      pending_ = r == ReadResult::kImage ? Pending::kImage : Pending::kVo;
      pending_stamp_ = r == ReadResult::kImage ? img_->stamp : vo_.stamp;
      if (!have_origin_) {
        have_origin_ = true;
        origin_stamp_ = pending_stamp_;
        origin_now_ = now;
      }
    }
    // A FIFO is paced by its writer; a file, if asked, by the recorded intervals.
    if (pace_ && !reader_->is_fifo() && now - origin_now_ < pending_stamp_ - origin_stamp_) break;
    const TimeNs stamp = arrival_ ? pending_stamp_ - origin_stamp_ + origin_now_ : pending_stamp_;
    // A record some reader has no room for waits (and everything behind it): a replay loses nothing.
    if (pending_ == Pending::kImage) {
      if (images >= max_frames_ || cam_out_.free_slots() == 0) break;
      img_->stamp = stamp;
      img_->published = now;
      ++c_.frames_published;
      device_->unit_received(true, now);
      device_->received_bytes(sizeof(CameraImageMsg));
      (void)cam_out_.push(*img_);
      ++images;
    } else {
      if (vos >= kVoRing || vo_out_.free_slots() == 0) break;
      vo_.stamp = stamp;
      vo_.published = now;
      ++c_.vo_published;
      (void)vo_out_.push(vo_);
      ++vos;
    }
    pending_ = Pending::kNothing;
  }
  note_replay_faults(now);
}

// The simulator's frames as they come (a frame a reader has no room for is refused and counted, as a
// live camera's).
void CameraStage::step_sim(TimeNs now) noexcept {
  for (int images = 0; images < max_frames_; ++images) {
    const CameraImageMsg* f = sim_->front();
    if (f == nullptr) break;
    ++c_.frames_published;
    device_->unit_received(true, now);
    device_->received_bytes(sizeof(CameraImageMsg));
    if (cam_out_.push(*f) != 0) ++c_.ring_full;
    sim_->pop();
  }
}

}  // namespace ag::camera
