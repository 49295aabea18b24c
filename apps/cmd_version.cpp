#include <png.h>
#include <xxhash.h>

#include <iostream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <tbb/version.h>

#include "apps/build_info.h"
#include "apps/commands.h"
#include "core/raw_volume.h"

namespace brickyard::cli {

void add_version_command(CLI::App& app) {
  auto* cmd = app.add_subcommand("version", "Print the version, build configuration and library versions");
  cmd->callback([] {
    std::cout << fmt::format("brickyard {} ({}, -march={}, {} {})\n", kVersion, kBuildType, kArch, kCompilerId,
                             kCompilerVersion);
    std::cout << fmt::format("raw sidecar format {}\n", kRawSidecarVersion);
    std::cout << fmt::format("libraries: oneTBB {}.{}, fmt {}.{}.{}, libpng {}, xxHash {}.{}.{}, CLI11 {}, nlohmann-json {}.{}.{}\n",
                             TBB_VERSION_MAJOR, TBB_VERSION_MINOR, FMT_VERSION / 10000, FMT_VERSION / 100 % 100,
                             FMT_VERSION % 100, PNG_LIBPNG_VER_STRING, XXH_VERSION_MAJOR, XXH_VERSION_MINOR,
                             XXH_VERSION_RELEASE, CLI11_VERSION, NLOHMANN_JSON_VERSION_MAJOR,
                             NLOHMANN_JSON_VERSION_MINOR, NLOHMANN_JSON_VERSION_PATCH);
  });
}

}  // namespace brickyard::cli
