// Viewing pictures of a world: class colours, albedo, colour-mapped heights with scale bars, hillshade, legend.
#include "airground/sim/world_png.hpp"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <vector>

#include "airground/sim/world_texture.hpp"

namespace ag::sim {

namespace {

namespace fs = std::filesystem;

std::string number(double v, int decimals) {
  char buf[64];
  const auto res = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::fixed, decimals);
  return std::string(buf, res.ptr);
}

Status write_png(const fs::path& path, const cv::Mat& bgr) {
  std::vector<std::uint8_t> bytes;
  if (!cv::imencode(".png", bgr, bytes, {cv::IMWRITE_PNG_COMPRESSION, 3})) {
    return Error::make(ErrorCode::kInternal, path.string() + ": PNG encoding failed");
  }
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  out.close();
  if (!out) return Error::make(ErrorCode::kIo, path.string() + ": cannot write");
  return ok_status();
}

// A colour-mapped layer with a vertical scale bar on its right: `to_unit` maps a value to [0, 1] on the
// bar, `ticks` are the values labelled.
cv::Mat with_scale_bar(const cv::Mat& layer, const std::function<double(double)>& to_unit, const std::vector<double>& ticks,
                       const std::string& title, cv::ColormapTypes map) {
  cv::Mat unit(layer.size(), CV_8UC1);
  for (int r = 0; r < layer.rows; ++r) {
    const auto* v = layer.ptr<float>(r);
    auto* o = unit.ptr<std::uint8_t>(r);
    for (int c = 0; c < layer.cols; ++c) {
      o[c] = static_cast<std::uint8_t>(std::lround(255.0 * std::clamp(to_unit(static_cast<double>(v[c])), 0.0, 1.0)));
    }
  }
  cv::Mat coloured;
  cv::applyColorMap(unit, coloured, map);
  const double font = std::max(0.45, layer.rows / 1800.0);
  const int thick = std::max(1, static_cast<int>(std::lround(font * 1.6)));
  const int bar_w = std::max(24, layer.rows / 40), margin = std::max(12, layer.rows / 40);
  const int label_w = static_cast<int>(font * 150);
  cv::Mat canvas(layer.rows, layer.cols + bar_w + label_w + 2 * margin, CV_8UC3, cv::Scalar(255, 255, 255));
  coloured.copyTo(canvas(cv::Rect(0, 0, layer.cols, layer.rows)));
  const int top = margin * 3, bottom = layer.rows - margin, x0 = layer.cols + margin;
  const int span = std::max(bottom - top, 2);
  cv::Mat ramp(span, 1, CV_8UC1);
  for (int i = 0; i < span; ++i) ramp.at<std::uint8_t>(i) = static_cast<std::uint8_t>(std::lround(255.0 * (span - 1 - i) / (span - 1)));
  cv::Mat ramp_colour;
  cv::applyColorMap(ramp, ramp_colour, map);
  cv::resize(ramp_colour, ramp_colour, cv::Size(bar_w, span), 0, 0, cv::INTER_NEAREST);
  ramp_colour.copyTo(canvas(cv::Rect(x0, top, bar_w, span)));
  cv::rectangle(canvas, cv::Rect(x0, top, bar_w, span), cv::Scalar(0, 0, 0), 1);
  cv::putText(canvas, title, cv::Point(layer.cols + margin / 2, top - margin), cv::FONT_HERSHEY_SIMPLEX, font, cv::Scalar(0, 0, 0), thick,
              cv::LINE_AA);
  for (const double t : ticks) {
    const int y = bottom - static_cast<int>(std::lround(std::clamp(to_unit(t), 0.0, 1.0) * (span - 1))) - 1;
    cv::line(canvas, cv::Point(x0 + bar_w, y), cv::Point(x0 + bar_w + margin / 2, y), cv::Scalar(0, 0, 0), thick);
    const int decimals = std::fabs(t - std::round(t)) < 0.05 ? 0 : 1;
    cv::putText(canvas, number(t, decimals), cv::Point(x0 + bar_w + margin / 2 + 3, y + static_cast<int>(font * 10)),
                cv::FONT_HERSHEY_SIMPLEX, font, cv::Scalar(0, 0, 0), thick, cv::LINE_AA);
  }
  return canvas;
}

cv::Mat legend_image(const ClassTable& classes) {
  const int row_h = 34, swatch = 24;
  cv::Mat img(row_h * static_cast<int>(classes.all().size()) + 10, 230, CV_8UC3, cv::Scalar(255, 255, 255));
  int y = 5;
  for (const ClassInfo& c : classes.all()) {
    cv::rectangle(img, cv::Rect(8, y + 4, swatch, swatch), cv::Scalar(c.color.b, c.color.g, c.color.r), cv::FILLED);
    cv::rectangle(img, cv::Rect(8, y + 4, swatch, swatch), cv::Scalar(0, 0, 0), 1);
    cv::putText(img, std::to_string(static_cast<int>(raw(c.id))) + "  " + c.name, cv::Point(8 + swatch + 10, y + 23),
                cv::FONT_HERSHEY_SIMPLEX, 0.6, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
    y += row_h;
  }
  return img;
}

}  // namespace

cv::Mat class_display_image(const cv::Mat& class_id, const ClassTable& classes) {
  CV_Assert(class_id.type() == CV_8UC1);
  cv::Mat lut(1, 256, CV_8UC3, cv::Scalar(0, 0, 0));
  for (const ClassInfo& c : classes.all()) lut.at<cv::Vec3b>(raw(c.id)) = cv::Vec3b(c.color.r, c.color.g, c.color.b);
  cv::Mat three, out;
  cv::cvtColor(class_id, three, cv::COLOR_GRAY2BGR);
  cv::LUT(three, lut, out);
  return out;
}

Status write_world_pngs(const World& w, const std::string& out_dir) {
  if (auto v = w.validate(); !v) return v;
  const fs::path dir(out_dir);
  std::error_code ec;
  if (fs::exists(dir / "world.yaml", ec)) {
    return Error::make(ErrorCode::kInvalidArgument,
                       out_dir + " holds a world (world.yaml): its class.png holds class ids; write the viewing pictures elsewhere");
  }
  fs::create_directories(dir, ec);
  if (ec) return Error::make(ErrorCode::kIo, out_dir + ": cannot create (" + ec.message() + ")");

  cv::Mat bgr;
  cv::cvtColor(class_display_image(w.class_id), bgr, cv::COLOR_RGB2BGR);
  if (auto s = write_png(dir / "class.png", bgr); !s) return s;
  cv::cvtColor(w.albedo, bgr, cv::COLOR_RGB2BGR);
  if (auto s = write_png(dir / "albedo.png", bgr); !s) return s;

  double hmin = 0, hmax = 0, tmin = 0, tmax = 0;
  cv::minMaxLoc(w.height, &hmin, &hmax);
  cv::minMaxLoc(w.terrain, &tmin, &tmax);
  const double htop = std::max(hmax, 1.0);
  std::vector<double> hticks;
  for (const double t : {0.0, 0.15, 1.5, 5.0, 10.0, 20.0, 30.0}) {
    if (t <= htop) hticks.push_back(t);
  }
  if (htop - hticks.back() > 0.1 * htop) hticks.push_back(std::round(htop * 10) / 10);
  const auto height_unit = [htop](double v) { return std::sqrt(std::max(v, 0.0) / htop); };
  if (auto s = write_png(dir / "height.png", with_scale_bar(w.height, height_unit, hticks, "height [m]", cv::COLORMAP_TURBO)); !s) return s;

  const double tspan = std::max(tmax - tmin, 0.1);
  std::vector<double> tticks;
  for (int k = 0; k <= 4; ++k) tticks.push_back(tmin + tspan * k / 4.0);
  const auto terrain_unit = [tmin, tspan](double v) { return (v - tmin) / tspan; };
  if (auto s = write_png(dir / "terrain.png", with_scale_bar(w.terrain, terrain_unit, tticks, "terrain [m]", cv::COLORMAP_VIRIDIS)); !s) {
    return s;
  }

  const cv::Mat shade = hillshade(w.terrain + w.height, w.header.grid.resolution);
  cv::Mat grey;
  shade.convertTo(grey, CV_8UC1, 255.0);
  if (auto s = write_png(dir / "hillshade.png", grey); !s) return s;
  if (auto s = write_png(dir / "legend.png", legend_image(ClassTable::builtin())); !s) return s;

  std::ostringstream y;
  y << "# Viewing pictures of world '" << w.header.name << "' (" << w.header.grid.width << "x" << w.header.grid.height << " cells at "
    << number(w.header.grid.resolution, 3) << " m, north up).\n";
  y << "class.png: class ids in display colours (legend.png, config/classes.yaml)\n";
  y << "albedo.png: aerial colour\n";
  y << "height.png: {what: object height above terrain, unit: m, min: " << number(hmin, 2) << ", max: " << number(hmax, 2)
    << ", scale: sqrt, colormap: turbo}\n";
  y << "terrain.png: {what: terrain elevation above the datum height, unit: m, min: " << number(tmin, 2) << ", max: " << number(tmax, 2)
    << ", scale: linear, colormap: viridis}\n";
  y << "hillshade.png: shaded relief of terrain + height, sun from the north-west at 45 degrees\n";
  std::ofstream side(dir / "pngs.yaml", std::ios::trunc);
  side << y.str();
  side.close();
  if (!side) return Error::make(ErrorCode::kIo, (dir / "pngs.yaml").string() + ": cannot write");
  return ok_status();
}

}  // namespace ag::sim
