#include <gtest/gtest.h>

#include "core/error.h"
#include "renderers/common/params.h"

namespace brickyard {
namespace {

struct Knobs {
  double step{};
  float gain{};
  int refine{};
  uint32_t slots{};
  bool shadows{};
};

const ParamTable<Knobs>& knobs() {
  static const ParamTable<Knobs> table{
      {"step", &Knobs::step, 0.5, 1e-3, 16, "sampling step"},
      {"gain", &Knobs::gain, 0.25, 0, 4, "amplitude ratio"},
      {"refine", &Knobs::refine, 6, 0, 40, "bisections"},
      {"slots", &Knobs::slots, 0, 0, 1 << 20, "pool slots"},
      {"shadows", &Knobs::shadows, 1, 0, 1, "1: shadow rays"},
  };
  return table;
}

TEST(ParamTable, EachParameterIsDeclaredOnceAndBindsItsField) {
  BackendInfo info;
  info.name = "knobs";
  info.params = knobs().declarations();
  ASSERT_EQ(info.params.size(), 5u);
  EXPECT_EQ(info.params[0].name, "step");
  EXPECT_EQ(info.params[0].default_value, 0.5);
  EXPECT_EQ(info.params[0].doc, "sampling step");
  EXPECT_FALSE(info.params[0].integer);
  EXPECT_FALSE(info.params[1].integer);
  EXPECT_TRUE(info.params[2].integer);
  EXPECT_TRUE(info.params[4].integer);
  const Knobs defaults = knobs().bind(BackendParams(info, {}));
  EXPECT_EQ(defaults.step, 0.5);
  EXPECT_EQ(defaults.gain, 0.25f);
  EXPECT_EQ(defaults.refine, 6);
  EXPECT_EQ(defaults.slots, 0u);
  EXPECT_TRUE(defaults.shadows);
  const Knobs set = knobs().bind(BackendParams(info, {{"step", 2}, {"refine", 11}, {"slots", 4096}, {"shadows", 0}}));
  EXPECT_EQ(set.step, 2.0);
  EXPECT_EQ(set.refine, 11);
  EXPECT_EQ(set.slots, 4096u);
  EXPECT_FALSE(set.shadows);
}

TEST(ParamTable, CountsAndSwitchesRefuseFractionsByName) {
  BackendInfo info;
  info.name = "knobs";
  info.params = knobs().declarations();
  for (const auto& [name, value] : {std::pair<std::string, double>{"refine", 2.5}, {"shadows", 0.5}}) {
    try {
      BackendParams(info, {{name, value}}, "scene.json");
      FAIL() << name;
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), Errc::invalid_argument);
      EXPECT_EQ(e.file(), "scene.json");
      EXPECT_EQ(e.field(), "backend.params." + name);
      EXPECT_NE(e.message().find("is not a whole number"), std::string::npos) << e.what();
    }
  }
  EXPECT_NO_THROW(BackendParams(info, {{"gain", 0.3}}));
}

TEST(ParamTable, EveryBuiltInBackEndDeclaresItsCountsAndSwitchesAsSuch) {
  for (const BackendEntry& e : builtin_backends().entries())
    for (const BackendParam& p : e.info.params)
      if (p.lo == 0 && p.hi == 1 && p.name != "step") {
        EXPECT_TRUE(p.integer) << e.info.name << "." << p.name;
      }
}

}  // namespace
}  // namespace brickyard
