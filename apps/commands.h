#pragma once
// Subcommands of the `brickyard` command line. Each add_* registers its options and a
// callback on the app; callbacks throw brickyard::Error and main() turns that into an exit code.

#include <CLI/CLI.hpp>

namespace brickyard {
struct Manifest;
struct OctreeBuildOptions;
}

namespace brickyard::cli {

struct GlobalOptions {
  bool quiet = false;
  int threads = 0;  ///< 0: all cores
};

void add_generate_command(CLI::App& app, const GlobalOptions& global);
void add_version_command(CLI::App& app);
/// @brief import, info, verify, export. verify sets exit_status (1 when it finds problems).
void add_store_commands(CLI::App& app, int& exit_status);
/// @brief build-octree.
void add_octree_commands(CLI::App& app);
/// @brief Builds a grid store's octree and says what it wrote (import --octree, build-octree).
void run_build_octree(const std::string& dir, const OctreeBuildOptions& options);
/// @brief What `info` prints of a grid's octree volume (nothing when it has none).
void print_octree_info(const Manifest& m);
/// @brief cachebench.
void add_cache_commands(CLI::App& app);
/// @brief render, bench.
void add_render_commands(CLI::App& app);

}  // namespace brickyard::cli
