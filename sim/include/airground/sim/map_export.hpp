// Export of the aerial ortho-map as GeoTIFF (UTM of the datum, with the geotransform) and PNGs.
// GDAL links dynamically, so this lives in the simulator's tools, not in the static role binaries.
#pragma once

#include <string>

#include "airground/aerial_mapping/ortho_map.hpp"
#include "airground/platform/result.hpp"
#include "airground/sim/world.hpp"

namespace ag::sim {

// The UTM zone of the datum and the affine map-frame -> UTM transform (meridian convergence and
// point scale included), fitted at the datum; sub-centimetre over a few kilometres.
struct UtmFrame {
  int zone{0};
  bool north{true};
  int epsg{0};          // 326zz (north) or 327zz (south)
  double e0{0}, n0{0};  // [m] UTM easting/northing of the map origin
  double a{1}, b{0}, c{0}, d{1};  // E = e0 + a x + b y, N = n0 + c x + d y
};
[[nodiscard]] UtmFrame utm_frame(const Datum& datum);

// Writes into dir: map_class.tif (Byte, class ids, 255 nodata, colour table), map_elevation.tif
// (Float32 [m above the datum height], NaN nodata), map_rgb.tif (3 x Byte), all in the datum's UTM zone;
// and map_class.png, map_rgb.png, map_elevation.png (colour-mapped) for people.
Status write_map_exports(const std::string& dir, const mapping::MapRaster& raster, const Datum& datum);

}  // namespace ag::sim
