// OpenVDB import and export in a build without OpenVDB: every entry point says how to get it,
// so the command line can list .vdb everywhere and fail with a useful message.

#include "core/error.h"
#include "preprocess/export.h"
#include "preprocess/volume_source.h"

namespace brickyard {
namespace {

[[noreturn]] void no_openvdb(const std::string& path) {
  throw Error(Errc::unsupported, "this brickyard was built without OpenVDB (install libopenvdb-dev and rebuild)")
      .with_file(path);
}

}  // namespace

bool vdb_support() { return false; }

std::unique_ptr<VolumeSource> open_vdb_source(const std::string& path, const std::string&) { no_openvdb(path); }

void export_vdb(const Store&, int, const VoxelBox&, const std::string& path, const std::string&, Progress*, int) {
  no_openvdb(path);
}

}  // namespace brickyard
