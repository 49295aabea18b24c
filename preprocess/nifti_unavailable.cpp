// NIfTI import in a build without nifticlib: the entry point says how to get it, so that the
// command line can list .nii everywhere and fail with a useful message.

#include "core/error.h"
#include "preprocess/volume_source.h"

namespace brickyard {

bool nifti_support() { return false; }

std::unique_ptr<VolumeSource> open_nifti_source(const std::string& path, const NiftiOptions&) {
  throw Error(Errc::unsupported, "this brickyard was built without NIfTI support (install libnifti2-dev and rebuild)")
      .with_file(path);
}

}  // namespace brickyard
