// netCDF import in a build without netCDF-C: the entry point says how to get it, so that the
// command line can list .nc everywhere and fail with a useful message.

#include "core/error.h"
#include "preprocess/volume_source.h"

namespace brickyard {

bool netcdf_support() { return false; }

std::unique_ptr<VolumeSource> open_netcdf_source(const std::string& path, const NetcdfOptions&) {
  throw Error(Errc::unsupported, "this brickyard was built without netCDF support (install libnetcdf-dev and rebuild)")
      .with_file(path);
}

}  // namespace brickyard
