#include <gtest/gtest.h>

#include <string>

#include "core/error.h"
#include "storage/manifest.h"

namespace brickyard {
namespace {

Manifest grid_manifest() {
  Manifest m;
  m.complete = true;
  m.dims = {40, 30, 20};
  m.format.type = ValueType::u16;
  m.format.brick_size = 16;
  m.levels = m.layout().levels;
  m.min_value = 1, m.max_value = 900;
  m.histogram.lo = 1, m.histogram.hi = 900;
  m.histogram.counts.assign(256, 3);
  m.stats.resize(size_t(m.levels));
  return m;
}

/// The manifest's JSON with the first `from` replaced by `to`.
std::string edited(const std::string& from, const std::string& to) {
  std::string text = grid_manifest().to_json();
  const size_t at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  return text.replace(at, from.size(), to);
}

void expect_field_error(const std::string& text, const std::string& field, const std::string& message) {
  try {
    Manifest::from_json(text, "s.store");
    FAIL() << "accepted " << field;
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::format) << e.what();
    EXPECT_EQ(e.file(), "s.store");
    EXPECT_EQ(e.field(), field) << e.what();
    EXPECT_NE(e.message().find(message), std::string::npos) << e.what();
  }
}

TEST(Manifest, RoundTripsThroughJson) {
  const std::string text = grid_manifest().to_json();
  EXPECT_EQ(Manifest::from_json(text, "s.store").to_json(), text);
}

// Found by fuzzing (tests/fuzz/regressions/manifest/): numbers that do not fit their key's type
// were converted with undefined behaviour (1e30 into an int), wrapped, or read as infinity.
TEST(Manifest, NumbersThatDoNotFitTheirKeyAreFormatErrorsNamingIt) {
  expect_field_error(edited("\"brick_size\": 16", "\"brick_size\": 1e30"), "brick_size",
                     "expected an integer in [-2147483648, 2147483647], found 1e+30");
  expect_field_error(edited("\"brick_size\": 16", "\"brick_size\": 16.5"), "brick_size", "found 16.5");
  expect_field_error(edited("\"dims\": [\n    40", "\"dims\": [\n    8.4e36"), "dims", "expected an array, each element an integer");
  expect_field_error(edited("\"raw_bytes\": 0", "\"raw_bytes\": -5e20"), "raw_bytes", "found -5e+20");
  expect_field_error(edited("\"raw_bytes\": 0", "\"raw_bytes\": -1"), "raw_bytes", "found -1");
  expect_field_error(edited("\"levels\": 3", "\"levels\": 18446744073709551615"), "levels", "found 18446744073709551615");
  expect_field_error(edited("\"complete\": true", "\"complete\": 1"), "complete", "expected true or false, found 1");
  expect_field_error(edited("\"level_stats\": [", "\"level_stats\": 7, \"x\": ["), "level_stats", "expected an array, found 7");
  // Integral numbers written as floats still read.
  EXPECT_EQ(Manifest::from_json(edited("\"brick_size\": 16", "\"brick_size\": 16.0"), "s.store").format.brick_size, 16);
}

// Found by fuzzing: a number beyond the double range is nlohmann's out_of_range (406), not a
// parse_error, and escaped every JSON reader.
TEST(Manifest, ANumberBeyondTheDoubleRangeIsNotValidJson) {
  try {
    Manifest::from_json(edited("\"background\": 0.0", "\"background\": 1e400"), "s.store");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::format);
    EXPECT_EQ(e.file(), "s.store");
    EXPECT_NE(e.message().find("not valid JSON"), std::string::npos) << e.what();
    EXPECT_NE(e.message().find("number overflow parsing '1e400'"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace brickyard
