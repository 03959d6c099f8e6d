// Monocular keyframe visual odometry for the quadrotor's nadir camera: corners tracked by pyramidal
// Lucas-Kanade, a two-view start (translation with the autopilot's rotation, or none), the camera pose
// of every frame against the local map (PnP: RANSAC then a robust refinement), new points triangulated
// at each keyframe and a sliding window of keyframes bundle-adjusted. The autopilot's attitude is the
// gravity: each segment's frame is level (z up) with the yaw of its first keyframe. Scale is unknown
// (the pose graph learns it from GPS); a tracking loss starts a new segment.
#pragma once

#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <optional>
#include <vector>

#include "airground/messages/camera.hpp"
#include "airground/platform/time.hpp"
#include "airground/visual_odometry/geometry.hpp"
#include "airground/visual_odometry/image_features.hpp"
#include "airground/visual_odometry/window_adjustment.hpp"

namespace ag::vo {

struct VoParams {
  PinholeCamera camera;                 // intrinsics of the frames given to process()
  int max_features{240};                // tracked corners at most (one per grid cell)
  int min_pose_inliers{20};             // fewer map points agreeing on the pose: tracking lost
  double init_parallax_px{20.0};        // median motion since the first keyframe before the two-view start
  double keyframe_parallax_px{24.0};    // median motion since the last keyframe that makes a new one (2 m at 40 m)
  double keyframe_min_tracked{0.6};     // ... or when fewer than this share of its map points are still tracked
  int window_keyframes{7};              // bundle-adjusted keyframes (the oldest two held fixed)
  double min_triangulation_deg{1.0};    // rays closer than this are not triangulated
  double max_reprojection_px{2.0};      // inlier threshold of the pose and of new points
  double gravity_sigma_rad{0.005};      // the autopilot's up direction, as a prior (PX4 EKF2: ~0.2-0.3 deg)
  int ba_iterations{5};
  double redetect_below{0.7};           // between keyframes, look for corners when fewer than this share are tracked
  CornerParams corners;
  FlowParams flow;
};

enum class VoState : std::uint8_t { kStarting, kTracking };

struct VoFrame {
  bool tracking{false};                 // the pose is valid
  bool keyframe{false};                 // this frame became a keyframe
  bool new_segment{false};              // first pose of a new segment (after a start or a loss)
  std::uint32_t segment{0};
  Eigen::Isometry3d body_in_segment{Eigen::Isometry3d::Identity()};  // [VO units, rad] body FLU pose
  int tracked{0};                       // corners tracked into this frame
  int inliers{0};                       // map points agreeing on its pose
};

struct VoStats {
  std::uint64_t frames{0}, tracked_frames{0}, keyframes{0}, segments{0}, losses{0};
  std::uint64_t starts_failed{0};        // two-view starts without consensus (retried)
  std::uint64_t points_triangulated{0}, points_rejected{0};
  std::uint64_t frames_without_attitude{0};
  WindowAdjustmentReport last_adjustment;
};

class VisualOdometry {
 public:
  explicit VisualOdometry(const VoParams& p);

  // One frame (RGB, p.camera's size). world_from_body: the autopilot's attitude at the frame's time
  // (REP-103 body in ENU), or none. Never allocates after the first frame.
  VoFrame process(TimeNs stamp, const std::uint8_t* rgb, const std::optional<Eigen::Matrix3d>& world_from_body) noexcept;
  // The same for an 8-bit grey frame.
  VoFrame process_grey(TimeNs stamp, const std::uint8_t* grey, const std::optional<Eigen::Matrix3d>& world_from_body) noexcept;

  [[nodiscard]] VoState state() const noexcept { return state_; }
  [[nodiscard]] const VoStats& stats() const noexcept { return stats_; }
  [[nodiscard]] const VoParams& params() const noexcept { return p_; }

 private:
  struct Track {
    Pixel px;                  // in the current frame
    Pixel kf_px;               // in the newest keyframe (or where it was first seen after it)
    std::uint32_t id{0};
    bool has_point{false};
    std::uint64_t anchor_kf{0};  // keyframe serial where it was first seen
    Eigen::Vector2d anchor_x{0, 0};  // its normalised coordinates there
  };
  struct MapPoint {
    std::uint32_t id{0};
    bool valid{false};
    Eigen::Vector3d X{0, 0, 0};
  };
  struct KfObs {
    std::uint32_t id{0};
    Eigen::Vector2d x{0, 0};
  };
  struct Keyframe {
    std::uint64_t serial{0};
    TimeNs stamp{0};
    CameraPose pose;
    GravityPrior gravity;
    int n_obs{0};
    std::vector<KfObs> obs;     // capacity max_features, sized at construction
  };
  struct BaTuple {
    std::uint32_t slot{0};
    std::int32_t kf{0};
    Eigen::Vector2d x{0, 0};
  };

  VoFrame step(TimeNs stamp, const std::optional<Eigen::Matrix3d>& world_from_body) noexcept;
  void restart(const GravityPrior& g, const Eigen::Matrix3d& R_wb, TimeNs stamp) noexcept;
  bool try_start(const GravityPrior& g, const std::optional<Eigen::Matrix3d>& R_wb, TimeNs stamp) noexcept;
  bool track_pose(const GravityPrior& g, CameraPose& pose, int& inliers) noexcept;
  void make_keyframe(const CameraPose& pose, const GravityPrior& g, TimeNs stamp) noexcept;
  void triangulate_new(Keyframe& kf) noexcept;
  void adjust_window() noexcept;
  void detect_corners(bool at_keyframe) noexcept;
  void drop_tracks(const std::vector<std::uint8_t>& keep) noexcept;
  Keyframe* keyframe_by_serial(std::uint64_t serial) noexcept;
  Keyframe& newest_keyframe() noexcept { return window_[(window_head_ + window_size_ - 1) % window_.size()]; }
  [[nodiscard]] Eigen::Vector2d normalised(const Pixel& px) const noexcept;
  [[nodiscard]] MapPoint* point_of(std::uint32_t id) noexcept;
  [[nodiscard]] double median_motion_since(std::uint64_t kf_serial) const noexcept;
  [[nodiscard]] VoFrame output(const CameraPose& pose, bool keyframe) const noexcept;

  VoParams p_;
  CornerDetector corners_;
  OpticalFlow flow_;
  WindowAdjustment adjustment_;
  SampleStream rng_{0x766f5f72616e7361ULL};
  ImagePyramid pyr_[2];
  int cur_{0};
  bool have_prev_{false};
  VoState state_{VoState::kStarting};
  std::uint32_t segment_{0};
  bool segment_started_{false};
  bool announce_segment_{false};
  std::uint32_t next_track_id_{1};
  std::uint64_t next_kf_serial_{1};

  std::vector<Track> tracks_;
  std::vector<Pixel> prev_px_, next_px_, rot_px_, new_corners_;
  std::vector<std::uint8_t> ok_, keep_;
  std::vector<float> motion_;
  Eigen::Matrix3d kf0_attitude_{Eigen::Matrix3d::Identity()};  // autopilot R_wb at the segment's first keyframe
  bool kf0_has_attitude_{false};
  std::vector<MapPoint> points_;
  std::vector<Keyframe> window_;
  std::size_t window_head_{0}, window_size_{0};
  std::vector<Eigen::Vector3d> pnp_X_;
  std::vector<Eigen::Vector2d> pnp_x_, two_view_x1_, two_view_x2_;
  std::vector<std::uint32_t> pnp_track_;
  std::vector<BaTuple> ba_tuples_;
  std::vector<BaObservation> ba_obs_;
  std::vector<Eigen::Vector3d> ba_points_;
  std::vector<std::uint32_t> ba_slots_;
  std::vector<CameraPose> ba_poses_;
  std::vector<GravityPrior> ba_gravity_;
  std::vector<std::uint8_t> ba_fixed_;

  CameraPose pose_, prev_pose_;        // current and previous frame's camera poses (segment frame)
  bool have_prev_pose_{false};
  std::optional<Eigen::Matrix3d> prev_attitude_;  // autopilot R_wb at the previous frame
  Pixel mean_flow_{};                  // last frame's median image motion (the next guess)
  TimeNs last_stamp_{0}, last_dt_{0};  // the previous frame's stamp and the interval before it
  VoStats stats_;
};

}  // namespace ag::vo
