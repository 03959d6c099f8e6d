// Pictures of a world for people to look at: the class map in display colours, the aerial colour,
// colour-mapped heights and terrain with a scale bar, a hillshade of the surface and a class legend.
#pragma once

#include <opencv2/core.hpp>

#include <string>

#include "airground/messages/classes.hpp"
#include "airground/platform/result.hpp"
#include "airground/sim/world.hpp"

namespace ag::sim {

// A class raster (CV_8UC1) in the table's display colours, RGB (CV_8UC3); ids not in the table are black.
[[nodiscard]] cv::Mat class_display_image(const cv::Mat& class_id, const ClassTable& classes = ClassTable::builtin());

// Writes class.png, albedo.png, height.png (square-root colour scale, so cars show next to towers),
// terrain.png (linear), both with a labelled scale bar, hillshade.png, legend.png and pngs.yaml (what
// each picture shows and its value range). Refuses a directory holding a world (world.yaml), whose
// class.png holds ids, not colours.
Status write_world_pngs(const World& w, const std::string& out_dir);

}  // namespace ag::sim
