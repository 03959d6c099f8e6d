// The mission area: one declaration of the four area_* rows that the planner and the regions stage (and
// the localizer) read, the tiles that cover it, and the refusal of an area that is not a rectangle.
#include "airground/messages/mission_area.hpp"

#include <gtest/gtest.h>

#include <string>

#include "airground/mission/stages.hpp"
#include "airground/planning/stages.hpp"

namespace ag {
namespace {

constexpr auto kAreaOnly = param_specs(mission_area_fields("west edge"));
constexpr ParamSection kSchema[] = {{"planner", kAreaOnly, "the area alone"}};

TEST(MissionArea, TilesCoverTheAreaOnBothSidesOfTheOrigin) {
  const TileExtent e = tiles_covering(MapRect{-100.0, -50.0, 100.0, 50.0}, 0.5, 64);  // 32 m tiles
  EXPECT_EQ(e.tile_x0, -4);  // floor(-100 / 32)
  EXPECT_EQ(e.tile_y0, -2);  // floor(-50 / 32)
  EXPECT_EQ(e.tiles_x, 8);   // tiles -4 .. 3
  EXPECT_EQ(e.tiles_y, 4);   // tiles -2 .. 1
  const TileExtent one = tiles_covering(MapRect{0.0, 0.0, 31.9, 31.9}, 0.5, 64);
  EXPECT_EQ(one.tiles_x, 1);
  EXPECT_EQ(one.tiles_y, 1);
}

TEST(MissionArea, TheStagesDeclareTheSameRowsWithTheirOwnHelp) {
  for (const auto& rows : {std::span<const ParamSpec>(plan::PlannerStage::kParams), std::span<const ParamSpec>(mission::kRegionsParams)}) {
    const char* keys[] = {"area_x0_m", "area_y0_m", "area_x1_m", "area_y1_m"};
    const double defaults[] = {-500.0, -500.0, 500.0, 500.0};
    for (int i = 0; i < 4; ++i) {
      const ParamSpec* r = find_param(rows, keys[i]);
      ASSERT_NE(r, nullptr) << keys[i];
      EXPECT_EQ(r->default_num, defaults[i]) << keys[i];
      EXPECT_EQ(r->min, -1e6);
      EXPECT_EQ(r->max, 1e6);
    }
  }
  EXPECT_NE(find_param(plan::PlannerStage::kParams, "area_x0_m")->help.find("roadmap"), std::string_view::npos);
  EXPECT_NE(find_param(mission::kRegionsParams, "area_x0_m")->help.find("class grid"), std::string_view::npos);
}

TEST(MissionArea, LoadsFromTheSectionAndRefusesAnAreaThatIsNotARectangle) {
  auto good = Config::load_string(kSchema, "planner:\n  area_x0_m: -20\n  area_x1_m: 80\n  area_y0_m: 5\n  area_y1_m: 6\n", "t.yaml");
  ASSERT_TRUE(good.ok()) << good.error().message;
  auto a = load_mission_area(SectionView(good.value(), "planner"), mission_area_fields("west edge"), "planner");
  ASSERT_TRUE(a.ok()) << a.error().message;
  EXPECT_EQ(a.value().rect().x0, -20.0);
  EXPECT_EQ(a.value().rect().x1, 80.0);
  EXPECT_TRUE(a.value().rect().contains(0.0, 5.5));
  EXPECT_FALSE(a.value().rect().contains(0.0, 6.5));

  for (const char* yaml : {"planner:\n  area_x0_m: 100\n  area_x1_m: 100\n", "planner:\n  area_y0_m: 600\n"}) {
    auto bad = Config::load_string(kSchema, yaml, "t.yaml");
    ASSERT_TRUE(bad.ok()) << bad.error().message;  // each value lies in its range; the pair does not
    auto refused = load_mission_area(SectionView(bad.value(), "planner"), mission_area_fields("west edge"), "planner");
    ASSERT_FALSE(refused.ok()) << yaml;
    EXPECT_NE(refused.error().message.find("planner.area_x1_m/area_y1_m must be east/north"), std::string::npos)
        << refused.error().message;
  }
}

}  // namespace
}  // namespace ag
