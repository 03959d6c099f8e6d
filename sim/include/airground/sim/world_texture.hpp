// Procedural textures and heights shared by the world generator and the importer: noise fields, per-class
// aerial colour with enough detail for stereo matching and segmentation training, and object heights for
// class maps that come without any.
#pragma once

#include <opencv2/core.hpp>

#include <cstdint>

namespace ag::sim {

// A well-mixed 64-bit hash of two words: per-object choices that do not depend on generation order.
[[nodiscard]] std::uint64_t mix_hash(std::uint64_t a, std::uint64_t b) noexcept;
// Uniform in [0, 1) from a hash.
[[nodiscard]] double hash_unit(std::uint64_t a, std::uint64_t b) noexcept;

// Independent per-cell noise, CV_32FC1 uniform in [-1, 1).
[[nodiscard]] cv::Mat white_noise(cv::Size size, std::uint64_t seed);
// Smooth value noise, CV_32FC1 in about [-1, 1]: a random lattice every cell_px cells, cubic-interpolated.
[[nodiscard]] cv::Mat value_noise(cv::Size size, double cell_px, std::uint64_t seed);
// Sum of `octaves` value noises, each with half the cell size and half the amplitude, scaled to about [-1, 1].
[[nodiscard]] cv::Mat fractal_noise(cv::Size size, double cell_px, int octaves, std::uint64_t seed);

// Shading of a surface [m] lit from the north-west, 45 degrees up: CV_32FC1, 0 (facing away) to 1
// (facing the sun); level ground is about 0.71.
[[nodiscard]] cv::Mat hillshade(const cv::Mat& surface, double resolution);

// Aerial colour (CV_8UC3, RGB) for a class raster (CV_8UC1) and its object heights (CV_32FC1): asphalt
// grain and repairs, concrete curbs, gravel speckle, grass patches of several hues, leafy tree crowns
// shaded by their height with dark rims, roofs coloured per building (tiled when pitched, with parapets
// when flat), cars in varied paint, rippled water darker away from the shore.
[[nodiscard]] cv::Mat paint_albedo(const cv::Mat& class_id, const cv::Mat& height, double resolution, std::uint64_t seed);

// Object heights [m] (CV_32FC1) for a class raster that has none: buildings 8-15 m per connected block,
// tree crowns 6-12 m domed towards the middle, vehicles 1.5 m, 0.15 m curbs where roads meet
// vegetation or buildings (only at 0.5 m/cell or finer, where a curb is a thin strip).
[[nodiscard]] cv::Mat synthesize_heights(const cv::Mat& class_id, double resolution, std::uint64_t seed);

// Distance [m] from each cell to the nearest cell of another class (CV_32FC1).
[[nodiscard]] cv::Mat distance_to_class_edge(const cv::Mat& class_id, double resolution);

}  // namespace ag::sim
