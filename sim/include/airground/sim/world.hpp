// The simulated world: a 2.5D raster of class, height above terrain, terrain elevation and albedo.
#pragma once

#include <opencv2/core.hpp>

#include <cstdint>
#include <string>

#include "airground/messages/classes.hpp"
#include "airground/messages/geometry.hpp"
#include "airground/platform/result.hpp"

namespace ag::sim {

// Geodetic anchor of the local ENU map frame (WGS84).
struct Datum {
  double lat_deg{47.3977};   // default: a field near Zurich
  double lon_deg{8.5456};
  double height_m{488.0};    // ellipsoidal height of the ENU origin
};

struct WorldHeader {
  std::string name{"world"};
  GridGeometry grid;          // resolution default 0.25 m; the map frame origin (0,0) is the datum
  Datum datum;
  std::uint64_t seed{0};      // generator seed (0 for imported worlds)
  std::string source{"generator"};  // "generator" or "import"
  std::int32_t format_version{1};
  // Where the ground robots start: the centre of a free paved area near the south-west corner, yaw
  // along the way out (generator: a 24 m staging pad beside a road; importer: the most south-westerly
  // road or dirt cell with free space around it).
  Pose2 staging;
};

// Layers share the grid (row 0 = north edge). The surface a ray or a wheel meets is terrain + height.
struct World {
  WorldHeader header;
  cv::Mat class_id;  // CV_8UC1: ClassId values (config/classes.yaml)
  cv::Mat height;    // CV_32FC1 [m]: object height above terrain (buildings 5-30, trees, cars 1.5, curbs)
  cv::Mat terrain;   // CV_32FC1 [m]: terrain elevation above the datum height
  cv::Mat albedo;    // CV_8UC3: colour, RGB channel order

  [[nodiscard]] const GridGeometry& grid() const noexcept { return header.grid; }
  [[nodiscard]] ClassId class_at(std::int32_t col, std::int32_t row) const noexcept {
    return static_cast<ClassId>(class_id.at<std::uint8_t>(row, col));
  }
  [[nodiscard]] float surface_at(std::int32_t col, std::int32_t row) const noexcept {
    return terrain.at<float>(row, col) + height.at<float>(row, col);
  }
  // Class under a map-frame point, kUnknown outside the world.
  [[nodiscard]] ClassId class_at_xy(double x, double y) const noexcept {
    const auto c = header.grid.col(x), r = header.grid.row(y);
    return header.grid.contains(c, r) ? class_at(c, r) : ClassId::kUnknown;
  }
  // Checks layer sizes and types against the header, class ids against the table, finite heights.
  [[nodiscard]] Status validate(const ClassTable& classes = ClassTable::builtin()) const;
};

// A world directory: world.yaml (header), class.png (ids, 8-bit grey), albedo.png (colour),
// height.tif and terrain.tif (float32 GeoTIFF with the ENU geotransform and the datum in metadata).
// The GeoTIFFs carry "+proj=ortho" centred on the datum (WGS84): the tangent plane of a local ENU, so
// GIS tools place the world where it is. Saving twice gives byte-identical files.
Status save_world(const World& w, const std::string& dir);
// Every file is checked; a missing, truncated or inconsistent file is an error naming it.
Result<World> load_world(const std::string& dir);

// The world under one square map cell of edge `res` centred on (x, y): the majority class of the world
// cells whose centres fall inside it (the single cell under the centre when the map cell is finer than
// the world's), and the mean surface height over them. `count` = 0 (class 255, surface NaN) off the world.
struct WorldCellSummary {
  std::uint8_t cls{255};
  double surface{0};
  int count{0};
};
WorldCellSummary summarise_cell(const World& w, double x, double y, double res) noexcept;

}  // namespace ag::sim
