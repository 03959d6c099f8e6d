// The ErfNet weights file: parse, validate against the architecture, serialize (docs/segmentation.md).
#include "airground/segmentation/weights.hpp"

#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <unordered_map>

namespace ag::seg {
namespace {

static_assert(std::endian::native == std::endian::little, "the weights format is little-endian; add byte swaps");

void add_conv(std::vector<TensorSpec>& v, const std::string& p, std::uint32_t o, std::uint32_t i, std::uint32_t kh,
              std::uint32_t kw) {
  v.push_back({p + ".weight", {o, i, kh, kw}});
  v.push_back({p + ".bias", {o}});
}
void add_convt(std::vector<TensorSpec>& v, const std::string& p, std::uint32_t i, std::uint32_t o, std::uint32_t k) {
  v.push_back({p + ".weight", {i, o, k, k}});  // ConvTranspose2d: (in, out, kh, kw)
  v.push_back({p + ".bias", {o}});
}
void add_bn(std::vector<TensorSpec>& v, const std::string& p, std::uint32_t c) {
  for (const char* s : {".weight", ".bias", ".running_mean", ".running_var"}) v.push_back({p + s, {c}});
}
void add_down(std::vector<TensorSpec>& v, const std::string& p, std::uint32_t in, std::uint32_t out) {
  add_conv(v, p + ".conv", out - in, in, 3, 3);
  add_bn(v, p + ".bn", out);
}
void add_nb(std::vector<TensorSpec>& v, const std::string& p, std::uint32_t c) {
  add_conv(v, p + ".conv3x1_1", c, c, 3, 1);
  add_conv(v, p + ".conv1x3_1", c, c, 1, 3);
  add_bn(v, p + ".bn1", c);
  add_conv(v, p + ".conv3x1_2", c, c, 3, 1);
  add_conv(v, p + ".conv1x3_2", c, c, 1, 3);
  add_bn(v, p + ".bn2", c);
}
void add_up(std::vector<TensorSpec>& v, const std::string& p, std::uint32_t in, std::uint32_t out) {
  add_convt(v, p + ".conv", in, out, 3);
  add_bn(v, p + ".bn", out);
}

// A bounds-checked little-endian reader over the file bytes; the first failure is kept.
class Reader {
 public:
  Reader(std::span<const std::uint8_t> b, std::size_t end) : b_(b), end_(end) {}
  bool take(void* dst, std::size_t n, const char* what) {
    if (!ok_) return false;
    if (end_ - pos_ < n) {
      ok_ = false;
      what_ = what;
      return false;
    }
    std::memcpy(dst, b_.data() + pos_, n);
    pos_ += n;
    return true;
  }
  template <typename T>
  T get(const char* what) {
    T v{};
    take(&v, sizeof v, what);
    return v;
  }
  [[nodiscard]] bool ok() const { return ok_; }
  [[nodiscard]] std::size_t pos() const { return pos_; }
  [[nodiscard]] std::size_t left() const { return end_ - pos_; }
  [[nodiscard]] const char* failed_at() const { return what_; }
  [[nodiscard]] const std::uint8_t* here() const { return b_.data() + pos_; }
  void skip(std::size_t n) { pos_ += n; }

 private:
  std::span<const std::uint8_t> b_;
  std::size_t end_, pos_{0};
  bool ok_{true};
  const char* what_{""};
};

Error bad(std::string_view source, const std::string& what) {
  return Error::make(ErrorCode::kMalformed, std::string(source) + ": " + what);
}

std::string shape_str(const std::vector<std::uint32_t>& d) {
  std::string s = "(";
  for (std::size_t i = 0; i < d.size(); ++i) s += (i ? ", " : "") + std::to_string(d[i]);
  return s + (d.size() == 1 ? ",)" : ")");
}

template <typename T>
void put(std::vector<std::uint8_t>& out, const T& v) {
  const auto* p = reinterpret_cast<const std::uint8_t*>(&v);
  out.insert(out.end(), p, p + sizeof v);
}

}  // namespace

const WeightTensor* ErfNetWeights::find(std::string_view name) const noexcept {
  for (const auto& t : tensors)
    if (t.name == name) return &t;
  return nullptr;
}

std::size_t ErfNetWeights::parameter_count() const noexcept {
  std::size_t n = 0;
  for (const auto& t : tensors) n += t.data.size();
  return n;
}

std::vector<TensorSpec> erfnet_tensor_specs(std::uint32_t num_classes) {
  std::vector<TensorSpec> v;
  add_down(v, "encoder.initial_block", 3, 16);
  add_down(v, "encoder.layers.0", 16, 64);
  for (int i = 1; i <= 5; ++i) add_nb(v, "encoder.layers." + std::to_string(i), 64);
  add_down(v, "encoder.layers.6", 64, 128);
  for (int i = 7; i <= 14; ++i) add_nb(v, "encoder.layers." + std::to_string(i), 128);
  add_up(v, "decoder.layers.0", 128, 64);
  add_nb(v, "decoder.layers.1", 64);
  add_nb(v, "decoder.layers.2", 64);
  add_up(v, "decoder.layers.3", 64, 16);
  add_nb(v, "decoder.layers.4", 16);
  add_nb(v, "decoder.layers.5", 16);
  add_convt(v, "decoder.output_conv", 16, num_classes, 2);
  return v;
}

std::uint32_t crc32(std::span<const std::uint8_t> bytes) noexcept {
  static const auto table = [] {
    std::array<std::uint32_t, 256> t{};
    for (std::uint32_t i = 0; i < 256; ++i) {
      std::uint32_t c = i;
      for (int k = 0; k < 8; ++k) c = (c & 1U) ? 0xEDB88320U ^ (c >> 1) : c >> 1;
      t[i] = c;
    }
    return t;
  }();
  std::uint32_t c = 0xFFFFFFFFU;
  for (std::uint8_t b : bytes) c = table[(c ^ b) & 0xFFU] ^ (c >> 8);
  return c ^ 0xFFFFFFFFU;
}

float half_to_float(std::uint16_t h) noexcept {
  const std::uint32_t sign = static_cast<std::uint32_t>(h & 0x8000U) << 16;
  std::uint32_t exp = (h >> 10) & 0x1FU;
  std::uint32_t man = h & 0x3FFU;
  std::uint32_t bits = 0;
  if (exp == 0) {
    if (man == 0) {
      bits = sign;
    } else {  // subnormal: normalise
      exp = 127 - 15 + 1;
      while ((man & 0x400U) == 0) {
        man <<= 1;
        --exp;
      }
      man &= 0x3FFU;
      bits = sign | (exp << 23) | (man << 13);
    }
  } else if (exp == 31) {
    bits = sign | 0x7F800000U | (man << 13);
  } else {
    bits = sign | ((exp + 127 - 15) << 23) | (man << 13);
  }
  return std::bit_cast<float>(bits);
}

std::uint16_t float_to_half(float f) noexcept {
  const std::uint32_t x = std::bit_cast<std::uint32_t>(f);
  const auto sign = static_cast<std::uint16_t>((x >> 16) & 0x8000U);
  const std::uint32_t ax = x & 0x7FFFFFFFU;
  if (ax >= 0x7F800000U) return static_cast<std::uint16_t>(sign | 0x7C00U | (ax > 0x7F800000U ? 0x200U : 0U));
  if (ax >= 0x477FF000U) return static_cast<std::uint16_t>(sign | 0x7C00U);  // overflows to inf
  if (ax < 0x38800000U) {                                                     // subnormal or zero in half
    if (ax < 0x33000000U) return sign;
    const std::uint32_t e = ax >> 23;
    const std::uint32_t m = (ax & 0x7FFFFFU) | 0x800000U;
    const std::uint32_t shift = 126 - e;  // 14 + (113 - e) ... places the value at half's subnormal scale
    std::uint32_t r = m >> (shift - 0);
    const std::uint32_t rem = m & ((1U << shift) - 1U);
    const std::uint32_t halfway = 1U << (shift - 1);
    if (rem > halfway || (rem == halfway && (r & 1U))) ++r;
    return static_cast<std::uint16_t>(sign | r);
  }
  std::uint32_t r = ((ax >> 13) - ((127 - 15) << 10));
  const std::uint32_t rem = ax & 0x1FFFU;
  if (rem > 0x1000U || (rem == 0x1000U && (r & 1U))) ++r;
  return static_cast<std::uint16_t>(sign | r);
}

Result<ErfNetWeights> parse_weights(std::span<const std::uint8_t> bytes, std::string_view source) {
  if (bytes.size() < sizeof kWeightsMagic || std::memcmp(bytes.data(), kWeightsMagic, sizeof kWeightsMagic) != 0)
    return bad(source, "not an airground ErfNet weights file (no AGERFNET magic)");
  if (bytes.size() < sizeof kWeightsMagic + 4 + 4) return bad(source, "truncated header (" + std::to_string(bytes.size()) + " bytes)");
  const std::size_t body = bytes.size() - 4;
  std::uint32_t stored_crc = 0;
  std::memcpy(&stored_crc, bytes.data() + body, 4);
  Reader r(bytes, body);
  r.skip(sizeof kWeightsMagic);
  ErfNetWeights w;
  WeightsHeader& h = w.header;
  h.version = r.get<std::uint32_t>("version");
  if (h.version != kWeightsVersion)
    return bad(source, "format version " + std::to_string(h.version) + ", this build reads version " + std::to_string(kWeightsVersion));
  const std::uint32_t computed = crc32(bytes.first(body));
  if (computed != stored_crc) {
    char buf[96];
    std::snprintf(buf, sizeof buf, "checksum mismatch (stored %08x, computed %08x): the file is corrupt or truncated", stored_crc,
                  computed);
    return bad(source, buf);
  }
  h.num_classes = r.get<std::uint32_t>("class count");
  h.input_width = r.get<std::uint32_t>("input width");
  h.input_height = r.get<std::uint32_t>("input height");
  r.take(h.mean, sizeof h.mean, "mean");
  r.take(h.std, sizeof h.std, "std");
  const auto names_len = r.get<std::uint32_t>("class names length");
  if (!r.ok()) return bad(source, std::string("truncated header at the ") + r.failed_at());
  if (names_len > r.left()) return bad(source, "class names length " + std::to_string(names_len) + " runs past the end of the file");
  std::string names(reinterpret_cast<const char*>(r.here()), names_len);
  r.skip(names_len);
  if (h.num_classes == 0 || h.num_classes > kMaxClasses)
    return bad(source, "class count " + std::to_string(h.num_classes) + " outside 1.." + std::to_string(kMaxClasses));
  if (h.input_width == 0 || h.input_height == 0 || h.input_width % 8 || h.input_height % 8 || h.input_width > 16384 ||
      h.input_height > 16384)
    return bad(source, "input size " + std::to_string(h.input_width) + "x" + std::to_string(h.input_height) +
                           " is not made of positive multiples of 8 (at most 16384)");
  for (int c = 0; c < 3; ++c) {
    if (!std::isfinite(h.mean[c]) || !std::isfinite(h.std[c]) || h.std[c] == 0.0F)
      return bad(source, "normalisation of channel " + std::to_string(c) + " is not finite or has std 0");
  }
  for (std::size_t a = 0; a <= names.size();) {
    const std::size_t b = std::min(names.find(',', a), names.size());
    if (b > a) h.class_names.push_back(names.substr(a, b - a));
    a = b + 1;
  }
  if (!h.class_names.empty() && h.class_names.size() != h.num_classes)
    return bad(source, "header lists " + std::to_string(h.class_names.size()) + " class names for " + std::to_string(h.num_classes) +
                           " classes");

  const auto count = r.get<std::uint32_t>("tensor count");
  if (!r.ok()) return bad(source, "truncated header at the tensor count");
  const std::vector<TensorSpec> specs = erfnet_tensor_specs(h.num_classes);
  std::unordered_map<std::string, std::size_t> want;
  for (std::size_t i = 0; i < specs.size(); ++i) want.emplace(specs[i].name, i);
  std::vector<bool> seen(specs.size(), false);
  if (count > 4096) return bad(source, "tensor count " + std::to_string(count) + " is implausible");
  for (std::uint32_t t = 0; t < count; ++t) {
    const std::string where = "tensor " + std::to_string(t);
    const auto len = r.get<std::uint16_t>("tensor name length");
    if (!r.ok() || len > r.left()) return bad(source, "truncated at " + where + " (name)");
    WeightTensor wt;
    wt.name.assign(reinterpret_cast<const char*>(r.here()), len);
    r.skip(len);
    const auto dtype = r.get<std::uint8_t>("dtype");
    const auto ndim = r.get<std::uint8_t>("ndim");
    if (!r.ok()) return bad(source, "truncated at " + where + " '" + wt.name + "'");
    if (dtype != kDtypeF32 && dtype != kDtypeF16)
      return bad(source, "tensor '" + wt.name + "' has unknown dtype " + std::to_string(dtype) + " (1 f32, 2 f16)");
    if (ndim == 0 || ndim > 4) return bad(source, "tensor '" + wt.name + "' has " + std::to_string(ndim) + " dimensions");
    wt.dims.resize(ndim);
    std::uint64_t n = 1;
    for (auto& d : wt.dims) {
      d = r.get<std::uint32_t>("dims");
      n *= d;
    }
    if (!r.ok()) return bad(source, "truncated at the shape of tensor '" + wt.name + "'");
    const auto it = want.find(wt.name);
    if (it == want.end()) return bad(source, "unexpected tensor '" + wt.name + "': not part of ErfNet with " + std::to_string(h.num_classes) + " classes");
    const TensorSpec& spec = specs[it->second];
    if (seen[it->second]) return bad(source, "tensor '" + wt.name + "' appears twice");
    seen[it->second] = true;
    if (wt.dims != spec.dims) {
      std::string msg = "tensor '" + wt.name + "' has shape " + shape_str(wt.dims) + ", ErfNet with " +
                        std::to_string(h.num_classes) + " classes needs " + shape_str(spec.dims);
      if (wt.name.rfind("decoder.output_conv", 0) == 0) msg += " (the header's class count does not match the output layer)";
      return bad(source, msg);
    }
    const std::size_t esize = dtype == kDtypeF32 ? 4 : 2;
    if (n * esize > r.left()) return bad(source, "truncated in the data of tensor '" + wt.name + "'");
    wt.data.resize(static_cast<std::size_t>(n));
    if (dtype == kDtypeF32) {
      std::memcpy(wt.data.data(), r.here(), n * 4);
    } else {
      for (std::size_t k = 0; k < n; ++k) {
        std::uint16_t hv = 0;
        std::memcpy(&hv, r.here() + 2 * k, 2);
        wt.data[k] = half_to_float(hv);
      }
    }
    r.skip(static_cast<std::size_t>(n) * esize);
    for (std::size_t k = 0; k < wt.data.size(); ++k) {
      if (!std::isfinite(wt.data[k])) return bad(source, "tensor '" + wt.name + "' holds a non-finite value at index " + std::to_string(k));
    }
    w.tensors.push_back(std::move(wt));
  }
  if (r.left() != 0) return bad(source, std::to_string(r.left()) + " unexpected bytes after the last tensor");
  for (std::size_t i = 0; i < specs.size(); ++i) {
    if (!seen[i]) return bad(source, "missing tensor '" + specs[i].name + "'" + (count < specs.size() ? " (" + std::to_string(specs.size() - count) + " missing in all)" : ""));
  }
  for (const auto& t : w.tensors) {
    if (t.name.find("running_var") != std::string::npos) {
      for (float v : t.data)
        if (v < 0.0F) return bad(source, "tensor '" + t.name + "' holds a negative variance");
    }
  }
  return w;
}

Result<ErfNetWeights> load_weights(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) return Error::make(ErrorCode::kIo, path + ": cannot open the weights file");
  std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  if (f.bad()) return Error::make(ErrorCode::kIo, path + ": read error");
  return parse_weights(bytes, path);
}

std::vector<std::uint8_t> serialize_weights(const ErfNetWeights& w, bool fp16) {
  std::vector<std::uint8_t> out(std::begin(kWeightsMagic), std::end(kWeightsMagic));
  const WeightsHeader& h = w.header;
  put(out, h.version);
  put(out, h.num_classes);
  put(out, h.input_width);
  put(out, h.input_height);
  for (float v : h.mean) put(out, v);
  for (float v : h.std) put(out, v);
  std::string names;
  for (std::size_t i = 0; i < h.class_names.size(); ++i) names += (i ? "," : "") + h.class_names[i];
  put(out, static_cast<std::uint32_t>(names.size()));
  out.insert(out.end(), names.begin(), names.end());
  put(out, static_cast<std::uint32_t>(w.tensors.size()));
  for (const auto& t : w.tensors) {
    put(out, static_cast<std::uint16_t>(t.name.size()));
    out.insert(out.end(), t.name.begin(), t.name.end());
    put(out, fp16 ? kDtypeF16 : kDtypeF32);
    put(out, static_cast<std::uint8_t>(t.dims.size()));
    for (auto d : t.dims) put(out, d);
    for (float v : t.data) {
      if (fp16) put(out, float_to_half(v));
      else put(out, v);
    }
  }
  put(out, crc32(out));
  return out;
}

}  // namespace ag::seg
