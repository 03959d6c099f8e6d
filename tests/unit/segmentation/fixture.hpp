// The committed ErfNet fixtures (tools/erfnet_goldens.py): random weights in our format (fp16) and a
// random image with the logits torch computed for it in float64.
#pragma once

#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "airground/segmentation/weights.hpp"

namespace ag::seg::test {

inline std::string data_path(const std::string& name) { return std::string(AG_SEG_DATA_DIR) + "/" + name; }
inline std::string weights_path() { return data_path("erfnet_random_c7.agw"); }

// The fixture weights, loaded once per test executable (loading is slow under qemu).
inline const ErfNetWeights& fixture_weights() {
  static const ErfNetWeights w = [] {
    auto r = load_weights(weights_path());
    if (!r.ok()) {
      ADD_FAILURE() << r.error().message;
      return ErfNetWeights{};
    }
    return r.value();
  }();
  return w;
}

// A w x h crop of the golden image (tests that compare engines with each other use small frames).
struct Crop {
  int width{0}, height{0};
  std::vector<std::uint8_t> rgb;
};

inline std::vector<std::uint8_t> read_bytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}

struct Golden {
  int width{0}, height{0}, classes{0};
  std::vector<std::uint8_t> rgb;  // height x width x 3
  std::vector<float> logits;      // classes x height x width
  [[nodiscard]] std::uint8_t argmax(std::size_t pixel) const {
    const std::size_t plane = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
    std::uint8_t best = 0;
    for (int c = 1; c < classes; ++c)
      if (logits[static_cast<std::size_t>(c) * plane + pixel] > logits[best * plane + pixel]) best = static_cast<std::uint8_t>(c);
    return best;
  }
};

inline Golden load_golden(const std::string& name) {
  const std::vector<std::uint8_t> b = read_bytes(data_path(name));
  Golden g;
  if (b.size() < 20 || std::memcmp(b.data(), "AGSEGGLD", 8) != 0) {
    ADD_FAILURE() << "golden " << name << " missing or malformed";
    return g;
  }
  std::uint32_t d[3];
  std::memcpy(d, b.data() + 8, sizeof d);
  g.width = static_cast<int>(d[0]);
  g.height = static_cast<int>(d[1]);
  g.classes = static_cast<int>(d[2]);
  const std::size_t px = static_cast<std::size_t>(d[0]) * d[1];
  if (b.size() != 20 + px * 3 + px * d[2] * 4) {
    ADD_FAILURE() << "golden " << name << " has the wrong size";
    return g;
  }
  g.rgb.assign(b.begin() + 20, b.begin() + static_cast<std::ptrdiff_t>(20 + px * 3));
  g.logits.resize(px * d[2]);
  std::memcpy(g.logits.data(), b.data() + 20 + px * 3, g.logits.size() * 4);
  return g;
}

inline Crop crop(const Golden& g, int w, int h) {
  Crop c{w, h, {}};
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < 3 * w; ++x) c.rgb.push_back(g.rgb[static_cast<std::size_t>(y * 3 * g.width + x)]);
  return c;
}

}  // namespace ag::seg::test

namespace ag::seg::test {
// What the tests hold of the cached weights: the same spelling as a Result's value().
struct WeightsRef {
  const ErfNetWeights& w;
  [[nodiscard]] const ErfNetWeights& value() const { return w; }
};
}  // namespace ag::seg::test
