// The map importer: a user's own area as a world, from a class raster (ids or colours) with a legend,
// optionally an elevation raster and a colour image; whatever is missing is synthesised.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "airground/platform/result.hpp"
#include "airground/sim/world.hpp"

namespace ag::sim {

struct ImportOptions {
  // Class raster, any format GDAL reads (PNG, GeoTIFF, ...): one band of class values, or colours
  // (RGB, RGBA where alpha < 128 is unknown, or a paletted image).
  std::string classes_path;
  // Legend YAML: `classes:` entries `{value: N, class: NAME}` for value rasters or
  // `{color: [R, G, B], class: NAME}` for colour rasters; NAME from config/classes.yaml.
  std::string legend_path;
  std::string elevation_path;  // optional: terrain elevation raster [m], resampled to the class raster's size
  std::string color_path;      // optional: aerial colour image, resampled to the class raster's size
  // [m/px]; 0 takes the pixel size of a georeferenced class raster (projected, metres).
  double resolution_m_per_px{0};
  Datum datum;
  std::string name{"imported"};
  // true: elevation values are heights in the datum's vertical reference, terrain = value - datum.height_m;
  // false: they already are terrain above the datum height.
  bool elevation_is_absolute{true};
  std::uint64_t texture_seed{1};  // for synthesised colour and heights
};

// What the import found, for the user: counts per class and everything that was guessed or repaired.
struct ImportReport {
  std::array<std::int64_t, 256> class_cells{};   // cells per class id in the result
  std::int64_t unknown_value_cells{0};           // value raster: cells whose value the legend lacks (-> unknown)
  std::vector<std::int64_t> unknown_values;      // those values (the first 32 distinct)
  std::int64_t transparent_cells{0};             // colour raster: alpha < 128 (-> unknown)
  std::int64_t blended_cells{0};                 // colour raster: not a legend colour, resolved to the nearest neighbouring class
  std::int64_t elevation_filled_cells{0};        // elevation nodata or not finite, filled with the mean
  bool elevation_resampled{false};
  bool color_resampled{false};
  bool heights_synthesised{true};
  bool albedo_synthesised{true};

  [[nodiscard]] std::string summary() const;
};

// The world grid is the class raster: its centre is the map origin (0, 0), north up. Colour rasters
// are matched to the nearest legend colour; a pixel that is no legend colour (anti-aliased edges, JPEG
// noise) takes the nearest among the legend colours found in its 5x5 neighbourhood, so a blend of two
// classes never becomes a third. A colour that is neither near a legend colour nor a blend of two and
// covers more than 0.2% of the raster is a missing legend entry: an error. Heights are synthesised per
// class (synthesize_heights), albedo from the class textures unless a colour image is given. Staging
// is the most south-westerly road or dirt cell with at least 3 m of road or dirt around it (or the
// most open one there is).
Result<World> import_world(const ImportOptions& options, ImportReport* report = nullptr);

}  // namespace ag::sim
