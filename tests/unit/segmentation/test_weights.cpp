// The ErfNet weights format: what tools/erfnet_export.py writes is read back exactly, and every kind of
// corrupt or mismatched file is refused with a message naming the file and what is wrong.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include "airground/segmentation/weights.hpp"
#include "fixture.hpp"

namespace ag::seg {
namespace {

std::string refuse(const std::vector<std::uint8_t>& bytes) {
  auto r = parse_weights(bytes, "w.agw");
  if (r.ok()) return "<accepted>";
  EXPECT_EQ(r.error().message.rfind("w.agw: ", 0), 0U) << r.error().message;  // names the file
  return r.error().message;
}

// Rewrites the trailing checksum so that only the deliberate change is wrong.
void reseal(std::vector<std::uint8_t>& b) {
  const std::uint32_t c = crc32(std::span<const std::uint8_t>(b.data(), b.size() - 4));
  std::memcpy(b.data() + b.size() - 4, &c, 4);
}

ErfNetWeights fixture() {
  auto w = load_weights(test::weights_path());
  EXPECT_TRUE(w.ok()) << w.error().message;
  return w.ok() ? w.value() : ErfNetWeights{};
}

#define EXPECT_CONTAINS(s, sub) EXPECT_NE((s).find(sub), std::string::npos) << (s)

TEST(Weights, Crc32IsZlibs) {
  const char* s = "123456789";
  EXPECT_EQ(crc32(std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(s), 9)), 0xCBF43926U);
}

TEST(Weights, HalfFloatsRoundTripExactlyAndRoundToNearestEven) {
  for (std::uint32_t h = 0; h < 0x10000U; ++h) {
    const auto hv = static_cast<std::uint16_t>(h);
    const float f = half_to_float(hv);
    if (std::isnan(f)) continue;
    ASSERT_EQ(float_to_half(f), hv) << std::hex << h;
  }
  EXPECT_EQ(half_to_float(0x3C00), 1.0F);
  EXPECT_EQ(half_to_float(0xC000), -2.0F);
  EXPECT_EQ(half_to_float(0x0001), std::ldexp(1.0F, -24));  // smallest subnormal
  EXPECT_EQ(float_to_half(1.0F + std::ldexp(1.0F, -11)), 0x3C00);  // halfway: to even
  EXPECT_EQ(float_to_half(1.0F + 3 * std::ldexp(1.0F, -11)), 0x3C02);
  EXPECT_EQ(float_to_half(65520.0F), 0x7C00);  // overflows to inf
  EXPECT_EQ(float_to_half(65504.0F), 0x7BFF);
}

TEST(Weights, TheExportersFileLoadsWithTheReferenceArchitecture) {
  const ErfNetWeights w = fixture();
  EXPECT_EQ(w.header.version, 1U);
  EXPECT_EQ(w.header.num_classes, 7U);
  EXPECT_EQ(w.header.input_width, 64U);
  EXPECT_EQ(w.header.input_height, 48U);
  EXPECT_EQ(w.header.std[0], 1.0F);
  EXPECT_EQ(w.tensors.size(), erfnet_tensor_specs(7).size());
  EXPECT_EQ(w.tensors.size(), 304U);
  // 2.07 M parameters (the issue), here with 7 classes (BN statistics counted too).
  EXPECT_NEAR(static_cast<double>(w.parameter_count()) / 1e6, 2.07, 0.01);
  const WeightTensor* out = w.find("decoder.output_conv.weight");
  ASSERT_NE(out, nullptr);
  EXPECT_EQ(out->dims, (std::vector<std::uint32_t>{16, 7, 2, 2}));
  const WeightTensor* c = w.find("encoder.layers.10.conv3x1_2.weight");
  ASSERT_NE(c, nullptr);
  EXPECT_EQ(c->dims, (std::vector<std::uint32_t>{128, 128, 3, 1}));
  EXPECT_EQ(w.find("module.decoder.output_conv.weight"), nullptr);  // the exporter stripped the prefix
  EXPECT_EQ(w.find("encoder.output_conv.weight"), nullptr);
}

TEST(Weights, SerializingReproducesThePythonFileByteForByte) {
  const std::vector<std::uint8_t> file = test::read_bytes(test::weights_path());
  const ErfNetWeights w = fixture();
  EXPECT_EQ(serialize_weights(w, true), file);
  // fp32 storage: twice the size, the same values.
  const std::vector<std::uint8_t> f32 = serialize_weights(w, false);
  EXPECT_GT(f32.size(), file.size() * 19 / 10);
  auto back = parse_weights(f32, "f32");
  ASSERT_TRUE(back.ok()) << back.error().message;
  ASSERT_EQ(back.value().tensors.size(), w.tensors.size());
  for (std::size_t i = 0; i < w.tensors.size(); ++i) EXPECT_EQ(back.value().tensors[i].data, w.tensors[i].data) << w.tensors[i].name;
}

TEST(Weights, MissingFileIsAnIoError) {
  auto r = load_weights("/nonexistent/erfnet.agw");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::kIo);
  EXPECT_CONTAINS(r.error().message, "/nonexistent/erfnet.agw");
}

TEST(Weights, CorruptFilesAreRefused) {
  const std::vector<std::uint8_t> file = test::read_bytes(test::weights_path());
  ASSERT_GT(file.size(), 1000U);
  EXPECT_CONTAINS(refuse({}), "magic");
  std::vector<std::uint8_t> png = {0x89, 'P', 'N', 'G', 0, 0, 0, 0, 0, 0, 0, 0};
  EXPECT_CONTAINS(refuse(png), "magic");
  // Truncated anywhere: the checksum (or the header) catches it.
  for (std::size_t cut : {std::size_t{9}, std::size_t{15}, std::size_t{40}, std::size_t{100}, file.size() / 2, file.size() - 1}) {
    std::vector<std::uint8_t> t(file.begin(), file.begin() + static_cast<std::ptrdiff_t>(cut));
    const std::string m = refuse(t);
    EXPECT_TRUE(m.find("checksum") != std::string::npos || m.find("truncated") != std::string::npos) << cut << ": " << m;
  }
  // One flipped bit in the middle of a tensor.
  std::vector<std::uint8_t> flip = file;
  flip[file.size() / 3] ^= 0x10;
  EXPECT_CONTAINS(refuse(flip), "checksum mismatch");
  // Trailing garbage (resealed): refused, not ignored.
  std::vector<std::uint8_t> tail = file;
  tail.insert(tail.end() - 4, {1, 2, 3});
  reseal(tail);
  EXPECT_CONTAINS(refuse(tail), "unexpected bytes");
}

TEST(Weights, MismatchedHeadersAreRefused) {
  const std::vector<std::uint8_t> file = test::read_bytes(test::weights_path());
  auto patch_u32 = [&](std::size_t off, std::uint32_t v) {
    std::vector<std::uint8_t> b = file;
    std::memcpy(b.data() + off, &v, 4);
    reseal(b);
    return refuse(b);
  };
  EXPECT_CONTAINS(patch_u32(8, 2), "format version 2");
  // Header says 20 classes (Cityscapes) but the output layer has 7.
  const std::string m = patch_u32(12, 20);
  EXPECT_CONTAINS(m, "decoder.output_conv");
  EXPECT_CONTAINS(m, "class count does not match");
  EXPECT_CONTAINS(patch_u32(12, 0), "class count 0");
  EXPECT_CONTAINS(patch_u32(16, 60), "multiples of 8");
  EXPECT_CONTAINS(patch_u32(20, 0), "multiples of 8");
  std::vector<std::uint8_t> b = file;
  const float zero = 0.0F;
  std::memcpy(b.data() + 8 + 16 + 12, &zero, 4);  // std[0]
  reseal(b);
  EXPECT_CONTAINS(refuse(b), "std 0");
}

TEST(Weights, TensorsMustBeExactlyTheArchitectures) {
  const ErfNetWeights w = fixture();
  {
    ErfNetWeights m = w;
    m.tensors.erase(m.tensors.begin() + 10);
    EXPECT_CONTAINS(refuse(serialize_weights(m, true)), "missing tensor '" + w.tensors[10].name + "'");
  }
  {
    ErfNetWeights m = w;
    m.tensors.push_back(m.tensors.back());
    m.tensors.back().name = "encoder.layers.15.conv3x1_1.weight";
    EXPECT_CONTAINS(refuse(serialize_weights(m, true)), "unexpected tensor 'encoder.layers.15.conv3x1_1.weight'");
  }
  {
    ErfNetWeights m = w;
    m.tensors.push_back(m.tensors[0]);
    EXPECT_CONTAINS(refuse(serialize_weights(m, true)), "appears twice");
  }
  {
    ErfNetWeights m = w;
    WeightTensor& t = m.tensors[2 * 6 + 6 + 2];  // some conv of the first block
    t.dims = {t.dims[0], t.dims[1], t.dims[3], t.dims[2]};  // 3x1 stored as 1x3
    EXPECT_CONTAINS(refuse(serialize_weights(m, true)), "has shape");
  }
  {
    ErfNetWeights m = w;
    m.tensors[3].data[0] = std::numeric_limits<float>::quiet_NaN();
    EXPECT_CONTAINS(refuse(serialize_weights(m, false)), "non-finite");
  }
  {
    ErfNetWeights m = w;
    for (auto& t : m.tensors)
      if (t.name == "encoder.layers.0.bn.running_var") t.data[5] = -1.0F;
    EXPECT_CONTAINS(refuse(serialize_weights(m, false)), "negative variance");
  }
  {
    ErfNetWeights m = w;
    m.header.class_names = {"road", "dirt"};
    EXPECT_CONTAINS(refuse(serialize_weights(m, true)), "2 class names for 7 classes");
    m.header.class_names = {"road", "dirt", "grass", "tree", "building", "vehicle", "water"};
    auto ok = parse_weights(serialize_weights(m, true), "named");
    ASSERT_TRUE(ok.ok()) << ok.error().message;
    EXPECT_EQ(ok.value().header.class_names, m.header.class_names);
  }
}

}  // namespace
}  // namespace ag::seg
