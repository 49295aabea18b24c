// DICOM import in a build without GDCM: the entry point says how to get it, so that the command
// line can take a DICOM directory everywhere and fail with a useful message.

#include "core/error.h"
#include "preprocess/volume_source.h"

namespace brickyard {

bool dicom_support() { return false; }

std::unique_ptr<VolumeSource> open_dicom_source(const std::string& path, const DicomOptions&) {
  throw Error(Errc::unsupported, "this brickyard was built without DICOM support (install libgdcm-dev and rebuild)")
      .with_file(path);
}

}  // namespace brickyard
