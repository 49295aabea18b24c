#pragma once
// Subcommands of the `brickyard` command line. Each add_* registers its options and a
// callback on the app; callbacks throw brickyard::Error and main() turns that into an exit code.

#include <CLI/CLI.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace brickyard {
struct Manifest;
struct OctreeBuildOptions;
class Store;
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
/// @brief What `import` reads from a tetrahedral mesh (a file, or mesh:FIELD).
struct MeshImportOptions {
  std::string source, out;
  std::string array;             ///< --array: the scalar (or series) to import; "" the first
  bool single_step = false;      ///< --single-step: only the first of a series of arrays
  int64_t cells = 32;            ///< mesh:FIELD
  double jitter = 0;
  int replicate = 1, steps = 1;
  double move = 0;               ///< mesh:FIELD: moving vertices (see ProceduralMeshSpec)
  std::vector<std::string> params;
  uint32_t cluster_tets = 8192;
  bool bvh = false;              ///< --bvh: store each cluster's BVH with it
  std::string map_size;
  bool force = false;
};
/// @brief Whether `import` reads this source as a mesh (mesh:FIELD, or a mesh file's extension).
bool is_mesh_source(const std::string& source);
void run_mesh_import(const MeshImportOptions& options);
/// @brief Why a store is incomplete, for info and verify: "being built by process N" while a
/// writer holds it, else "build interrupted".
std::string incomplete_reason(const std::string& path);
/// @brief info, verify and export of a tetrahedral store.
void print_mesh_info(const std::string& path, const Store& store);
int verify_mesh(const std::string& path, const Store& store);
/// @brief Writes the store's mesh as a .vtu (`encoding`: ascii, binary, appended, base64, zlib).
void export_mesh(const Store& store, const std::string& out, const std::string& encoding);
/// @brief flight, cachebench. flight sets exit_status (kExitDamaged, see report_unreadable).
void add_cache_commands(CLI::App& app, int& exit_status);
/// @brief render, bench. render sets exit_status (kExitDamaged, see report_unreadable).
void add_render_commands(CLI::App& app, int& exit_status);

/// @brief Says on stderr how many records a run could not read and why (each error names its
/// store and key; the first few in full), and that the image drew them from a coarser level or
/// left them empty. Returns kExitDamaged, or 0 when there were none or `allow_damaged`.
int report_unreadable(const std::vector<std::string>& errors, bool allow_damaged);

}  // namespace brickyard::cli
