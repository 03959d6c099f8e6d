// ParamField tables: the spec rows take their defaults from the struct, and load_params() fills every
// bound member from YAML and from the defaults.
#include "airground/platform/param_binding.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <string>

namespace ag {

namespace {

enum class Gait : std::uint8_t { kWalk = 3, kTrot = 5, kGallop = 9 };

struct RigParams {
  double period_s{0.25};
  float gain{2.5F};
  int queue{8};
  std::int64_t offset{-3};
  std::uint32_t cells{64};
  bool enabled{true};
  std::string label{"front"};
  Gait gait{Gait::kTrot};
  double not_a_parameter{7.0};
};

constexpr ParamField<RigParams> kRigFields[] = {
    field::real("period_s", &RigParams::period_s, 0.01, 10.0, "s", "time between frames"),
    field::real("gain", &RigParams::gain, 0.0, 10.0, "", "a float member"),
    field::integer("queue", &RigParams::queue, 1, 64, "count", "frames buffered"),
    field::integer("offset", &RigParams::offset, -100, 100, "", "signed"),
    field::integer("cells", &RigParams::cells, 1, 1024, "cells", "unsigned"),
    field::boolean("enabled", &RigParams::enabled, "capture at all"),
    field::text("label", &RigParams::label, "front", "", "free text"),
    field::choice<&RigParams::gait>("gait", "walk|trot|gallop", {Gait::kWalk, Gait::kTrot, Gait::kGallop}, "how it moves"),
};
constexpr auto kRigSpecs = param_specs(kRigFields);
constexpr ParamSection kSchema[] = {{"rig", kRigSpecs, "a rig"}};

// The defaults are the struct's initializers, at compile time.
static_assert(kRigSpecs[0].default_num == 0.25);
static_assert(kRigSpecs[2].default_num == 8.0);
static_assert(kRigSpecs[3].default_num == -3.0);
static_assert(kRigSpecs[5].default_num == 1.0);
static_assert(kRigSpecs[7].default_text == "trot");
static_assert(kRigSpecs[7].type == ParamType::kText);

TEST(ParamBinding, SpecRowsCarryTheStructDefaultsAndTheDeclaredRanges) {
  ASSERT_EQ(kRigSpecs.size(), 8U);
  EXPECT_EQ(kRigSpecs[0].key, "period_s");
  EXPECT_EQ(kRigSpecs[0].type, ParamType::kReal);
  EXPECT_EQ(kRigSpecs[0].min, 0.01);
  EXPECT_EQ(kRigSpecs[0].max, 10.0);
  EXPECT_EQ(kRigSpecs[0].unit, "s");
  EXPECT_EQ(kRigSpecs[0].help, "time between frames");
  EXPECT_EQ(kRigSpecs[1].default_num, 2.5);
  EXPECT_EQ(kRigSpecs[4].type, ParamType::kInt);
  EXPECT_EQ(kRigSpecs[4].default_num, 64.0);
  EXPECT_EQ(kRigSpecs[6].default_text, "front");
  EXPECT_EQ(kRigSpecs[7].choices, "walk|trot|gallop");
}

TEST(ParamBinding, LoaderFillsEveryBoundMemberFromDefaults) {
  const Config c = Config::defaults(kSchema);
  RigParams p{};
  p.period_s = -1;  // overwritten: every bound member comes from the config
  p.gait = Gait::kGallop;
  p.label = "x";
  load_params(SectionView(c, "rig"), std::span<const ParamField<RigParams>>(kRigFields), p);
  const RigParams d{};
  EXPECT_EQ(p.period_s, d.period_s);
  EXPECT_EQ(p.gain, d.gain);
  EXPECT_EQ(p.queue, d.queue);
  EXPECT_EQ(p.offset, d.offset);
  EXPECT_EQ(p.cells, d.cells);
  EXPECT_EQ(p.enabled, d.enabled);
  EXPECT_EQ(p.label, d.label);
  EXPECT_EQ(p.gait, d.gait);
}

TEST(ParamBinding, LoaderFillsEveryBoundMemberFromYaml) {
  auto c = Config::load_string(kSchema,
                               "rig:\n  period_s: 0.5\n  gain: 4.5\n  queue: 16\n  offset: -42\n  cells: 1000\n"
                               "  enabled: false\n  label: rear left\n  gait: gallop\n",
                               "test.yaml");
  ASSERT_TRUE(c.ok()) << c.error().message;
  RigParams p = load_params(SectionView(c.value(), "rig"), kRigFields);
  EXPECT_EQ(p.period_s, 0.5);
  EXPECT_EQ(p.gain, 4.5F);
  EXPECT_EQ(p.queue, 16);
  EXPECT_EQ(p.offset, -42);
  EXPECT_EQ(p.cells, 1000U);
  EXPECT_FALSE(p.enabled);
  EXPECT_EQ(p.label, "rear left");
  EXPECT_EQ(p.gait, Gait::kGallop);
  EXPECT_EQ(p.not_a_parameter, 7.0);  // unbound members keep their initializer
}

TEST(ParamBinding, ConfigRefusesAValueOutsideTheBoundRowsRange) {
  auto c = Config::load_string(kSchema, "rig:\n  queue: 65\n", "test.yaml");
  ASSERT_FALSE(c.ok());
  EXPECT_NE(c.error().message.find("rig.queue"), std::string::npos) << c.error().message;
}

// A default outside [min, max] fails to compile (param_check::default_must_lie_within_min_max); the
// same rule at run time:
TEST(ParamBinding, RangeCheckRefusesADefaultOutsideItsRange) {
  EXPECT_TRUE(param_field_ok(ParamSpec::real("a", 1.0, 0.0, 2.0, "", "")));
  EXPECT_FALSE(param_field_ok(ParamSpec::real("a", 3.0, 0.0, 2.0, "", "")));
  EXPECT_FALSE(param_field_ok(ParamSpec::integer("a", 0, 1, 5, "", "")));
  EXPECT_FALSE(param_field_ok(ParamSpec::real("a", 1.0, 2.0, 0.0, "", "")));
  EXPECT_TRUE(param_field_ok(ParamSpec::text("a", "x", "", "")));
}

TEST(ParamBinding, ParamSpecsConcatenatesTablesAndPlainRowsInOrder) {
  constexpr ParamSpec kExtra[] = {ParamSpec::boolean("extra", false, "a plain row")};
  constexpr auto all = param_specs(kExtra, kRigFields);
  static_assert(all.size() == 9);
  EXPECT_EQ(all[0].key, "extra");
  EXPECT_EQ(all[1].key, "period_s");
  EXPECT_EQ(all[8].key, "gait");
}

TEST(ParamBinding, NthChoiceSplitsOnBars) {
  EXPECT_EQ(nth_choice("a|bb|c", 0), "a");
  EXPECT_EQ(nth_choice("a|bb|c", 1), "bb");
  EXPECT_EQ(nth_choice("a|bb|c", 2), "c");
  EXPECT_EQ(nth_choice("a|bb|c", 3), "");
  EXPECT_EQ(count_choices("a|bb|c"), 3U);
  EXPECT_EQ(count_choices(""), 0U);
}

}  // namespace

}  // namespace ag
