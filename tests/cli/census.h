#pragma once
// The bad-input census (test_cli_census.cpp runs it, census_cases.cpp holds the table): what a
// case is, and the workspace every case runs in.

#include <unistd.h>

#include <filesystem>
#include <functional>
#include <memory>
#include <regex>
#include <string>
#include <utility>
#include <vector>

#include "test_util.h"

namespace brickyard::census {

inline const std::string kExe = BRICKYARD_EXE;
inline const std::string kSource = BRICKYARD_SOURCE_DIR;

inline void replace_all(std::string& text, const std::string& from, const std::string& to) {
  for (size_t at = 0; (at = text.find(from, at)) != std::string::npos; at += to.size()) text.replace(at, from.size(), to);
}

class Workspace {
 public:
  /// @brief `text` with $TMP and $SRC made real paths.
  std::string real(std::string text) const {
    replace_all(text, "$TMP", dir_.path().string());
    replace_all(text, "$SRC", kSource);
    return text;
  }
  /// @brief `text` with real paths (and this process's pid) made placeholders again.
  std::string placeholders(std::string text) const {
    replace_all(text, kExe, "brickyard");
    replace_all(text, dir_.path().string(), "$TMP");
    replace_all(text, kSource, "$SRC");
    replace_all(text, "(pid " + std::to_string(::getpid()) + ")", "(pid $PID)");
    replace_all(text, "by process " + std::to_string(::getpid()), "by process $PID");
    // Checksums of damaged records: what they are depends on the codec's output, not the check.
    static const std::regex checksum("(stored|computed|decoded data) [0-9a-f]{16}");
    return std::regex_replace(text, checksum, "$1 <xxh3>");
  }
  std::string file(const std::string& name) const { return dir_.file(name); }
  void write(const std::string& name, const std::string& bytes) const {
    std::ofstream(file(name), std::ios::binary | std::ios::trunc) << bytes;
  }
  std::string read(const std::string& name) const { return testing::read_file(file(name)); }
  void copy_store(const std::string& from, const std::string& to) const {
    std::filesystem::copy(file(from), file(to), std::filesystem::copy_options::recursive);
  }
  /// @brief Keeps `what` alive until the case's command has run (a lock the test holds).
  void hold(std::shared_ptr<void> what) const { held_ = std::move(what); }
  void release() const { held_.reset(); }

 private:
  testing::TempDir dir_;
  mutable std::shared_ptr<void> held_;
};

using Setup = std::function<void(const Workspace&)>;

struct Case {
  std::string area;     ///< a key of kAreas
  std::string name;     ///< short, unique within the area
  Setup setup;          ///< writes the case's files (may be empty)
  std::string command;  ///< "[ENV=VALUE ...] brickyard ARGS", naming $TMP and $SRC
  int exit_code;
  std::string expect;   ///< a part of the output that names the file, key or field
  bool needs_vdb = false;
};

/// The areas, in the census's order, with their headings.
inline const std::vector<std::pair<std::string, std::string>> kAreas = {
    {"cli", "Command line and generate"},
    {"import", "Importers: raw files, sidecars, NRRD, MetaImage, NIfTI, DICOM, netCDF, OpenVDB"},
    {"scene", "Scenes"},
    {"render", "render and bench options"},
    {"store", "Stores: info, verify, export, build-octree"},
    {"cache", "Cache: flight"},
    {"trace", "Traces: cachebench"},
    {"mesh", "Tetrahedral meshes"},
};

/// @brief The files every case may use: grid, octree and mesh stores, a raw file with its
/// sidecar, a camera path, a scene, a trace, a directory and a plain file.
void build_fixtures(const Workspace& ws);

/// @brief Every case, area by area in kAreas' order.
std::vector<Case> census_cases();

}  // namespace brickyard::census
