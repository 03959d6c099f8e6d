// Foxglove's message schemas as JSON Schema text (composed from shared parts: time, pose, packed field,
// colour), and the message JSON our recordings write. Numbers print in their shortest round-trip form,
// so the same values give the same bytes.
#include "airground/drivers/recording/mcap/foxglove_json.hpp"

#include <charconv>
#include <cmath>
#include <map>

#include "airground/drivers/recording/mcap/mcap_writer.hpp"

namespace ag::foxglove {
namespace {

std::string prop(std::string_view name, std::string_view body) { return "\"" + std::string(name) + "\":" + std::string(body); }

std::string object(std::string_view title, std::string_view description, const std::vector<std::string>& props) {
  std::string s = "{";
  if (!title.empty()) s += "\"title\":\"" + std::string(title) + "\",";
  s += "\"description\":\"" + std::string(description) + "\",\"type\":\"object\",\"properties\":{";
  for (std::size_t i = 0; i < props.size(); ++i) s += (i ? "," : "") + props[i];
  return s + "}}";
}
std::string number(std::string_view d) { return "{\"type\":\"number\",\"description\":\"" + std::string(d) + "\"}"; }
std::string integer(std::string_view d) { return "{\"type\":\"integer\",\"minimum\":0,\"description\":\"" + std::string(d) + "\"}"; }
std::string string(std::string_view d) { return "{\"type\":\"string\",\"description\":\"" + std::string(d) + "\"}"; }
std::string boolean(std::string_view d) { return "{\"type\":\"boolean\",\"description\":\"" + std::string(d) + "\"}"; }
std::string bytes(std::string_view d) {
  return "{\"type\":\"string\",\"contentEncoding\":\"base64\",\"description\":\"" + std::string(d) + "\"}";
}
std::string time(std::string_view d) {
  return "{\"type\":\"object\",\"title\":\"time\",\"properties\":{\"sec\":{\"type\":\"integer\",\"minimum\":0},"
         "\"nsec\":{\"type\":\"integer\",\"minimum\":0,\"maximum\":999999999}},\"description\":\"" + std::string(d) + "\"}";
}
std::string duration(std::string_view d) {
  return "{\"type\":\"object\",\"title\":\"duration\",\"properties\":{\"sec\":{\"type\":\"integer\"},"
         "\"nsec\":{\"type\":\"integer\",\"minimum\":0,\"maximum\":999999999}},\"description\":\"" + std::string(d) + "\"}";
}
std::string vector3(std::string_view title, std::string_view d) {
  return object(title, d, {prop("x", number("x coordinate length")), prop("y", number("y coordinate length")),
                           prop("z", number("z coordinate length"))});
}
std::string quaternion(std::string_view d) {
  return object("foxglove.Quaternion", d, {prop("x", number("x value")), prop("y", number("y value")), prop("z", number("z value")),
                                           prop("w", number("w value"))});
}
std::string pose(std::string_view d) {
  return object("foxglove.Pose", d, {prop("position", vector3("foxglove.Vector3", "Point denoting position in 3D space")),
                                     prop("orientation", quaternion("Quaternion denoting orientation in 3D space"))});
}
std::string color(std::string_view d) {
  return object("foxglove.Color", d, {prop("r", number("Red value between 0 and 1")), prop("g", number("Green value between 0 and 1")),
                                      prop("b", number("Blue value between 0 and 1")), prop("a", number("Alpha value between 0 and 1"))});
}
std::string enumeration(std::string_view title, std::string_view d, const std::vector<std::pair<std::string, int>>& values) {
  std::string s = "{\"title\":\"" + std::string(title) + "\",\"description\":\"" + std::string(d) + "\",\"oneOf\":[";
  for (std::size_t i = 0; i < values.size(); ++i)
    s += (i ? "," : "") + std::string("{\"title\":\"") + values[i].first + "\",\"const\":" + std::to_string(values[i].second) + "}";
  return s + "]}";
}
std::string array(std::string_view items, std::string_view d) {
  return "{\"type\":\"array\",\"items\":" + std::string(items) + ",\"description\":\"" + std::string(d) + "\"}";
}
std::string packed_fields(std::string_view d) {
  return array(object("foxglove.PackedElementField", "A field present within each element in a byte array of packed elements.",
                      {prop("name", string("Name of the field")), prop("offset", integer("Byte offset from start of data buffer")),
                       prop("type", enumeration("foxglove.NumericType",
                                                "Type of data in the field. Integers are stored using little-endian byte order.",
                                                {{"UNKNOWN", 0}, {"UINT8", 1}, {"INT8", 2}, {"UINT16", 3}, {"INT16", 4},
                                                 {"UINT32", 5}, {"INT32", 6}, {"FLOAT32", 7}, {"FLOAT64", 8}}))}),
               d);
}
// A top-level schema: object() with the generator comment.
std::string top(std::string_view title, std::string_view d, const std::vector<std::string>& props) {
  std::string s = object(title, d, props);
  return s.insert(s.find(",\"type\""), ",\"$comment\":\"Foxglove's published schema (github.com/foxglove/schemas), written by airground\"");
}

std::map<std::string, std::string, std::less<>> make_schemas() {
  std::map<std::string, std::string, std::less<>> m;
  m["foxglove.PoseInFrame"] = top("foxglove.PoseInFrame", "A timestamped pose for an object or reference frame in 3D space",
                                  {prop("timestamp", time("Timestamp of pose")),
                                   prop("frame_id", string("Frame of reference for pose position and orientation")),
                                   prop("pose", pose("Pose in 3D space"))});
  const std::string transform = object(
      "foxglove.FrameTransform", "A transform between two reference frames in 3D space",
      {prop("timestamp", time("Timestamp of transform")), prop("parent_frame_id", string("Name of the parent frame")),
       prop("child_frame_id", string("Name of the child frame")),
       prop("translation", vector3("foxglove.Vector3", "Translation component of the transform")),
       prop("rotation", quaternion("Rotation component of the transform"))});
  m["foxglove.FrameTransforms"] = top("foxglove.FrameTransforms", "An array of FrameTransform messages",
                                      {prop("transforms", array(transform, "Array of transforms"))});
  m["foxglove.PointCloud"] = top(
      "foxglove.PointCloud",
      "A collection of N-dimensional points, which may contain additional fields with information like normals, intensity, etc.",
      {prop("timestamp", time("Timestamp of point cloud")), prop("frame_id", string("Frame of reference")),
       prop("pose", pose("The origin of the point cloud relative to the frame of reference")),
       prop("point_stride", integer("Number of bytes between points in the `data`")),
       prop("fields", packed_fields("Fields in `data`. At least 2 coordinate fields from `x`, `y`, and `z` are required for each "
                                    "point's position; `red`, `green`, `blue`, and `alpha` are optional for customizing each point's color.")),
       prop("data", bytes("Point data, interpreted using `fields`"))});
  m["foxglove.Grid"] = top(
      "foxglove.Grid", "A 2D grid of data",
      {prop("timestamp", time("Timestamp of grid")), prop("frame_id", string("Frame of reference")),
       prop("pose", pose("Origin of grid's corner relative to frame of reference; grid is positioned in the x-y plane relative to this origin")),
       prop("column_count", integer("Number of grid columns")),
       prop("cell_size", object("foxglove.Vector2", "Size of single grid cell along x and y axes, relative to `pose`",
                                {prop("x", number("x coordinate length")), prop("y", number("y coordinate length"))})),
       prop("row_stride", integer("Number of bytes between rows in `data`")),
       prop("cell_stride", integer("Number of bytes between cells within a row in `data`")),
       prop("fields", packed_fields("Fields in `data`")),
       prop("data", bytes("Grid cell data, interpreted using `fields`, in row-major (y-major) order"))});
  m["foxglove.CompressedImage"] = top(
      "foxglove.CompressedImage", "A compressed image",
      {prop("timestamp", time("Timestamp of image")), prop("frame_id", string("Frame of reference for the image. The origin of the frame is the optical center of the camera. +x points to the right in the image, +y points down, and +z points into the plane of the image.")),
       prop("data", bytes("Compressed image data")),
       prop("format", string("Image format (webp, jpeg, png)"))});
  m["foxglove.RawImage"] = top(
      "foxglove.RawImage", "A raw image",
      {prop("timestamp", time("Timestamp of image")), prop("frame_id", string("Frame of reference for the image. The origin of the frame is the optical center of the camera. +x points to the right in the image, +y points down, and +z points into the plane of the image.")),
       prop("width", integer("Image width")), prop("height", integer("Image height")),
       prop("encoding", string("Encoding of the raw image data")), prop("step", integer("Byte length of a single row")),
       prop("data", bytes("Raw image data"))});
  const std::string line = object(
      "foxglove.LinePrimitive", "A primitive representing a series of points connected by lines",
      {prop("type", enumeration("foxglove.LineType", "Drawing primitive to use for lines", {{"LINE_STRIP", 0}, {"LINE_LOOP", 1}, {"LINE_LIST", 2}})),
       prop("pose", pose("Origin of lines relative to reference frame")),
       prop("thickness", number("Width of the line")), prop("scale_invariant", boolean("Indicates whether `thickness` is a fixed size in screen pixels (true), or specified in world coordinates and scales with distance from the camera (false)")),
       prop("points", array(vector3("foxglove.Point3", "A point representing a position in 3D space"), "Points along the line")),
       prop("color", color("Solid color to use for the whole line. One of `color` or `colors` must be provided.")),
       prop("colors", array(color("A color in RGBA format"), "Per-point colors (if specified, must have the same length as `points`). One of `color` or `colors` must be provided.")),
       prop("indices", array("{\"type\":\"integer\",\"minimum\":0}", "Indices into the `points` and `colors` attribute arrays, which can be used to avoid duplicating attribute data."))});
  const std::string sphere = object("foxglove.SpherePrimitive", "A primitive representing a sphere or ellipsoid",
                                    {prop("pose", pose("Position of the center of the sphere and orientation of the sphere")),
                                     prop("size", vector3("foxglove.Vector3", "Size (diameter) of the sphere along each axis")),
                                     prop("color", color("Color of the sphere"))});
  const std::string text = object(
      "foxglove.TextPrimitive", "A primitive representing a text label",
      {prop("pose", pose("Position of the center of the text box and orientation of the text. Identity orientation means the text is oriented in the xy-plane and flows from -x to +x.")),
       prop("billboard", boolean("Whether the text should respect `pose.orientation` (false) or always face the camera (true)")),
       prop("font_size", number("Font size (height of one line of text)")),
       prop("scale_invariant", boolean("Indicates whether `font_size` is a fixed size in screen pixels (true), or specified in world coordinates and scales with distance from the camera (false)")),
       prop("color", color("Color of the text")), prop("text", string("Text"))});
  // SceneEntity: the fields and the three primitive arrays we write (arrows, cubes, cylinders,
  // triangles and models are optional in the published schema and left out of ours).
  const std::string entity = object(
      "foxglove.SceneEntity", "A visual element in a 3D scene. An entity may be composed of multiple primitives which all share the same frame of reference.",
      {prop("timestamp", time("Timestamp of the entity")), prop("frame_id", string("Frame of reference")),
       prop("id", string("Identifier for the entity. A entity will replace any prior entity on the same topic with the same `id`.")),
       prop("lifetime", duration("Length of time (relative to `timestamp`) after which the entity should be automatically removed. Zero value indicates the entity should remain visible until it is replaced or deleted.")),
       prop("frame_locked", boolean("Whether the entity should keep its location in the fixed frame (false) or follow the frame specified in `frame_id` as it moves relative to the fixed frame (true)")),
       prop("metadata", array(object("foxglove.KeyValuePair", "An entry representing a key and its associated value",
                                     {prop("key", string("Key")), prop("value", string("Value"))}),
                              "Additional user-provided metadata associated with the entity. Keys must be unique.")),
       prop("spheres", array(sphere, "Sphere primitives")), prop("lines", array(line, "Line primitives")),
       prop("texts", array(text, "Text primitives"))});
  const std::string deletion = object(
      "foxglove.SceneEntityDeletion", "Command to remove previously published entities",
      {prop("timestamp", time("Timestamp of the deletion. Only matching entities earlier than this timestamp will be deleted.")),
       prop("type", enumeration("foxglove.SceneEntityDeletionType", "Type of deletion action to perform", {{"MATCHING_ID", 0}, {"ALL", 1}})),
       prop("id", string("Identifier which must match if `type` is `MATCHING_ID`."))});
  m["foxglove.SceneUpdate"] = top("foxglove.SceneUpdate", "An update to the entities displayed in a 3D scene",
                                  {prop("deletions", array(deletion, "Scene entities to delete")),
                                   prop("entities", array(entity, "Scene entities to add or replace"))});
  m["foxglove.Log"] = top(
      "foxglove.Log", "A log message",
      {prop("timestamp", time("Timestamp of log message")),
       prop("level", enumeration("foxglove.LogLevel", "Log level", {{"UNKNOWN", 0}, {"DEBUG", 1}, {"INFO", 2}, {"WARNING", 3}, {"ERROR", 4}, {"FATAL", 5}})),
       prop("message", string("Log message")), prop("name", string("Process or node name")), prop("file", string("Filename")),
       prop("line", integer("Line number in the file"))});
  m["foxglove.LocationFix"] = top(
      "foxglove.LocationFix", "A navigation satellite fix for any Global Navigation Satellite System",
      {prop("frame_id", string("Frame for the sensor. Latitude and longitude readings are at the origin of the frame.")),
       prop("timestamp", time("Timestamp of the message")), prop("latitude", number("Latitude in degrees")),
       prop("longitude", number("Longitude in degrees")), prop("altitude", number("Altitude in meters")),
       prop("position_covariance", "{\"type\":\"array\",\"items\":{\"type\":\"number\"},\"minItems\":9,\"maxItems\":9,\"description\":\"Position covariance (m^2) defined relative to a tangential plane through the reported position. The components are East, North, and Up (ENU), in row-major order.\"}"),
       prop("position_covariance_type", enumeration("foxglove.PositionCovarianceType", "If `position_covariance` is available, `position_covariance_type` must be set to indicate the type of covariance.",
                                                    {{"UNKNOWN", 0}, {"APPROXIMATED", 1}, {"DIAGONAL_KNOWN", 2}, {"KNOWN", 3}}))});
  return m;
}

std::string ts(std::uint64_t t_ns) {
  return "{\"sec\":" + std::to_string(t_ns / 1000000000u) + ",\"nsec\":" + std::to_string(t_ns % 1000000000u) + "}";
}
std::string vec(const Vec3& v) { return "{\"x\":" + json_number(v.x) + ",\"y\":" + json_number(v.y) + ",\"z\":" + json_number(v.z) + "}"; }
std::string quat(const Quat& q) {
  return "{\"x\":" + json_number(q.x) + ",\"y\":" + json_number(q.y) + ",\"z\":" + json_number(q.z) + ",\"w\":" + json_number(q.w) + "}";
}
std::string pose_json(const Pose& p) { return "{\"position\":" + vec(p.position) + ",\"orientation\":" + quat(p.orientation) + "}"; }
std::string color_json(const Color& c) {
  return "{\"r\":" + json_number(c.r) + ",\"g\":" + json_number(c.g) + ",\"b\":" + json_number(c.b) + ",\"a\":" + json_number(c.a) + "}";
}
std::string fields_json(const std::vector<PackedElementField>& fields) {
  std::string s = "[";
  for (std::size_t i = 0; i < fields.size(); ++i)
    s += (i ? "," : "") + std::string("{\"name\":") + json_string(fields[i].name) + ",\"offset\":" + std::to_string(fields[i].offset) +
         ",\"type\":" + std::to_string(static_cast<int>(fields[i].type)) + "}";
  return s + "]";
}

}  // namespace

const std::string& schema(std::string_view name) {
  static const std::map<std::string, std::string, std::less<>> schemas = make_schemas();
  static const std::string none;
  const auto it = schemas.find(name);
  return it == schemas.end() ? none : it->second;
}

Quat quat_from_rpy(double roll, double pitch, double yaw) noexcept {
  const double cr = std::cos(roll / 2), sr = std::sin(roll / 2), cp = std::cos(pitch / 2), sp = std::sin(pitch / 2);
  const double cy = std::cos(yaw / 2), sy = std::sin(yaw / 2);
  return Quat{sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy};
}

std::string json_string(std::string_view s) {
  std::string out = "\"";
  for (const char c : s) {
    switch (c) {
      case '"': out += "\\\""; break;
      case '\\': out += "\\\\"; break;
      case '\n': out += "\\n"; break;
      case '\t': out += "\\t"; break;
      case '\r': out += "\\r"; break;
      default:
        if (static_cast<unsigned char>(c) < 0x20) {
          static constexpr char kHex[] = "0123456789abcdef";
          out += "\\u00";
          out += kHex[(static_cast<unsigned char>(c) >> 4) & 15u];
          out += kHex[static_cast<unsigned char>(c) & 15u];
        } else {
          out += c;
        }
    }
  }
  return out + "\"";
}

std::string json_number(double v) {
  if (!std::isfinite(v)) return "null";
  if (v == 0) return "0";  // also -0
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, r.ptr);
}

std::string pose_in_frame(std::uint64_t t_ns, std::string_view frame_id, const Pose& pose) {
  return "{\"timestamp\":" + ts(t_ns) + ",\"frame_id\":" + json_string(frame_id) + ",\"pose\":" + pose_json(pose) + "}";
}

std::string frame_transforms(std::uint64_t t_ns, const std::vector<FrameTransform>& transforms) {
  std::string s = "{\"transforms\":[";
  for (std::size_t i = 0; i < transforms.size(); ++i) {
    const FrameTransform& f = transforms[i];
    s += (i ? "," : "") + std::string("{\"timestamp\":") + ts(t_ns) + ",\"parent_frame_id\":" + json_string(f.parent_frame_id) +
         ",\"child_frame_id\":" + json_string(f.child_frame_id) + ",\"translation\":" + vec(f.translation) +
         ",\"rotation\":" + quat(f.rotation) + "}";
  }
  return s + "]}";
}

std::string point_cloud(std::uint64_t t_ns, std::string_view frame_id, const Pose& origin, std::uint32_t point_stride,
                        const std::vector<PackedElementField>& fields, std::span<const std::uint8_t> data) {
  return "{\"timestamp\":" + ts(t_ns) + ",\"frame_id\":" + json_string(frame_id) + ",\"pose\":" + pose_json(origin) +
         ",\"point_stride\":" + std::to_string(point_stride) + ",\"fields\":" + fields_json(fields) + ",\"data\":\"" +
         mcap::base64(data) + "\"}";
}

std::string grid(std::uint64_t t_ns, std::string_view frame_id, const Pose& corner, std::uint32_t column_count, double cell_x,
                 double cell_y, std::uint32_t row_stride, std::uint32_t cell_stride, const std::vector<PackedElementField>& fields,
                 std::span<const std::uint8_t> data) {
  return "{\"timestamp\":" + ts(t_ns) + ",\"frame_id\":" + json_string(frame_id) + ",\"pose\":" + pose_json(corner) +
         ",\"column_count\":" + std::to_string(column_count) + ",\"cell_size\":{\"x\":" + json_number(cell_x) + ",\"y\":" +
         json_number(cell_y) + "},\"row_stride\":" + std::to_string(row_stride) + ",\"cell_stride\":" + std::to_string(cell_stride) +
         ",\"fields\":" + fields_json(fields) + ",\"data\":\"" + mcap::base64(data) + "\"}";
}

std::string compressed_image(std::uint64_t t_ns, std::string_view frame_id, std::string_view format, std::span<const std::uint8_t> data) {
  return "{\"timestamp\":" + ts(t_ns) + ",\"frame_id\":" + json_string(frame_id) + ",\"data\":\"" + mcap::base64(data) +
         "\",\"format\":" + json_string(format) + "}";
}

std::string raw_image(std::uint64_t t_ns, std::string_view frame_id, std::uint32_t width, std::uint32_t height, std::string_view encoding,
                      std::uint32_t step, std::span<const std::uint8_t> data) {
  return "{\"timestamp\":" + ts(t_ns) + ",\"frame_id\":" + json_string(frame_id) + ",\"width\":" + std::to_string(width) +
         ",\"height\":" + std::to_string(height) + ",\"encoding\":" + json_string(encoding) + ",\"step\":" + std::to_string(step) +
         ",\"data\":\"" + mcap::base64(data) + "\"}";
}

std::string scene_update(std::uint64_t t_ns, const std::vector<SceneEntity>& entities) {
  const std::string identity = pose_json(Pose{});
  std::string s = "{\"deletions\":[],\"entities\":[";
  for (std::size_t i = 0; i < entities.size(); ++i) {
    const SceneEntity& e = entities[i];
    s += (i ? "," : "") + std::string("{\"timestamp\":") + ts(t_ns) + ",\"frame_id\":" + json_string(e.frame_id) +
         ",\"id\":" + json_string(e.id) + ",\"lifetime\":{\"sec\":0,\"nsec\":0},\"frame_locked\":false,\"metadata\":[],\"spheres\":[";
    for (std::size_t k = 0; k < e.spheres.size(); ++k) {
      const Sphere& p = e.spheres[k];
      s += (k ? "," : "") + std::string("{\"pose\":") + pose_json(Pose{p.position, {}}) + ",\"size\":" +
           vec(Vec3{p.diameter, p.diameter, p.diameter}) + ",\"color\":" + color_json(p.color) + "}";
    }
    s += "],\"lines\":[";
    for (std::size_t k = 0; k < e.lines.size(); ++k) {
      const LineStrip& l = e.lines[k];
      s += (k ? "," : "") + std::string("{\"type\":") + (l.loop ? "1" : "0") + ",\"pose\":" + identity + ",\"thickness\":" +
           json_number(l.thickness) + ",\"scale_invariant\":false,\"points\":[";
      for (std::size_t j = 0; j < l.points.size(); ++j) s += (j ? "," : "") + vec(l.points[j]);
      s += "],\"color\":" + color_json(l.color) + ",\"colors\":[],\"indices\":[]}";
    }
    s += "],\"texts\":[";
    for (std::size_t k = 0; k < e.texts.size(); ++k) {
      const Text& t = e.texts[k];
      s += (k ? "," : "") + std::string("{\"pose\":") + pose_json(Pose{t.position, {}}) + ",\"billboard\":true,\"font_size\":" +
           json_number(t.font_size) + ",\"scale_invariant\":true,\"color\":" + color_json(t.color) + ",\"text\":" + json_string(t.text) + "}";
    }
    s += "]}";
  }
  return s + "]}";
}

std::string log(std::uint64_t t_ns, LogLevel level, std::string_view name, std::string_view message) {
  return "{\"timestamp\":" + ts(t_ns) + ",\"level\":" + std::to_string(static_cast<int>(level)) + ",\"message\":" + json_string(message) +
         ",\"name\":" + json_string(name) + ",\"file\":\"\",\"line\":0}";
}

std::string location_fix(std::uint64_t t_ns, std::string_view frame_id, double lat_deg, double lon_deg, double alt_m, double horizontal_sigma_m) {
  const std::string v = json_number(horizontal_sigma_m * horizontal_sigma_m);
  return "{\"timestamp\":" + ts(t_ns) + ",\"frame_id\":" + json_string(frame_id) + ",\"latitude\":" + json_number(lat_deg) +
         ",\"longitude\":" + json_number(lon_deg) + ",\"altitude\":" + json_number(alt_m) + ",\"position_covariance\":[" + v +
         ",0,0,0," + v + ",0,0,0," + json_number(4 * horizontal_sigma_m * horizontal_sigma_m) + "],\"position_covariance_type\":2}";
}

}  // namespace ag::foxglove
