#pragma once
/// @file volume_source.h
/// @brief What the multiresolution builder reads: a volume delivered slab by slab in z, so
/// that no source ever needs the whole grid in memory.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>

#include "core/math.h"
#include "core/value_type.h"
#include "fields/field.h"
#include "preprocess/convert.h"

namespace brickyard {

class VolumeSource {
 public:
  virtual ~VolumeSource() = default;

  /// @brief What error messages call the source: its path, or "field fbm".
  virtual std::string name() const = 0;
  virtual Vec3s dims() const = 0;
  virtual ValueType type() const = 0;
  virtual Vec3d spacing() const { return Vec3d(1.0); }
  virtual Vec3d origin() const { return Vec3d(0.0); }
  /// @brief The value of space the source does not describe (OpenVDB's background); constant
  /// bricks at this value are flagged empty.
  virtual double background() const { return 0.0; }
  /// @brief Whether the data is a level set (a signed distance, negative inside): its coarser
  /// levels then keep the zero crossing by default (Downsample::min), so thin parts survive.
  virtual bool is_level_set() const { return false; }
  /// @brief Checks the data against what describes it before a build reads it (a raw file
  /// against its sidecar's checksum: a whole pass over the file); Error naming the file when
  /// they differ. build_store calls it unless the store or checkpoint in place was built from
  /// this file unchanged since (the same "checked_mtime_ns" in its source description).
  virtual void verify_content() {}
  /// @brief Bounds of the stored values when known without reading the data (stored units).
  virtual std::optional<ValueRange> value_range_hint() const { return std::nullopt; }
  /// @brief Whether the data may hold NaN or infinities (f32 files may; fields never do).
  virtual bool may_contain_nonfinite() const { return type() == ValueType::f32; }
  /// @brief Fills z-slices [z0, z1) into out, x fastest; exactly (z1-z0)*nx*ny values. Calls
  /// come in increasing z; rewind() starts over at z = 0.
  virtual void read_slab(int64_t z0, int64_t z1, std::span<std::byte> out) = 0;
  virtual void rewind() {}
  /// @brief Whether read_slab may skip slices (calls still come in increasing z); a stream that
  /// decompresses must read every slice.
  virtual bool can_skip() const { return true; }
  /// @brief Provenance as a JSON object (kind, path, size, checksum, parameters).
  virtual std::string describe_json() const = 0;
  /// @brief What converting the file's elements to the stored type did (u32, i32, f64 files),
  /// measured when the source was opened; nullopt when values are stored as they are.
  virtual std::optional<ConversionReport> conversion() const { return std::nullopt; }
  /// @brief Total input bytes, for throughput figures (the raw file size, or dims * type size).
  virtual uint64_t input_bytes() const { return uint64_t(volume(dims())) * size_of(type()); }
};

/// @brief How a raw file is laid out (everything the sidecar would say).
struct RawFileSpec {
  Vec3s dims{0};
  /// What the file holds; stored as stored_type(type), converted when not native.
  ElementType type = ElementType::u8;
  ConvertOptions convert;
  bool little_endian = true;
  uint64_t header_bytes = 0;  ///< bytes to skip before the first voxel
  Vec3d spacing{1.0};
  Vec3d origin{0.0};
  std::optional<ValueRange> range;  ///< from a sidecar, if any
  /// XXH3-64 of the file from its sidecar: then the store's record of its source is the
  /// content, so regenerating identical data does not make a complete store look stale.
  std::optional<uint64_t> xxh3_64;
  /// What generated the data, from its sidecar: {"field": NAME, "params": {...}, and for u8/u16
  /// "quantization": [lo, hi]} as JSON text ("" when unknown). Recorded in the store's source so
  /// that the reference renderer can render the analytic truth.
  std::string generator_json;
};

/// @brief A raw file, memory-mapped. Checks its size against dims, type and header first; a
/// file of u32, i32 or f64 is scanned once to measure its conversion (check_conversion).
std::unique_ptr<VolumeSource> open_raw_source(const std::string& path, const RawFileSpec& spec);
/// @brief A procedural field sampled on the fly (no temporary file).
std::unique_ptr<VolumeSource> make_field_source(std::unique_ptr<Field> field, const Vec3s& dims, ValueType type);
/// @brief A NRRD file (raw or gzip encoding; attached or detached data).
/// Types map onto the stored ones (short -> i16, ...); int, uint and double convert to f32.
std::unique_ptr<VolumeSource> open_nrrd_source(const std::string& path, const ConvertOptions& convert = {});
/// @brief A MetaImage file (ITK, 3D Slicer): .mha with its data attached, or .mhd naming a data
/// file; raw (memory-mapped) or zlib-compressed (streamed slab by slab). NDims 2 or 3, one
/// channel; MET_UINT, MET_INT and MET_DOUBLE convert to f32 as NRRD's do. TransformMatrix and
/// AnatomicalOrientation are recorded in the source's provenance, not applied.
std::unique_ptr<VolumeSource> open_metaimage_source(const std::string& path, const ConvertOptions& convert = {});
/// @brief How a NIfTI file is read.
struct NiftiOptions {
  ConvertOptions convert;
  /// Which volume of a 4D file (0-based, `--time-step`); a 4D file needs one.
  std::optional<int64_t> time_step;
};
/// @brief A NIfTI-1 or NIfTI-2 file (.nii, .nii.gz, .hdr/.img, .img.gz), streamed slab by slab.
/// u8, i8, u16, i16 and f32 are stored as they are; u32, i32 and f64 convert to f32 (measured
/// first, as raw files); scl_slope/scl_inter scaling is applied (integer results stay integers
/// where they fit, else f32). Spacing from pixdim, origin from the sform or qform; the affine is
/// recorded in the source's provenance, not applied (the grid is axis-aligned).
std::unique_ptr<VolumeSource> open_nifti_source(const std::string& path, const NiftiOptions& options = {});
/// @brief Whether this build can read NIfTI files (nifticlib was found).
bool nifti_support();
/// @brief How a DICOM series is read.
struct DicomOptions {
  /// SeriesInstanceUID of the series to import (`--series`); empty: the largest in the directory.
  std::string series_uid;
  ConvertOptions convert;
};
/// @brief A DICOM series: a directory of slice files (searched recursively; files that are not
/// DICOM images are skipped), or one multi-frame file, through GDCM. Slices are sorted along the
/// normal of ImageOrientationPatient by ImagePositionPatient and must be evenly spaced, of one
/// size, pixel format and orientation; x/y spacing from PixelSpacing, origin the first slice's
/// position. RescaleSlope/Intercept are applied (whole results stay integers where they fit,
/// else f32); the orientation is recorded in the provenance, not applied. Pixels are decoded one
/// file at a time as slabs are read. The provenance names the series chosen and the others.
std::unique_ptr<VolumeSource> open_dicom_source(const std::string& path, const DicomOptions& options = {});
/// @brief Whether this build can read DICOM series (GDCM was found).
bool dicom_support();
/// @brief How a netCDF file is read.
struct NetcdfOptions {
  /// The variable to import (`--variable`); empty: the file's only 3D or 4D numeric variable.
  std::string variable;
  /// Which time step of a (time, z, y, x) variable (0-based, `--time-step`); needed when it has
  /// several.
  std::optional<int64_t> time_step;
  ConvertOptions convert;
};
/// @brief One variable of a netCDF file (classic, 64-bit offset or data, netCDF-4), read slab by
/// slab with nc_get_vara: (z, y, x), or one step of (time, z, y, x). byte, ubyte, short, ushort
/// and float are stored as they are; int, uint and double convert to f32 (measured first, as raw
/// files). CF scale_factor/add_offset are applied (integer results stay integers where they fit,
/// else f32); voxels at _FillValue or missing_value become the source's background, a value just
/// below the valid data, so that wholly missing bricks are stored empty. Spacing and origin come
/// from uniform, increasing coordinate variables (else 1 and 0).
std::unique_ptr<VolumeSource> open_netcdf_source(const std::string& path, const NetcdfOptions& options = {});
/// @brief Whether this build can read netCDF files (netCDF-C was found).
bool netcdf_support();
/// @brief Whether this build can read OpenVDB files.
bool vdb_support();
/// @brief One grid of an OpenVDB file (float, double or int32; level set or fog volume).
std::unique_ptr<VolumeSource> open_vdb_source(const std::string& path, const std::string& grid_name);

}  // namespace brickyard
