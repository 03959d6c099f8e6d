// Small line and timeline charts for the reports (OpenCV drawing, PNG): axes with ticks, a legend.
#pragma once

#include <opencv2/core.hpp>

#include <string>
#include <vector>

namespace ag::sim {

struct PlotSeries {
  std::string name;
  std::vector<double> x, y;
  cv::Scalar colour{0, 0, 0};  // BGR
  bool points{false};          // dots instead of a line
};

struct PlotOptions {
  std::string title, x_label, y_label;
  int width{960}, height{420};
  double y_min{0}, y_max{0};   // y_max <= y_min: from the data
  std::vector<double> h_lines{};  // dashed horizontal reference lines (e.g. a goal)
};

// A line chart of the series over one x axis.
cv::Mat line_plot(const std::vector<PlotSeries>& series, const PlotOptions& o);

// A timeline: one row per lane, coloured spans [t0, t1) with an optional label.
struct TimelineSpan {
  double t0{0}, t1{0};
  cv::Scalar colour{0, 0, 0};
  std::string label;
};
struct TimelineLane {
  std::string name;
  std::vector<TimelineSpan> spans;
};
cv::Mat timeline_plot(const std::vector<TimelineLane>& lanes, double t_end, const std::string& title,
                      const std::vector<std::pair<std::string, cv::Scalar>>& legend);

// A distinct colour per index (BGR).
cv::Scalar series_colour(std::size_t i);

}  // namespace ag::sim
