// The resource check before long work: the decision from given numbers (no dependence on this
// machine), the parsers of what Linux reports, and the environment's caps.

#include <gtest/gtest.h>

#include <cstdlib>
#include <limits>
#include <string>

#include "core/error.h"
#include "core/resources.h"

namespace brickyard {
namespace {

constexpr uint64_t GiB = uint64_t(1) << 30;

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

ResourceNeeds import_needs(uint64_t memory, uint64_t disk) {
  ResourceNeeds n;
  n.task = "import of 8192x8192x8192 u8";
  n.memory = {memory, "slices and a row of bricks", "a smaller --brick-size lowers it"};
  n.disk = {disk, "every brick at LZ4's worst case", "--no-disk-check starts anyway"};
  n.disk_path = "/data/s";
  return n;
}

TEST(Resources, ShortDiskNamesTheNeedWhatIsFreeTheDirectoryAndTheOption) {
  const auto e = resource_shortfall(import_needs(GiB, 800 * GiB), {64 * GiB, 70 * GiB});
  ASSERT_TRUE(e.has_value());
  EXPECT_EQ(e->code(), Errc::resource);
  EXPECT_EQ(e->file(), "/data/s");
  EXPECT_STREQ(e->what(), "/data/s: import of 8192x8192x8192 u8 needs up to 800 GiB of disk (every brick at LZ4's worst "
                          "case), but 70 GiB is free there; --no-disk-check starts anyway");
}

TEST(Resources, ShortMemoryNamesTheNeedWhatIsAvailableAndTheOption) {
  const auto e = resource_shortfall(import_needs(12 * GiB, GiB), {8 * GiB, 70 * GiB});
  ASSERT_TRUE(e.has_value());
  EXPECT_EQ(e->code(), Errc::resource);
  EXPECT_TRUE(e->file().empty());  // the disk was not short: no directory to name
  EXPECT_STREQ(e->what(), "import of 8192x8192x8192 u8 needs about 12 GiB of memory (slices and a row of bricks), but "
                          "8 GiB is available; a smaller --brick-size lowers it");
}

TEST(Resources, BothShortAreNamedInOneMessage) {
  const auto e = resource_shortfall(import_needs(12 * GiB, 800 * GiB), {8 * GiB, 70 * GiB});
  ASSERT_TRUE(e.has_value());
  for (const char* part : {"up to 800 GiB of disk", "and about 12 GiB of memory", "--no-disk-check", "--brick-size"})
    EXPECT_TRUE(contains(e->what(), part)) << part << " missing from " << e->what();
}

TEST(Resources, WhatFitsOrCannotBeMeasuredIsNotRefused) {
  EXPECT_FALSE(resource_shortfall(import_needs(8 * GiB, 70 * GiB), {8 * GiB, 70 * GiB}).has_value());  // exactly fits
  EXPECT_FALSE(resource_shortfall(import_needs(100 * GiB, 900 * GiB), {std::nullopt, std::nullopt}).has_value());
  EXPECT_FALSE(resource_shortfall(import_needs(0, 0), {0, 0}).has_value());  // nothing asked
  // Counts that would print alike are printed exactly.
  const auto e = resource_shortfall(import_needs(GiB + 1, 0), {GiB, std::nullopt});
  ASSERT_TRUE(e.has_value());
  EXPECT_TRUE(contains(e->what(), "1073741825 bytes of memory")) << e->what();
}

TEST(Resources, ParsesMeminfoAndCgroupFiles) {
  EXPECT_EQ(meminfo_available("MemTotal:       16000 kB\nMemFree:  1 kB\nMemAvailable:    2048 kB\nBuffers: 3 kB\n"),
            uint64_t(2048) * 1024);
  EXPECT_FALSE(meminfo_available("MemTotal: 16000 kB\n").has_value());
  EXPECT_FALSE(cgroup_headroom("max\n", "1000\n").has_value());  // no limit
  EXPECT_EQ(cgroup_headroom("1000\n", "300\n"), uint64_t(700));
  EXPECT_EQ(cgroup_headroom("1000", "1200"), uint64_t(0));
  EXPECT_EQ(cgroup_headroom("1000\n", "900\n", 500), uint64_t(600));  // inactive page cache counts as free
  EXPECT_FALSE(cgroup_headroom("", "").has_value());                   // no such file
}

TEST(Resources, EstimatesBeyondSixtyFourBitsSaturate) {
  EXPECT_EQ(saturating_bytes(1e30), std::numeric_limits<uint64_t>::max());
  EXPECT_EQ(saturating_bytes(0.5), uint64_t(1));
  EXPECT_EQ(saturating_bytes(-3), uint64_t(0));
  EXPECT_EQ(saturating_bytes(4096), uint64_t(4096));
}

TEST(Resources, TheEnvironmentLowersWhatIsAvailableButNeverRaisesIt) {
  ::setenv("BRICKYARD_AVAILABLE_MEMORY", "1MiB", 1);
  ::setenv("BRICKYARD_AVAILABLE_DISK", "1KiB", 1);
  EXPECT_EQ(available_memory(), uint64_t(1) << 20);  // this process has more than 1 MiB
  const auto disk = free_disk("/tmp/brickyard-no-such-dir/store");  // measured at the nearest existing parent
  EXPECT_EQ(disk, uint64_t(1024));
  ResourceNeeds n = import_needs(2 << 20, 0);
  try {
    check_resources(n);
    FAIL() << "2 MiB fitted in 1 MiB";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::resource);
    EXPECT_TRUE(contains(e.what(), "but 1 MiB is available")) << e.what();
  }
  ::setenv("BRICKYARD_AVAILABLE_MEMORY", "1000TiB", 1);  // more than any machine: the measurement stands
  EXPECT_LT(available_memory().value_or(0), uint64_t(1000) << 40);
  ::setenv("BRICKYARD_AVAILABLE_MEMORY", "plenty", 1);
  EXPECT_THROW(available_memory(), Error);
  ::unsetenv("BRICKYARD_AVAILABLE_MEMORY");
  ::unsetenv("BRICKYARD_AVAILABLE_DISK");
  EXPECT_GT(available_memory().value_or(1), uint64_t(0));
  EXPECT_GT(free_disk("/tmp").value_or(1), uint64_t(0));
}

}  // namespace
}  // namespace brickyard
