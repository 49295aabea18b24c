#include <gtest/gtest.h>

#include <string>
#include <utility>

#include "core/error.h"
#include "core/units.h"
#include "core/value_type.h"

namespace brickyard {
namespace {

TEST(Error, WhatNamesFileKeyAndField) {
  Error e(Errc::format, "expected 3 numbers");
  EXPECT_STREQ(e.what(), "expected 3 numbers");
  e.with_file("/data/vol.json").with_field("dims");
  EXPECT_STREQ(e.what(), "/data/vol.json: field 'dims': expected 3 numbers");
  e.with_key("L2 (1, 2, 3)");
  EXPECT_STREQ(e.what(), "/data/vol.json: key L2 (1, 2, 3): field 'dims': expected 3 numbers");
  EXPECT_EQ(e.code(), Errc::format);
  EXPECT_EQ(e.message(), "expected 3 numbers");
}

TEST(Error, ExitCodesSeparateUsageFromFailure) {
  EXPECT_EQ(exit_code(Errc::invalid_argument), 2);
  EXPECT_EQ(exit_code(Errc::io), 1);
  EXPECT_EQ(exit_code(Errc::corrupt), 1);
  EXPECT_EQ(exit_code(Errc::resource), kExitOutOfResources);
  EXPECT_NE(kExitOutOfResources, 1);
  EXPECT_NE(kExitOutOfResources, 2);
}

TEST(Error, CheckMacrosReportBothOperands) {
  try {
    const int a = 3, b = 4;
    BY_CHECK_EQ(a, b);
    FAIL() << "BY_CHECK_EQ did not throw";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::internal);
    EXPECT_NE(std::string(e.what()).find("a == b with 3 vs 4"), std::string::npos) << e.what();
  }
  EXPECT_NO_THROW(BY_CHECK_LT(1, 2));
}

TEST(ValueType, NamesSizesAndParsing) {
  EXPECT_EQ(size_of(ValueType::u8), 1u);
  EXPECT_EQ(size_of(ValueType::u16), 2u);
  EXPECT_EQ(size_of(ValueType::f32), 4u);
  EXPECT_EQ(size_of(ValueType::i8), 1u);
  EXPECT_EQ(size_of(ValueType::i16), 2u);
  for (auto t : {ValueType::u8, ValueType::i8, ValueType::u16, ValueType::i16, ValueType::f32}) {
    EXPECT_EQ(parse_value_type(to_string(t)), t);
    EXPECT_TRUE(is_value_type_code(uint8_t(t)));
    EXPECT_EQ(stored_type(element_type(t)), t);
    EXPECT_TRUE(is_native(element_type(t)));
    if (is_integer(t)) {
      EXPECT_EQ(integer_count(t), size_t(1) << (8 * size_of(t)));
    }
  }
  EXPECT_FALSE(is_value_type_code(0));
  EXPECT_FALSE(is_value_type_code(6));
  EXPECT_EQ(integer_min(ValueType::i16), -32768.0);
  EXPECT_EQ(integer_max(ValueType::i8), 127.0);
  EXPECT_EQ(parse_value_type("float"), ValueType::f32);
  EXPECT_EQ(parse_value_type("int16"), ValueType::i16);
  EXPECT_FALSE(parse_value_type("f64").has_value());
  // Files may hold 32-bit integers and doubles: they are element types, stored as f32.
  for (const char* name : {"u32", "i32", "f64", "double"}) {
    const auto e = parse_element_type(name);
    ASSERT_TRUE(e.has_value()) << name;
    EXPECT_FALSE(is_native(*e));
    EXPECT_EQ(stored_type(*e), ValueType::f32);
  }
  EXPECT_EQ(size_of(ElementType::f64), 8u);
  try {
    value_type_from_string("i32", "--type");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.field(), "--type");
    EXPECT_NE(std::string(e.what()).find("u8, i8, u16, i16 or f32"), std::string::npos);
  }
  try {
    element_type_from_string("u64", "--type");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("or u32, i32, f64 to convert to f32"), std::string::npos);
  }
  EXPECT_EQ(dispatch_value_type(ValueType::u16, [](auto tag) { return sizeof(tag); }), 2u);
  EXPECT_EQ(dispatch_value_type(ValueType::i16, [](auto tag) { return std::is_signed_v<decltype(tag)>; }), true);
}

TEST(Units, HumanReadableNumbers) {
  EXPECT_EQ(format_count(999), "999");
  EXPECT_EQ(format_count(1234567), "1.23M");
  EXPECT_EQ(format_count(16777216), "16.8M");
  EXPECT_EQ(format_bytes(512), "512 B");
  EXPECT_EQ(format_bytes(1536), "1.5 KiB");
  EXPECT_EQ(format_bytes(64.0 * 1024 * 1024), "64 MiB");
  EXPECT_EQ(format_duration(0.0123), "12.3 ms");
  EXPECT_EQ(format_duration(4.5), "4.50 s");
  EXPECT_EQ(format_duration(187), "3:07");
  EXPECT_EQ(format_duration(3723), "1:02:03");
}

TEST(Units, TwoByteCountsInOneMessageNeverReadAlike) {
  // One byte short of a 32^3 f32 brick with its apron rounds to the brick's own "154 KiB".
  using Pair = std::pair<std::string, std::string>;
  EXPECT_EQ(format_bytes_apart(157215, 157216), (Pair{"157215 bytes", "157216 bytes"}));
  EXPECT_EQ(format_bytes_apart(1024, 157216), (Pair{"1 KiB", "154 KiB"}));
  EXPECT_EQ(format_bytes_apart(0, 157216), (Pair{"0 B", "154 KiB"}));
  EXPECT_EQ(format_bytes_apart(2048, 2048), (Pair{"2 KiB", "2 KiB"}));
}

TEST(Units, ZeroBytesIsASizeOnlyWhereTheCallerAllowsIt) {
  EXPECT_EQ(parse_bytes("0", "cache.l2", /*allow_zero=*/true), 0u);
  EXPECT_EQ(parse_bytes("0MiB", "cache.l2", /*allow_zero=*/true), 0u);
  EXPECT_EQ(parse_bytes("512KiB", "cache.l2", /*allow_zero=*/true), uint64_t(512) << 10);
  EXPECT_THROW(parse_bytes("0", "--sizes"), Error);
  EXPECT_THROW(parse_bytes("-1", "cache.l2", /*allow_zero=*/true), Error);
}

}  // namespace
}  // namespace brickyard
