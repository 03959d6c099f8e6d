// The mission file: the shipped example loads; every kind of bad file is refused with file:line and key.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <span>
#include <sstream>
#include <string>

#include "airground/mission/mission_file.hpp"
#include "airground/mission/stages.hpp"
#include "airground/platform/param_binding.hpp"

namespace ag::mission {
namespace {

std::string source_dir() {
  const char* s = std::getenv("AG_SOURCE_DIR");
  return s != nullptr ? s : AG_TEST_SOURCE_DIR;
}

const char* kGood = R"(mission: {name: t, type: regions}
datum: {lat: 47.4, lon: 8.5, alt: 400}
area: {x0: -100, y0: -50, x1: 100, y1: 50}
team:
  - {id: 1, priority: 2, start: [1, 2, 0.5]}
  - {id: 2, priority: 1, start: [3, 4], initial_guess: [5, 6, 0.1], initial_sigma_m: 8}
targets: [[10, 10], [20, -20]]
parameters: {visit_radius_m: 2.5, max_sigma_m: 1.0}
survey: {altitude_m: 50, speed_mps: 4, line_spacing_m: 20}
)";

TEST(MissionFile, TheShippedExampleLoads) {
  auto f = load_mission_file(source_dir() + "/config/missions/default.yaml");
  ASSERT_TRUE(f.ok()) << f.error().message;
  EXPECT_EQ(f->type, MissionType::kRegions);
  EXPECT_EQ(f->team.size(), 3U);
  EXPECT_DOUBLE_EQ(f->area.x0, -200);
  EXPECT_DOUBLE_EQ(f->survey.altitude_m, 40);
  EXPECT_DOUBLE_EQ(f->survey.area.x1, 200) << "the survey covers the mission area by default";
}

TEST(MissionFile, AGoodFileGivesEveryValue) {
  auto f = load_mission_string(kGood, "good.yaml");
  ASSERT_TRUE(f.ok()) << f.error().message;
  EXPECT_EQ(f->name, "t");
  EXPECT_DOUBLE_EQ(f->lat_deg, 47.4);
  EXPECT_DOUBLE_EQ(f->alt_m, 400);
  ASSERT_EQ(f->team.size(), 2U);
  EXPECT_EQ(f->team[0].priority, 2);
  EXPECT_DOUBLE_EQ(f->team[0].start_yaw, 0.5);
  EXPECT_DOUBLE_EQ(f->team[0].guess_x, 1) << "the guess defaults to the start";
  EXPECT_DOUBLE_EQ(f->team[1].guess_y, 6);
  EXPECT_DOUBLE_EQ(f->team[1].guess_sigma_m, 8);
  ASSERT_EQ(f->targets.size(), 2U);
  EXPECT_DOUBLE_EQ(f->targets[1].y, -20);
  EXPECT_DOUBLE_EQ(f->params.visit_radius_m, 2.5);
  EXPECT_DOUBLE_EQ(f->params.claim_timeout_s, 20) << "defaults for what is not given";
  EXPECT_DOUBLE_EQ(f->survey.spacing_m(), 20);
  EXPECT_TRUE(f->survey.return_home) << "back over the launch point by default (RTL)";
  EXPECT_DOUBLE_EQ(f->params.survey_end_s, 0) << "the simulator estimates it";
  auto g = load_mission_string(std::string(kGood).replace(std::string(kGood).find("line_spacing_m: 20"), 18,
                                                          "line_spacing_m: 20, return_home: false"),
                               "good2.yaml");
  ASSERT_TRUE(g.ok()) << g.error().message;
  EXPECT_FALSE(g->survey.return_home);
  ASSERT_NE(f->member(2), nullptr);
  EXPECT_EQ(f->member(7), nullptr);
}

TEST(MissionFile, TheSurveyIsALawnmowerOverTheArea) {
  Survey s;
  s.area = Area{0, 0, 100, 60};
  s.line_spacing_m = 20;
  const auto w = survey_waypoints(s);
  ASSERT_EQ(w.size(), 6U);  // 3 lines of 2 ends
  EXPECT_NEAR(w[0].y, 10, 1e-9);
  EXPECT_NEAR(w[2].y, 30, 1e-9);
  EXPECT_NEAR(w[4].y, 50, 1e-9);
  EXPECT_NEAR(w[0].x, 0, 1e-9);
  EXPECT_NEAR(w[1].x, 100, 1e-9);
  EXPECT_NEAR(w[2].x, 100, 1e-9) << "alternating direction";
  EXPECT_NEAR(w[3].x, 0, 1e-9);
  // spacing from overlap: 40 m altitude, 70 deg field of view -> 56 m footprint, 60 % overlap -> 22.4 m
  Survey o;
  o.altitude_m = 40;
  o.overlap = 0.6;
  o.camera_hfov_deg = 70;
  EXPECT_NEAR(o.spacing_m(), 0.4 * 2 * 40 * std::tan(35.0 * 3.14159265358979 / 180), 1e-6);
  // lines running north-south
  s.heading_deg = 90;
  const auto v = survey_waypoints(s);
  ASSERT_EQ(v.size(), 10U);  // 100 m across at 20 m: 5 lines
  EXPECT_NEAR(v[0].x, v[1].x, 1e-9);
}

struct Bad {
  const char* name;
  std::string yaml;
  const char* expect;  // in the message
  int line;            // expected line (0: do not check)
};

std::string with(const std::string& from, const std::string& to) {
  std::string s = kGood;
  const auto p = s.find(from);
  EXPECT_NE(p, std::string::npos) << from;
  return s.replace(p, from.size(), to);
}

TEST(MissionFile, EveryKindOfBadFileNamesFileLineAndKey) {
  const Bad cases[] = {
      {"malformed", "datum: {lat: 1\nteam: [", "malformed YAML", 0},
      {"not a map", "- 1\n- 2\n", "(top level)", 1},
      {"unknown top key", std::string(kGood) + "colour: red\n", "colour: unknown key", 10},
      {"missing datum", with("datum: {lat: 47.4, lon: 8.5, alt: 400}\n", ""), "datum: missing", 0},
      {"lat out of range", with("lat: 47.4", "lat: 147.4"), "datum.lat: 147.4 outside [-90, 90]", 2},
      {"lat not a number", with("lat: 47.4", "lat: north"), "datum.lat: 'north' is not a number", 2},
      {"area inverted", with("x1: 100", "x1: -200"), "area: x1/y1 must be east/north", 3},
      {"area missing key", with("y1: 50", "z1: 50"), "area.z1: unknown key", 3},
      {"no team", with("team:\n  - {id: 1, priority: 2, start: [1, 2, 0.5]}\n  - {id: 2, priority: 1, start: [3, 4], initial_guess: [5, 6, 0.1], initial_sigma_m: 8}\n", ""), "team: missing", 0},
      {"duplicate id", with("id: 2,", "id: 1,"), "team[1].id: duplicate robot id 1", 6},
      {"duplicate priority", with("priority: 1,", "priority: 2,"), "team[1].priority: duplicate priority 2", 6},
      {"start missing", with("start: [1, 2, 0.5]", "initial_sigma_m: 3"), "team[0].start: missing", 5},
      {"start not a list", with("start: [1, 2, 0.5]", "start: here"), "team[0].start: must be [x, y]", 5},
      {"start with a word", with("start: [1, 2, 0.5]", "start: [1, b]"), "team[0].start: 'b' is not a number", 5},
      {"bad type", with("type: regions", "type: patrol"), "mission.type: 'patrol' is not one of regions|waypoints", 1},
      {"waypoints without any", with("type: regions", "type: waypoints"), "needs waypoints", 0},
      {"bad parameter", with("visit_radius_m: 2.5", "visit_radius_m: 200"), "parameters.visit_radius_m: 200 outside", 8},
      {"unknown parameter", with("max_sigma_m: 1.0", "max_sigma: 1.0"), "parameters.max_sigma: unknown key", 8},
      {"bad pattern", with("altitude_m: 50", "pattern: spiral, altitude_m: 50"), "survey.pattern: 'spiral' is not one of lawnmower", 9},
      {"survey too low", with("altitude_m: 50", "altitude_m: 2"), "survey.altitude_m: 2 outside", 9},
      {"survey by a ground robot", with("altitude_m: 50", "robot: 1, altitude_m: 50"), "survey.robot: robot 1 is a ground robot", 9},
      {"return_home not a bool", with("altitude_m: 50", "return_home: maybe, altitude_m: 50"), "survey.return_home: 'maybe' is not true or false", 9},
      {"survey_end_s negative", with("max_sigma_m: 1.0", "max_sigma_m: 1.0, survey_end_s: -5"), "parameters.survey_end_s: -5 outside", 8},
      {"target not a pair", with("[20, -20]", "[20]"), "targets[1]: must be [x, y]", 7},
  };
  for (const Bad& c : cases) {
    auto f = load_mission_string(c.yaml, "bad.yaml");
    ASSERT_FALSE(f.ok()) << c.name;
    const std::string& m = f.error().message;
    EXPECT_NE(m.find("mission file bad.yaml"), std::string::npos) << c.name << ": " << m;
    EXPECT_NE(m.find(c.expect), std::string::npos) << c.name << ": " << m;
    if (c.line > 0) {
      EXPECT_NE(m.find("bad.yaml:" + std::to_string(c.line) + ":"), std::string::npos) << c.name << ": " << m;
    }
  }
  auto missing = load_mission_file("/nonexistent/m.yaml");
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().message.find("/nonexistent/m.yaml"), std::string::npos);
}

// The mission file has no ranges of its own for the stages' parameters: just past a stage row's max is
// refused, naming the key and that row's range; the max itself is taken.
TEST(MissionFile, StageParametersAreCheckedAgainstTheStagesOwnRows) {
  const struct {
    std::span<const ParamSpec> rows;
    const char* key;
  } owned[] = {{MissionStage::kParams, "visit_radius_m"}, {MissionStage::kParams, "claim_timeout_s"},
               {RegionsStage::kParams, "merge_distance_m"}, {RegionsStage::kParams, "min_region_cells"}};
  for (const auto& o : owned) {
    const ParamSpec* row = find_param(o.rows, o.key);
    ASSERT_NE(row, nullptr) << o.key;
    const auto file = [&](double v) {
      std::ostringstream s;
      s << "parameters: {max_sigma_m: 1.0, " << o.key << ": " << v << "}";
      return with("parameters: {visit_radius_m: 2.5, max_sigma_m: 1.0}", s.str());
    };
    EXPECT_TRUE(load_mission_string(file(row->max), "edge.yaml").ok()) << o.key;
    auto f = load_mission_string(file(row->max + 1), "bad.yaml");
    ASSERT_FALSE(f.ok()) << o.key;
    std::ostringstream range;
    range << "parameters." << o.key << ": " << row->max + 1 << " outside [" << row->min << ", " << row->max << "]";
    EXPECT_NE(f.error().message.find(range.str()), std::string::npos) << f.error().message;
  }
}

}  // namespace
}  // namespace ag::mission
