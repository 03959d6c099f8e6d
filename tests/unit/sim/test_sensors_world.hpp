// Small in-memory Worlds for the sensor tests: flat ground, blocks of known height, classes and colours.
#pragma once

#include <opencv2/core.hpp>

#include <algorithm>
#include <cstdint>

#include "airground/messages/classes.hpp"
#include "airground/sim/world.hpp"

namespace ag::sim::testing {

// A flat world of `cls` at terrain 0; x in [origin_x, origin_x + width * res), y down from origin_y.
inline World flat_world(std::int32_t width, std::int32_t height, double res, double origin_x, double origin_y,
                        ClassId cls = ClassId::kRoad) {
  World w;
  w.header.grid.resolution = res;
  w.header.grid.width = width;
  w.header.grid.height = height;
  w.header.grid.origin_x = origin_x;
  w.header.grid.origin_y = origin_y;
  w.class_id = cv::Mat(height, width, CV_8UC1, cv::Scalar(raw(cls)));
  w.height = cv::Mat(height, width, CV_32FC1, cv::Scalar(0.0));
  w.terrain = cv::Mat(height, width, CV_32FC1, cv::Scalar(0.0));
  const Rgb c = ClassTable::builtin().info(cls).color;
  w.albedo = cv::Mat(height, width, CV_8UC3, cv::Scalar(c.r, c.g, c.b));
  return w;
}

// Sets cells [col0, col1) x [row0, row1) (clipped to the grid) to a class, object height and colour.
inline void fill_cells(World& w, std::int32_t col0, std::int32_t row0, std::int32_t col1, std::int32_t row1, ClassId cls,
                       float object_height, cv::Vec3b rgb) {
  const GridGeometry& g = w.grid();
  for (std::int32_t r = std::max(row0, 0); r < std::min(row1, g.height); ++r) {
    for (std::int32_t c = std::max(col0, 0); c < std::min(col1, g.width); ++c) {
      w.class_id.at<std::uint8_t>(r, c) = raw(cls);
      w.height.at<float>(r, c) = object_height;
      w.albedo.at<cv::Vec3b>(r, c) = rgb;
    }
  }
}

// The same for a map-frame rectangle [x0, x1) x [y0, y1) [m]: cells whose centre lies inside.
inline void fill_rect(World& w, double x0, double y0, double x1, double y1, ClassId cls, float object_height,
                      cv::Vec3b rgb) {
  const GridGeometry& g = w.grid();
  for (std::int32_t r = 0; r < g.height; ++r) {
    const double y = g.y_of(r);
    if (y < y0 || y >= y1) continue;
    for (std::int32_t c = 0; c < g.width; ++c) {
      const double x = g.x_of(c);
      if (x < x0 || x >= x1) continue;
      w.class_id.at<std::uint8_t>(r, c) = raw(cls);
      w.height.at<float>(r, c) = object_height;
      w.albedo.at<cv::Vec3b>(r, c) = rgb;
    }
  }
}

inline cv::Vec3b class_rgb(ClassId cls) {
  const Rgb c = ClassTable::builtin().info(cls).color;
  return {c.r, c.g, c.b};
}

}  // namespace ag::sim::testing
