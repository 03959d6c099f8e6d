// Line and timeline charts for the reports.
#include "airground/sim/plot.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

namespace ag::sim {

namespace {

constexpr int kLeft = 70, kRight = 170, kTop = 50, kBottom = 46;  // the title, then the y label, above the frame
const cv::Scalar kInk(40, 40, 40), kGrid(225, 225, 225);

// A "nice" tick step for a range (1, 2 or 5 times a power of ten), about n ticks.
double nice_step(double range, int n) {
  if (!(range > 0)) return 1.0;
  const double raw = range / n;
  const double p = std::pow(10.0, std::floor(std::log10(raw)));
  const double f = raw / p;
  return (f < 1.5 ? 1.0 : f < 3.5 ? 2.0 : f < 7.5 ? 5.0 : 10.0) * p;
}

std::string tick_text(double v, double step) {
  char b[32];
  if (step >= 1.0) std::snprintf(b, sizeof b, "%.0f", v);
  else if (step >= 0.1) std::snprintf(b, sizeof b, "%.1f", v);
  else std::snprintf(b, sizeof b, "%.2f", v);
  return b;
}

void text(cv::Mat& img, const std::string& s, cv::Point p, double scale = 0.45, const cv::Scalar& c = kInk) {
  cv::putText(img, s, p, cv::FONT_HERSHEY_SIMPLEX, scale, c, 1, cv::LINE_AA);
}

}  // namespace

cv::Scalar series_colour(std::size_t i) {
  static const cv::Scalar k[] = {{180, 119, 31}, {14, 127, 255}, {44, 160, 44}, {40, 39, 214}, {189, 103, 148},
                                 {75, 86, 140},  {194, 119, 227}, {127, 127, 127}, {34, 189, 188}, {207, 190, 23}};
  return k[i % (sizeof k / sizeof k[0])];
}

cv::Mat line_plot(const std::vector<PlotSeries>& series, const PlotOptions& o) {
  cv::Mat img(o.height, o.width, CV_8UC3, cv::Scalar(255, 255, 255));
  double x0 = std::numeric_limits<double>::infinity(), x1 = -x0, y0 = x0, y1 = -x0;
  for (const auto& s : series)
    for (std::size_t i = 0; i < std::min(s.x.size(), s.y.size()); ++i) {
      if (!std::isfinite(s.x[i]) || !std::isfinite(s.y[i])) continue;
      x0 = std::min(x0, s.x[i]);
      x1 = std::max(x1, s.x[i]);
      y0 = std::min(y0, s.y[i]);
      y1 = std::max(y1, s.y[i]);
    }
  for (double h : o.h_lines) {
    y0 = std::min(y0, h);
    y1 = std::max(y1, h);
  }
  if (!std::isfinite(x0)) x0 = 0, x1 = 1, y0 = 0, y1 = 1;
  if (o.y_max > o.y_min) y0 = o.y_min, y1 = o.y_max;
  else y0 = std::min(y0, 0.0);
  if (x1 <= x0) x1 = x0 + 1;
  if (y1 <= y0) y1 = y0 + 1;
  y1 += 0.05 * (y1 - y0);
  const int pw = o.width - kLeft - kRight, ph = o.height - kTop - kBottom;
  auto px = [&](double x, double y) {
    return cv::Point(kLeft + static_cast<int>(std::lround((x - x0) / (x1 - x0) * pw)),
                     kTop + ph - static_cast<int>(std::lround((std::clamp(y, y0, y1) - y0) / (y1 - y0) * ph)));
  };
  const double xs = nice_step(x1 - x0, 8), ys = nice_step(y1 - y0, 6);
  for (double x = std::ceil(x0 / xs) * xs; x <= x1 + 1e-9; x += xs) {
    cv::line(img, px(x, y0), px(x, y1), kGrid, 1);
    text(img, tick_text(x, xs), px(x, y0) + cv::Point(-12, 18));
  }
  for (double y = std::ceil(y0 / ys) * ys; y <= y1 + 1e-9; y += ys) {
    cv::line(img, px(x0, y), px(x1, y), kGrid, 1);
    text(img, tick_text(y, ys), px(x0, y) + cv::Point(-50, 5));
  }
  cv::rectangle(img, cv::Point(kLeft, kTop), cv::Point(kLeft + pw, kTop + ph), kInk, 1);
  for (double h : o.h_lines)
    for (int k = 0; k < pw; k += 12) cv::line(img, cv::Point(kLeft + k, px(x0, h).y), cv::Point(kLeft + std::min(pw, k + 6), px(x0, h).y), cv::Scalar(0, 0, 200), 1);
  for (std::size_t si = 0; si < series.size(); ++si) {
    const auto& s = series[si];
    const std::size_t n = std::min(s.x.size(), s.y.size());
    for (std::size_t i = 0; i < n; ++i) {
      if (!std::isfinite(s.x[i]) || !std::isfinite(s.y[i])) continue;
      if (s.points) cv::circle(img, px(s.x[i], s.y[i]), 2, s.colour, cv::FILLED, cv::LINE_AA);
      else if (i > 0 && std::isfinite(s.x[i - 1]) && std::isfinite(s.y[i - 1])) cv::line(img, px(s.x[i - 1], s.y[i - 1]), px(s.x[i], s.y[i]), s.colour, 2, cv::LINE_AA);
    }
    const int ly = kTop + 14 + 20 * static_cast<int>(si);
    cv::line(img, cv::Point(kLeft + pw + 12, ly - 4), cv::Point(kLeft + pw + 36, ly - 4), s.colour, 3);
    text(img, s.name, cv::Point(kLeft + pw + 42, ly));
  }
  text(img, o.title, cv::Point(kLeft, 22), 0.6);
  text(img, o.x_label, cv::Point(kLeft + pw / 2 - 30, o.height - 8));
  text(img, o.y_label, cv::Point(6, kTop - 8));
  return img;
}

cv::Mat timeline_plot(const std::vector<TimelineLane>& lanes, double t_end, const std::string& title,
                      const std::vector<std::pair<std::string, cv::Scalar>>& legend) {
  const int lane_h = 30;
  const int width = 1100, height = kTop + kBottom + lane_h * std::max<int>(1, static_cast<int>(lanes.size()));
  cv::Mat img(height, width, CV_8UC3, cv::Scalar(255, 255, 255));
  const int pw = width - kLeft - kRight;
  if (!(t_end > 0)) t_end = 1;
  auto px = [&](double t) { return kLeft + static_cast<int>(std::lround(std::clamp(t / t_end, 0.0, 1.0) * pw)); };
  const double xs = nice_step(t_end, 10);
  for (double x = 0; x <= t_end + 1e-9; x += xs) {
    cv::line(img, cv::Point(px(x), kTop), cv::Point(px(x), height - kBottom), kGrid, 1);
    text(img, tick_text(x, xs), cv::Point(px(x) - 12, height - kBottom + 18));
  }
  for (std::size_t li = 0; li < lanes.size(); ++li) {
    const int y = kTop + lane_h * static_cast<int>(li);
    text(img, lanes[li].name, cv::Point(6, y + 20));
    for (const auto& s : lanes[li].spans) {
      const int a = px(s.t0), b = std::max(px(s.t1), a + 1);
      cv::rectangle(img, cv::Point(a, y + 4), cv::Point(b, y + lane_h - 4), s.colour, cv::FILLED);
      if (!s.label.empty() && b - a > 18) text(img, s.label, cv::Point(a + 3, y + 20), 0.4, cv::Scalar(255, 255, 255));
    }
  }
  for (std::size_t k = 0; k < legend.size(); ++k) {
    const int ly = kTop + 14 + 20 * static_cast<int>(k);
    cv::rectangle(img, cv::Point(kLeft + pw + 12, ly - 10), cv::Point(kLeft + pw + 32, ly), legend[k].second, cv::FILLED);
    text(img, legend[k].first, cv::Point(kLeft + pw + 40, ly));
  }
  text(img, title, cv::Point(kLeft, 22), 0.6);
  text(img, "simulated time [s]", cv::Point(kLeft + pw / 2 - 60, height - 8));
  return img;
}

}  // namespace ag::sim
