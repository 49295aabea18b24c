// NIfTI-1 and NIfTI-2 volumes (https://nifti.nimh.nih.gov/nifti-1, nifti-2), through nifticlib:
// nifti_image_read(path, 0) reads and checks the header (either version, .nii, .nii.gz, or an
// .hdr/.img pair) without the data; the data is streamed through nifticlib's znzlib, slab by
// slab in z, so that neither the volume nor its decompressed bytes are ever held whole.
//
// This is the only file that includes nifticlib's headers (nifti_unavailable.cpp stands in for it
// in builds without the library).

#include <sys/stat.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <memory>
#include <optional>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <nifti2_io.h>
#include <znzlib.h>

#include "core/atomic_file.h"
#include "core/error.h"
#include "preprocess/volume_source.h"

namespace brickyard {
namespace {

namespace fs = std::filesystem;

using NiftiImagePtr = std::unique_ptr<nifti_image, decltype(&nifti_image_free)>;

/// The element types brickyard reads; nullopt for the rest (complex, RGB, 64-bit integers, ...).
std::optional<ElementType> element_of(int datatype) {
  switch (datatype) {
    case DT_UINT8: return ElementType::u8;
    case DT_INT8: return ElementType::i8;
    case DT_UINT16: return ElementType::u16;
    case DT_INT16: return ElementType::i16;
    case DT_UINT32: return ElementType::u32;
    case DT_INT32: return ElementType::i32;
    case DT_FLOAT32: return ElementType::f32;
    case DT_FLOAT64: return ElementType::f64;
    default: return std::nullopt;
  }
}


/// Up to `n` bytes from the start of a (possibly gzip-compressed) file; nullopt when zlib
/// reports corrupt data.
std::optional<std::vector<unsigned char>> read_head(const std::string& file, size_t n) {
  znzFile f = znzopen(file.c_str(), "rb", nifti_is_gzfile(file.c_str()));
  if (znz_isnull(f)) throw Error(Errc::io, fmt::format("cannot open: {}", std::strerror(errno))).with_file(file);
  std::vector<unsigned char> bytes(n);
  const size_t got = znzread(bytes.data(), 1, n, f);
  znzclose(f);
  if (got > n) return std::nullopt;  // znzread returns gzread's -1, as a size_t, on corrupt data
  bytes.resize(got);
  return bytes;
}

template <typename T>
T load_endian(const unsigned char* p, bool swap) {
  unsigned char b[sizeof(T)];
  std::memcpy(b, p, sizeof(T));
  if (swap) std::reverse(b, b + sizeof(T));
  T v;
  std::memcpy(&v, b, sizeof(T));
  return v;
}

/// The header's version from its first field, sizeof_hdr: 348 (NIfTI-1, and ANALYZE 7.5) or 540
/// (NIfTI-2), in either byte order; 0 when it is neither. `swapped`: the file's order is not ours.
int header_version(const std::vector<unsigned char>& head, bool& swapped) {
  if (head.size() < 4) return 0;
  for (const bool swap : {false, true}) {
    const int32_t size = load_endian<int32_t>(head.data(), swap);
    swapped = swap;
    if (size == 348) return 1;
    if (size == 540) return 2;
  }
  return 0;
}

/// Checks the header's bytes for what nifticlib cannot explain or forgives: the version
/// (sizeof_hdr), a short header, and the sizes (nifti_image_read takes a size of 0 or less
/// beyond dim[1] for 1, which would import another shape than the file's). Returns the version:
/// nim->nifti_type says NIfTI-1 for NIfTI-2 files in nifticlib 3.0.1.
int check_raw_header(const std::string& header) {
  const auto head = read_head(header, 540);
  if (!head)
    throw Error(Errc::format, "the gzip data is corrupt: zlib cannot inflate it (or its checksum fails)").with_file(header);
  bool swapped = false;
  const int version = header_version(*head, swapped);
  if (version == 0) {
    if (head->size() < 4)
      throw Error(Errc::format, fmt::format("the header is truncated: {} bytes, a NIfTI header has 348 or 540", head->size()))
          .with_file(header)
          .with_field("sizeof_hdr");
    throw Error(Errc::format,
                fmt::format("not a NIfTI file: its first field, sizeof_hdr, is {}, not 348 (NIfTI-1) or 540 (NIfTI-2) in "
                            "either byte order",
                            load_endian<int32_t>(head->data(), false)))
        .with_file(header)
        .with_field("sizeof_hdr");
  }
  const size_t need = version == 1 ? 348 : 540;
  if (head->size() < need)
    throw Error(Errc::format, fmt::format("the header is truncated: {} bytes, a NIfTI-{} header has {}", head->size(),
                                          version, need))
        .with_file(header)
        .with_field("sizeof_hdr");
  // dim[8]: int16 at byte 40 in NIfTI-1, int64 at byte 16 in NIfTI-2.
  std::array<int64_t, 8> dim{};
  for (size_t i = 0; i < 8; ++i)
    dim[i] = version == 1 ? load_endian<int16_t>(head->data() + 40 + 2 * i, swapped)
                          : load_endian<int64_t>(head->data() + 16 + 8 * i, swapped);
  if (dim[0] < 1 || dim[0] > 7)
    throw Error(Errc::format, fmt::format("dim[0] is {}: the number of dimensions must be 1 to 7", dim[0]))
        .with_file(header)
        .with_field("dim");
  for (size_t i = 1; i <= size_t(dim[0]); ++i)
    if (dim[i] <= 0)
      throw Error(Errc::format, fmt::format("dim[{}] is {}: every size must be positive", i, dim[i]))
          .with_file(header)
          .with_field("dim");
  return version;
}

/// The header file: `path`, or the .hdr beside the .img the user may have named.
std::string header_file_of(const std::string& path) {
  char* found = nifti_findhdrname(path.c_str());
  if (!found) {
    const std::string name = fs::path(path).filename().string();
    const bool image = name.size() > 4 && (name.ends_with(".img") || name.ends_with(".img.gz") ||
                                           name.ends_with(".IMG") || name.ends_with(".IMG.GZ"));
    if (image) throw Error(Errc::not_found, "no header (.hdr) found beside this image file").with_file(path);
    return path;
  }
  std::string header = found;
  std::free(found);
  return header;
}

/// What the source needs from the header, copied out so that nifticlib's image is freed at once.
struct NiftiHeader {
  int version = 1;
  bool analyze = false;  ///< an ANALYZE 7.5 header (no NIfTI magic): no qform or sform
  std::string header_file, data_file;
  bool gzip = false;
  uint64_t volume_offset = 0;  ///< byte of the selected volume's first voxel in the data file
  Vec3s dims{0};
  int64_t steps = 1;
  std::optional<int64_t> time_step;
  int datatype = 0;
  std::string datatype_name;
  ElementType element = ElementType::u8;
  bool swap = false;
  bool little_endian = true;
  bool scaled = false;
  double slope = 1, inter = 0;
  Vec3d spacing{1.0}, origin{0.0};
  int qform_code = 0, sform_code = 0;
  std::string affine_from;  ///< "sform", "qform", or "pixdim" when neither is set
  int affine_code = 0;
  std::array<double, 16> affine{};
};

NiftiHeader read_header(const std::string& path, const NiftiOptions& options) {
  check_readable_file(path);
  NiftiHeader h;
  // Our checks first, so that the error names the field: nifticlib prints its reasons for
  // refusing a header to stderr, at best, and returns NULL.
  h.header_file = header_file_of(path);
  h.version = check_raw_header(h.header_file);
  nifti_set_debug_level(0);
  NiftiImagePtr nim(nifti_image_read(path.c_str(), 0), &nifti_image_free);
  if (!nim)
    throw Error(Errc::format, fmt::format("nifticlib cannot read this NIfTI-{} header (inconsistent datatype, sizes or "
                                          "offsets)",
                                          h.version))
        .with_file(h.header_file);
  if (nim->fname) h.header_file = nim->fname;
  h.analyze = nim->nifti_type == NIFTI_FTYPE_ANALYZE;
  if (!nim->iname)
    throw Error(Errc::not_found, "no image file (.img or .img.gz) found beside this header").with_file(h.header_file);
  h.data_file = nim->iname;
  h.gzip = nifti_is_gzfile(nim->iname) != 0;

  // --- Sizes: three dimensions, a fourth (time) only with --time-step, nothing beyond.
  const int64_t ndim = nim->ndim;
  for (int64_t i = 5; i <= std::min<int64_t>(ndim, 7); ++i)
    if (nim->dim[i] > 1)
      throw Error(Errc::unsupported, fmt::format("dim[{}] is {}: data with more than four dimensions (vector, tensor or "
                                                 "multi-component voxels) is not supported",
                                                 i, nim->dim[i]))
          .with_file(h.header_file)
          .with_field("dim");
  h.dims = {nim->nx, nim->ny, nim->nz};
  h.steps = ndim >= 4 ? std::max<int64_t>(1, nim->nt) : 1;
  if (h.dims.x < 1 || h.dims.y < 1 || h.dims.z < 1)
    throw Error(Errc::format, fmt::format("sizes {}x{}x{}: every size must be positive", h.dims.x, h.dims.y, h.dims.z))
        .with_file(h.header_file)
        .with_field("dim");
  if (options.time_step) {
    if (*options.time_step < 0 || *options.time_step >= h.steps)
      throw Error(Errc::invalid_argument, fmt::format("time step {} is outside the file's {} step{} (0 to {})",
                                                      *options.time_step, h.steps, h.steps == 1 ? "" : "s", h.steps - 1))
          .with_file(path)
          .with_field("--time-step");
    h.time_step = options.time_step;
  } else if (h.steps > 1) {
    // A store holds one volume; time-varying stores are future work.
    throw Error(Errc::invalid_argument, fmt::format("the file holds {} time steps (dim[4]); a store holds one volume: "
                                                    "choose it with --time-step 0 to {}",
                                                    h.steps, h.steps - 1))
        .with_file(path)
        .with_field("--time-step");
  }

  // --- Element type and byte order.
  h.datatype = nim->datatype;
  const char* type_name = nifti_datatype_string(nim->datatype);
  h.datatype_name = type_name ? type_name : "UNKNOWN";
  const auto element = element_of(nim->datatype);
  if (!element)
    throw Error(Errc::unsupported, fmt::format("datatype {} ({}) is not supported: brickyard reads UINT8, INT8, UINT16, "
                                               "INT16 and FLOAT32 as they are, and INT32, UINT32 and FLOAT64 as f32",
                                               nim->datatype, h.datatype_name))
        .with_file(h.header_file)
        .with_field("datatype");
  h.element = *element;
  if (size_t(nim->nbyper) != size_of(h.element))
    throw Error(Errc::format, fmt::format("bitpix says {} bytes per voxel, datatype {} has {}", nim->nbyper,
                                          h.datatype_name, size_of(h.element)))
        .with_file(h.header_file)
        .with_field("bitpix");
  h.swap = size_of(h.element) > 1 && nim->byteorder != nifti_short_order();
  h.little_endian = nim->byteorder == 1;  // nifticlib's LSB_FIRST, which its header keeps to its sources

  // --- Where the voxels are: the volume's bytes, checked against the file unless compressed.
  uint64_t volume_bytes = size_of(h.element), total_bytes = 0;
  for (int a = 0; a < 3; ++a)
    if (__builtin_mul_overflow(volume_bytes, uint64_t(h.dims[a]), &volume_bytes) || volume_bytes > uint64_t(INT64_MAX))
      throw Error(Errc::format, fmt::format("sizes {}x{}x{} overflow a 64-bit byte count", h.dims.x, h.dims.y, h.dims.z))
          .with_file(h.header_file)
          .with_field("dim");
  if (__builtin_mul_overflow(volume_bytes, uint64_t(h.steps), &total_bytes) || total_bytes > uint64_t(INT64_MAX))
    throw Error(Errc::format, fmt::format("{} time steps of {} bytes overflow a 64-bit byte count", h.steps, volume_bytes))
        .with_file(h.header_file)
        .with_field("dim");
  if (nim->iname_offset < 0)
    throw Error(Errc::format, fmt::format("vox_offset {} is negative", nim->iname_offset)).with_file(h.header_file).with_field("vox_offset");
  const uint64_t data_start = uint64_t(nim->iname_offset);
  h.volume_offset = data_start + uint64_t(h.time_step.value_or(0)) * volume_bytes;
  check_readable_file(h.data_file);
  if (!h.gzip) {
    std::error_code ec;
    const uint64_t file_bytes = fs::file_size(h.data_file, ec);
    if (ec) throw Error(Errc::io, fmt::format("cannot read the data file: {}", ec.message())).with_file(h.data_file);
    if (file_bytes < data_start + total_bytes)
      throw Error(Errc::format,
                  fmt::format("the data is truncated: {} bytes from byte {} (vox_offset), but {}x{}x{}{} {} needs {}",
                              file_bytes - std::min(file_bytes, data_start), data_start, h.dims.x, h.dims.y, h.dims.z,
                              h.steps > 1 ? fmt::format("x{}", h.steps) : std::string(), h.datatype_name, total_bytes))
          .with_file(h.data_file)
          .with_field("dim");
  }

  // --- Scaling: a slope of 0 (or non-finite) means none, as does the identity (1, 0).
  if (std::isfinite(nim->scl_slope) && nim->scl_slope != 0 && !(nim->scl_slope == 1 && nim->scl_inter == 0)) {
    if (!std::isfinite(nim->scl_inter))
      throw Error(Errc::format, fmt::format("scl_inter is {} with scl_slope {}", nim->scl_inter, nim->scl_slope))
          .with_file(h.header_file)
          .with_field("scl_inter");
    h.scaled = true;
    h.slope = nim->scl_slope;
    h.inter = nim->scl_inter;
  }

  // --- Geometry. An axis of size 1 (a 2D image) may carry no spacing: 1 stands in for it.
  const double pixdim[3] = {nim->dx, nim->dy, nim->dz};
  for (int a = 0; a < 3; ++a) {
    if (std::isfinite(pixdim[a]) && pixdim[a] > 0) h.spacing[a] = pixdim[a];
    else if (h.dims[a] == 1) h.spacing[a] = 1.0;
    else
      throw Error(Errc::format, fmt::format("pixdim[{}] is {:g}: every spacing must be positive and finite", a + 1, pixdim[a]))
          .with_file(h.header_file)
          .with_field("pixdim");
  }
  // brickyard's grid is axis-aligned: the origin is the affine's translation, and the affine
  // itself (its rotation, shear or flips) is recorded in the store's provenance, not applied.
  h.qform_code = nim->qform_code;
  h.sform_code = nim->sform_code;
  const nifti_dmat44* m = nullptr;
  if (nim->sform_code > 0) {
    m = &nim->sto_xyz;
    h.affine_from = "sform";
    h.affine_code = nim->sform_code;
  } else if (nim->qform_code > 0) {
    m = &nim->qto_xyz;
    h.affine_from = "qform";
    h.affine_code = nim->qform_code;
  }
  if (m) {
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) h.affine[size_t(4 * r + c)] = m->m[r][c];
    h.origin = {m->m[0][3], m->m[1][3], m->m[2][3]};
    if (!std::isfinite(h.origin.x) || !std::isfinite(h.origin.y) || !std::isfinite(h.origin.z))
      throw Error(Errc::format, fmt::format("the {} places the first voxel at ({:g}, {:g}, {:g})", h.affine_from,
                                            h.origin.x, h.origin.y, h.origin.z))
          .with_file(h.header_file)
          .with_field(h.affine_from == "sform" ? "srow" : "qoffset");
  } else {
    h.affine_from = "pixdim";
    for (int a = 0; a < 3; ++a) h.affine[size_t(5 * a)] = h.spacing[a];
    h.affine[15] = 1;
  }
  return h;
}

/// The data file, read sequentially from the selected volume's first byte through znzlib
/// (which inflates gzip); restartable.
class DataStream {
 public:
  explicit DataStream(const NiftiHeader& h) : h_(h) { open(); }
  ~DataStream() { close(); }
  DataStream(const DataStream&) = delete;
  DataStream& operator=(const DataStream&) = delete;

  /// Moves to byte `pos` of the volume (gzip: znzseek inflates up to it, or starts over).
  void seek(uint64_t pos) {
    if (pos == position_) return;
    const uint64_t at = h_.volume_offset + pos;
    if (znzseek(f_, znz_off_t(at), SEEK_SET) < 0)
      throw Error(Errc::format, fmt::format("cannot seek to byte {}: the file ends before", at)).with_file(h_.data_file);
    position_ = pos;
  }

  void read(std::byte* out, size_t n) {
    size_t done = 0;
    while (done < n) {
      const size_t want = std::min<size_t>(n - done, size_t(1) << 30);
      const size_t got = znzread(out + done, 1, want, f_);
      if (got > want)  // gzread's -1, as a size_t
        throw Error(Errc::format, fmt::format("the gzip data is corrupt after {} bytes of the volume (zlib cannot "
                                              "inflate it, or its checksum fails)",
                                              position_ + done))
            .with_file(h_.data_file);
      if (got == 0)
        throw Error(Errc::format, fmt::format("{} is truncated: it ends after {} bytes of the volume, which needs {} "
                                              "({}x{}x{} {})",
                                              h_.gzip ? "the decompressed data" : "the data", position_ + done,
                                              uint64_t(volume(h_.dims)) * size_of(h_.element), h_.dims.x, h_.dims.y,
                                              h_.dims.z, h_.datatype_name))
            .with_file(h_.data_file);
      done += got;
    }
    position_ += n;
  }

  /// After the volume's last byte: gzip checks its CRC only when inflation reaches the stream's
  /// end, so read on (one byte) to have corrupt data refused rather than imported.
  void check_gzip_end() {
    if (!h_.gzip) return;
    std::byte extra{};
    const size_t got = znzread(&extra, 1, 1, f_);
    if (got > 1)
      throw Error(Errc::format, "the gzip data is corrupt: its checksum fails at the end of the stream").with_file(h_.data_file);
    position_ += got;  // a byte read here is the next time step's, or trailing data: not imported
  }

  void restart() {
    close();
    open();
  }

 private:
  void open() {
    check_readable_file(h_.data_file);
    f_ = znzopen(h_.data_file.c_str(), "rb", h_.gzip ? 1 : 0);
    if (znz_isnull(f_)) throw Error(Errc::io, fmt::format("cannot open: {}", std::strerror(errno))).with_file(h_.data_file);
    position_ = ~uint64_t(0);
    seek(0);
  }
  void close() {
    if (!znz_isnull(f_)) znzclose(f_);
    f_ = nullptr;
  }

  const NiftiHeader& h_;
  znzFile f_ = nullptr;
  uint64_t position_ = 0;  ///< bytes of the volume before the file position
};



class NiftiSource final : public VolumeSource {
 public:
  NiftiSource(std::string path, NiftiHeader h, const ConvertOptions& convert)
      : path_(std::move(path)), h_(std::move(h)), stream_(h_), slice_elements_(size_t(h_.dims.x * h_.dims.y)) {
    struct stat st {};
    if (::stat(h_.data_file.c_str(), &st) == 0) {
      data_bytes_ = uint64_t(st.st_size);
      mtime_ns_ = int64_t(st.st_mtim.tv_sec) * 1000000000 + st.st_mtim.tv_nsec;
    }
    if (h_.scaled) choose_scaled_type(convert);
    else if (!is_native(h_.element)) {
      // One pass before the build: a conversion that would change values is refused first.
      type_ = ValueType::f32;
      conversion_ = scan_conversion(h_.dims, h_.element, [&](int64_t z0, int64_t z1, std::span<std::byte> out) {
        read_elements(z0, z1, out);
      });
      check_conversion(*conversion_, convert, path_);
      if (conversion_->min <= conversion_->max) range_ = ValueRange{conversion_->min, conversion_->max};
      rewind();
    } else {
      type_ = stored_type(h_.element);
    }
  }

  std::string name() const override { return path_; }
  Vec3s dims() const override { return h_.dims; }
  ValueType type() const override { return type_; }
  Vec3d spacing() const override { return h_.spacing; }
  Vec3d origin() const override { return h_.origin; }
  std::optional<ValueRange> value_range_hint() const override { return range_; }
  bool may_contain_nonfinite() const override {
    if (type_ != ValueType::f32) return false;
    if (conversion_) return conversion_->nonfinite > 0;
    return h_.element == ElementType::f32 || h_.element == ElementType::f64;
  }
  std::optional<ConversionReport> conversion() const override { return conversion_; }
  bool can_skip() const override { return !h_.gzip; }
  void rewind() override {
    // gzip cannot seek back cheaply: start over. A plain file seeks on the next read.
    if (h_.gzip) stream_.restart();
  }
  void read_slab(int64_t z0, int64_t z1, std::span<std::byte> out) override {
    const size_t n = size_t(z1 - z0) * slice_elements_;
    BY_CHECK_EQ(out.size(), n * size_of(type_));
    if (!h_.scaled && h_.element == element_type(type_)) {
      read_elements(z0, z1, out);  // stored as it is: straight into the slab
      return;
    }
    raw_.resize(n * size_of(h_.element));
    read_elements(z0, z1, raw_);
    if (!h_.scaled) {
      convert_elements(raw_.data(), h_.element, n, out.data());
      return;
    }
    scaled_.resize(n);
    scale_elements(raw_.data(), h_.element, n, h_.slope, h_.inter, scaled_.data());
    // Integer types hold every scaled value exactly (checked when the source was opened).
    store_values(scaled_.data(), n, type_, out.data());
  }
  std::string describe_json() const override {
    nlohmann::json j = {{"kind", "nifti"},
                        {"path", path_},
                        {"version", h_.version},
                        {"datatype", h_.datatype_name},
                        {"datatype_code", h_.datatype},
                        {"byte_order", h_.little_endian ? "little" : "big"},
                        {"compressed", h_.gzip},
                        {"bytes", data_bytes_},
                        {"mtime_ns", mtime_ns_},
                        {"qform_code", h_.qform_code},
                        {"sform_code", h_.sform_code},
                        {"affine_from", h_.affine_from},
                        {"affine_code", h_.affine_code},
                        {"affine_code_name", nifti_xform_string(h_.affine_code)},
                        {"affine", h_.affine}};
    if (h_.analyze) j["analyze75"] = true;
    if (h_.data_file != path_) j["data"] = h_.data_file;
    if (h_.steps > 1) j["time_steps"] = h_.steps;
    if (h_.time_step) j["time_step"] = *h_.time_step;
    if (h_.scaled) j["scl_slope"] = h_.slope, j["scl_inter"] = h_.inter;
    if (conversion_) j["conversion"] = nlohmann::json::parse(conversion_->to_json());
    return j.dump();
  }
  uint64_t input_bytes() const override { return uint64_t(volume(h_.dims)) * size_of(h_.element); }

 private:
  /// Slices [z0, z1) of the file's elements, in native byte order, into `out`.
  void read_elements(int64_t z0, int64_t z1, std::span<std::byte> out) {
    const uint64_t slice_bytes = slice_elements_ * size_of(h_.element);
    BY_CHECK_EQ(out.size(), size_t(z1 - z0) * slice_bytes);
    stream_.seek(uint64_t(z0) * slice_bytes);
    stream_.read(out.data(), out.size());
    if (h_.swap) swap_element_bytes(out, size_of(h_.element));
    if (z1 == h_.dims.z) stream_.check_gzip_end();
  }

  /// Scaled values stay integers where slope and intercept are whole and every value fits the
  /// element's stored type, or i16 (u8 CT data scaled by 1 and -1024, say); else they are f32.
  /// The element type's limits decide without reading when they fit already; otherwise one
  /// measuring pass over the scaled values does.
  void choose_scaled_type(const ConvertOptions& convert) {
    std::vector<ValueType> candidates;
    const bool small_integers = h_.element == ElementType::u8 || h_.element == ElementType::i8 ||
                                h_.element == ElementType::u16 || h_.element == ElementType::i16;
    if (small_integers && is_whole(h_.slope) && is_whole(h_.inter)) {
      candidates.push_back(stored_type(h_.element));
      if (candidates.back() != ValueType::i16) candidates.push_back(ValueType::i16);
      auto [lo, hi] = element_limits(h_.element);
      lo = h_.slope * lo + h_.inter, hi = h_.slope * hi + h_.inter;
      if (lo > hi) std::swap(lo, hi);
      for (ValueType t : candidates)
        if (range_fits(lo, hi, t)) {
          type_ = t;
          return;
        }
    }
    // The scaled values are computed in double: the report measures them against f32.
    ConversionReport report = scan_conversion(h_.dims, ElementType::f64, [&](int64_t z0, int64_t z1, std::span<std::byte> out) {
      const size_t n = size_t(z1 - z0) * slice_elements_;
      raw_.resize(n * size_of(h_.element));
      read_elements(z0, z1, raw_);
      scale_elements(raw_.data(), h_.element, n, h_.slope, h_.inter, reinterpret_cast<double*>(out.data()));
    });
    rewind();
    if (report.min <= report.max) range_ = ValueRange{report.min, report.max};
    for (ValueType t : candidates)
      if (report.min <= report.max && range_fits(report.min, report.max, t)) {
        type_ = t;
        return;
      }
    check_conversion(report, convert, path_);
    type_ = ValueType::f32;
    conversion_ = report;
  }

  std::string path_;
  NiftiHeader h_;
  DataStream stream_;
  size_t slice_elements_;
  ValueType type_ = ValueType::f32;
  std::optional<ConversionReport> conversion_;
  std::optional<ValueRange> range_;
  uint64_t data_bytes_ = 0;
  int64_t mtime_ns_ = 0;
  std::vector<std::byte> raw_;
  std::vector<double> scaled_;
};

}  // namespace

bool nifti_support() { return true; }

std::unique_ptr<VolumeSource> open_nifti_source(const std::string& path, const NiftiOptions& options) {
  return std::make_unique<NiftiSource>(path, read_header(path, options), options.convert);
}

}  // namespace brickyard
