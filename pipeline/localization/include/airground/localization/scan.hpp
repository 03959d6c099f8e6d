// A ground robot's LiDAR scan as the localizer sees it, and the channels its labels are matched in.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>

#include "airground/messages/classes.hpp"
#include "airground/messages/messages.hpp"

namespace ag::loc {

// One return of an organised scan (an Ouster: rings x columns; pixels without a return are absent):
// the "lidar_scan" channel's ScanReturn itself, so a stage labels and renders the message's points in
// place. Sensor frame (x forward, y left, z up) [m]; ring 0 is the top beam (ring + 1 looks further
// down); neighbouring columns are neighbouring azimuths; cls is written by a ScanLabeller.
using ScanPoint = ScanReturn;

// Channels are what the scan and the aerial map are compared in: one channel per class, or one per class
// group. A channel has a weight, the scan labels counted into it and the aerial classes that are its
// sources (the cells its distance field measures the distance to).
inline constexpr int kMaxChannels = 7;  // + the class byte: 8 bytes per distance-field cell

class LocalizationChannels {
 public:
  LocalizationChannels() noexcept;  // no channels; add them with add_channel()

  // One channel per known class of `table` with a localization weight > 0 (ground-truth or segmentation
  // labels): scan label c counts into the channel of aerial class c.
  static LocalizationChannels per_class(const ClassTable& table = ClassTable::builtin());

  // The paper's geometric labelling (GeometricLabeller): two channels,
  //   ground   = road | dirt | grass | water  (the labeller writes kGroundLabel = road for flat points)
  //   obstacle = tree | building | vehicle    (the labeller writes kObstacleLabel = building)
  // Scan labels of any member class count into the group, so ground-truth labels work here too.
  // Water is ground: calm water mostly returns nothing to a LiDAR, but what it does return (ripples,
  // steep incidence, a shallow bottom) is a flat surface at ground level that the geometric labeller
  // calls ground, so the ground channel takes it.
  // obstacle_faces: a third channel, "obstacle faces", the same classes as a surface channel
  // (set_surface): the LiDAR at 0.6 m sees the sides of walls, vehicles and crowns that reach the ground,
  // where the aerial map's regions end. Obstacle points count into it instead of "obstacle" once the
  // filter's range bins are at most kFacesMaxBinM (tracking): with the regions alone an obstacle point
  // deep inside a region costs nothing, and beside the default world's park the estimate slid 1.2-1.7 m
  // into the trees (SimulatedLidar.TheParkRoadDoesNotPullTheGeometricEstimate). While converging, with
  // bins of up to 4 m whose centres fall well inside the obstacles, the regions still judge.
  static constexpr double kFacesMaxBinM = 1.5;
  static LocalizationChannels two_class(double ground_weight = 1.0, double obstacle_weight = 1.5, bool obstacle_faces = true);

  [[nodiscard]] int count() const noexcept { return count_; }
  // Channel a scan label counts into, -1 if it is not counted.
  [[nodiscard]] int scan_channel(std::uint8_t label) const noexcept { return scan_[label]; }
  // ... while the filter's range bins are at most fine_max_bin_m() [m] (by default the same channel).
  [[nodiscard]] int fine_scan_channel(std::uint8_t label) const noexcept { return fine_[label]; }
  [[nodiscard]] double fine_max_bin_m() const noexcept { return fine_max_bin_m_; }
  // Bit k set: aerial class `cls` is a source of channel k.
  [[nodiscard]] std::uint8_t map_sources(std::uint8_t cls) const noexcept { return sources_[cls]; }
  [[nodiscard]] float weight(int channel) const noexcept { return weight_[static_cast<std::size_t>(channel)]; }
  [[nodiscard]] const std::string& name(int channel) const noexcept { return name_[static_cast<std::size_t>(channel)]; }

  // Adds a channel (count() < kMaxChannels); scan labels and map classes are assigned with the two below.
  int add_channel(std::string name, double weight);
  void count_scan_label(std::uint8_t label, int channel) noexcept {
    scan_[label] = static_cast<std::int8_t>(channel);
    fine_[label] = static_cast<std::int8_t>(channel);
  }
  // Label `label` counts into `channel` instead while the range bins are at most max_bin_m (one bound for all).
  void count_scan_label_fine(std::uint8_t label, int channel, double max_bin_m) noexcept {
    fine_[label] = static_cast<std::int8_t>(channel);
    fine_max_bin_m_ = max_bin_m;
  }
  void add_map_source(std::uint8_t cls, int channel) noexcept {
    sources_[cls] = static_cast<std::uint8_t>(sources_[cls] | (1U << static_cast<unsigned>(channel)));
  }
  // A surface channel's sources are only the member cells on a region's boundary (a 4-neighbour is not a
  // member): a LiDAR sees the faces of a solid obstacle, never its inside, so a face point that the pose
  // moves deeper into the region costs as one moved out of it. Without this the cost is one-sided at a
  // face and the estimate slides into the obstacles along a road lined with them on one side only.
  void set_surface(int channel, bool surface) noexcept {
    const auto bit = static_cast<std::uint8_t>(1U << static_cast<unsigned>(channel));
    surface_ = static_cast<std::uint8_t>(surface ? (surface_ | bit) : (surface_ & ~bit));
  }
  // Bit k set: channel k is a surface channel.
  [[nodiscard]] std::uint8_t surface_channels() const noexcept { return surface_; }
  // Obstacle channels: their sources are the cells a ground robot cannot enter (region channels, not
  // surface ones), so the smallest of their distances at a cell is its clearance, as the planner
  // measures it (the particle filter's obstacle prior). No bit set: no such channels, no prior.
  void set_obstacle_space(int channel) noexcept {
    obstacle_ = static_cast<std::uint8_t>(obstacle_ | (1U << static_cast<unsigned>(channel)));
    blocked_ = static_cast<std::uint8_t>(blocked_ | (1U << static_cast<unsigned>(channel)));
  }
  [[nodiscard]] std::uint8_t obstacle_space_channels() const noexcept { return obstacle_; }
  // The channels of the classes a robot cannot enter (set_obstacle_space), also after add_off_route made
  // the off-route channel the only obstacle channel: the room a confirmed fix is checked against
  // (ParticleFilterParams::confirmed_room_obstacles_only).
  [[nodiscard]] std::uint8_t blocked_space_channels() const noexcept { return blocked_; }
  // Adds the "off route" channel (weight 0, no scan label counts into it): its sources are the classes of
  // `table` above `level` (the planner's traversable), and it becomes the only obstacle channel. Its
  // distance at a cell is then the planner's own clearance (to the nearest cell it does not route over),
  // so the obstacle prior's room is the planner's free space: on the imported world's wood, whose
  // clearings ErfNet's map labels grass, the obstacle channels alone left room between the crowns.
  int add_off_route(Traversability level, const ClassTable& table = ClassTable::builtin());

 private:
  int count_{0};
  std::array<std::int8_t, 256> scan_{};
  std::array<std::int8_t, 256> fine_{};
  double fine_max_bin_m_{0.0};
  std::array<std::uint8_t, 256> sources_{};
  std::uint8_t surface_{0};
  std::uint8_t obstacle_{0};
  std::uint8_t blocked_{0};
  std::array<float, kMaxChannels> weight_{};
  std::array<std::string, kMaxChannels> name_{};
};

inline constexpr ClassId kGroundLabel = ClassId::kRoad;        // GeometricLabeller: flat, drivable-looking
inline constexpr ClassId kObstacleLabel = ClassId::kBuilding;  // GeometricLabeller: high gradient or tall

}  // namespace ag::loc
