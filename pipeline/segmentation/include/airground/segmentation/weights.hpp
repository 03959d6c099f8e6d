// ErfNet weights: airground's own file format (docs/segmentation.md) and its loader. The loader checks
// the checksum, the header and that the tensors are exactly the reference architecture's for the header's
// class count, and refuses anything else with a message naming the file and what is wrong.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "airground/platform/result.hpp"

namespace ag::seg {

inline constexpr char kWeightsMagic[8] = {'A', 'G', 'E', 'R', 'F', 'N', 'E', 'T'};
inline constexpr std::uint32_t kWeightsVersion = 1;
inline constexpr std::uint8_t kDtypeF32 = 1;
inline constexpr std::uint8_t kDtypeF16 = 2;
inline constexpr std::uint32_t kMaxClasses = 256;

struct WeightsHeader {
  std::uint32_t version{kWeightsVersion};
  std::uint32_t num_classes{0};
  std::uint32_t input_width{0}, input_height{0};  // [px] the size the model is made for; multiples of 8
  float mean[3]{0.0F, 0.0F, 0.0F};                // input = (rgb / 255 - mean) / std, per channel R, G, B
  float std[3]{1.0F, 1.0F, 1.0F};
  std::vector<std::string> class_names;           // empty, or one per class in logit order
};

struct WeightTensor {
  std::string name;                 // reference module naming, e.g. "encoder.layers.3.conv1x3_2.weight"
  std::vector<std::uint32_t> dims;  // PyTorch shape
  std::vector<float> data;          // row-major, converted to float32 whatever the stored type
};

struct ErfNetWeights {
  WeightsHeader header;
  std::vector<WeightTensor> tensors;  // file order

  [[nodiscard]] const WeightTensor* find(std::string_view name) const noexcept;
  [[nodiscard]] std::size_t parameter_count() const noexcept;
};

// One tensor the architecture has, with its PyTorch shape.
struct TensorSpec {
  std::string name;
  std::vector<std::uint32_t> dims;
};
// Every tensor ErfNet has for `num_classes`, in the reference state_dict order (without the encoder's
// unused output_conv and the BN batch counters): what a weights file must hold, no more, no less.
std::vector<TensorSpec> erfnet_tensor_specs(std::uint32_t num_classes);

// CRC-32 (IEEE 802.3, as zlib.crc32).
std::uint32_t crc32(std::span<const std::uint8_t> bytes) noexcept;

// Parses and validates a weights file's bytes; `source` names it in error messages.
Result<ErfNetWeights> parse_weights(std::span<const std::uint8_t> bytes, std::string_view source);
Result<ErfNetWeights> load_weights(const std::string& path);
// The file's bytes for `w` (tensors stored as f16 when `fp16`); what tools/erfnet_weights.py writes.
std::vector<std::uint8_t> serialize_weights(const ErfNetWeights& w, bool fp16);

float half_to_float(std::uint16_t h) noexcept;
std::uint16_t float_to_half(float f) noexcept;  // round to nearest even

}  // namespace ag::seg
