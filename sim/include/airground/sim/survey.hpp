// Survey route generation: lawnmower lines spaced so that neighbouring camera footprints overlap.
#pragma once

#include <cstdint>
#include <vector>

#include "airground/platform/result.hpp"
#include "airground/sim/quadrotor.hpp"

namespace ag::sim {

enum class SurveyCorner : std::uint8_t { kSouthWest, kSouthEast, kNorthWest, kNorthEast };

struct SurveyOptions {
  SurveyCorner start_corner{SurveyCorner::kSouthWest};  // where the first line begins
  bool lines_along_x{true};     // lines run east-west (false: north-south)
  double ground_height_m{0.0};  // [m] ground height above the datum: waypoints fly at ground + altitude
  double speed_mps{0.0};        // [m/s] written into every waypoint, 0 = the quadrotor's cruise speed
};

// Across-track width of a nadir camera's ground footprint: 2 * altitude * tan(hfov / 2) [m].
[[nodiscard]] double survey_footprint_width(double altitude_m, double camera_hfov_rad) noexcept;
// Distance between neighbouring lines for a side overlap fraction: width * (1 - side_overlap) [m].
[[nodiscard]] double survey_line_spacing(double altitude_m, double side_overlap, double camera_hfov_rad) noexcept;

// A boustrophedon over the rectangle: lines exactly survey_line_spacing() apart, as many as needed for
// the footprints to cover the rectangle across track, centred on it (the outer footprints reach past the
// edges by the same amount); each line spans the rectangle along track. Two waypoints per line, at
// ground_height_m + altitude_m. Errors (ErrorCode::kInvalidArgument): an empty or non-finite rectangle,
// altitude_m <= 0, side_overlap outside [0, 0.95], camera_hfov_rad outside (0, 3].
Result<std::vector<Waypoint>> survey_lawnmower(double x_min, double y_min, double x_max, double y_max,
                                               double altitude_m, double side_overlap, double camera_hfov_rad,
                                               const SurveyOptions& options = {});

}  // namespace ag::sim
