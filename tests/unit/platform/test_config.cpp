// Config: defaults, YAML overrides, the error messages operators see, --set, and to_yaml() round trips.
#include "roles.hpp"
#include "airground/platform/config.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "airground/platform/role_instance.hpp"
#include "airground/platform/role_table.hpp"

namespace ag {

namespace {

constexpr ParamSpec kCameraParams[] = {
    ParamSpec::real("period_s", 0.1, 0.01, 10.0, "s", "time between frames"),
    ParamSpec::integer("queue", 8, 1, 64, "count", "frames buffered"),
    ParamSpec::boolean("enabled", true, "capture at all"),
    ParamSpec::text("mode", "auto", "auto|manual", "exposure mode"),
    ParamSpec::text("label", "", "", "free text"),
};
constexpr ParamSpec kMapParams[] = {
    ParamSpec::real("resolution_m", 0.05, 0.001, 1.0, "m", "cell size"),
    ParamSpec::integer("offset", -3, -100, 100, "", "signed integer"),
};
constexpr ParamSection kSchema[] = {
    {"camera", kCameraParams, "the camera"},
    {"map", kMapParams, "the map"},
};

testing::AssertionResult contains(const std::string& text, std::string_view part) {
  if (text.find(part) != std::string::npos) return testing::AssertionSuccess();
  return testing::AssertionFailure() << "'" << part << "' not in: " << text;
}

// Loads `yaml` from origin "cam.yaml" and expects a kConfig error; returns its message.
std::string config_error_of(std::string_view yaml) {
  Result<Config> r = Config::load_string(kSchema, yaml, "cam.yaml");
  EXPECT_FALSE(r.ok()) << "loaded without error:\n" << yaml;
  if (r.ok()) return {};
  EXPECT_EQ(r.error().code, ErrorCode::kConfig);
  return r.error().message;
}

TEST(Config, DefaultsHoldEveryParameterAtItsDefault) {
  const Config c = Config::defaults(kSchema);
  EXPECT_DOUBLE_EQ(c.get_real("camera.period_s"), 0.1);
  EXPECT_EQ(c.get_int("camera.queue"), 8);
  EXPECT_TRUE(c.get_bool("camera.enabled"));
  EXPECT_EQ(c.get_text("camera.mode"), "auto");
  EXPECT_EQ(c.get_text("camera.label"), "");
  EXPECT_DOUBLE_EQ(c.get_real("map.resolution_m"), 0.05);
  EXPECT_EQ(c.get_int("map.offset"), -3);
  EXPECT_TRUE(c.has("camera.queue"));
  EXPECT_FALSE(c.has("camera.nope"));
}

TEST(Config, OutlivesTheSchemaListItWasBuiltFrom) {
  // role_schema() returns a temporary list: the Config must keep its own copy of it.
  Config c = Config::defaults(role_schema(ugv_role()));
  std::vector<ParamSection> junk(64, ParamSection{"junk", {}, "overwrites the freed list's memory"});
  ASSERT_TRUE(c.set("status.log_every=4").ok());
  EXPECT_EQ(c.get_int("status.log_every"), 4);
  EXPECT_NE(c.to_yaml().find("scheduler:"), std::string::npos);
  EXPECT_EQ(c.schema().front().name, "robot");
}

TEST(Config, YamlOverridesOnlyTheKeysItNames) {
  Result<Config> r = Config::load_string(kSchema,
                                         "camera:\n"
                                         "  period_s: 0.5\n"
                                         "  mode: manual\n"
                                         "  enabled: false\n"
                                         "map:\n"
                                         "  offset: -100\n",
                                         "cam.yaml");
  ASSERT_TRUE(r.ok()) << r.error().message;
  const Config& c = r.value();
  EXPECT_DOUBLE_EQ(c.get_real("camera.period_s"), 0.5);
  EXPECT_EQ(c.get_text("camera.mode"), "manual");
  EXPECT_FALSE(c.get_bool("camera.enabled"));
  EXPECT_EQ(c.get_int("map.offset"), -100);
  EXPECT_EQ(c.get_int("camera.queue"), 8);
  EXPECT_DOUBLE_EQ(c.get_real("map.resolution_m"), 0.05);
}

TEST(Config, EmptyYamlAndEmptySectionsMeanDefaults) {
  Result<Config> empty = Config::load_string(kSchema, "", "empty.yaml");
  ASSERT_TRUE(empty.ok()) << empty.error().message;
  EXPECT_EQ(empty.value().get_int("camera.queue"), 8);
  Result<Config> comments = Config::load_string(kSchema, "# nothing set\ncamera:\nmap:\n", "c.yaml");
  ASSERT_TRUE(comments.ok()) << comments.error().message;
  EXPECT_EQ(comments.value().get_int("camera.queue"), 8);
}

TEST(Config, IntegerAcceptedForARealParameter) {
  Result<Config> r = Config::load_string(kSchema, "camera:\n  period_s: 2\n", "cam.yaml");
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_DOUBLE_EQ(r.value().get_real("camera.period_s"), 2.0);
}

TEST(Config, RangeEndsAreAllowed) {
  Result<Config> r = Config::load_string(kSchema, "camera:\n  period_s: 10\n  queue: 1\nmap:\n  resolution_m: 0.001\n",
                                         "cam.yaml");
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r.value().get_int("camera.queue"), 1);
}

TEST(Config, UnknownKeyIsAConfigErrorNamingFileLineKeyAndKnownKeys) {
  const std::string m = config_error_of("camera:\n  period_s: 1\n  perod_s: 1\n");
  EXPECT_TRUE(contains(m, "cam.yaml:3"));
  EXPECT_TRUE(contains(m, "camera.perod_s"));
  EXPECT_TRUE(contains(m, "period_s"));  // the known keys, so the typo is easy to spot
}

TEST(Config, UnknownSectionIsAConfigErrorNamingFileSectionAndKnownSections) {
  const std::string m = config_error_of("map:\n  offset: 1\ncamrea:\n  period_s: 1\n");
  EXPECT_TRUE(contains(m, "cam.yaml:3"));
  EXPECT_TRUE(contains(m, "camrea"));
  EXPECT_TRUE(contains(m, "camera"));
  EXPECT_TRUE(contains(m, "map"));
}

TEST(Config, WrongTypeIsAConfigErrorNamingFileKeyTypeAndRange) {
  {
    const std::string m = config_error_of("camera:\n  period_s: fast\n");
    EXPECT_TRUE(contains(m, "cam.yaml:2"));
    EXPECT_TRUE(contains(m, "camera.period_s"));
    EXPECT_TRUE(contains(m, "number"));
    EXPECT_TRUE(contains(m, "[0.01, 10] s"));
    EXPECT_TRUE(contains(m, "fast"));
  }
  {
    const std::string m = config_error_of("camera:\n  queue: 2.5\n");
    EXPECT_TRUE(contains(m, "camera.queue"));
    EXPECT_TRUE(contains(m, "integer"));
    EXPECT_TRUE(contains(m, "[1, 64] count"));
  }
  {
    const std::string m = config_error_of("camera:\n  enabled: 3\n");
    EXPECT_TRUE(contains(m, "camera.enabled"));
    EXPECT_TRUE(contains(m, "true|false"));
  }
  {
    const std::string m = config_error_of("camera:\n  queue: [1, 2]\n");
    EXPECT_TRUE(contains(m, "cam.yaml:2"));
    EXPECT_TRUE(contains(m, "camera.queue"));
    EXPECT_TRUE(contains(m, "single value"));
  }
}

TEST(Config, OutOfRangeIsAConfigErrorNamingFileKeyValueAndRange) {
  {
    const std::string m = config_error_of("camera:\n  period_s: 20\n");
    EXPECT_TRUE(contains(m, "cam.yaml:2"));
    EXPECT_TRUE(contains(m, "camera.period_s"));
    EXPECT_TRUE(contains(m, "20"));
    EXPECT_TRUE(contains(m, "out of range"));
    EXPECT_TRUE(contains(m, "[0.01, 10] s"));
  }
  {
    const std::string m = config_error_of("map:\n  offset: -101\n");
    EXPECT_TRUE(contains(m, "map.offset"));
    EXPECT_TRUE(contains(m, "[-100, 100]"));
  }
  {
    const std::string m = config_error_of("camera:\n  mode: turbo\n");
    EXPECT_TRUE(contains(m, "camera.mode"));
    EXPECT_TRUE(contains(m, "turbo"));
    EXPECT_TRUE(contains(m, "auto|manual"));
  }
}

TEST(Config, MalformedYamlIsAConfigErrorNamingFileAndLine) {
  const std::string m = config_error_of("camera:\n  period_s: 0.5\n  queue: [1, 2\n");
  EXPECT_TRUE(contains(m, "cam.yaml:"));
  EXPECT_TRUE(contains(m, "malformed YAML"));
}

TEST(Config, TopLevelThatIsNotAMappingIsAConfigError) {
  const std::string m = config_error_of("- camera\n- map\n");
  EXPECT_TRUE(contains(m, "cam.yaml"));
  EXPECT_TRUE(contains(m, "mapping"));
}

TEST(Config, FileErrorsNameThePath) {
  const std::string path = testing::TempDir() + "ag_test_config_bad.yaml";
  {
    std::ofstream f(path);
    f << "camera:\n  queue: 65\n";
  }
  Result<Config> r = Config::load_file(kSchema, path);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::kConfig);
  EXPECT_TRUE(contains(r.error().message, path + ":2"));
  EXPECT_TRUE(contains(r.error().message, "[1, 64] count"));
  std::remove(path.c_str());

  Result<Config> missing = Config::load_file(kSchema, testing::TempDir() + "ag_no_such_config.yaml");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, ErrorCode::kConfig);
  EXPECT_TRUE(contains(missing.error().message, "ag_no_such_config.yaml"));
}

TEST(Config, SetAssignsAValidatedValue) {
  Config c = Config::defaults(kSchema);
  ASSERT_TRUE(c.set("camera.period_s=0.25").ok());
  EXPECT_DOUBLE_EQ(c.get_real("camera.period_s"), 0.25);
  ASSERT_TRUE(c.set("camera.enabled=false").ok());
  EXPECT_FALSE(c.get_bool("camera.enabled"));
  ASSERT_TRUE(c.set("camera.label=a=b").ok());  // only the first '=' separates
  EXPECT_EQ(c.get_text("camera.label"), "a=b");
}

TEST(Config, SetRejectsBadAssignmentsWithTheSameMessagesAsTheFile) {
  Config c = Config::defaults(kSchema);
  {
    Status st = c.set("camera.period_s=99");
    ASSERT_FALSE(st.ok());
    EXPECT_EQ(st.error().code, ErrorCode::kConfig);
    EXPECT_TRUE(contains(st.error().message, "--set"));
    EXPECT_TRUE(contains(st.error().message, "camera.period_s"));
    EXPECT_TRUE(contains(st.error().message, "[0.01, 10] s"));
  }
  {
    Status st = c.set("camera.queue=many", "--set (argument 3)");
    ASSERT_FALSE(st.ok());
    EXPECT_EQ(st.error().code, ErrorCode::kConfig);
    EXPECT_TRUE(contains(st.error().message, "argument 3"));
  }
  for (const char* bad : {"camera.nope=1", "nosection.key=1", "no_equals_sign", "=1", "camera.mode=turbo"}) {
    Status st = c.set(bad);
    EXPECT_FALSE(st.ok()) << bad;
    if (!st.ok()) {
      EXPECT_EQ(st.error().code, ErrorCode::kConfig) << bad;
    }
  }
  EXPECT_DOUBLE_EQ(c.get_real("camera.period_s"), 0.1);  // a refused set changes nothing
  EXPECT_EQ(c.get_int("camera.queue"), 8);
}

TEST(Config, GettersThrowForKeysOutsideTheSchemaOrOfAnotherType) {
  const Config c = Config::defaults(kSchema);
  EXPECT_THROW((void)c.get_real("camera.nope"), std::logic_error);
  EXPECT_THROW((void)c.get_int("camera.period_s"), std::logic_error);
  EXPECT_THROW((void)c.get_text("camera.enabled"), std::logic_error);
  EXPECT_THROW((void)c.get_bool("camera.queue"), std::logic_error);
}

void expect_same_values(const Config& a, const Config& b) {
  for (const auto& sec : a.schema()) {
    for (const auto& p : sec.params) {
      const std::string k = std::string(sec.name) + "." + std::string(p.key);
      switch (p.type) {
        case ParamType::kBool: EXPECT_EQ(a.get_bool(k), b.get_bool(k)) << k; break;
        case ParamType::kInt: EXPECT_EQ(a.get_int(k), b.get_int(k)) << k; break;
        case ParamType::kReal: EXPECT_EQ(a.get_real(k), b.get_real(k)) << k; break;  // bit-exact on purpose
        case ParamType::kText: EXPECT_EQ(a.get_text(k), b.get_text(k)) << k; break;
      }
    }
  }
}

TEST(Config, ToYamlOfDefaultsLoadsBackToTheSameValues) {
  const Config c = Config::defaults(kSchema);
  const std::string yaml = c.to_yaml();
  Result<Config> back = Config::load_string(kSchema, yaml, "to_yaml");
  ASSERT_TRUE(back.ok()) << back.error().message << "\n" << yaml;
  expect_same_values(c, back.value());
}

TEST(Config, ToYamlOfChangedValuesLoadsBackToIdenticalValues) {
  Config c = Config::defaults(kSchema);
  ASSERT_TRUE(c.set("camera.period_s=0.123456789012345678").ok());  // needs all 17 digits to survive
  ASSERT_TRUE(c.set("map.resolution_m=0.0012345678901").ok());
  ASSERT_TRUE(c.set("camera.queue=64").ok());
  ASSERT_TRUE(c.set("camera.enabled=off").ok());
  ASSERT_TRUE(c.set("camera.mode=manual").ok());
  ASSERT_TRUE(c.set("map.offset=-7").ok());
  ASSERT_TRUE(c.set(R"(camera.label=say "hi" \ # not a comment: really)").ok());
  const std::string yaml = c.to_yaml();
  Result<Config> back = Config::load_string(kSchema, yaml, "to_yaml");
  ASSERT_TRUE(back.ok()) << back.error().message << "\n" << yaml;
  expect_same_values(c, back.value());
  EXPECT_EQ(back.value().get_text("camera.label"), R"(say "hi" \ # not a comment: really)");
}

TEST(Config, ToYamlEscapesControlCharactersInText) {
  Config c = Config::defaults(kSchema);
  ASSERT_TRUE(c.set("camera.label=tab\there\nnext line").ok());
  const std::string yaml = c.to_yaml();
  Result<Config> back = Config::load_string(kSchema, yaml, "to_yaml");
  ASSERT_TRUE(back.ok()) << back.error().message << "\n" << yaml;
  EXPECT_EQ(back.value().get_text("camera.label"), "tab\there\nnext line");
}

TEST(Config, ToYamlCommentsCarryRangeUnitAndHelp) {
  const std::string yaml = Config::defaults(kSchema).to_yaml();
  EXPECT_TRUE(contains(yaml, "camera:"));
  EXPECT_TRUE(contains(yaml, "[0.01, 10] s"));
  EXPECT_TRUE(contains(yaml, "time between frames"));
  EXPECT_TRUE(contains(yaml, "auto|manual"));
  EXPECT_TRUE(contains(yaml, "# the camera"));
}

// Every role's schema (common sections + its stages) round-trips, and its shipped YAML file loads.
class RoleConfig : public testing::TestWithParam<const char*> {
 protected:
  static const RoleDescription& role(std::string_view name) {
    if (name == "uav") return uav_role();
    if (name == "ugv") return ugv_role();
    return base_role();
  }
};

TEST_P(RoleConfig, DefaultsRoundTripThroughToYaml) {
  const std::vector<ParamSection> schema = role_schema(role(GetParam()));
  const Config c = Config::defaults(schema);
  Result<Config> back = Config::load_string(schema, c.to_yaml(), "to_yaml");
  ASSERT_TRUE(back.ok()) << back.error().message;
  expect_same_values(c, back.value());
}

TEST_P(RoleConfig, ShippedConfigFileLoads) {
  const char* src = std::getenv("AG_SOURCE_DIR");
  if (src == nullptr) GTEST_SKIP() << "AG_SOURCE_DIR not set (run through ctest)";
  const std::string name = GetParam();
  const std::vector<ParamSection> schema = role_schema(role(name));
  Result<Config> r = Config::load_file(schema, std::string(src) + "/firmware_host/" + name + "/" + name + ".yaml");
  ASSERT_TRUE(r.ok()) << r.error().message;
}

INSTANTIATE_TEST_SUITE_P(Roles, RoleConfig, testing::Values("uav", "ugv", "base"),
                         [](const testing::TestParamInfo<const char*>& i) { return std::string(i.param); });

}  // namespace
}  // namespace ag
