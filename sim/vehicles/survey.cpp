// Lawnmower survey routes: line spacing from the camera footprint and the requested side overlap.
#include "airground/sim/survey.hpp"

#include <cmath>
#include <string>

namespace ag::sim {

double survey_footprint_width(double altitude_m, double camera_hfov_rad) noexcept {
  return 2.0 * altitude_m * std::tan(0.5 * camera_hfov_rad);
}

double survey_line_spacing(double altitude_m, double side_overlap, double camera_hfov_rad) noexcept {
  return survey_footprint_width(altitude_m, camera_hfov_rad) * (1.0 - side_overlap);
}

Result<std::vector<Waypoint>> survey_lawnmower(double x_min, double y_min, double x_max, double y_max,
                                               double altitude_m, double side_overlap, double camera_hfov_rad,
                                               const SurveyOptions& options) {
  const auto bad = [](const std::string& what) {
    return Error::make(ErrorCode::kInvalidArgument, "survey_lawnmower: " + what);
  };
  if (!std::isfinite(x_min) || !std::isfinite(y_min) || !std::isfinite(x_max) || !std::isfinite(y_max) ||
      !(x_max > x_min) || !(y_max > y_min))
    return bad("the rectangle must be finite with x_max > x_min and y_max > y_min");
  if (!(altitude_m > 0) || !std::isfinite(altitude_m)) return bad("altitude_m must be > 0");
  if (!(side_overlap >= 0 && side_overlap <= 0.95)) return bad("side_overlap must be in [0, 0.95]");
  if (!(camera_hfov_rad > 0 && camera_hfov_rad <= 3.0)) return bad("camera_hfov_rad must be in (0, 3]");
  if (!std::isfinite(options.ground_height_m) || !(options.speed_mps >= 0))
    return bad("options: ground_height_m must be finite and speed_mps >= 0");

  const double width = survey_footprint_width(altitude_m, camera_hfov_rad);
  const double spacing = survey_line_spacing(altitude_m, side_overlap, camera_hfov_rad);
  const bool along_x = options.lines_along_x;
  const double across_lo = along_x ? y_min : x_min, across_hi = along_x ? y_max : x_max;
  const double along_lo = along_x ? x_min : y_min, along_hi = along_x ? x_max : y_max;
  const double across = across_hi - across_lo;
  // Lines needed for (n - 1) * spacing + width >= across; the tolerance keeps an exact fit at n.
  const int n = across <= width ? 1 : static_cast<int>(std::ceil((across - width) / spacing - 1e-9)) + 1;
  const double first = 0.5 * (across_lo + across_hi) - 0.5 * (n - 1) * spacing;

  // Corner: which end across-track the lines start from, and which end along-track the first line starts.
  const bool south = options.start_corner == SurveyCorner::kSouthWest || options.start_corner == SurveyCorner::kSouthEast;
  const bool west = options.start_corner == SurveyCorner::kSouthWest || options.start_corner == SurveyCorner::kNorthWest;
  const bool across_up = along_x ? south : west;  // lines ordered by increasing cross coordinate
  bool forward = along_x ? west : south;          // first line runs toward increasing along coordinate

  std::vector<Waypoint> route;
  route.reserve(static_cast<std::size_t>(2 * n));
  const double z = options.ground_height_m + altitude_m;
  for (int i = 0; i < n; ++i) {
    const double c = first + (across_up ? i : n - 1 - i) * spacing;
    const double a0 = forward ? along_lo : along_hi, a1 = forward ? along_hi : along_lo;
    for (const double a : {a0, a1}) {
      Waypoint w;
      w.x = along_x ? a : c;
      w.y = along_x ? c : a;
      w.z = z;
      w.speed_mps = options.speed_mps;
      route.push_back(w);
    }
    forward = !forward;
  }
  return route;
}

}  // namespace ag::sim
