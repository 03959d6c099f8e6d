// The runner's wait for the online map counts only ground inside the mission area: a robot started near
// the world's edge is released once the mappable part of its surroundings is known (issue 27: on an
// imported world whose staging pose lies 5 m from the edge, 40 % of the 30 m disc could never be mapped
// and `eval localization --map online` waited for ever).
#include <gtest/gtest.h>

#include <cmath>

#include "airground/sim/map_coverage.hpp"

namespace ag::sim {
namespace {

// A 200 m x 200 m mission area centred on the origin.
GridGeometry area() {
  GridGeometry g;
  g.resolution = 0.25;
  g.width = 800;
  g.height = 800;
  g.origin_x = -100;
  g.origin_y = 100;
  return g;
}

TEST(MapCoverage, GroundOutsideTheMissionAreaDoesNotCount) {
  // Everything inside the area is known: a robot 5 m from the west edge sees a fully known disc, although
  // about 40 % of its 30 m disc lies beyond the edge.
  const auto inside = [](double x, double) { return x >= -100.0; };
  EXPECT_DOUBLE_EQ(known_fraction(inside, -95.0, 0.0, 30.0, 0.5, area()), 1.0);
  // Counted over the whole disc (as before) the same map would be ~0.6 known: the wait never ended at 0.5
  // of a disc half beyond the edge.
  GridGeometry everywhere = area();
  everywhere.origin_x = -1000;
  everywhere.origin_y = 1000;
  everywhere.width = everywhere.height = 8000;
  const double whole = known_fraction(inside, -95.0, 0.0, 30.0, 0.5, everywhere);
  EXPECT_GT(whole, 0.55);
  EXPECT_LT(whole, 0.65);
}

TEST(MapCoverage, TheShareOfKnownCellsInsideIsCounted) {
  // East half of the area known: a robot in the middle sees half its disc known.
  const auto east = [](double x, double) { return x >= 0.0; };
  EXPECT_NEAR(known_fraction(east, 0.0, 0.0, 20.0, 0.5, area()), 0.5, 0.02);
  const auto none = [](double, double) { return false; };
  EXPECT_DOUBLE_EQ(known_fraction(none, 0.0, 0.0, 20.0, 0.5, area()), 0.0);
  // A disc wholly outside the area has nothing to wait for.
  EXPECT_DOUBLE_EQ(known_fraction(none, 500.0, 0.0, 20.0, 0.5, area()), 1.0);
}

}  // namespace
}  // namespace ag::sim
