// Raster files through GDAL: reading any raster a GIS tool writes, and writing float layers as GeoTIFF
// georeferenced on the local ENU map frame, so worlds and maps open in QGIS where they belong.
#pragma once

#include <opencv2/core.hpp>

#include <array>
#include <optional>
#include <string>
#include <string_view>

#include "airground/messages/geometry.hpp"
#include "airground/platform/result.hpp"
#include "airground/sim/world.hpp"

namespace ag::sim {

struct Raster {
  cv::Mat pixels;                         // bands as channels (1..4), the file's depth (8U, 16U, 16S, 32S, 32F, 64F)
  std::string data_type;                  // GDAL's name of the stored type, e.g. "Float32"
  std::optional<std::array<double, 6>> geotransform;  // absent when the file has none
  std::optional<double> nodata;           // of band 1
  cv::Mat palette;                        // CV_8UC3 RGB, one row per palette index; empty without a colour table
  std::string projection_wkt;
};

// Reads every band of a raster file; errors (kIo: missing or unreadable, kMalformed: truncated, corrupt,
// unsupported type) name the file.
Result<Raster> read_raster(const std::string& path);

// Size, band count and type from the file's header alone: lets a caller refuse a wrong or absurdly large
// raster before any pixel memory is allocated.
struct RasterShape {
  int width{0}, height{0}, bands{0};
  std::string data_type;
};
Result<RasterShape> probe_raster(const std::string& path);

// The PROJ string of the map frame: an orthographic projection on WGS84 centred on the datum, which is
// the ENU tangent plane (east, north) for points on the ellipsoid.
[[nodiscard]] std::string enu_proj_string(const Datum& datum);

// Writes a CV_32FC1 layer as a tiled, deflate-compressed float32 GeoTIFF: geotransform from the grid
// (origin_x west edge, origin_y north edge, pixel res x -res), the ENU projection, and metadata
// AG_LAYER (what the values are), AG_UNIT, AG_DATUM_LAT_DEG/LON_DEG/HEIGHT_M and AG_RESOLUTION_M.
Status write_geotiff(const std::string& path, const cv::Mat& layer, const GridGeometry& grid, const Datum& datum,
                     std::string_view layer_name, std::string_view meaning);

}  // namespace ag::sim
