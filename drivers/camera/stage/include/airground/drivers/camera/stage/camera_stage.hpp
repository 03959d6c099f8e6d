// The camera stage: the quadrotor's nadir camera. Every step it takes what the source has and publishes
// it on the "camera" and "visual_odometry" rings the mapping stages read:
//   v4l2    a V4L2 device (drivers/camera/v4l2): each frame converted to BGR, area-averaged to
//           640x400 RGB (no OpenCV: the static aarch64 binaries cannot link it), labels none;
//   replay  a frame-stream file or FIFO (frame_stream.hpp): the recorded images and VO, in order;
//   none    nothing.
// A device or file that is absent or fails does not stop the robot (it keeps flying its mission, and
// relaying for the team): the fault is logged once, counted in device_errors, and retried.
#pragma once

#include <memory>
#include <span>
#include <string>
#include <vector>

#include "airground/messages/channels.hpp"
#include "airground/drivers/camera/stage/sim_camera.hpp"
#include "airground/messages/messages.hpp"
#include "airground/drivers/camera/frame_stream/frame_stream.hpp"
#include "airground/drivers/camera/v4l2/camera.hpp"
#include "airground/platform/param_binding.hpp"
#include "airground/platform/stage.hpp"

namespace ag::camera {

struct CameraSettings {
  std::string source{"v4l2"};
  std::string device{"/dev/video0"};
  int width{1280};
  int height{800};
  std::string format{"YUYV"};
  int fps{10};
  int max_frames_per_step{2};
  std::string replay;
  std::string stamps{"record"};
  bool pace{false};
  std::string camera_channel{chan::kCamera.name};
  std::string vo_channel{chan::kVisualOdometryRecorded.name};
};
inline constexpr ParamField<CameraSettings> kCameraStageFields[] = {
    field::text("source", &CameraSettings::source, "v4l2", "v4l2|replay|sim|none", "images from the camera (V4L2), a frame-stream recording or FIFO (replay), the simulator's camera, or none"),
    field::text("device", &CameraSettings::device, "/dev/video0", "", "V4L2 capture device"),
    field::integer("width", &CameraSettings::width, 16, 4096, "px", "capture width asked of the device (the device may round it); resampled to 640"),
    field::integer("height", &CameraSettings::height, 16, 4096, "px", "capture height asked of the device; resampled to 400 (keep 16:10 or the image is stretched)"),
    field::text("format", &CameraSettings::format, "YUYV", "GREY|YUYV|RGGB8|GRBG8", "pixel format asked of the device"),
    field::integer("fps", &CameraSettings::fps, 1, 120, "Hz", "frame rate asked of the device"),
    field::integer("max_frames_per_step", &CameraSettings::max_frames_per_step, 1, 16, "", "images published per step (each is converted, resampled and copied: ~1 MB)"),
    field::text("replay", &CameraSettings::replay, "", "", "frame-stream file or FIFO when source is replay"),
    field::text("stamps", &CameraSettings::stamps, "record", "record|arrival", "replay: keep the recorded stamps (a HIL simulator on this machine's clock) or shift them to the arrival of the first record (a recording from another boot)"),
    field::boolean("pace", &CameraSettings::pace, "replay of a file: hand records out at their recorded intervals from the first, not as fast as the rings take them"),
    field::text("camera_channel", &CameraSettings::camera_channel, chan::kCamera.name, "", "ring channel the images are published on"),
    field::text("vo_channel", &CameraSettings::vo_channel, chan::kVisualOdometryRecorded.name, "", "ring channel a frame-stream recording's own odometry is published on (the robot's vo stage writes visual_odometry)"),
};
inline constexpr auto kCameraStageParams = param_specs(kCameraStageFields);

struct CameraStageCounters {
  std::uint64_t frames_published{0};
  std::uint64_t vo_published{0};
  std::uint64_t device_errors{0};   // logged faults: device or replay path not opened, camera failed mid-run, replay read error
  std::uint64_t reopens{0};         // device or replay path opened by a retry after a fault
  std::uint64_t ring_full{0};       // live images some reader's ring refused (a replay waits for room instead)
  FrameStreamCounters replay;       // the replay reader's, as of the last step
  std::uint64_t silence_warnings{0};  // "no image for a few seconds" warnings logged
};

// BGR of one size to RGB of another: area averaging when shrinking (each output pixel the mean of the
// source area it covers, partial pixels weighted: OpenCV's INTER_AREA), bilinear when enlarging.
class AreaResampler {
 public:
  // Allocates the tables; run() then never allocates.
  void configure(std::uint32_t src_w, std::uint32_t src_h, std::uint32_t dst_w, std::uint32_t dst_h);
  void run(const std::uint8_t* bgr, std::uint8_t* rgb) noexcept;
  [[nodiscard]] std::uint32_t src_width() const noexcept { return sw_; }
  [[nodiscard]] std::uint32_t src_height() const noexcept { return sh_; }

 private:
  struct Tap {
    std::uint32_t src;
    float w;
  };
  static void taps(std::uint32_t n, std::uint32_t m, std::vector<Tap>& out, std::vector<std::uint32_t>& first);
  std::uint32_t sw_{0}, sh_{0}, dw_{0}, dh_{0};
  std::vector<Tap> xt_, yt_;
  std::vector<std::uint32_t> x0_, y0_;  // first tap of each output column / row (size + 1 entries)
  std::vector<float> row_, acc_;
};

class CameraStage final : public Stage {
 public:
  static constexpr std::span<const ParamSpec> kParams{kCameraStageParams};
  static std::unique_ptr<Stage> make() { return std::make_unique<CameraStage>(); }
  // Tests: the system calls the V4L2 backend makes (a fake device) for stages initialised from now on;
  // null restores the real ones.
  static void set_syscalls_for_tests(v4l2::Syscalls* sys) noexcept;

  Status init(StageContext& ctx) override;
  void step(TimeNs now) noexcept override;

  [[nodiscard]] const CameraStageCounters& counters() const noexcept { return c_; }
  [[nodiscard]] const v4l2::Camera* camera() const noexcept { return cam_.get(); }         // null while absent or failed
  [[nodiscard]] const FrameStreamReader* reader() const noexcept { return reader_.get(); }  // null while not open
  [[nodiscard]] bool replay_finished() const noexcept { return finished_; }
  [[nodiscard]] const CameraImageMsg& last_image() const noexcept { return *img_; }

 private:
  enum class Source : std::uint8_t { kNone, kV4l2, kReplay, kSim };
  enum class Pending : std::uint8_t { kNothing, kImage, kVo };
  bool open_camera(TimeNs now, bool retry);
  bool open_replay(TimeNs now, bool retry);
  void step_v4l2(TimeNs now) noexcept;
  void step_replay(TimeNs now) noexcept;
  void step_sim(TimeNs now) noexcept;
  void note_replay_faults(TimeNs now) noexcept;
  void note_device(TimeNs now) noexcept;

  Source source_{Source::kNone};
  std::string where_;
  RingWriter<CameraImageMsg, kCameraRing> cam_out_;
  RingWriter<VoMsg, kVoRing> vo_out_;
  std::unique_ptr<CameraImageMsg> img_;
  VoMsg vo_{};
  int max_frames_{2};
  TimeNs last_try_{0};
  bool fault_logged_{false};
  // v4l2
  v4l2::Syscalls* sys_{nullptr};
  v4l2::CameraConfig cfg_;
  std::unique_ptr<v4l2::Camera> cam_;
  std::vector<std::uint8_t> bgr_;
  AreaResampler resample_;
  std::uint32_t seq_{0};
  SimCameraLink* sim_{nullptr};  // source: sim
  // replay
  std::string replay_path_;
  std::unique_ptr<FrameStreamReader> reader_;
  bool retry_replay_{false}, arrival_{false}, pace_{false}, finished_{false};
  Pending pending_{Pending::kNothing};
  TimeNs pending_stamp_{0};
  bool have_origin_{false};
  TimeNs origin_stamp_{0}, origin_now_{0};
  std::uint64_t faults_logged_{0};
  TimeNs last_fault_log_{0};
  CameraStageCounters c_;
  DeviceCounters own_device_;
  DeviceCounters* device_{&own_device_};
  DeviceSilence silence_;
};

}  // namespace ag::camera
