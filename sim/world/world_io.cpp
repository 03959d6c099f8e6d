// World validation and the world directory format (world.yaml, class.png, albedo.png, height.tif, terrain.tif).
#include <yaml-cpp/yaml.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <sstream>
#include <vector>

#include "airground/sim/world.hpp"
#include "airground/sim/world_raster.hpp"

namespace ag::sim {

namespace {

namespace fs = std::filesystem;

constexpr std::int32_t kFormatVersion = 1;
constexpr std::int32_t kMaxCells = 100000;  // per side: a 25 km world at 0.25 m; beyond that a header is surely wrong

struct LayerFiles {
  std::string class_png{"class.png"};
  std::string albedo_png{"albedo.png"};
  std::string height_tif{"height.tif"};
  std::string terrain_tif{"terrain.tif"};
};

std::string number(double v) {
  char buf[64];
  const auto res = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, res.ptr);
}

std::string size_text(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }

std::string cell_text(int col, int row) { return "cell (col " + std::to_string(col) + ", row " + std::to_string(row) + ")"; }

std::string type_text(const cv::Mat& m) {
  static const char* const kDepth[] = {"8-bit", "8-bit signed", "16-bit", "16-bit signed", "32-bit int", "float32", "float64", "float16"};
  return std::string(kDepth[m.depth()]) + " " + std::to_string(m.channels()) + "-channel";
}

std::optional<std::string> check_grid(const GridGeometry& g) {
  if (!(std::isfinite(g.resolution) && g.resolution > 0.0)) return "resolution must be a positive number of metres, got " + number(g.resolution);
  if (g.width <= 0 || g.height <= 0 || g.width > kMaxCells || g.height > kMaxCells) {
    return "width and height must be 1.." + std::to_string(kMaxCells) + " cells, got " + size_text(g.width, g.height);
  }
  if (!std::isfinite(g.origin_x) || !std::isfinite(g.origin_y)) return "origin_x and origin_y must be finite";
  return std::nullopt;
}

std::optional<std::string> check_datum(const Datum& d) {
  if (!(d.lat_deg >= -90.0 && d.lat_deg <= 90.0)) return "datum lat_deg must be in [-90, 90], got " + number(d.lat_deg);
  if (!(d.lon_deg >= -180.0 && d.lon_deg <= 180.0)) return "datum lon_deg must be in [-180, 180], got " + number(d.lon_deg);
  if (!std::isfinite(d.height_m)) return "datum height_m must be finite";
  return std::nullopt;
}

std::optional<std::string> check_shape(const cv::Mat& m, const GridGeometry& g, int type, const char* expected) {
  if (m.empty()) return std::string("is empty");
  if (m.type() != type) return "has type " + type_text(m) + ", expected " + expected;
  if (m.cols != g.width || m.rows != g.height) {
    return "is " + size_text(m.cols, m.rows) + " cells, the header says " + size_text(g.width, g.height);
  }
  return std::nullopt;
}

std::optional<std::string> check_class_ids(const cv::Mat& ids, const ClassTable& classes) {
  for (int r = 0; r < ids.rows; ++r) {
    const auto* row = ids.ptr<std::uint8_t>(r);
    for (int c = 0; c < ids.cols; ++c) {
      if (!classes.valid_id(row[c])) {
        return "class id " + std::to_string(row[c]) + " at " + cell_text(c, r) + " is not in the class table";
      }
    }
  }
  return std::nullopt;
}

std::optional<std::string> check_metres(const cv::Mat& m, bool non_negative) {
  for (int r = 0; r < m.rows; ++r) {
    const auto* row = m.ptr<float>(r);
    for (int c = 0; c < m.cols; ++c) {
      if (!std::isfinite(row[c])) return "value " + number(static_cast<double>(row[c])) + " (not finite) at " + cell_text(c, r);
      if (non_negative && row[c] < 0.0F) {
        return "negative height " + number(static_cast<double>(row[c])) + " at " + cell_text(c, r) + " (heights are above terrain)";
      }
      if (std::fabs(row[c]) > 20000.0F) return "implausible value " + number(static_cast<double>(row[c])) + " m at " + cell_text(c, r);
    }
  }
  return std::nullopt;
}

Error file_error(ErrorCode code, const std::string& path, const std::string& problem) {
  return Error::make(code, "world file " + path + ": " + problem);
}

Result<std::vector<std::uint8_t>> read_bytes(const std::string& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) return file_error(ErrorCode::kIo, path, "missing (no such file)");
  std::ifstream in(path, std::ios::binary);
  if (!in) return file_error(ErrorCode::kIo, path, "cannot open");
  in.seekg(0, std::ios::end);
  std::vector<std::uint8_t> bytes(static_cast<std::size_t>(std::max<std::streamoff>(in.tellg(), 0)));
  in.seekg(0);
  in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  if (!in) return file_error(ErrorCode::kIo, path, "read error");
  return bytes;
}

// ---- world.yaml ----

std::string quoted(const std::string& s) {
  std::string out = "\"";
  for (const char ch : s) {
    if (ch == '"' || ch == '\\') out += '\\';
    if (static_cast<unsigned char>(ch) >= 0x20) out += ch;
  }
  return out + "\"";
}

std::string header_yaml(const WorldHeader& h, const LayerFiles& files) {
  std::ostringstream y;
  y << "# airground world (sim/include/airground/sim/world.hpp): a 2.5D raster world in the local ENU map frame\n"
       "# anchored at the datum. Rasters are north-up: row 0 is the north edge (origin_y), col 0 the west edge\n"
       "# (origin_x). The surface a ray or a wheel meets is terrain + height.\n";
  y << "format_version: " << h.format_version << "\n";
  y << "name: " << quoted(h.name) << "\n";
  y << "source: " << quoted(h.source) << "  # generator or import\n";
  y << "seed: " << h.seed << "  # generator seed, 0 for imported worlds\n";
  y << "resolution: " << number(h.grid.resolution) << "  # [m/cell]\n";
  y << "width: " << h.grid.width << "  # cells, eastwards\n";
  y << "height: " << h.grid.height << "  # cells, southwards from the north edge\n";
  y << "origin_x: " << number(h.grid.origin_x) << "  # [m] west edge\n";
  y << "origin_y: " << number(h.grid.origin_y) << "  # [m] north edge\n";
  y << "datum: {lat_deg: " << number(h.datum.lat_deg) << ", lon_deg: " << number(h.datum.lon_deg)
    << ", height_m: " << number(h.datum.height_m) << "}  # WGS84, ellipsoidal height\n";
  y << "staging: {x: " << number(h.staging.x) << ", y: " << number(h.staging.y) << ", yaw: " << number(h.staging.yaw)
    << "}  # [m, m, rad] where ground robots start\n";
  y << "layers:\n";
  y << "  class: " << quoted(files.class_png) << "  # 8-bit grey class ids (config/classes.yaml)\n";
  y << "  albedo: " << quoted(files.albedo_png) << "  # RGB colour seen from above\n";
  y << "  height: " << quoted(files.height_tif) << "  # float32 GeoTIFF [m]: object height above terrain\n";
  y << "  terrain: " << quoted(files.terrain_tif) << "  # float32 GeoTIFF [m]: terrain elevation above the datum height\n";
  return y.str();
}

// Reads typed keys of world.yaml; the first problem becomes the error.
class HeaderReader {
 public:
  explicit HeaderReader(std::string path) : path_(std::move(path)) {}

  template <typename T>
  T get(const YAML::Node& parent, const std::string& key, const std::string& where = "") {
    const std::string name = where.empty() ? key : where + "." + key;
    if (problem_) return T{};
    const YAML::Node n = parent[key];
    if (!n) {
      problem_ = "missing key '" + name + "'";
      return T{};
    }
    if (!n.IsScalar()) {
      problem_ = "key '" + name + "' (line " + std::to_string(n.Mark().line + 1) + ") must be a single value";
      return T{};
    }
    try {
      return n.as<T>();
    } catch (const YAML::Exception&) {
      problem_ = "key '" + name + "' (line " + std::to_string(n.Mark().line + 1) + ") has the wrong type: '" + n.Scalar() + "'";
      return T{};
    }
  }
  YAML::Node map(const YAML::Node& parent, const std::string& key) {
    if (problem_) return YAML::Node();
    const YAML::Node n = parent[key];
    if (!n || !n.IsMap()) problem_ = "missing or malformed '" + key + ":' map";
    return n;
  }
  void fail(std::string p) {
    if (!problem_) problem_ = std::move(p);
  }
  [[nodiscard]] const std::optional<std::string>& problem() const { return problem_; }

 private:
  std::string path_;
  std::optional<std::string> problem_;
};

std::optional<std::string> check_layer_name(const std::string& name) {
  if (name.empty()) return std::string("is empty");
  const fs::path p(name);
  if (p.is_absolute()) return "'" + name + "' must be a file name inside the world directory";
  for (const auto& part : p) {
    if (part == "..") return "'" + name + "' must not leave the world directory";
  }
  return std::nullopt;
}

Result<std::pair<WorldHeader, LayerFiles>> read_header(const std::string& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) return file_error(ErrorCode::kIo, path, "missing (no such file)");
  auto bytes = read_bytes(path);
  if (!bytes) return bytes.error();
  const std::string text(bytes->begin(), bytes->end());
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    return file_error(ErrorCode::kMalformed, path, "malformed YAML at line " + std::to_string(e.mark.line + 1) + ": " + e.msg);
  }
  if (!root.IsMap()) return file_error(ErrorCode::kMalformed, path, "expected a map of header keys (empty or truncated file?)");
  HeaderReader rd(path);
  WorldHeader h;
  LayerFiles files;
  h.format_version = rd.get<std::int32_t>(root, "format_version");
  if (!rd.problem() && h.format_version != kFormatVersion) {
    rd.fail("format_version " + std::to_string(h.format_version) + " is not supported (this build reads " +
            std::to_string(kFormatVersion) + ")");
  }
  h.name = rd.get<std::string>(root, "name");
  h.source = rd.get<std::string>(root, "source");
  h.seed = rd.get<std::uint64_t>(root, "seed");
  h.grid.resolution = rd.get<double>(root, "resolution");
  h.grid.width = rd.get<std::int32_t>(root, "width");
  h.grid.height = rd.get<std::int32_t>(root, "height");
  h.grid.origin_x = rd.get<double>(root, "origin_x");
  h.grid.origin_y = rd.get<double>(root, "origin_y");
  const YAML::Node datum = rd.map(root, "datum");
  h.datum.lat_deg = rd.get<double>(datum, "lat_deg", "datum");
  h.datum.lon_deg = rd.get<double>(datum, "lon_deg", "datum");
  h.datum.height_m = rd.get<double>(datum, "height_m", "datum");
  const YAML::Node staging = rd.map(root, "staging");
  h.staging.x = rd.get<double>(staging, "x", "staging");
  h.staging.y = rd.get<double>(staging, "y", "staging");
  h.staging.yaw = rd.get<double>(staging, "yaw", "staging");
  const YAML::Node layers = rd.map(root, "layers");
  files.class_png = rd.get<std::string>(layers, "class", "layers");
  files.albedo_png = rd.get<std::string>(layers, "albedo", "layers");
  files.height_tif = rd.get<std::string>(layers, "height", "layers");
  files.terrain_tif = rd.get<std::string>(layers, "terrain", "layers");
  if (rd.problem()) return file_error(ErrorCode::kMalformed, path, *rd.problem());
  if (auto p = check_grid(h.grid)) return file_error(ErrorCode::kMalformed, path, *p);
  if (auto p = check_datum(h.datum)) return file_error(ErrorCode::kMalformed, path, *p);
  if (!std::isfinite(h.staging.x) || !std::isfinite(h.staging.y) || !std::isfinite(h.staging.yaw)) {
    return file_error(ErrorCode::kMalformed, path, "staging must be finite");
  }
  for (const std::string* name : {&files.class_png, &files.albedo_png, &files.height_tif, &files.terrain_tif}) {
    if (auto p = check_layer_name(*name)) return file_error(ErrorCode::kMalformed, path, "layer file " + *p);
  }
  return std::make_pair(std::move(h), std::move(files));
}

// ---- PNG layers ----

// Decodes a PNG of the grid's size; the size in the PNG header is checked before any pixel is decoded.
Result<cv::Mat> read_png(const std::string& path, const GridGeometry& g) {
  auto bytes = read_bytes(path);
  if (!bytes) return bytes.error();
  static constexpr std::array<std::uint8_t, 8> kPngSignature{0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
  const std::vector<std::uint8_t>& b = bytes.value();
  if (b.size() < kPngSignature.size() || !std::equal(kPngSignature.begin(), kPngSignature.end(), b.begin())) {
    return file_error(ErrorCode::kMalformed, path, "not a PNG file (bad signature)");
  }
  if (b.size() < 24 || !std::equal(b.begin() + 12, b.begin() + 16, "IHDR")) {
    return file_error(ErrorCode::kMalformed, path, "truncated PNG (no image header)");
  }
  const auto be32 = [&](std::size_t at) {
    return static_cast<std::int64_t>((std::uint32_t{b[at]} << 24) | (std::uint32_t{b[at + 1]} << 16) | (std::uint32_t{b[at + 2]} << 8) | b[at + 3]);
  };
  if (be32(16) != g.width || be32(20) != g.height) {
    return file_error(ErrorCode::kMalformed, path,
                      "is " + std::to_string(be32(16)) + "x" + std::to_string(be32(20)) + " pixels, world.yaml says " + size_text(g.width, g.height));
  }
  cv::Mat img;
  try {
    img = cv::imdecode(b, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    return file_error(ErrorCode::kMalformed, path, std::string("cannot decode PNG: ") + e.what());
  }
  if (img.empty()) return file_error(ErrorCode::kMalformed, path, "cannot decode PNG (truncated or corrupt)");
  return img;
}

Status write_file(const std::string& path, const std::vector<std::uint8_t>& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) return file_error(ErrorCode::kIo, path, "cannot create");
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  out.close();
  if (!out) return file_error(ErrorCode::kIo, path, "write failed (disk full?)");
  return ok_status();
}

Status write_png(const std::string& path, const cv::Mat& img) {
  std::vector<std::uint8_t> bytes;
  // Level 3 keeps a 4000x4000 world quick to save while still compressing the flat class layer well.
  if (!cv::imencode(".png", img, bytes, {cv::IMWRITE_PNG_COMPRESSION, 3})) return file_error(ErrorCode::kInternal, path, "PNG encoding failed");
  return write_file(path, bytes);
}

Result<cv::Mat> read_float_layer(const std::string& path, const WorldHeader& h, bool non_negative) {
  // Shape first, from the header: a wrong file is refused before its pixels are read.
  auto shape = probe_raster(path);
  if (!shape) return Error::make(shape.error().code, "world file " + shape.error().message);  // already names the file
  if (shape->bands != 1) return file_error(ErrorCode::kMalformed, path, "has " + std::to_string(shape->bands) + " bands, expected 1");
  if (shape->data_type != "Float32") return file_error(ErrorCode::kMalformed, path, "has pixel type " + shape->data_type + ", expected Float32");
  if (shape->width != h.grid.width || shape->height != h.grid.height) {
    return file_error(ErrorCode::kMalformed, path,
                      "is " + size_text(shape->width, shape->height) + " cells, world.yaml says " + size_text(h.grid.width, h.grid.height));
  }
  auto raster = read_raster(path);
  if (!raster) return Error::make(raster.error().code, "world file " + raster.error().message);
  const cv::Mat& px = raster->pixels;
  if (raster->geotransform) {
    const auto& gt = *raster->geotransform;
    const double tol = 1e-6 * std::max(1.0, std::fabs(h.grid.origin_x) + std::fabs(h.grid.origin_y));
    if (std::fabs(gt[0] - h.grid.origin_x) > tol || std::fabs(gt[3] - h.grid.origin_y) > tol ||
        std::fabs(gt[1] - h.grid.resolution) > 1e-9 || std::fabs(gt[5] + h.grid.resolution) > 1e-9 || gt[2] != 0.0 || gt[4] != 0.0) {
      return file_error(ErrorCode::kMalformed, path,
                        "geotransform (" + number(gt[0]) + ", " + number(gt[1]) + ", " + number(gt[3]) + ", " + number(gt[5]) +
                            ") does not match world.yaml's grid (origin_x, resolution, origin_y, -resolution)");
    }
  }
  if (auto p = check_metres(px, non_negative)) return file_error(ErrorCode::kMalformed, path, *p);
  return px;
}

}  // namespace

WorldCellSummary summarise_cell(const World& w, double x, double y, double res) noexcept {
  const GridGeometry& g = w.grid();
  auto c0 = static_cast<std::int32_t>(std::ceil(g.col_f(x - 0.5 * res) - 0.5));
  auto c1 = static_cast<std::int32_t>(std::ceil(g.col_f(x + 0.5 * res) - 0.5)) - 1;
  auto r0 = static_cast<std::int32_t>(std::ceil(g.row_f(y + 0.5 * res) - 0.5));
  auto r1 = static_cast<std::int32_t>(std::ceil(g.row_f(y - 0.5 * res) - 0.5)) - 1;
  if (c0 > c1 || r0 > r1) {
    c0 = c1 = g.col(x);
    r0 = r1 = g.row(y);
  }
  std::array<std::uint16_t, 256> votes{};
  std::uint16_t best_n = 0;
  WorldCellSummary s;
  double sum = 0;
  for (std::int32_t wr = r0; wr <= r1; ++wr)
    for (std::int32_t wc = c0; wc <= c1; ++wc) {
      if (!g.contains(wc, wr)) continue;
      const std::uint8_t k = w.class_id.at<std::uint8_t>(wr, wc);
      if (++votes[k] > best_n) {
        best_n = votes[k];
        s.cls = k;
      }
      sum += static_cast<double>(w.surface_at(wc, wr));
      ++s.count;
    }
  s.surface = s.count > 0 ? sum / s.count : std::numeric_limits<double>::quiet_NaN();
  return s;
}

Status World::validate(const ClassTable& classes) const {
  const auto bad = [](const std::string& what) { return Error::make(ErrorCode::kMalformed, "world: " + what); };
  if (auto p = check_grid(header.grid)) return bad(*p);
  if (auto p = check_datum(header.datum)) return bad(*p);
  if (auto p = check_shape(class_id, header.grid, CV_8UC1, "8-bit 1-channel (CV_8UC1)")) return bad("class layer " + *p);
  if (auto p = check_shape(height, header.grid, CV_32FC1, "float32 1-channel (CV_32FC1)")) return bad("height layer " + *p);
  if (auto p = check_shape(terrain, header.grid, CV_32FC1, "float32 1-channel (CV_32FC1)")) return bad("terrain layer " + *p);
  if (auto p = check_shape(albedo, header.grid, CV_8UC3, "8-bit 3-channel RGB (CV_8UC3)")) return bad("albedo layer " + *p);
  if (auto p = check_class_ids(class_id, classes)) return bad("class layer: " + *p);
  if (auto p = check_metres(height, true)) return bad("height layer: " + *p);
  if (auto p = check_metres(terrain, false)) return bad("terrain layer: " + *p);
  return ok_status();
}

Status save_world(const World& w, const std::string& dir) {
  if (auto v = w.validate(); !v) return Error::make(v.error().code, "cannot save to " + dir + ": " + v.error().message);
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return Error::make(ErrorCode::kIo, "world directory " + dir + ": cannot create (" + ec.message() + ")");
  const LayerFiles files;
  const fs::path base(dir);
  const std::string yaml = header_yaml(w.header, files);
  if (auto s = write_file((base / "world.yaml").string(), std::vector<std::uint8_t>(yaml.begin(), yaml.end())); !s) return s;
  if (auto s = write_png((base / files.class_png).string(), w.class_id); !s) return s;
  cv::Mat bgr;
  cv::cvtColor(w.albedo, bgr, cv::COLOR_RGB2BGR);
  if (auto s = write_png((base / files.albedo_png).string(), bgr); !s) return s;
  if (auto s = write_geotiff((base / files.height_tif).string(), w.height, w.header.grid, w.header.datum, "height",
                             "object height above terrain [m] (buildings, trees, vehicles, curbs)");
      !s) {
    return s;
  }
  return write_geotiff((base / files.terrain_tif).string(), w.terrain, w.header.grid, w.header.datum, "terrain",
                       "terrain elevation above the datum height [m]");
}

Result<World> load_world(const std::string& dir) {
  const fs::path base(dir);
  std::error_code ec;
  if (!fs::is_directory(base, ec)) return Error::make(ErrorCode::kIo, "world directory " + dir + ": missing or not a directory");
  auto header = read_header((base / "world.yaml").string());
  if (!header) return header.error();
  World w;
  w.header = header->first;
  const LayerFiles& files = header->second;
  const GridGeometry& g = w.header.grid;

  const std::string class_path = (base / files.class_png).string();
  auto ids = read_png(class_path, g);
  if (!ids) return ids.error();
  if (ids->type() != CV_8UC1) return file_error(ErrorCode::kMalformed, class_path, "has type " + type_text(ids.value()) + ", expected 8-bit grey class ids");
  if (ids->cols != g.width || ids->rows != g.height) {
    return file_error(ErrorCode::kMalformed, class_path, "is " + size_text(ids->cols, ids->rows) + " pixels, world.yaml says " + size_text(g.width, g.height));
  }
  if (auto p = check_class_ids(ids.value(), ClassTable::builtin())) return file_error(ErrorCode::kMalformed, class_path, *p);
  w.class_id = std::move(ids.value());

  const std::string albedo_path = (base / files.albedo_png).string();
  auto colour = read_png(albedo_path, g);
  if (!colour) return colour.error();
  if (colour->type() != CV_8UC3) return file_error(ErrorCode::kMalformed, albedo_path, "has type " + type_text(colour.value()) + ", expected 8-bit RGB");
  if (colour->cols != g.width || colour->rows != g.height) {
    return file_error(ErrorCode::kMalformed, albedo_path,
                      "is " + size_text(colour->cols, colour->rows) + " pixels, world.yaml says " + size_text(g.width, g.height));
  }
  cv::cvtColor(colour.value(), w.albedo, cv::COLOR_BGR2RGB);

  auto height = read_float_layer((base / files.height_tif).string(), w.header, true);
  if (!height) return height.error();
  w.height = std::move(height.value());
  auto terrain = read_float_layer((base / files.terrain_tif).string(), w.header, false);
  if (!terrain) return terrain.error();
  w.terrain = std::move(terrain.value());

  if (auto v = w.validate(); !v) return Error::make(v.error().code, "world directory " + dir + ": " + v.error().message);
  return w;
}

}  // namespace ag::sim
