// Foxglove's published message schemas (foxglove.PoseInFrame, FrameTransforms, PointCloud, Grid,
// CompressedImage, SceneUpdate, Log) in their JSON encoding: the JSON Schema text for an MCAP Schema
// record (encoding "jsonschema") and the message JSON for an MCAP Message on a "json" channel. Binary
// fields (PointCloud.data, Grid.data, CompressedImage.data) are base64 strings, as Foxglove reads them.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace ag::foxglove {

inline constexpr std::string_view kSchemaEncoding = "jsonschema";
inline constexpr std::string_view kMessageEncoding = "json";

// The JSON Schema of a foxglove message, by its name ("foxglove.PointCloud", ...); empty if we have not
// written that one. The names we have: kSchemaNames.
[[nodiscard]] const std::string& schema(std::string_view name);
inline constexpr std::string_view kSchemaNames[] = {
    "foxglove.PoseInFrame", "foxglove.FrameTransforms", "foxglove.PointCloud", "foxglove.Grid",
    "foxglove.CompressedImage", "foxglove.RawImage", "foxglove.SceneUpdate", "foxglove.Log", "foxglove.LocationFix"};

struct Vec3 {
  double x{0}, y{0}, z{0};
};
struct Quat {
  double x{0}, y{0}, z{0}, w{1};
};
struct Pose {
  Vec3 position;
  Quat orientation;
};
struct Color {
  double r{1}, g{1}, b{1}, a{1};  // [0, 1]
};

// Roll, pitch, yaw (ZYX, radians) as a unit quaternion.
[[nodiscard]] Quat quat_from_rpy(double roll, double pitch, double yaw) noexcept;

// foxglove.NumericType
enum class NumericType : int { kUint8 = 1, kInt8 = 2, kUint16 = 3, kInt16 = 4, kUint32 = 5, kInt32 = 6, kFloat32 = 7, kFloat64 = 8 };
struct PackedElementField {
  std::string name;
  std::uint32_t offset{0};
  NumericType type{NumericType::kFloat32};
};

struct FrameTransform {
  std::string parent_frame_id, child_frame_id;
  Vec3 translation;
  Quat rotation;
};

// foxglove.SceneEntity with the primitives we draw: line strips, spheres and texts.
struct LineStrip {
  std::vector<Vec3> points;
  Color color;
  double thickness{0.5};  // [m]
  bool loop{false};       // LINE_LOOP instead of LINE_STRIP
};
struct Sphere {
  Vec3 position;
  double diameter{1};  // [m]
  Color color;
};
struct Text {
  Vec3 position;
  std::string text;
  Color color;
  double font_size{12};  // [px], scale invariant, billboard
};
struct SceneEntity {
  std::string id;
  std::string frame_id;
  std::vector<LineStrip> lines;
  std::vector<Sphere> spheres;
  std::vector<Text> texts;
};

// foxglove.Log levels
enum class LogLevel : int { kDebug = 1, kInfo = 2, kWarning = 3, kError = 4, kFatal = 5 };

// Message JSON; t_ns is the message's timestamp (sec, nsec).
[[nodiscard]] std::string pose_in_frame(std::uint64_t t_ns, std::string_view frame_id, const Pose& pose);
[[nodiscard]] std::string frame_transforms(std::uint64_t t_ns, const std::vector<FrameTransform>& transforms);
[[nodiscard]] std::string point_cloud(std::uint64_t t_ns, std::string_view frame_id, const Pose& origin, std::uint32_t point_stride,
                                      const std::vector<PackedElementField>& fields, std::span<const std::uint8_t> data);
[[nodiscard]] std::string grid(std::uint64_t t_ns, std::string_view frame_id, const Pose& corner, std::uint32_t column_count,
                               double cell_x, double cell_y, std::uint32_t row_stride, std::uint32_t cell_stride,
                               const std::vector<PackedElementField>& fields, std::span<const std::uint8_t> data);
[[nodiscard]] std::string compressed_image(std::uint64_t t_ns, std::string_view frame_id, std::string_view format,
                                           std::span<const std::uint8_t> data);
// foxglove.RawImage: `encoding` "rgb8" etc., `step` bytes per row (the robots' recorder: no JPEG encoder
// in the static binaries).
[[nodiscard]] std::string raw_image(std::uint64_t t_ns, std::string_view frame_id, std::uint32_t width, std::uint32_t height,
                                    std::string_view encoding, std::uint32_t step, std::span<const std::uint8_t> data);
// Replaces the entities with these ids (no deletions; entities never expire).
[[nodiscard]] std::string scene_update(std::uint64_t t_ns, const std::vector<SceneEntity>& entities);
[[nodiscard]] std::string log(std::uint64_t t_ns, LogLevel level, std::string_view name, std::string_view message);
[[nodiscard]] std::string location_fix(std::uint64_t t_ns, std::string_view frame_id, double lat_deg, double lon_deg, double alt_m,
                                       double horizontal_sigma_m);

// JSON helpers for other messages: a quoted, escaped string; a number (shortest round-trip form,
// null for NaN/inf).
[[nodiscard]] std::string json_string(std::string_view s);
[[nodiscard]] std::string json_number(double v);

}  // namespace ag::foxglove
