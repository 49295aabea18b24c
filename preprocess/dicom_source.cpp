// DICOM series (a directory of slices, or one multi-frame file), through GDCM (Debian's
// libgdcm-dev). Opening reads only the headers: every file once, up to its pixel data, which is
// skipped. The series is chosen (--series, else the largest), its frames sorted along the slice
// normal and checked (size, pixel format, orientation, even spacing); the pixel data is decoded
// slice file by slice file as read_slab asks for it, so that no more than one file's pixels are
// ever held.
//
// This is the only file that includes GDCM's headers (dicom_unavailable.cpp stands in for it in
// builds without the library).

#include <sys/stat.h>

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <gdcmDataSet.h>
#include <gdcmFile.h>
#include <gdcmImage.h>
#include <gdcmImageReader.h>
#include <gdcmReader.h>
#include <gdcmSequenceOfItems.h>
#include <gdcmTrace.h>
#include <gdcmUIDs.h>

#include "core/atomic_file.h"
#include "core/error.h"
#include "preprocess/volume_source.h"

namespace brickyard {
namespace {

namespace fs = std::filesystem;

// --- The attributes read (PS3.6 tags), by their DICOM keywords.
const gdcm::Tag kSopClassUid(0x0008, 0x0016), kSopInstanceUid(0x0008, 0x0018), kModality(0x0008, 0x0060),
    kSeriesDescription(0x0008, 0x103e), kSliceThickness(0x0018, 0x0050), kSpacingBetweenSlices(0x0018, 0x0088),
    kSeriesInstanceUid(0x0020, 0x000e), kImagePositionPatient(0x0020, 0x0032),
    kImageOrientationPatient(0x0020, 0x0037), kPlanePositionSequence(0x0020, 0x9113),
    kPlaneOrientationSequence(0x0020, 0x9116), kSamplesPerPixel(0x0028, 0x0002),
    kPhotometricInterpretation(0x0028, 0x0004), kNumberOfFrames(0x0028, 0x0008), kRows(0x0028, 0x0010),
    kColumns(0x0028, 0x0011), kPixelSpacing(0x0028, 0x0030), kBitsAllocated(0x0028, 0x0100),
    kBitsStored(0x0028, 0x0101), kPixelRepresentation(0x0028, 0x0103), kRescaleIntercept(0x0028, 0x1052),
    kRescaleSlope(0x0028, 0x1053), kPixelMeasuresSequence(0x0028, 0x9110),
    kPixelValueTransformationSequence(0x0028, 0x9145), kSharedFunctionalGroupsSequence(0x5200, 0x9229),
    kPerFrameFunctionalGroupsSequence(0x5200, 0x9230), kFloatPixelData(0x7fe0, 0x0008),
    kDoubleFloatPixelData(0x7fe0, 0x0009), kPixelData(0x7fe0, 0x0010);

/// GDCM reports through its own global trace streams (a warning for every MR file whose rescale
/// it "forces", another for pixel data shorter than the image): every problem is an Error here,
/// naming the file and attribute, so its chatter on stderr is turned off once.
void quiet_gdcm() {
  static const bool quiet = [] {
    gdcm::Trace::DebugOff();
    gdcm::Trace::WarningOff();
    gdcm::Trace::ErrorOff();
    return true;
  }();
  (void)quiet;
}

// ----------------------------------------------------------------------------- attribute values

/// A text value with its padding (trailing spaces and NULs, leading spaces) removed; nullopt when
/// absent or empty. GDCM hands values over in the host's byte order and, for text, as written.
std::optional<std::string> text_of(const gdcm::DataSet& ds, const gdcm::Tag& tag) {
  if (!ds.FindDataElement(tag)) return std::nullopt;
  const gdcm::ByteValue* bv = ds.GetDataElement(tag).GetByteValue();
  if (!bv || bv->GetLength() == 0) return std::nullopt;
  std::string s(bv->GetPointer(), bv->GetLength());
  while (!s.empty() && (s.back() == ' ' || s.back() == '\0')) s.pop_back();
  const size_t first = s.find_first_not_of(' ');
  if (first == std::string::npos) return std::nullopt;
  return s.substr(first);
}

/// The numbers of a decimal string (DS) or integer string (IS) value, "a\b\c"; nullopt when
/// absent. A value that is not numbers is an error naming the file and the attribute.
std::optional<std::vector<double>> numbers_of(const gdcm::DataSet& ds, const gdcm::Tag& tag, const char* keyword,
                                              const std::string& file, size_t expect = 0) {
  const auto s = text_of(ds, tag);
  if (!s) return std::nullopt;
  std::vector<double> values;
  size_t at = 0;
  while (true) {
    const size_t end = std::min(s->find('\\', at), s->size());
    std::string one = s->substr(at, end - at);
    while (!one.empty() && one.back() == ' ') one.pop_back();
    const size_t first = one.find_first_not_of(' ');
    one = first == std::string::npos ? std::string() : one.substr(first);
    if (!one.empty() && one[0] == '+') one.erase(0, 1);
    double v = 0;
    const auto [ptr, ec] = std::from_chars(one.data(), one.data() + one.size(), v);
    if (one.empty() || ec != std::errc() || ptr != one.data() + one.size() || !std::isfinite(v))
      throw Error(Errc::format, fmt::format("{} is '{}': not {}", keyword, *s,
                                            expect > 1 ? fmt::format("{} numbers separated by '\\'", expect)
                                                       : std::string("a number")))
          .with_file(file)
          .with_field(keyword);
    values.push_back(v);
    if (end == s->size()) break;
    at = end + 1;
  }
  if (expect && values.size() != expect)
    throw Error(Errc::format, fmt::format("{} is '{}': {} value{}, it has {}", keyword, *s, values.size(),
                                          values.size() == 1 ? "" : "s", expect))
        .with_file(file)
        .with_field(keyword);
  return values;
}

/// An unsigned short (US) value; nullopt when absent.
std::optional<uint16_t> ushort_of(const gdcm::DataSet& ds, const gdcm::Tag& tag) {
  if (!ds.FindDataElement(tag)) return std::nullopt;
  const gdcm::ByteValue* bv = ds.GetDataElement(tag).GetByteValue();
  if (!bv || bv->GetLength() < 2) return std::nullopt;
  uint16_t v;
  std::memcpy(&v, bv->GetPointer(), 2);
  return v;
}

/// The first item's data set of sequence `tag` in `ds`, or nullptr; `keep` holds the sequence.
const gdcm::DataSet* first_item(const gdcm::DataSet* ds, const gdcm::Tag& tag,
                                gdcm::SmartPointer<gdcm::SequenceOfItems>& keep) {
  if (!ds || !ds->FindDataElement(tag)) return nullptr;
  keep = ds->GetDataElement(tag).GetValueAsSQ();
  if (!keep || keep->GetNumberOfItems() < 1) return nullptr;
  return &keep->GetItem(1).GetNestedDataSet();
}

// --------------------------------------------------------------------------------- the headers

using Cosines = std::array<double, 6>;

/// One slice of the volume: a single-frame file, or one frame of a multi-frame file.
struct Frame {
  size_t file = 0;    ///< index into DicomScan::files
  int64_t index = 0;  ///< within its file, from 0
  std::optional<Vec3d> position;
  std::optional<Cosines> orientation;
  std::optional<std::array<double, 2>> pixel_spacing;  ///< as written: row spacing (y), column spacing (x)
  double slope = 1, intercept = 0;
  double along = 0;  ///< the position's projection on the slice normal
};

/// What one file's header says, for the checks and the decoding.
struct DicomFile {
  std::string path, shown;  ///< shown: relative to the directory imported
  std::string series_uid, sop_uid, sop_class, modality, description, photometric, transfer_syntax;
  int64_t rows = 0, columns = 0, frames = 1;
  int samples = 1, bits_allocated = 0, bits_stored = 0, pixel_representation = 0;
  std::optional<double> spacing_between_slices, slice_thickness;
  uint64_t bytes = 0;
  int64_t mtime_ns = 0;
  /// A value of this file that is not what its attribute allows: refused when the file belongs to
  /// the series imported, not when another series of the directory has it.
  std::optional<Error> problem;
};

struct DicomScan {
  std::vector<DicomFile> files;
  std::vector<Frame> frames;
  std::vector<std::string> not_dicom, not_image;  ///< skipped files, as shown
};

std::string transfer_syntax_name(const gdcm::TransferSyntax& ts) {
  const char* uid = ts.GetString();
  if (!uid) return "unknown";
  gdcm::UIDs uids;
  const char* name = uids.SetFromUID(uid) ? uids.GetName() : nullptr;
  return name ? fmt::format("{} ({})", name, uid) : std::string(uid);
}

/// The frames of file `f` (number `file_index`), with their geometry and rescale, into `frames`.
void read_frames(const gdcm::DataSet& ds, DicomFile& f, size_t file_index, std::vector<Frame>& frames) {
  const std::string& path = f.path;
  if (const auto n = numbers_of(ds, kNumberOfFrames, "NumberOfFrames", path, 1)) {
    if ((*n)[0] < 1 || (*n)[0] != std::floor((*n)[0]) || (*n)[0] > 1e9)
      throw Error(Errc::format, fmt::format("NumberOfFrames is {:g}: it must be a whole number, at least 1", (*n)[0]))
          .with_file(path)
          .with_field("NumberOfFrames");
    f.frames = int64_t((*n)[0]);
  }
  if (const auto v = numbers_of(ds, kSpacingBetweenSlices, "SpacingBetweenSlices", path, 1))
    f.spacing_between_slices = (*v)[0];
  if (const auto v = numbers_of(ds, kSliceThickness, "SliceThickness", path, 1)) f.slice_thickness = (*v)[0];

  // Geometry and rescale: an enhanced multi-frame file says them per frame or once for all in
  // its functional groups (PS3.3 C.7.6.16); other files, at the top level.
  gdcm::SmartPointer<gdcm::SequenceOfItems> shared_sq, per_frame_sq;
  const gdcm::DataSet* shared = first_item(&ds, kSharedFunctionalGroupsSequence, shared_sq);
  if (ds.FindDataElement(kPerFrameFunctionalGroupsSequence))
    per_frame_sq = ds.GetDataElement(kPerFrameFunctionalGroupsSequence).GetValueAsSQ();
  const bool enhanced = per_frame_sq && per_frame_sq->GetNumberOfItems() > 0;
  if (enhanced && int64_t(per_frame_sq->GetNumberOfItems()) != f.frames)
    throw Error(Errc::format, fmt::format("PerFrameFunctionalGroupsSequence has {} items for {} frames (NumberOfFrames)",
                                          per_frame_sq->GetNumberOfItems(), f.frames))
        .with_file(path)
        .with_field("PerFrameFunctionalGroupsSequence");
  for (int64_t k = 0; k < f.frames; ++k) {
    const gdcm::DataSet* own = enhanced ? &per_frame_sq->GetItem(size_t(k) + 1).GetNestedDataSet() : nullptr;
    // The group `tag` of this frame: its own, else the shared one, else none (then the top level).
    auto group = [&](const gdcm::Tag& tag, gdcm::SmartPointer<gdcm::SequenceOfItems>& keep) -> const gdcm::DataSet* {
      if (const gdcm::DataSet* g = first_item(own, tag, keep)) return g;
      return first_item(shared, tag, keep);
    };
    gdcm::SmartPointer<gdcm::SequenceOfItems> keep_position, keep_orientation, keep_measures, keep_values;
    const gdcm::DataSet* pos_ds = group(kPlanePositionSequence, keep_position);
    const gdcm::DataSet* ori_ds = group(kPlaneOrientationSequence, keep_orientation);
    const gdcm::DataSet* measures_ds = group(kPixelMeasuresSequence, keep_measures);
    const gdcm::DataSet* values_ds = group(kPixelValueTransformationSequence, keep_values);
    Frame fr;
    fr.file = file_index;
    fr.index = k;
    if (const auto p = numbers_of(pos_ds ? *pos_ds : ds, kImagePositionPatient, "ImagePositionPatient", path, 3))
      fr.position = Vec3d((*p)[0], (*p)[1], (*p)[2]);
    if (const auto o = numbers_of(ori_ds ? *ori_ds : ds, kImageOrientationPatient, "ImageOrientationPatient", path, 6))
      fr.orientation = Cosines{(*o)[0], (*o)[1], (*o)[2], (*o)[3], (*o)[4], (*o)[5]};
    if (const auto s = numbers_of(measures_ds ? *measures_ds : ds, kPixelSpacing, "PixelSpacing", path, 2))
      fr.pixel_spacing = std::array<double, 2>{(*s)[0], (*s)[1]};
    const gdcm::DataSet& rescale = values_ds ? *values_ds : ds;
    if (const auto v = numbers_of(rescale, kRescaleSlope, "RescaleSlope", path, 1)) fr.slope = (*v)[0];
    if (const auto v = numbers_of(rescale, kRescaleIntercept, "RescaleIntercept", path, 1)) fr.intercept = (*v)[0];
    if (fr.slope == 0)
      throw Error(Errc::format, "RescaleSlope is 0: every value would be the intercept")
          .with_file(path)
          .with_field("RescaleSlope");
    frames.push_back(fr);
  }
  // A multi-frame file without per-frame positions (a legacy NM or a converted volume) places
  // its frames SpacingBetweenSlices apart along the normal; without that they cannot be placed.
  if (!enhanced && f.frames > 1) {
    Frame& first = frames[frames.size() - size_t(f.frames)];
    if (!first.position || !first.orientation || !f.spacing_between_slices)
      throw Error(Errc::unsupported,
                  fmt::format("NumberOfFrames is {}, but the file says where only its first frame lies (no "
                              "PerFrameFunctionalGroupsSequence, and no ImagePositionPatient, ImageOrientationPatient "
                              "and SpacingBetweenSlices to place the others)",
                              f.frames))
          .with_file(path)
          .with_field("PerFrameFunctionalGroupsSequence");
    const Cosines& c = *first.orientation;
    const Vec3d normal = cross(Vec3d(c[0], c[1], c[2]), Vec3d(c[3], c[4], c[5]));
    for (int64_t k = 1; k < f.frames; ++k)
      frames[frames.size() - size_t(f.frames) + size_t(k)].position =
          *first.position + normal * (*f.spacing_between_slices * double(k));
  }
}

/// Reads `path`'s header into `scan`; a file GDCM cannot read, or one without an image, is
/// recorded as skipped.
void scan_file(const std::string& path, const std::string& shown, DicomScan& scan) {
  gdcm::Reader reader;
  reader.SetFileName(path.c_str());
  // Up to the pixel data, whose value (and any float pixel data's) is skipped, not read.
  const std::set<gdcm::Tag> skip = {kFloatPixelData, kDoubleFloatPixelData, kPixelData};
  if (!reader.ReadUpToTag(kPixelData, skip)) {
    scan.not_dicom.push_back(shown);
    return;
  }
  const gdcm::DataSet& ds = reader.GetFile().GetDataSet();
  const auto rows = ushort_of(ds, kRows), columns = ushort_of(ds, kColumns);
  if (!rows || !columns) {
    scan.not_image.push_back(shown);  // a DICOMDIR, a structured report, a presentation state ...
    return;
  }
  DicomFile f;
  f.path = path;
  f.shown = shown;
  f.rows = *rows;
  f.columns = *columns;
  f.series_uid = text_of(ds, kSeriesInstanceUid).value_or("");
  f.sop_uid = text_of(ds, kSopInstanceUid).value_or("");
  f.sop_class = text_of(ds, kSopClassUid).value_or("");
  f.modality = text_of(ds, kModality).value_or("");
  f.description = text_of(ds, kSeriesDescription).value_or("");
  f.photometric = text_of(ds, kPhotometricInterpretation).value_or("MONOCHROME2");
  f.samples = ushort_of(ds, kSamplesPerPixel).value_or(1);
  f.bits_allocated = ushort_of(ds, kBitsAllocated).value_or(0);
  f.bits_stored = ushort_of(ds, kBitsStored).value_or(uint16_t(f.bits_allocated));
  f.pixel_representation = ushort_of(ds, kPixelRepresentation).value_or(0);
  f.transfer_syntax = transfer_syntax_name(reader.GetFile().GetHeader().GetDataSetTransferSyntax());
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0) {
    f.bytes = uint64_t(st.st_size);
    f.mtime_ns = int64_t(st.st_mtim.tv_sec) * 1000000000 + st.st_mtim.tv_nsec;
  }
  const size_t frames_before = scan.frames.size();
  try {
    read_frames(ds, f, scan.files.size(), scan.frames);
  } catch (const Error& e) {
    scan.frames.resize(frames_before);
    f.problem = e;
  }
  scan.files.push_back(std::move(f));
}

/// Every regular file under `dir` (recursively: a DICOMDIR export nests its series), sorted.
std::vector<fs::path> list_files(const std::string& dir) {
  std::vector<fs::path> files;
  std::error_code ec;
  fs::recursive_directory_iterator it(dir, fs::directory_options::skip_permission_denied, ec);
  if (ec) throw Error(Errc::io, fmt::format("cannot list the directory: {}", ec.message())).with_file(dir);
  for (; it != fs::recursive_directory_iterator(); it.increment(ec)) {
    if (ec) throw Error(Errc::io, fmt::format("cannot list the directory: {}", ec.message())).with_file(dir);
    std::error_code type_ec;
    if (it->is_regular_file(type_ec)) files.push_back(it->path());
  }
  std::sort(files.begin(), files.end());
  return files;
}

/// "a, b, c and 4 more"
std::string some_names(const std::vector<std::string>& names, size_t show = 3) {
  std::string s;
  for (size_t i = 0; i < names.size() && i < show; ++i) s += (i ? ", " : "") + names[i];
  if (names.size() > show) s += fmt::format(" and {} more", names.size() - show);
  return s;
}

// ------------------------------------------------------------------------------ series choice

struct SeriesInfo {
  std::string uid;
  int64_t frames = 0;
  std::string modality, description;
};

std::string series_label(const SeriesInfo& s) {
  std::string label = fmt::format("{} ({} slice{}", s.uid.empty() ? "(no SeriesInstanceUID)" : s.uid, s.frames,
                                  s.frames == 1 ? "" : "s");
  if (!s.modality.empty()) label += ", " + s.modality;
  if (!s.description.empty()) label += ", '" + s.description + "'";
  return label + ")";
}

/// The series of the scan, largest first (then by UID, so that the choice is repeatable).
std::vector<SeriesInfo> list_series(const DicomScan& scan) {
  std::map<std::string, SeriesInfo> by_uid;
  for (const DicomFile& f : scan.files) {
    SeriesInfo& s = by_uid[f.series_uid];
    s.uid = f.series_uid;
    s.frames += f.frames;
    if (s.modality.empty()) s.modality = f.modality;
    if (s.description.empty()) s.description = f.description;
  }
  std::vector<SeriesInfo> series;
  for (auto& [uid, s] : by_uid) series.push_back(s);
  std::stable_sort(series.begin(), series.end(),
                   [](const SeriesInfo& a, const SeriesInfo& b) { return a.frames > b.frames; });
  return series;
}

// ------------------------------------------------------------------------------ the volume

/// What the importer decided from the headers of the chosen series.
struct DicomVolume {
  std::string path;  ///< the directory (or file) imported
  bool directory = true;
  std::vector<DicomFile> files;  ///< of the chosen series only
  std::vector<Frame> frames;     ///< sorted along the normal: frames[z] is slice z
  std::vector<SeriesInfo> series;
  size_t chosen = 0;             ///< index into series
  std::string chosen_by;         ///< "--series", "largest" or "only"
  size_t skipped_not_dicom = 0, skipped_not_image = 0;
  Vec3s dims{0};
  Vec3d spacing{1.0}, origin{0.0};
  bool pixel_spacing_given = false;
  std::optional<Cosines> orientation;
  Vec3d normal{0, 0, 1};
  ElementType element = ElementType::u8;
  std::string summary;  ///< one line for the import's output (series chosen, the others)
};

std::optional<ElementType> element_of(int bits_allocated, int pixel_representation) {
  const bool is_signed = pixel_representation == 1;
  switch (bits_allocated) {
    case 8: return is_signed ? ElementType::i8 : ElementType::u8;
    case 16: return is_signed ? ElementType::i16 : ElementType::u16;
    case 32: return is_signed ? ElementType::i32 : ElementType::u32;
    default: return std::nullopt;
  }
}

std::string frame_name(const DicomVolume& v, const Frame& f) {
  const DicomFile& file = v.files[f.file];
  return file.frames > 1 ? fmt::format("{} frame {}", file.shown, f.index + 1) : file.shown;
}

std::string position_text(const Frame& f) {
  return fmt::format("({:g}, {:g}, {:g})", f.position->x, f.position->y, f.position->z);
}

std::string spacing_text(const std::optional<std::array<double, 2>>& s) {
  return s ? fmt::format("{:g}\\{:g}", (*s)[0], (*s)[1]) : std::string("(none)");
}

bool same_cosines(const Cosines& a, const Cosines& b) {
  for (size_t i = 0; i < a.size(); ++i)
    if (std::abs(a[i] - b[i]) > 1e-4) return false;
  return true;
}

std::string cosines_text(const Cosines& c) {
  return fmt::format("{:g}\\{:g}\\{:g}\\{:g}\\{:g}\\{:g}", c[0], c[1], c[2], c[3], c[4], c[5]);
}

/// Checks that every file of the series has the first one's size and pixel format, and one
/// channel of grey values.
void check_files_agree(const DicomVolume& v) {
  const DicomFile& a = v.files.front();
  for (const DicomFile& f : v.files) {
    if (f.samples != 1)
      throw Error(Errc::unsupported, fmt::format("SamplesPerPixel is {} ({}): colour images are not supported, only one "
                                                 "channel of grey values",
                                                 f.samples, f.photometric))
          .with_file(f.path)
          .with_field("SamplesPerPixel");
    if (f.photometric != "MONOCHROME1" && f.photometric != "MONOCHROME2")
      throw Error(Errc::unsupported, fmt::format("PhotometricInterpretation is {}: only grey values (MONOCHROME1, "
                                                 "MONOCHROME2) are supported",
                                                 f.photometric))
          .with_file(f.path)
          .with_field("PhotometricInterpretation");
    if (!element_of(f.bits_allocated, f.pixel_representation))
      throw Error(Errc::unsupported, fmt::format("BitsAllocated is {} (PixelRepresentation {}): brickyard reads 8, 16 "
                                                 "and 32 bits",
                                                 f.bits_allocated, f.pixel_representation))
          .with_file(f.path)
          .with_field("BitsAllocated");
    if (f.rows != a.rows || f.columns != a.columns)
      throw Error(Errc::format, fmt::format("{} is {} columns by {} rows, but {} is {} by {}: the slices of a series "
                                            "must all be the same size",
                                            f.shown, f.columns, f.rows, a.shown, a.columns, a.rows))
          .with_file(v.path)
          .with_field(f.rows != a.rows ? "Rows" : "Columns");
    if (f.bits_allocated != a.bits_allocated || f.pixel_representation != a.pixel_representation)
      throw Error(Errc::format, fmt::format("{} has BitsAllocated {} and PixelRepresentation {}, but {} has {} and {}: "
                                            "the slices of a series must all have one pixel format",
                                            f.shown, f.bits_allocated, f.pixel_representation, a.shown,
                                            a.bits_allocated, a.pixel_representation))
          .with_file(v.path)
          .with_field(f.bits_allocated != a.bits_allocated ? "BitsAllocated" : "PixelRepresentation");
  }
}

/// Sorts the frames along the slice normal and derives the grid: the normal is the cross product
/// of the orientation's row and column directions, each frame's place its position's projection
/// on it. The spacing between slices must be even: a gap that differs from the median gap by
/// more than 1% of it, or by more than 0.01 mm if that is more (positions are decimal strings of
/// at most 16 characters), is refused, as are two slices at one place.
void place_frames(DicomVolume& v) {
  const Frame& first = v.frames.front();
  const DicomFile& file0 = v.files[first.file];
  v.dims = {file0.columns, file0.rows, int64_t(v.frames.size())};

  // --- Orientation: one for all frames.
  for (const Frame& f : v.frames) {
    if (f.orientation.has_value() != first.orientation.has_value() ||
        (f.orientation && !same_cosines(*f.orientation, *first.orientation)))
      throw Error(Errc::format, fmt::format("{} has ImageOrientationPatient {}, but {} has {}: the slices of a series "
                                            "must all face one way",
                                            frame_name(v, f), f.orientation ? cosines_text(*f.orientation) : "(none)",
                                            frame_name(v, first),
                                            first.orientation ? cosines_text(*first.orientation) : "(none)"))
          .with_file(v.path)
          .with_field("ImageOrientationPatient");
  }
  v.orientation = first.orientation;
  if (v.orientation) {
    const Cosines& c = *v.orientation;
    const Vec3d row(c[0], c[1], c[2]), column(c[3], c[4], c[5]);
    v.normal = cross(row, column);
    const double n = length(v.normal);
    if (!(n > 0.5))
      throw Error(Errc::format, fmt::format("ImageOrientationPatient {} has parallel row and column directions",
                                            cosines_text(c)))
          .with_file(v.files[first.file].path)
          .with_field("ImageOrientationPatient");
    v.normal = v.normal / n;
  }

  // --- Pixel spacing: PixelSpacing is (row spacing, column spacing), the distance between rows
  // (along y) first; absent, 1 mm stands in and the provenance says so.
  for (const Frame& f : v.frames) {
    const bool differ = f.pixel_spacing.has_value() != first.pixel_spacing.has_value() ||
                        (f.pixel_spacing && (std::abs((*f.pixel_spacing)[0] - (*first.pixel_spacing)[0]) > 1e-4 ||
                                             std::abs((*f.pixel_spacing)[1] - (*first.pixel_spacing)[1]) > 1e-4));
    if (differ)
      throw Error(Errc::format, fmt::format("{} has PixelSpacing {}, but {} has {}: the slices of a series must all "
                                            "have one spacing",
                                            frame_name(v, f), spacing_text(f.pixel_spacing), frame_name(v, first),
                                            spacing_text(first.pixel_spacing)))
          .with_file(v.path)
          .with_field("PixelSpacing");
  }
  if (first.pixel_spacing) {
    v.pixel_spacing_given = true;
    v.spacing.x = (*first.pixel_spacing)[1];
    v.spacing.y = (*first.pixel_spacing)[0];
    for (int a = 0; a < 2; ++a)
      if (!(v.spacing[a] > 0))
        throw Error(Errc::format, fmt::format("PixelSpacing is {}: both must be positive", spacing_text(first.pixel_spacing)))
            .with_file(v.files[first.file].path)
            .with_field("PixelSpacing");
  }

  // --- One slice: nothing to sort; the slice spacing is what the file says it is, else 1.
  if (v.frames.size() == 1) {
    v.origin = first.position.value_or(Vec3d(0.0));
    const double dz = file0.spacing_between_slices.value_or(file0.slice_thickness.value_or(1.0));
    v.spacing.z = dz > 0 ? dz : 1.0;
    return;
  }
  for (const Frame& f : v.frames)
    if (!f.position || !f.orientation)
      throw Error(Errc::format, fmt::format("{} has no {}: the slices cannot be put in order", frame_name(v, f),
                                            !f.position ? "ImagePositionPatient" : "ImageOrientationPatient"))
          .with_file(v.files[f.file].path)
          .with_field(!f.position ? "ImagePositionPatient" : "ImageOrientationPatient");

  // --- Order along the normal (ties broken by file and frame, for a repeatable message).
  for (Frame& f : v.frames) f.along = dot(*f.position, v.normal);
  std::stable_sort(v.frames.begin(), v.frames.end(), [](const Frame& a, const Frame& b) { return a.along < b.along; });
  std::vector<double> gaps(v.frames.size() - 1);
  for (size_t i = 0; i + 1 < v.frames.size(); ++i) {
    gaps[i] = v.frames[i + 1].along - v.frames[i].along;
    if (gaps[i] <= 1e-4) {
      const Frame &a = v.frames[i], &b = v.frames[i + 1];
      const DicomFile &fa = v.files[a.file], &fb = v.files[b.file];
      const bool same_image = !fa.sop_uid.empty() && fa.sop_uid == fb.sop_uid && fa.frames == 1;
      throw Error(Errc::format, fmt::format("{} and {} lie at the same place along the slice normal ({} and {}){}: "
                                            "duplicate slices (or two acquisitions in one series)",
                                            frame_name(v, a), frame_name(v, b), position_text(a), position_text(b),
                                            same_image ? fmt::format(", both SOPInstanceUID {}: the same image twice",
                                                                     fa.sop_uid)
                                                       : std::string()))
          .with_file(v.path)
          .with_field("ImagePositionPatient");
    }
  }
  std::vector<double> sorted = gaps;
  std::sort(sorted.begin(), sorted.end());
  const size_t m = sorted.size() / 2;
  const double median = sorted.size() % 2 ? sorted[m] : 0.5 * (sorted[m - 1] + sorted[m]);
  const double tolerance = std::max(0.01 * median, 0.01);
  size_t irregular = 0, worst = 0;
  for (size_t i = 0; i < gaps.size(); ++i)
    if (std::abs(gaps[i] - median) > tolerance) {
      if (irregular == 0 || std::abs(gaps[i] - median) > std::abs(gaps[worst] - median)) worst = i;
      ++irregular;
    }
  if (irregular > 0) {
    const Frame &a = v.frames[worst], &b = v.frames[worst + 1];
    throw Error(Errc::format,
                fmt::format("irregular slice spacing: the gap between {} at {} and {} at {} is {:g} mm, the median gap "
                            "{:g} mm{} (slices must be evenly spaced, within 1% or 0.01 mm: a missing slice?)",
                            frame_name(v, a), position_text(a), frame_name(v, b), position_text(b), gaps[worst], median,
                            irregular > 1 ? fmt::format("; {} gaps of {} differ", irregular, gaps.size()) : std::string()))
        .with_file(v.path)
        .with_field("ImagePositionPatient");
  }
  v.spacing.z = (v.frames.back().along - v.frames.front().along) / double(v.frames.size() - 1);
  // brickyard's grid is axis-aligned, placed by spacing and origin only: x runs along the rows,
  // y down the columns and z along the normal, whatever directions the patient's axes take.
  // Turning the grid into the patient's frame would mean resampling (or a transform that every
  // renderer and the reference would have to apply), so the orientation's cosines are recorded
  // in the provenance, not applied, as NIfTI's affine is; the origin is the first slice's
  // position, exact for the axis-aligned series most scanners write.
  v.origin = *v.frames.front().position;
}

DicomVolume read_volume(const std::string& path, const DicomOptions& options) {
  quiet_gdcm();
  DicomVolume v;
  v.path = path;
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (st.type() == fs::file_type::not_found)
    throw Error(Errc::not_found, "cannot open: No such file or directory").with_file(path);
  v.directory = fs::is_directory(st);

  // --- Every file's header.
  DicomScan scan;
  if (v.directory) {
    const std::vector<fs::path> files = list_files(path);
    if (files.empty()) throw Error(Errc::not_found, "no DICOM files in this directory: it holds no files").with_file(path);
    for (const fs::path& p : files) scan_file(p.string(), p.lexically_relative(path).string(), scan);
  } else {
    check_readable_file(path);
    scan_file(path, fs::path(path).filename().string(), scan);
  }
  v.skipped_not_dicom = scan.not_dicom.size();
  v.skipped_not_image = scan.not_image.size();
  if (scan.files.empty()) {
    if (!v.directory)
      throw Error(Errc::format, scan.not_image.empty() ? "not a DICOM file: GDCM cannot read it"
                                                       : "a DICOM file without an image (no Rows and Columns)")
          .with_file(path);
    std::string why;
    if (!scan.not_dicom.empty())
      why = fmt::format("{} file{} that {} not DICOM ({})", scan.not_dicom.size(), scan.not_dicom.size() == 1 ? "" : "s",
                        scan.not_dicom.size() == 1 ? "is" : "are", some_names(scan.not_dicom));
    if (!scan.not_image.empty())
      why += fmt::format("{}{} DICOM file{} without an image ({})", why.empty() ? "" : ", and ", scan.not_image.size(),
                         scan.not_image.size() == 1 ? "" : "s", some_names(scan.not_image));
    throw Error(Errc::not_found, fmt::format("no DICOM {} in this directory: it holds {}",
                                             scan.not_image.empty() ? "files" : "images", why))
        .with_file(path);
  }

  // --- The series: the one asked for, else the largest.
  v.series = list_series(scan);
  std::string labels;
  for (const SeriesInfo& s : v.series) labels += (labels.empty() ? "" : ", ") + series_label(s);
  if (!options.series_uid.empty()) {
    const auto it = std::find_if(v.series.begin(), v.series.end(),
                                 [&](const SeriesInfo& s) { return s.uid == options.series_uid; });
    if (it == v.series.end())
      throw Error(Errc::invalid_argument, fmt::format("no series {} in {}: it holds {} series: {}", options.series_uid, path,
                                                      v.series.size(), labels))
          .with_field("--series");
    v.chosen = size_t(it - v.series.begin());
    v.chosen_by = "--series";
  } else {
    v.chosen = 0;
    v.chosen_by = v.series.size() == 1 ? "only" : "largest";
  }
  const std::string& uid = v.series[v.chosen].uid;
  std::vector<size_t> file_map(scan.files.size(), SIZE_MAX);
  for (size_t i = 0; i < scan.files.size(); ++i)
    if (scan.files[i].series_uid == uid) {
      file_map[i] = v.files.size();
      v.files.push_back(std::move(scan.files[i]));
    }
  for (Frame& f : scan.frames)
    if (file_map[f.file] != SIZE_MAX) {
      f.file = file_map[f.file];
      v.frames.push_back(f);
    }

  // --- What it holds, and where.
  for (const DicomFile& f : v.files)
    if (f.problem) throw *f.problem;
  check_files_agree(v);
  v.element = *element_of(v.files.front().bits_allocated, v.files.front().pixel_representation);
  place_frames(v);

  v.summary = fmt::format("DICOM series {}", series_label(v.series[v.chosen]));
  if (v.series.size() > 1) {
    std::string others;
    for (size_t i = 0; i < v.series.size(); ++i)
      if (i != v.chosen) others += (others.empty() ? "" : ", ") + series_label(v.series[i]);
    v.summary += fmt::format("{} of {} series; the others: {}{}",
                             v.chosen_by == "largest" ? ", the largest" : ", chosen by --series", v.series.size(), others,
                             v.chosen_by == "largest" ? " (choose one with --series UID)" : "");
  }
  if (const size_t skipped = v.skipped_not_dicom + v.skipped_not_image; skipped > 0)
    v.summary += skipped == 1 ? std::string("; skipped 1 file that is not a DICOM image")
                              : fmt::format("; skipped {} files that are not DICOM images", skipped);
  return v;
}

// ------------------------------------------------------------------------------ the source




class DicomSource final : public VolumeSource {
 public:
  DicomSource(DicomVolume v, const ConvertOptions& convert)
      : v_(std::move(v)), slice_elements_(size_t(v_.dims.x * v_.dims.y)) {
    for (const Frame& f : v_.frames) rescaled_ = rescaled_ || f.slope != 1 || f.intercept != 0;
    if (rescaled_) choose_scaled_type(convert);
    else if (!is_native(v_.element)) {
      // 32-bit pixels: one pass before the build measures their conversion to f32.
      type_ = ValueType::f32;
      conversion_ = scan_conversion(v_.dims, v_.element, [&](int64_t z0, int64_t z1, std::span<std::byte> out) {
        read_elements(z0, z1, out);
      });
      check_conversion(*conversion_, convert, v_.path);
      if (conversion_->min <= conversion_->max) range_ = ValueRange{conversion_->min, conversion_->max};
    } else {
      type_ = stored_type(v_.element);
    }
    release();
  }

  std::string name() const override { return v_.path; }
  Vec3s dims() const override { return v_.dims; }
  ValueType type() const override { return type_; }
  Vec3d spacing() const override { return v_.spacing; }
  Vec3d origin() const override { return v_.origin; }
  std::optional<ValueRange> value_range_hint() const override { return range_; }
  bool may_contain_nonfinite() const override { return conversion_ && conversion_->nonfinite > 0; }
  std::optional<ConversionReport> conversion() const override { return conversion_; }
  bool can_skip() const override { return true; }  // every slice is decoded from its own file
  void rewind() override { release(); }
  uint64_t input_bytes() const override { return uint64_t(volume(v_.dims)) * size_of(v_.element); }

  void read_slab(int64_t z0, int64_t z1, std::span<std::byte> out) override {
    BY_CHECK_EQ(out.size(), size_t(z1 - z0) * slice_elements_ * size_of(type_));
    const size_t n = slice_elements_;
    for (int64_t z = z0; z < z1; ++z) {
      const Frame& f = v_.frames[size_t(z)];
      const std::byte* in = frame_bytes(f);
      std::byte* dst = out.data() + size_t(z - z0) * n * size_of(type_);
      if (!rescaled_) {
        if (is_native(v_.element)) std::memcpy(dst, in, n * size_of(type_));
        else convert_elements(in, v_.element, n, dst);
        continue;
      }
      scaled_.resize(n);
      scale_elements(in, v_.element, n, f.slope, f.intercept, scaled_.data());
      // Integer types hold every scaled value exactly (checked when the source was opened).
      store_values(scaled_.data(), n, type_, dst);
    }
  }

  std::string describe_json() const override {
    const DicomFile& first = v_.files[v_.frames.front().file];
    uint64_t bytes = 0;
    int64_t mtime_ns = 0;
    std::set<std::string> syntaxes;
    for (const DicomFile& f : v_.files) {
      bytes += f.bytes;
      mtime_ns = std::max(mtime_ns, f.mtime_ns);
      syntaxes.insert(f.transfer_syntax);
    }
    nlohmann::json others = nlohmann::json::array();
    for (size_t i = 0; i < v_.series.size(); ++i)
      if (i != v_.chosen)
        others.push_back({{"uid", v_.series[i].uid}, {"slices", v_.series[i].frames}, {"modality", v_.series[i].modality}});
    nlohmann::json j = {{"kind", "dicom"},
                        {"path", v_.path},
                        {"series_uid", v_.series[v_.chosen].uid},
                        {"series_count", v_.series.size()},
                        {"series_chosen_by", v_.chosen_by},
                        {"other_series", others},
                        {"summary", v_.summary},
                        {"files", v_.files.size()},
                        {"bytes", bytes},
                        {"mtime_ns", mtime_ns},
                        {"first_file", first.shown},
                        {"last_file", v_.files[v_.frames.back().file].shown},
                        {"modality", first.modality},
                        {"sop_class_uid", first.sop_class},
                        {"transfer_syntaxes", syntaxes},
                        {"photometric_interpretation", first.photometric},
                        {"bits_allocated", first.bits_allocated},
                        {"bits_stored", first.bits_stored},
                        {"pixel_representation", first.pixel_representation},
                        {"element", to_string(v_.element)},
                        {"pixel_spacing_given", v_.pixel_spacing_given},
                        {"normal", {v_.normal.x, v_.normal.y, v_.normal.z}}};
    if (v_.orientation) j["orientation"] = *v_.orientation;
    else j["orientation"] = nullptr;
    if (v_.skipped_not_dicom) j["skipped_not_dicom"] = v_.skipped_not_dicom;
    if (v_.skipped_not_image) j["skipped_not_image"] = v_.skipped_not_image;
    if (rescaled_) {
      double slope_lo = INFINITY, slope_hi = -INFINITY, icpt_lo = INFINITY, icpt_hi = -INFINITY;
      for (const Frame& f : v_.frames) {
        slope_lo = std::min(slope_lo, f.slope), slope_hi = std::max(slope_hi, f.slope);
        icpt_lo = std::min(icpt_lo, f.intercept), icpt_hi = std::max(icpt_hi, f.intercept);
      }
      if (slope_lo == slope_hi && icpt_lo == icpt_hi) j["rescale"] = {{"slope", slope_lo}, {"intercept", icpt_lo}};
      else j["rescale"] = {{"slope", {slope_lo, slope_hi}}, {"intercept", {icpt_lo, icpt_hi}}, {"per_slice", true}};
    }
    if (conversion_) j["conversion"] = nlohmann::json::parse(conversion_->to_json());
    return j.dump();
  }

 private:
  /// The decoded pixels of frame `f`, in the element type and the host's byte order: its file is
  /// decoded whole (GDCM decodes a multi-frame file at once, compressed or not) and kept until a
  /// frame of another file is asked for, so that memory stays bounded by one file and a
  /// multi-frame file read slab by slab is decoded once per pass.
  const std::byte* frame_bytes(const Frame& f) {
    if (decoded_file_ != f.file) decode(f.file);
    return decoded_.data() + size_t(f.index) * slice_elements_ * size_of(v_.element);
  }

  void decode(size_t index) {
    release();
    const DicomFile& file = v_.files[index];
    gdcm::ImageReader reader;
    reader.SetFileName(file.path.c_str());
    if (!reader.Read())
      throw Error(Errc::format, fmt::format("GDCM cannot read the pixel data (transfer syntax {}): damaged, or a "
                                            "compression this GDCM build does not decode",
                                            file.transfer_syntax))
          .with_file(file.path)
          .with_field("PixelData");
    const gdcm::Image& image = reader.GetImage();
    const gdcm::PixelFormat& pf = image.GetPixelFormat();
    const int64_t frames = image.GetNumberOfDimensions() > 2 ? int64_t(image.GetDimension(2)) : 1;
    if (int64_t(image.GetDimension(0)) != file.columns || int64_t(image.GetDimension(1)) != file.rows ||
        frames != file.frames)
      throw Error(Errc::format, fmt::format("GDCM decodes {}x{}x{} pixels where the header says {}x{}x{} (Columns, "
                                            "Rows, NumberOfFrames)",
                                            image.GetDimension(0), image.GetDimension(1), frames, file.columns,
                                            file.rows, file.frames))
          .with_file(file.path)
          .with_field("PixelData");
    if (pf.GetSamplesPerPixel() != 1 || int(pf.GetBitsAllocated()) != file.bits_allocated ||
        int(pf.GetPixelRepresentation()) != file.pixel_representation)
      throw Error(Errc::format, fmt::format("GDCM decodes {} sample{} of {} bits (PixelRepresentation {}) where the "
                                            "header says 1 of {} ({})",
                                            pf.GetSamplesPerPixel(), pf.GetSamplesPerPixel() == 1 ? "" : "s",
                                            pf.GetBitsAllocated(), pf.GetPixelRepresentation(), file.bits_allocated,
                                            file.pixel_representation))
          .with_file(file.path)
          .with_field("PixelData");
    const size_t need = size_t(file.frames) * slice_elements_ * size_of(v_.element);
    // Uncompressed pixel data shorter than the image: GDCM pads it (and says so only on its
    // trace stream), so it is measured here.
    const gdcm::DataSet& ds = reader.GetFile().GetDataSet();
    if (ds.FindDataElement(kPixelData)) {
      const gdcm::ByteValue* bv = ds.GetDataElement(kPixelData).GetByteValue();
      if (bv && bv->GetLength() < need)
        throw Error(Errc::format, fmt::format("the pixel data is truncated: {} bytes, but {} columns by {} rows{} of {} "
                                              "bits need {}",
                                              bv->GetLength(), file.columns, file.rows,
                                              file.frames > 1 ? fmt::format(" by {} frames", file.frames) : std::string(),
                                              file.bits_allocated, need))
            .with_file(file.path)
            .with_field("PixelData");
    }
    if (image.GetBufferLength() != need)
      throw Error(Errc::format, fmt::format("GDCM decodes {} bytes of pixels where the header needs {}",
                                            image.GetBufferLength(), need))
          .with_file(file.path)
          .with_field("PixelData");
    decoded_.resize(need);
    if (!image.GetBuffer(reinterpret_cast<char*>(decoded_.data())))
      throw Error(Errc::format, fmt::format("GDCM cannot decode the pixel data (transfer syntax {}): damaged, or a "
                                            "compression this GDCM build does not decode",
                                            file.transfer_syntax))
          .with_file(file.path)
          .with_field("PixelData");
    decoded_file_ = index;
  }

  void release() {
    decoded_file_ = SIZE_MAX;
    decoded_.clear();
    decoded_.shrink_to_fit();
  }

  /// Slices [z0, z1) of the file's elements, unscaled, in the host's byte order.
  void read_elements(int64_t z0, int64_t z1, std::span<std::byte> out) {
    const size_t slice_bytes = slice_elements_ * size_of(v_.element);
    BY_CHECK_EQ(out.size(), size_t(z1 - z0) * slice_bytes);
    for (int64_t z = z0; z < z1; ++z)
      std::memcpy(out.data() + size_t(z - z0) * slice_bytes, frame_bytes(v_.frames[size_t(z)]), slice_bytes);
  }

  /// Rescaled values stay integers where every slope and intercept is whole and every value fits
  /// the pixels' stored type, or i16 (a CT's unsigned or signed pixels with intercept -1024, say);
  /// else they are f32. The pixel type's limits decide without reading when they fit already;
  /// otherwise one pass over the rescaled values measures them.
  void choose_scaled_type(const ConvertOptions& convert) {
    bool whole_params = true;
    double lo = INFINITY, hi = -INFINITY;
    const auto [elo, ehi] = element_limits(v_.element);
    for (const Frame& f : v_.frames) {
      whole_params = whole_params && is_whole(f.slope) && is_whole(f.intercept);
      const double a = f.slope * elo + f.intercept, b = f.slope * ehi + f.intercept;
      lo = std::min({lo, a, b}), hi = std::max({hi, a, b});
    }
    std::vector<ValueType> candidates;
    if (whole_params) {
      if (is_native(v_.element)) candidates.push_back(stored_type(v_.element));
      if (candidates.empty() || candidates.back() != ValueType::i16) candidates.push_back(ValueType::i16);
      for (ValueType t : candidates)
        if (range_fits(lo, hi, t)) {
          type_ = t;
          return;
        }
    }
    // The rescaled values are computed in double: the report measures them against f32.
    const auto read_scaled = [&](int64_t z0, int64_t z1, std::span<std::byte> out) {
      double* dst = reinterpret_cast<double*>(out.data());
      for (int64_t z = z0; z < z1; ++z) {
        const Frame& f = v_.frames[size_t(z)];
        scale_elements(frame_bytes(f), v_.element, slice_elements_, f.slope, f.intercept,
                       dst + size_t(z - z0) * slice_elements_);
      }
    };
    ConversionReport report = scan_conversion(v_.dims, ElementType::f64, read_scaled);
    if (report.min <= report.max) range_ = ValueRange{report.min, report.max};
    for (ValueType t : candidates)
      if (report.min <= report.max && range_fits(report.min, report.max, t)) {
        type_ = t;
        return;
      }
    check_conversion(report, convert, v_.path);
    type_ = ValueType::f32;
    conversion_ = report;
  }

  DicomVolume v_;
  size_t slice_elements_;
  bool rescaled_ = false;
  ValueType type_ = ValueType::f32;
  std::optional<ConversionReport> conversion_;
  std::optional<ValueRange> range_;
  size_t decoded_file_ = SIZE_MAX;
  std::vector<std::byte> decoded_;
  std::vector<double> scaled_;
};

}  // namespace

bool dicom_support() { return true; }

std::unique_ptr<VolumeSource> open_dicom_source(const std::string& path, const DicomOptions& options) {
  return std::make_unique<DicomSource>(read_volume(path, options), options.convert);
}

}  // namespace brickyard
