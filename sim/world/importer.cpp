// Importing a user's class raster, legend, elevation and colour image into a world.
#include "airground/sim/importer.hpp"

#include <yaml-cpp/yaml.h>

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <optional>
#include <sstream>
#include <unordered_map>

#include "airground/messages/classes.hpp"
#include "airground/sim/world_raster.hpp"
#include "airground/sim/world_texture.hpp"

namespace ag::sim {

namespace {

constexpr int kPureColourDistance = 24;   // a legend colour up to this far (RGB Euclidean): JPEG noise, dithering
constexpr int kExplainedDistance = 48;    // up to this far from a legend colour a pixel is not a missing entry
constexpr double kBlendDistance = 20.0;   // this close to the line between two legend colours: an anti-aliased mix
constexpr double kMissingEntryShare = 0.002;
constexpr double kMaxAspectMismatch = 0.02;

Error import_error(ErrorCode code, const std::string& what) { return Error::make(code, "import: " + what); }

struct LegendColour {
  cv::Vec3i rgb;
  ClassId cls;
};

struct Legend {
  bool by_colour{false};
  std::map<std::int64_t, ClassId> values;
  std::vector<LegendColour> colours;
};

std::string class_names() {
  std::string s;
  for (const ClassInfo& c : ClassTable::builtin().all()) s += (s.empty() ? "" : ", ") + c.name;
  return s;
}

Result<Legend> read_legend(const std::string& path) {
  const auto bad = [&](int line, const std::string& what) {
    return import_error(ErrorCode::kMalformed, "legend " + path + (line > 0 ? ":" + std::to_string(line) : "") + ": " + what);
  };
  std::error_code ec;
  if (path.empty()) return import_error(ErrorCode::kInvalidArgument, "no legend file given (legend_path)");
  if (!std::filesystem::exists(path, ec)) return import_error(ErrorCode::kIo, "legend " + path + ": missing (no such file)");
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::BadFile&) {
    return import_error(ErrorCode::kIo, "legend " + path + ": cannot open");
  } catch (const YAML::Exception& e) {
    return bad(e.mark.line + 1, "malformed YAML: " + e.msg);
  }
  if (!root.IsMap() || !root["classes"] || !root["classes"].IsSequence() || root["classes"].size() == 0) {
    return bad(0, "expected a non-empty 'classes:' list of {value: N, class: NAME} or {color: [R, G, B], class: NAME}");
  }
  Legend legend;
  bool any_value = false, any_colour = false;
  for (const YAML::Node& n : root["classes"]) {
    const int line = n.Mark().line + 1;
    if (!n.IsMap()) return bad(line, "each entry must be a map");
    try {
      if (!n["class"]) return bad(line, "entry has no 'class:'");
      const std::string name = n["class"].as<std::string>();
      const auto cls = ClassTable::builtin().by_name(name);
      if (!cls) return bad(line, "unknown class '" + name + "' (known: " + class_names() + ")");
      if (n["value"] && n["color"]) return bad(line, "an entry has either 'value' or 'color', not both");
      if (n["value"]) {
        any_value = true;
        const auto v = n["value"].as<std::int64_t>();
        if (v < std::numeric_limits<std::int32_t>::min() || v > std::numeric_limits<std::uint32_t>::max()) return bad(line, "value out of range");
        if (const auto it = legend.values.find(v); it != legend.values.end() && it->second != *cls) {
          return bad(line, "value " + std::to_string(v) + " is listed twice with different classes");
        }
        legend.values[v] = *cls;
      } else if (n["color"]) {
        any_colour = true;
        const YAML::Node c = n["color"];
        if (!c.IsSequence() || c.size() != 3) return bad(line, "color must be [R, G, B]");
        cv::Vec3i rgb;
        for (int k = 0; k < 3; ++k) {
          rgb[k] = c[static_cast<std::size_t>(k)].as<int>();
          if (rgb[k] < 0 || rgb[k] > 255) return bad(line, "color components must be 0..255");
        }
        for (const LegendColour& other : legend.colours) {
          if (other.rgb == rgb && other.cls != *cls) return bad(line, "color listed twice with different classes");
        }
        legend.colours.push_back(LegendColour{rgb, *cls});
      } else {
        return bad(line, "entry needs 'value: N' (value rasters) or 'color: [R, G, B]' (colour rasters)");
      }
    } catch (const YAML::Exception& e) {
      return bad(line, "bad entry: " + e.msg);
    }
  }
  if (legend.colours.size() > 100) return bad(0, "at most 100 color entries");
  if (any_value && any_colour) return bad(0, "mixes value and color entries; a legend describes either a value raster or a colour raster");
  legend.by_colour = any_colour;
  return legend;
}

std::string size_text(const cv::Mat& m) { return std::to_string(m.cols) + "x" + std::to_string(m.rows); }

// Brings an auxiliary raster to the class raster's size; sizes whose shapes differ are an error.
Result<cv::Mat> fit_to(const cv::Mat& src, cv::Size target, const std::string& what, const std::string& path, bool& resampled) {
  if (src.size() == target) return src;
  const double a = static_cast<double>(src.cols) / src.rows, b = static_cast<double>(target.width) / target.height;
  if (std::fabs(a - b) / b > kMaxAspectMismatch) {
    return import_error(ErrorCode::kInvalidArgument, what + " " + path + " is " + size_text(src) + ", the class raster is " +
                                                         std::to_string(target.width) + "x" + std::to_string(target.height) +
                                                         ": mismatched sizes (different shapes, cannot be resampled onto it)");
  }
  cv::Mat out;
  cv::resize(src, out, target, 0, 0, src.cols > target.width ? cv::INTER_AREA : cv::INTER_LINEAR);
  resampled = true;
  return out;
}

// 8-bit RGB from a raster of colours: RGB, RGBA (alpha returned separately), grey, or paletted.
Result<cv::Mat> to_rgb(const Raster& r, const std::string& what, const std::string& path, cv::Mat* alpha) {
  const cv::Mat& px = r.pixels;
  if (!r.palette.empty() && px.channels() == 1) {
    if (px.depth() != CV_8U && px.depth() != CV_16U) return import_error(ErrorCode::kMalformed, what + " " + path + ": palette indices must be 8 or 16 bit");
    cv::Mat out(px.size(), CV_8UC3);
    for (int y = 0; y < px.rows; ++y) {
      for (int x = 0; x < px.cols; ++x) {
        const int i = px.depth() == CV_8U ? px.at<std::uint8_t>(y, x) : px.at<std::uint16_t>(y, x);
        out.at<cv::Vec3b>(y, x) = i < r.palette.rows ? r.palette.at<cv::Vec3b>(i) : cv::Vec3b(0, 0, 0);
      }
    }
    return out;
  }
  if (px.depth() != CV_8U) return import_error(ErrorCode::kMalformed, what + " " + path + ": colours must be 8-bit (got " + r.data_type + ")");
  cv::Mat out;
  switch (px.channels()) {
    case 1: cv::cvtColor(px, out, cv::COLOR_GRAY2RGB); break;
    case 3: out = px; break;
    case 4: {
      std::vector<cv::Mat> ch;
      cv::split(px, ch);
      if (alpha != nullptr) *alpha = ch[3];
      ch.pop_back();
      cv::merge(ch, out);
      break;
    }
    default: return import_error(ErrorCode::kMalformed, what + " " + path + ": has 2 bands; expected grey, RGB or RGBA");
  }
  return out;
}

double distance_to_segment(const cv::Vec3d& p, const cv::Vec3d& a, const cv::Vec3d& b) {
  const cv::Vec3d ab = b - a;
  const double len2 = ab.dot(ab);
  const double t = len2 > 0 ? std::clamp((p - a).dot(ab) / len2, 0.0, 1.0) : 0.0;
  return cv::norm(p - (a + ab * t));
}

Result<cv::Mat> classes_from_colours(const cv::Mat& rgb, const cv::Mat& alpha, const Legend& legend, const std::string& path, ImportReport& rep) {
  const auto& lc = legend.colours;
  const int n = static_cast<int>(lc.size());
  // Nearest legend entry per distinct colour, computed once: bit 7 marks "a legend colour (pure)".
  std::vector<std::uint8_t> nearest(1U << 24, 0xFF);
  std::unordered_map<std::uint32_t, std::int64_t> counts;
  const auto classify = [&](const cv::Vec3b& p) -> std::uint8_t {
    const std::uint32_t key = (static_cast<std::uint32_t>(p[0]) << 16) | (static_cast<std::uint32_t>(p[1]) << 8) | p[2];
    std::uint8_t& slot = nearest[key];
    if (slot == 0xFF) {
      int best = 0, best_d = std::numeric_limits<int>::max();
      for (int i = 0; i < n; ++i) {
        const cv::Vec3i d = cv::Vec3i(p[0], p[1], p[2]) - lc[static_cast<std::size_t>(i)].rgb;
        const int d2 = d.dot(d);
        if (d2 < best_d) best_d = d2, best = i;
      }
      slot = static_cast<std::uint8_t>(best | (best_d <= kPureColourDistance * kPureColourDistance ? 0x80 : 0));
    }
    return slot;
  };
  cv::Mat entry(rgb.size(), CV_8UC1);  // legend index + 0x80 when pure
  for (int y = 0; y < rgb.rows; ++y) {
    for (int x = 0; x < rgb.cols; ++x) {
      const cv::Vec3b p = rgb.at<cv::Vec3b>(y, x);
      entry.at<std::uint8_t>(y, x) = classify(p);
      if (!alpha.empty() && alpha.at<std::uint8_t>(y, x) < 128) continue;  // transparent: no colour to explain
      ++counts[(static_cast<std::uint32_t>(p[0]) << 16) | (static_cast<std::uint32_t>(p[1]) << 8) | p[2]];
    }
  }
  // A colour used a lot that is neither a legend colour nor a mix of two is a missing legend entry.
  const auto total = static_cast<double>(rgb.total());
  for (const auto& [key, count] : counts) {
    if (static_cast<double>(count) < std::max(50.0, kMissingEntryShare * total)) continue;
    const cv::Vec3d p(static_cast<double>(key >> 16), static_cast<double>((key >> 8) & 0xFF), static_cast<double>(key & 0xFF));
    bool explained = false;
    for (int i = 0; i < n && !explained; ++i) {
      const cv::Vec3d a(lc[static_cast<std::size_t>(i)].rgb);
      explained = cv::norm(p - a) <= kExplainedDistance;
      for (int j = i + 1; j < n && !explained; ++j) {
        explained = distance_to_segment(p, a, cv::Vec3d(lc[static_cast<std::size_t>(j)].rgb)) <= kBlendDistance;
      }
    }
    if (!explained) {
      std::ostringstream m;
      m << "class raster " << path << ": colour [" << (key >> 16) << ", " << ((key >> 8) & 0xFF) << ", " << (key & 0xFF) << "] covers "
        << count << " pixels and is not in the legend (missing legend entry?)";
      return import_error(ErrorCode::kInvalidArgument, m.str());
    }
  }
  cv::Mat out(rgb.size(), CV_8UC1);
  for (int y = 0; y < rgb.rows; ++y) {
    for (int x = 0; x < rgb.cols; ++x) {
      const std::uint8_t e = entry.at<std::uint8_t>(y, x);
      int pick = e & 0x7F;
      if ((e & 0x80) == 0) {
        // A blend: the nearest legend colour among the pure pixels around it.
        ++rep.blended_cells;
        const cv::Vec3b p = rgb.at<cv::Vec3b>(y, x);
        int best_d = std::numeric_limits<int>::max(), best = -1;
        for (int dy = -2; dy <= 2; ++dy) {
          for (int dx = -2; dx <= 2; ++dx) {
            const int yy = y + dy, xx = x + dx;
            if (yy < 0 || xx < 0 || yy >= rgb.rows || xx >= rgb.cols) continue;
            const std::uint8_t ne = entry.at<std::uint8_t>(yy, xx);
            if ((ne & 0x80) == 0) continue;
            const int k = ne & 0x7F;
            const cv::Vec3i d = cv::Vec3i(p[0], p[1], p[2]) - lc[static_cast<std::size_t>(k)].rgb;
            if (d.dot(d) < best_d || (d.dot(d) == best_d && k < best)) best_d = d.dot(d), best = k;  // ties: earlier entry
          }
        }
        if (best >= 0) pick = best;
      }
      ClassId cls = lc[static_cast<std::size_t>(pick)].cls;
      if (!alpha.empty() && alpha.at<std::uint8_t>(y, x) < 128) {
        cls = ClassId::kUnknown;
        ++rep.transparent_cells;
      }
      out.at<std::uint8_t>(y, x) = raw(cls);
    }
  }
  return out;
}

Result<cv::Mat> classes_from_values(const cv::Mat& values, const Legend& legend, const std::string& path, ImportReport& rep) {
  if (values.channels() != 1) {
    return import_error(ErrorCode::kInvalidArgument, "class raster " + path + " has " + std::to_string(values.channels()) +
                                                         " bands but the legend lists values; a value raster has one band (use color: entries for colour rasters)");
  }
  cv::Mat v64;
  values.convertTo(v64, CV_64F);
  cv::Mat out(values.size(), CV_8UC1);
  for (int y = 0; y < v64.rows; ++y) {
    for (int x = 0; x < v64.cols; ++x) {
      const double d = v64.at<double>(y, x);
      if (!std::isfinite(d) || d != std::floor(d)) {
        return import_error(ErrorCode::kMalformed, "class raster " + path + ": value " + std::to_string(d) + " at (" + std::to_string(x) + ", " +
                                                       std::to_string(y) + ") is not an integer class value");
      }
      const auto v = static_cast<std::int64_t>(d);
      const auto it = legend.values.find(v);
      if (it == legend.values.end()) {
        ++rep.unknown_value_cells;
        if (rep.unknown_values.size() < 32 && std::find(rep.unknown_values.begin(), rep.unknown_values.end(), v) == rep.unknown_values.end()) {
          rep.unknown_values.push_back(v);
        }
        out.at<std::uint8_t>(y, x) = raw(ClassId::kUnknown);
      } else {
        out.at<std::uint8_t>(y, x) = raw(it->second);
      }
    }
  }
  std::sort(rep.unknown_values.begin(), rep.unknown_values.end());
  return out;
}

// The ground robots' staging pad keeps this far inside the world's edges where the map has room: the
// quadrotor's survey leaves a border out (the simulator's survey_margin_m, 20 m, so that its camera stays
// over the world), the robots' first guesses are up to 16 m off (mission --init-error), and a robot whose
// guess lies over unmapped ground can settle on a wrong place. 20 + 16 + 4 m keeps every guess over the map.
// Measured on a generated 200 m world's class raster imported: a pad 5 m in never converged with the
// online map; 30 m in, a robot with seed 1's guess settled 46 m off, "tracking", and drove to the edge.
constexpr double kStagingInsetM = 40.0;

// The ground robots' staging pad: the most south-westerly open cell (road or dirt) with room around it,
// kStagingInsetM inside every edge when the world has such a cell, else anywhere.
Pose2 find_staging(const World& w) {
  const GridGeometry& g = w.header.grid;
  cv::Mat open = (w.class_id == raw(ClassId::kRoad)) | (w.class_id == raw(ClassId::kDirt));
  if (cv::countNonZero(open) == 0) return Pose2{};
  cv::Mat room;
  cv::distanceTransform(open, room, cv::DIST_L2, cv::DIST_MASK_5);
  double most = 0;
  cv::minMaxLoc(room, nullptr, &most);
  const float wanted = static_cast<float>(std::min(3.0 / g.resolution, 0.8 * most));
  const auto south_westerly = [&](double inset_m) -> std::optional<Pose2> {
    double best = std::numeric_limits<double>::max();
    std::optional<Pose2> pose;
    for (int r = 0; r < g.height; ++r) {
      for (int c = 0; c < g.width; ++c) {
        if (room.at<float>(r, c) < wanted) continue;
        const double x = g.x_of(c), y = g.y_of(r);
        const double from_west = x - g.origin_x, from_south = y - (g.origin_y - g.size_y());
        if (std::min({from_west, from_south, g.size_x() - from_west, g.size_y() - from_south}) < inset_m) continue;
        if (from_west + from_south < best) best = from_west + from_south, pose = Pose2{x, y, 0.0};
      }
    }
    return pose;
  };
  if (auto inside = south_westerly(kStagingInsetM)) return *inside;
  return south_westerly(0.0).value_or(Pose2{});
}

}  // namespace

std::string ImportReport::summary() const {
  std::ostringstream s;
  bool first = true;
  for (const ClassInfo& c : ClassTable::builtin().all()) {
    const auto n = class_cells[raw(c.id)];
    if (n == 0) continue;
    s << (first ? "" : ", ") << c.name << " " << n;
    first = false;
  }
  s << " cells";
  if (unknown_value_cells > 0) {
    s << "; " << unknown_value_cells << " cells with values not in the legend (";
    for (std::size_t i = 0; i < unknown_values.size(); ++i) s << (i ? " " : "") << unknown_values[i];
    s << ") set to unknown";
  }
  if (transparent_cells > 0) s << "; " << transparent_cells << " transparent cells set to unknown";
  if (blended_cells > 0) s << "; " << blended_cells << " blended edge cells matched to a neighbouring class";
  if (elevation_filled_cells > 0) s << "; " << elevation_filled_cells << " elevation nodata cells filled";
  if (elevation_resampled) s << "; elevation resampled";
  if (color_resampled) s << "; colour image resampled";
  s << (heights_synthesised ? "; heights synthesised per class" : "");
  s << (albedo_synthesised ? "; colour synthesised from class textures" : "");
  return s.str();
}

Result<World> import_world(const ImportOptions& opt, ImportReport* report) {
  ImportReport local;
  ImportReport& rep = report != nullptr ? *report : local;
  rep = ImportReport{};
  if (opt.classes_path.empty()) return import_error(ErrorCode::kInvalidArgument, "no class raster given (classes_path)");
  auto legend = read_legend(opt.legend_path);
  if (!legend) return legend.error();
  auto classes = read_raster(opt.classes_path);
  if (!classes) return import_error(classes.error().code, "class raster " + classes.error().message);

  World w;
  w.header.name = opt.name;
  w.header.source = "import";
  w.header.seed = 0;
  w.header.datum = opt.datum;
  double res = opt.resolution_m_per_px;
  if (!(res > 0)) {
    const auto& gt = classes->geotransform;
    if (!gt || (*gt)[2] != 0.0 || (*gt)[4] != 0.0 || std::fabs(std::fabs((*gt)[1]) - std::fabs((*gt)[5])) > 0.01 * std::fabs((*gt)[1])) {
      return import_error(ErrorCode::kInvalidArgument, "no resolution given and class raster " + opt.classes_path +
                                                           " has no north-up square-pixel geotransform to take it from");
    }
    res = std::fabs((*gt)[1]);
  }
  if (!(res >= 0.01 && res <= 100.0)) return import_error(ErrorCode::kInvalidArgument, "resolution must be in [0.01, 100] m/px");
  const cv::Mat& px = classes->pixels;
  w.header.grid = GridGeometry{res, px.cols, px.rows, -px.cols * res / 2, px.rows * res / 2};

  if (legend->by_colour) {
    cv::Mat alpha;
    auto rgb = to_rgb(classes.value(), "class raster", opt.classes_path, &alpha);
    if (!rgb) return rgb.error();
    auto ids = classes_from_colours(rgb.value(), alpha, legend.value(), opt.classes_path, rep);
    if (!ids) return ids.error();
    w.class_id = std::move(ids.value());
  } else {
    auto ids = classes_from_values(px, legend.value(), opt.classes_path, rep);
    if (!ids) return ids.error();
    w.class_id = std::move(ids.value());
  }
  const cv::Size size = w.class_id.size();

  if (!opt.elevation_path.empty()) {
    auto elev = read_raster(opt.elevation_path);
    if (!elev) return import_error(elev.error().code, "elevation raster " + elev.error().message);
    cv::Mat band;
    cv::extractChannel(elev->pixels, band, 0);
    band.convertTo(band, CV_32F);
    cv::Mat valid(band.size(), CV_8UC1);
    double sum = 0;
    std::int64_t n_valid = 0;
    for (int y = 0; y < band.rows; ++y) {
      for (int x = 0; x < band.cols; ++x) {
        const float v = band.at<float>(y, x);
        const bool ok = std::isfinite(v) && !(elev->nodata && static_cast<double>(v) == static_cast<double>(static_cast<float>(*elev->nodata)));
        valid.at<std::uint8_t>(y, x) = ok ? 255 : 0;
        if (ok) sum += static_cast<double>(v), ++n_valid;
      }
    }
    if (n_valid == 0) return import_error(ErrorCode::kMalformed, "elevation raster " + opt.elevation_path + " has no valid values");
    const auto filled = static_cast<std::int64_t>(band.total()) - n_valid;
    band.setTo(cv::Scalar(sum / static_cast<double>(n_valid)), ~valid);
    auto fitted = fit_to(band, size, "elevation raster", opt.elevation_path, rep.elevation_resampled);
    if (!fitted) return fitted.error();
    rep.elevation_filled_cells = filled;
    w.terrain = fitted.value();
    if (opt.elevation_is_absolute) w.terrain -= opt.datum.height_m;
  } else {
    w.terrain = cv::Mat(size, CV_32FC1, cv::Scalar(0));
  }

  w.height = synthesize_heights(w.class_id, res, opt.texture_seed);
  if (!opt.color_path.empty()) {
    auto colour = read_raster(opt.color_path);
    if (!colour) return import_error(colour.error().code, "colour image " + colour.error().message);
    auto rgb = to_rgb(colour.value(), "colour image", opt.color_path, nullptr);
    if (!rgb) return rgb.error();
    auto fitted = fit_to(rgb.value(), size, "colour image", opt.color_path, rep.color_resampled);
    if (!fitted) return fitted.error();
    w.albedo = fitted.value().clone();
    rep.albedo_synthesised = false;
  } else {
    w.albedo = paint_albedo(w.class_id, w.height, res, opt.texture_seed);
  }
  w.header.staging = find_staging(w);
  for (int y = 0; y < w.class_id.rows; ++y) {
    const auto* row = w.class_id.ptr<std::uint8_t>(y);
    for (int x = 0; x < w.class_id.cols; ++x) ++rep.class_cells[row[x]];
  }
  if (auto v = w.validate(); !v) return import_error(ErrorCode::kMalformed, v.error().message);
  return w;
}

}  // namespace ag::sim
