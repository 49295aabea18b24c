// MetaImage volumes (the format of ITK's MetaIO and 3D Slicer): a text header of `Key = Value`
// lines that ends with ElementDataFile, then the voxels in the same file (ElementDataFile =
// LOCAL, usually .mha) or in a detached data file (.mhd), raw or zlib-compressed. Raw data is
// memory-mapped through the raw source, which also converts element types a store does not
// hold; compressed data is inflated slab by slab, so nothing is ever decompressed or converted
// whole. No MetaIO library is linked: Debian packages none outside ITK, which is far too heavy
// a dependency for one header format.

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#if BRICKYARD_HAVE_ZLIB
#include <zlib.h>
#endif

#include "core/atomic_file.h"
#include "core/error.h"
#include "core/raw_volume.h"
#include "preprocess/volume_source.h"

namespace brickyard {
namespace {

namespace fs = std::filesystem;

// A MetaImage header is a few hundred bytes; a file with no ElementDataFile this far in is not one.
constexpr size_t kMaxHeaderBytes = size_t(1) << 20;

struct MetaHeader {
  ElementType type = ElementType::u8;
  std::string type_name;  // as written: MET_SHORT
  int ndims = 3;
  Vec3s dims{1};
  Vec3d spacing{1.0};
  Vec3d origin{0.0};
  bool little_endian = true;
  bool compressed = false;
  std::optional<uint64_t> compressed_size;
  int64_t header_size = 0;              // detached data: bytes to skip; -1: the data ends the file
  std::vector<double> transform;        // TransformMatrix as written (NDims^2 numbers); empty if absent
  std::vector<double> center_of_rotation;
  std::string anatomical_orientation;
  std::string data_file;                // resolved against the header's directory; empty: LOCAL
  std::string data_file_as_written;
  uint64_t data_offset = 0;             // LOCAL: the byte after the ElementDataFile line
};

// The element types brickyard reads, by MetaIO's names.
struct MetType {
  const char* name;
  ElementType type;
};
constexpr MetType kMetTypes[] = {{"MET_CHAR", ElementType::i8},   {"MET_UCHAR", ElementType::u8},
                                 {"MET_SHORT", ElementType::i16}, {"MET_USHORT", ElementType::u16},
                                 {"MET_INT", ElementType::i32},   {"MET_UINT", ElementType::u32},
                                 {"MET_FLOAT", ElementType::f32}, {"MET_DOUBLE", ElementType::f64}};

std::string known_type_names() {
  std::string names;
  for (const MetType& t : kMetTypes) names += (names.empty() ? "" : ", ") + std::string(t.name);
  return names;
}

ElementType met_element_type(const std::string& name, const std::string& path) {
  for (const MetType& t : kMetTypes)
    if (name == t.name) return t.type;
  // MetaIO's other names. Its longs are refused rather than guessed: MetaIO's type table makes
  // MET_LONG 4 bytes while writers hand it 8-byte longs (VTK 9.1 writes a volume of 64-bit
  // longs as MET_LONG, 4 bytes each), and 64-bit integers would not fit f32 anyway.
  static const char* const other[] = {"MET_LONG", "MET_ULONG", "MET_LONG_LONG", "MET_ULONG_LONG", "MET_ASCII_CHAR",
                                      "MET_STRING", "MET_FLOAT_MATRIX", "MET_NONE", "MET_OTHER"};
  const bool metaio_name = std::any_of(std::begin(other), std::end(other), [&](const char* o) { return name == o; }) ||
                           (name.rfind("MET_", 0) == 0 && name.size() > 6 && name.substr(name.size() - 6) == "_ARRAY");
  if (metaio_name)
    throw Error(Errc::unsupported,
                fmt::format("ElementType '{}' is not supported (brickyard reads {})", name, known_type_names()))
        .with_file(path)
        .with_field("ElementType");
  throw Error(Errc::format, fmt::format("unknown ElementType '{}' (MetaImage's scalar types: {})", name, known_type_names()))
      .with_file(path)
      .with_field("ElementType");
}

std::string trim(const std::string& s) {
  const auto a = s.find_first_not_of(" \t\r");
  const auto b = s.find_last_not_of(" \t\r");
  return a == std::string::npos ? std::string() : s.substr(a, b - a + 1);
}

std::vector<std::string> split_words(const std::string& text) {
  std::vector<std::string> out;
  size_t at = 0;
  while ((at = text.find_first_not_of(" \t", at)) != std::string::npos) {
    const size_t end = std::min(text.find_first_of(" \t", at), text.size());
    out.push_back(text.substr(at, end - at));
    at = end;
  }
  return out;
}

int64_t parse_integer(const std::string& text, const std::string& path, const std::string& key) {
  int64_t v = 0;
  const char* begin = text.data() + (text.size() > 1 && text[0] == '+' ? 1 : 0);
  const char* end = text.data() + text.size();
  const auto [p, ec] = std::from_chars(begin, end, v);
  if (ec == std::errc::result_out_of_range)
    throw Error(Errc::format, fmt::format("'{}' is out of range", text)).with_file(path).with_field(key);
  if (ec != std::errc() || p != end || text.empty())
    throw Error(Errc::format, fmt::format("'{}' is not an integer", text)).with_file(path).with_field(key);
  return v;
}

/// Exactly `count` finite numbers (`what` says what the count is, for the message).
std::vector<double> parse_numbers(const std::string& text, size_t count, const char* what, const std::string& path,
                                  const std::string& key) {
  std::vector<double> out;
  for (const std::string& word : split_words(text)) {
    double v = 0;
    const char* begin = word.data() + (word.size() > 1 && word[0] == '+' ? 1 : 0);
    const char* end = word.data() + word.size();
    const auto [p, ec] = std::from_chars(begin, end, v);
    if (ec != std::errc() || p != end || !std::isfinite(v))
      throw Error(Errc::format, fmt::format("'{}' is not a finite number", word)).with_file(path).with_field(key);
    out.push_back(v);
  }
  if (out.size() != count)
    throw Error(Errc::format, fmt::format("'{}' has {} numbers, {} needs {}", text, out.size(), what, count))
        .with_file(path)
        .with_field(key);
  return out;
}

bool parse_bool(const std::string& text, const std::string& path, const std::string& key) {
  std::string lower = text;
  std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  if (lower == "true" || lower == "1") return true;
  if (lower == "false" || lower == "0") return false;
  throw Error(Errc::format, fmt::format("'{}' is neither True nor False", text)).with_file(path).with_field(key);
}

/// The header's lines up to and including ElementDataFile, as key -> value (the last of a
/// repeated key wins, as in MetaIO); sets h.data_offset to the byte after that line.
std::map<std::string, std::string> read_keys(const std::string& path, MetaHeader& h) {
  check_readable_file(path);
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(Errc::io, fmt::format("cannot open: {}", std::strerror(errno))).with_file(path);
  std::string head(kMaxHeaderBytes, '\0');
  in.read(head.data(), std::streamsize(head.size()));
  head.resize(size_t(in.gcount()));

  std::map<std::string, std::string> keys;
  size_t at = 0;
  for (int line_no = 1; at < head.size(); ++line_no) {
    size_t eol = head.find('\n', at);
    if (eol == std::string::npos) {
      if (head.size() == kMaxHeaderBytes) break;  // the line goes on past what a header can be
      eol = head.size();
    }
    const std::string raw = head.substr(at, eol - at);
    // A binary file (or data reached without ElementDataFile) shows as control bytes; bytes
    // from 0x80 up may be UTF-8 in a comment or a file name.
    for (size_t i = 0; i < raw.size(); ++i) {
      const auto c = static_cast<unsigned char>(raw[i]);
      if ((c < 0x20 && c != '\t' && c != '\r') || c == 0x7f)
        throw Error(Errc::format, fmt::format("not a MetaImage header: byte {} (line {}) is 0x{:02x}, not text, and no "
                                              "ElementDataFile line came before it",
                                              at + i, line_no, c))
            .with_file(path);
    }
    at = eol + 1;
    const std::string line = trim(raw);
    if (line.empty()) continue;
    // MetaIO separates a key from its value with '=' (or ':', which it also accepts).
    const size_t sep = line.find_first_of("=:");
    const std::string key = sep == std::string::npos ? std::string() : trim(line.substr(0, sep));
    if (key.empty()) {
      std::string shown = line.size() > 80 ? line.substr(0, 80) + "..." : line;
      for (char& c : shown)
        if (static_cast<unsigned char>(c) >= 0x7f) c = '?';  // a binary file's first bytes, readable
      throw Error(Errc::format, fmt::format("not a MetaImage header: line {} '{}' is not Key = Value", line_no, shown))
          .with_file(path);
    }
    keys[key] = trim(line.substr(sep + 1));
    if (key == "ElementDataFile") {  // the last key: the data follows its line
      h.data_offset = std::min<uint64_t>(at, head.size());
      return keys;
    }
  }
  throw Error(Errc::format,
              head.size() == kMaxHeaderBytes
                  ? std::string("no ElementDataFile in the first 1 MiB: not a MetaImage header")
                  : std::string("no ElementDataFile line: a MetaImage header ends with ElementDataFile (LOCAL, or the "
                                "name of the data file)"))
      .with_file(path)
      .with_field("ElementDataFile");
}

MetaHeader parse_header(const std::string& path) {
  MetaHeader h;
  const std::map<std::string, std::string> keys = read_keys(path, h);
  auto find = [&](const char* key) -> const std::string* {
    auto it = keys.find(key);
    return it == keys.end() ? nullptr : &it->second;
  };
  auto need = [&](const char* key) -> const std::string& {
    const std::string* v = find(key);
    if (!v) throw Error(Errc::format, "missing required key").with_file(path).with_field(key);
    return *v;
  };
  // The first of several synonyms present, and its name.
  auto first_of = [&](std::initializer_list<const char*> names) -> std::pair<const char*, const std::string*> {
    for (const char* n : names)
      if (const std::string* v = find(n)) return {n, v};
    return {nullptr, nullptr};
  };

  if (const std::string* t = find("ObjectType"); t && *t != "Image")
    throw Error(Errc::unsupported, fmt::format("ObjectType '{}' is not an image (ObjectType = Image)", *t))
        .with_file(path)
        .with_field("ObjectType");
  const int64_t ndims = parse_integer(need("NDims"), path, "NDims");
  if (ndims != 2 && ndims != 3)
    throw Error(Errc::unsupported, fmt::format("NDims {} (only 2D images and 3D volumes)", ndims))
        .with_file(path)
        .with_field("NDims");
  h.ndims = int(ndims);
  const size_t n = size_t(ndims);

  const std::string& dim_text = need("DimSize");
  const std::vector<std::string> sizes = split_words(dim_text);
  if (sizes.size() != n)
    throw Error(Errc::format, fmt::format("'{}' has {} sizes, NDims {} needs {}", dim_text, sizes.size(), ndims, ndims))
        .with_file(path)
        .with_field("DimSize");
  for (size_t a = 0; a < n; ++a) {
    h.dims[int(a)] = parse_integer(sizes[a], path, "DimSize");
    if (h.dims[int(a)] < 1)
      throw Error(Errc::format, fmt::format("'{}': every size must be at least 1", dim_text)).with_file(path).with_field("DimSize");
  }

  h.type_name = need("ElementType");
  h.type = met_element_type(h.type_name, path);
  uint64_t bytes = size_of(h.type);
  for (int a = 0; a < 3; ++a)
    if (__builtin_mul_overflow(bytes, uint64_t(h.dims[a]), &bytes) || bytes > uint64_t(INT64_MAX))
      throw Error(Errc::format, fmt::format("sizes {}x{}x{} overflow a 64-bit byte count", h.dims.x, h.dims.y, h.dims.z))
          .with_file(path)
          .with_field("DimSize");

  if (const std::string* c = find("ElementNumberOfChannels")) {
    const int64_t channels = parse_integer(*c, path, "ElementNumberOfChannels");
    if (channels != 1)
      throw Error(Errc::unsupported, fmt::format("{} channels per voxel (only scalar images: 1 channel)", channels))
          .with_file(path)
          .with_field("ElementNumberOfChannels");
  }
  if (const std::string* b = find("BinaryData"); b && !parse_bool(*b, path, "BinaryData"))
    throw Error(Errc::unsupported, "ASCII data (BinaryData = False) is not supported").with_file(path).with_field("BinaryData");

  // MetaIO writes either name for the byte order (True: big endian); both present must agree.
  const std::string* msb_binary = find("BinaryDataByteOrderMSB");
  const std::string* msb_element = find("ElementByteOrderMSB");
  const bool big_binary = msb_binary && parse_bool(*msb_binary, path, "BinaryDataByteOrderMSB");
  const bool big_element = msb_element && parse_bool(*msb_element, path, "ElementByteOrderMSB");
  if (msb_binary && msb_element && big_binary != big_element)
    throw Error(Errc::format, fmt::format("ElementByteOrderMSB {} disagrees with BinaryDataByteOrderMSB {}", *msb_element,
                                          *msb_binary))
        .with_file(path)
        .with_field("ElementByteOrderMSB");
  h.little_endian = !(big_binary || big_element);

  if (const std::string* c = find("CompressedData")) h.compressed = parse_bool(*c, path, "CompressedData");
  if (const std::string* s = find("CompressedDataSize"); s && h.compressed) {
    const int64_t size = parse_integer(*s, path, "CompressedDataSize");
    if (size < 1)
      throw Error(Errc::format, fmt::format("CompressedDataSize {} (expected a number of bytes)", size))
          .with_file(path)
          .with_field("CompressedDataSize");
    h.compressed_size = uint64_t(size);
  }

  // ElementSize is the voxel's extent, which MetaIO takes for the spacing when none is given.
  if (auto [key, value] = first_of({"ElementSpacing", "ElementSize"}); key) {
    const auto s = parse_numbers(*value, n, "NDims", path, key);
    for (size_t a = 0; a < n; ++a) h.spacing[int(a)] = s[a];
    if (const std::string problem = spacing_problem(h.spacing); !problem.empty())
      throw Error(Errc::format, problem).with_file(path).with_field(key);
  }
  if (auto [key, value] = first_of({"Offset", "Position", "Origin"}); key) {
    const auto o = parse_numbers(*value, n, "NDims", path, key);
    for (size_t a = 0; a < n; ++a) h.origin[int(a)] = o[a];
  }
  // The direction cosines are recorded, not applied: a store's grid is axis-aligned, placed by
  // spacing and origin alone, so a rotated image is imported in its own index frame.
  if (auto [key, value] = first_of({"TransformMatrix", "Rotation", "Orientation"}); key)
    h.transform = parse_numbers(*value, n * n, "NDims x NDims", path, key);
  if (const std::string* c = find("CenterOfRotation")) h.center_of_rotation = parse_numbers(*c, n, "NDims", path, "CenterOfRotation");
  if (const std::string* o = find("AnatomicalOrientation")) h.anatomical_orientation = *o;
  // ElementMin and ElementMax are ignored: writers copy them from whatever the image came from,
  // and a stale range would mislead the builder more than no range at all.

  if (const std::string* s = find("HeaderSize")) {
    h.header_size = parse_integer(*s, path, "HeaderSize");
    if (h.header_size < -1)
      throw Error(Errc::format, fmt::format("HeaderSize {} (expected -1 or a number of bytes)", h.header_size))
          .with_file(path)
          .with_field("HeaderSize");
  }

  h.data_file_as_written = need("ElementDataFile");
  std::string lower = h.data_file_as_written;
  std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  if (lower == "local") {
    if (h.header_size != 0)
      throw Error(Errc::unsupported, fmt::format("HeaderSize {} with LOCAL data: HeaderSize applies to a detached data file",
                                                 h.header_size))
          .with_file(path)
          .with_field("HeaderSize");
    return h;
  }
  const std::vector<std::string> words = split_words(h.data_file_as_written);
  if ((!words.empty() && words[0] == "LIST") || h.data_file_as_written.find('%') != std::string::npos)
    throw Error(Errc::unsupported, fmt::format("'{}': data split over several files (LIST or a numbered pattern) is "
                                               "not supported; join the slices into one file",
                                               h.data_file_as_written))
        .with_file(path)
        .with_field("ElementDataFile");
  if (h.data_file_as_written.empty())
    throw Error(Errc::format, "empty (expected LOCAL or the name of the data file)").with_file(path).with_field("ElementDataFile");
  fs::path data(h.data_file_as_written);
  if (data.is_relative()) data = fs::path(path).parent_path() / data;
  h.data_file = data.string();
  return h;
}

/// The provenance both sources record: kind, files, element type, compression, byte order and
/// the orientation the grid does not apply.
void add_metaimage_fields(nlohmann::json& j, const MetaHeader& h, const std::string& path) {
  j["kind"] = "metaimage";
  j["path"] = path;
  j["data"] = h.data_file.empty() ? path : h.data_file;
  j["element_type"] = h.type_name;
  j["compression"] = h.compressed ? "zlib" : "none";
  j["endianness"] = h.little_endian ? "little" : "big";
  if (!h.transform.empty()) {
    j["transform"] = {{"matrix", h.transform}};
    if (!h.center_of_rotation.empty()) j["transform"]["center_of_rotation"] = h.center_of_rotation;
  }
  if (!h.anatomical_orientation.empty()) j["anatomical_orientation"] = h.anatomical_orientation;
}

std::string dims_text(const MetaHeader& h) {
  return h.ndims == 2 ? fmt::format("{}x{}", h.dims.x, h.dims.y) : fmt::format("{}x{}x{}", h.dims.x, h.dims.y, h.dims.z);
}

#if BRICKYARD_HAVE_ZLIB
/// Sequential reader of the zlib stream in bytes [offset, offset + size) of a file, restartable.
/// MetaIO writes zlib's compress2 output (RFC 1950); windowBits 15 + 32 also accepts a gzip
/// wrapper, as MetaIO's own reader does. (NRRD's reader goes through gzread, which passes
/// zlib-wrapped data through undecoded, so it cannot serve here.) Not thread-safe.
class InflateStream {
 public:
  InflateStream(const std::string& file, uint64_t offset, uint64_t size, uint64_t expected, const std::string& header,
                std::string what)
      : file_(file), offset_(offset), size_(size), expected_(expected), header_(header), what_(std::move(what)) {
    fd_ = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) throw Error(Errc::io, fmt::format("cannot open data: {}", std::strerror(errno))).with_file(file);
    if (inflateInit2(&zs_, 15 + 32) != Z_OK) {
      ::close(fd_);
      throw Error(Errc::resource, "cannot start zlib decoding").with_file(header);
    }
  }
  ~InflateStream() {
    inflateEnd(&zs_);
    ::close(fd_);
  }
  InflateStream(const InflateStream&) = delete;
  InflateStream& operator=(const InflateStream&) = delete;

  void read(std::byte* out, size_t n) {
    size_t done = 0;
    while (done < n) {
      if (ended_) throw short_data(position_ + done, false);
      const size_t want = std::min<size_t>(n - done, size_t(1) << 30);
      zs_.next_out = reinterpret_cast<Bytef*>(out + done);
      zs_.avail_out = uInt(want);
      const int rc = inflate(&zs_, Z_NO_FLUSH);
      const size_t got = want - zs_.avail_out;
      done += got;
      if (rc == Z_STREAM_END) ended_ = true;
      else if (rc != Z_OK && rc != Z_BUF_ERROR) throw corrupt(position_ + done, rc);
      else if (got == 0 && zs_.avail_in == 0 && !fill()) throw short_data(position_ + done, true);
    }
    position_ += n;
  }

  /// After the last voxel: the stream must end here (its checksum verified), with nothing more
  /// to decompress; a stream longer than DimSize says is refused as a raw file's would be.
  void expect_end() {
    while (!ended_) {
      unsigned char probe = 0;
      zs_.next_out = &probe;
      zs_.avail_out = 1;
      const int rc = inflate(&zs_, Z_NO_FLUSH);
      if (zs_.avail_out == 0)
        throw Error(Errc::format, fmt::format("the compressed data{} holds more than the {} bytes DimSize {} of {} needs",
                                              what_, expected_, dims_, type_))
            .with_file(header_)
            .with_field("DimSize");
      if (rc == Z_STREAM_END) ended_ = true;
      else if (rc != Z_OK && rc != Z_BUF_ERROR) throw corrupt(position_, rc);
      else if (zs_.avail_in == 0 && !fill())
        throw Error(Errc::format, fmt::format("the zlib stream{} does not end within its {} compressed bytes (its checksum "
                                              "is missing): the file is truncated or CompressedDataSize is wrong",
                                              what_, size_))
            .with_file(header_)
            .with_field("CompressedDataSize");
    }
  }

  void restart() {
    inflateReset(&zs_);
    zs_.avail_in = 0;
    consumed_ = position_ = 0;
    ended_ = false;
  }

  void describe(std::string dims, std::string type) {
    dims_ = std::move(dims);
    type_ = std::move(type);
  }

 private:
  /// More compressed bytes; false when all `size_` are consumed.
  bool fill() {
    if (consumed_ >= size_) return false;
    in_.resize(size_t(std::min<uint64_t>(size_ - consumed_, uint64_t(1) << 20)));
    const ssize_t got = ::pread(fd_, in_.data(), in_.size(), off_t(offset_ + consumed_));
    if (got < 0) throw Error(Errc::io, fmt::format("cannot read: {}", std::strerror(errno))).with_file(file_);
    if (got == 0)
      throw Error(Errc::format, fmt::format("the data file ends at byte {}, inside its compressed data", offset_ + consumed_))
          .with_file(file_);
    consumed_ += uint64_t(got);
    zs_.next_in = in_.data();
    zs_.avail_in = uInt(got);
    return true;
  }

  Error corrupt(uint64_t at, int rc) const {
    return std::move(Error(Errc::format, fmt::format("the zlib data{} is corrupt after {} decompressed bytes: {}", what_, at,
                                                     zs_.msg ? zs_.msg : fmt::format("zlib error {}", rc)))
                         .with_file(header_)
                         .with_field("CompressedData"));
  }
  Error short_data(uint64_t at, bool input_ran_out) const {
    return std::move(
        Error(Errc::format,
              fmt::format("the compressed data{} ends after {} decompressed bytes, but DimSize {} of {} needs {}{}", what_, at,
                          dims_, type_, expected_,
                          input_ran_out ? fmt::format(" (its {} bytes end before the zlib stream does: the file is truncated "
                                                      "or CompressedDataSize is wrong)",
                                                      size_)
                                        : ""))
            .with_file(header_)
            .with_field(input_ran_out ? "CompressedDataSize" : "CompressedData"));
  }

  std::string file_;
  uint64_t offset_, size_, expected_;
  std::string header_, what_, dims_, type_;
  int fd_ = -1;
  z_stream zs_{};
  std::vector<unsigned char> in_;
  uint64_t consumed_ = 0;  ///< compressed bytes handed to zlib
  uint64_t position_ = 0;  ///< decompressed bytes returned
  bool ended_ = false;
};

/// Compressed data, inflated slab by slab; element types a store does not hold are measured in
/// one pass before the build (as the NRRD stream source does) and converted on the way.
class MetaImageStreamSource final : public VolumeSource {
 public:
  MetaImageStreamSource(const std::string& path, const MetaHeader& h, uint64_t offset, uint64_t size,
                        const ConvertOptions& convert)
      : path_(path), h_(h), data_(h.data_file.empty() ? path : h.data_file),
        stream_(data_, offset, size, uint64_t(volume(h.dims)) * size_of(h.type), path,
                h.data_file.empty() ? std::string() : " in " + h.data_file_as_written),
        type_(stored_type(h.type)), compressed_bytes_(size) {
    stream_.describe(dims_text(h), h.type_name);
    struct stat st {};
    if (::stat(data_.c_str(), &st) == 0) {
      file_bytes_ = uint64_t(st.st_size);
      mtime_ns_ = int64_t(st.st_mtim.tv_sec) * 1000000000 + st.st_mtim.tv_nsec;
    }
    if (is_native(h_.type)) return;
    // One pass before the build: a conversion that would change values is refused first.
    conversion_ = scan_conversion(h_.dims, h_.type, [&](int64_t, int64_t, std::span<std::byte> out) {
      stream_.read(out.data(), out.size());
      if (!h_.little_endian) swap_element_bytes(out, size_of(h_.type));
    });
    stream_.expect_end();
    check_conversion(*conversion_, convert, path_);
    stream_.restart();
  }
  std::string name() const override { return path_; }
  Vec3s dims() const override { return h_.dims; }
  ValueType type() const override { return type_; }
  Vec3d spacing() const override { return h_.spacing; }
  Vec3d origin() const override { return h_.origin; }
  bool may_contain_nonfinite() const override {
    return conversion_ ? conversion_->nonfinite > 0 : h_.type == ElementType::f32;
  }
  std::optional<ValueRange> value_range_hint() const override {
    if (conversion_ && conversion_->min <= conversion_->max) return ValueRange{conversion_->min, conversion_->max};
    return std::nullopt;
  }
  std::optional<ConversionReport> conversion() const override { return conversion_; }
  bool can_skip() const override { return false; }
  void rewind() override {
    stream_.restart();
    next_z_ = 0;
  }
  void read_slab(int64_t z0, int64_t z1, std::span<std::byte> out) override {
    if (z0 != next_z_) throw Error(Errc::internal, "compressed MetaImage data is read in order").with_file(path_);
    next_z_ = z1;
    const size_t n = size_t((z1 - z0) * h_.dims.x * h_.dims.y);
    const size_t es = size_of(h_.type);
    BY_CHECK_EQ(out.size(), n * size_of(type_));
    if (is_native(h_.type)) {  // straight into out: no copy
      stream_.read(out.data(), out.size());
      if (!h_.little_endian) swap_element_bytes(out, es);
    } else {
      buffer_.resize(n * es);
      stream_.read(buffer_.data(), buffer_.size());
      if (!h_.little_endian) swap_element_bytes(buffer_, es);
      convert_elements(buffer_.data(), h_.type, n, out.data());
    }
    if (z1 == h_.dims.z) stream_.expect_end();
  }
  std::string describe_json() const override {
    nlohmann::json j = nlohmann::json::object();
    add_metaimage_fields(j, h_, path_);
    j["bytes"] = file_bytes_;
    j["compressed_bytes"] = compressed_bytes_;
    j["mtime_ns"] = mtime_ns_;
    if (conversion_) j["conversion"] = nlohmann::json::parse(conversion_->to_json());
    return j.dump();
  }
  uint64_t input_bytes() const override { return uint64_t(volume(h_.dims)) * size_of(h_.type); }

 private:
  std::string path_;
  MetaHeader h_;
  std::string data_;
  InflateStream stream_;
  ValueType type_;
  uint64_t compressed_bytes_ = 0, file_bytes_ = 0;
  int64_t mtime_ns_ = 0;
  std::optional<ConversionReport> conversion_;
  std::vector<std::byte> buffer_;
  int64_t next_z_ = 0;
};
#endif  // BRICKYARD_HAVE_ZLIB

/// Raw data: the raw source does the work (memory-mapped, converted where needed); this adds
/// the MetaImage provenance.
class MetaImageRawSource final : public VolumeSource {
 public:
  MetaImageRawSource(const std::string& path, const MetaHeader& h, std::unique_ptr<VolumeSource> raw)
      : path_(path), h_(h), raw_(std::move(raw)) {}
  std::string name() const override { return path_; }
  Vec3s dims() const override { return raw_->dims(); }
  ValueType type() const override { return raw_->type(); }
  Vec3d spacing() const override { return raw_->spacing(); }
  Vec3d origin() const override { return raw_->origin(); }
  bool may_contain_nonfinite() const override { return raw_->may_contain_nonfinite(); }
  std::optional<ValueRange> value_range_hint() const override { return raw_->value_range_hint(); }
  std::optional<ConversionReport> conversion() const override { return raw_->conversion(); }
  void read_slab(int64_t z0, int64_t z1, std::span<std::byte> out) override { raw_->read_slab(z0, z1, out); }
  void rewind() override { raw_->rewind(); }
  bool can_skip() const override { return raw_->can_skip(); }
  uint64_t input_bytes() const override { return raw_->input_bytes(); }
  std::string describe_json() const override {
    auto j = nlohmann::json::parse(raw_->describe_json());  // bytes, header_bytes, mtime_ns, conversion
    add_metaimage_fields(j, h_, path_);
    return j.dump();
  }

 private:
  std::string path_;
  MetaHeader h_;
  std::unique_ptr<VolumeSource> raw_;
};

}  // namespace

std::unique_ptr<VolumeSource> open_metaimage_source(const std::string& path, const ConvertOptions& convert) {
  const MetaHeader h = parse_header(path);
  const bool local = h.data_file.empty();
  const std::string data = local ? path : h.data_file;
  std::error_code ec;
  if (!local && fs::status(data, ec).type() == fs::file_type::not_found)
    throw Error(Errc::not_found, fmt::format("the data file '{}' does not exist (looked for {})", h.data_file_as_written, data))
        .with_file(path)
        .with_field("ElementDataFile");
  check_readable_file(data);  // a directory or a FIFO named as the data file
  const uint64_t file_bytes = fs::file_size(data, ec);
  if (ec) throw Error(Errc::io, fmt::format("cannot read the data file: {}", ec.message())).with_file(data);
  const uint64_t bytes = uint64_t(volume(h.dims)) * size_of(h.type);
  const std::string where = local ? "after the header" : fmt::format("in {}", h.data_file_as_written);

  // Where the data starts: after the header (LOCAL) or after HeaderSize bytes of the data
  // file; HeaderSize -1 means "the last `bytes` bytes of the file" (uncompressed only).
  uint64_t offset = local ? h.data_offset : 0;
  if (h.header_size == -1) {
    if (h.compressed)
      throw Error(Errc::format, "HeaderSize -1 (the data ends the file) needs uncompressed data").with_file(path).with_field("HeaderSize");
    if (file_bytes < bytes)
      throw Error(Errc::format, fmt::format("data is truncated: {} bytes {}, but DimSize {} of {} needs {}", file_bytes, where,
                                            dims_text(h), h.type_name, bytes))
          .with_file(path)
          .with_field("DimSize");
    offset = file_bytes - bytes;
  } else if (h.header_size > 0) {
    offset = uint64_t(h.header_size);
    if (offset > file_bytes)
      throw Error(Errc::format, fmt::format("HeaderSize {} is past the end of {}, which has {} bytes", offset,
                                            h.data_file_as_written, file_bytes))
          .with_file(path)
          .with_field("HeaderSize");
  }
  const uint64_t available = file_bytes - std::min(file_bytes, offset);

  if (!h.compressed) {
    // As for raw and NRRD files: a data size other than DimSize's is a mistake either way.
    if (available != bytes)
      throw Error(Errc::format, fmt::format("data is {}: {} bytes {}{}, but DimSize {} of {} needs {}",
                                            available < bytes ? "truncated" : "longer than DimSize says", available, where,
                                            !local && offset ? fmt::format(" (after {} skipped)", offset) : "", dims_text(h),
                                            h.type_name, bytes))
          .with_file(path)
          .with_field("DimSize");
    RawFileSpec spec;
    spec.dims = h.dims;
    spec.type = h.type;
    spec.convert = convert;
    spec.little_endian = h.little_endian;
    spec.header_bytes = offset;
    spec.spacing = h.spacing;
    spec.origin = h.origin;
    return std::make_unique<MetaImageRawSource>(path, h, open_raw_source(data, spec));
  }

  const uint64_t compressed = h.compressed_size.value_or(available);
  if (compressed > available)
    throw Error(Errc::format, fmt::format("CompressedDataSize {} is larger than the {} bytes {}", compressed, available, where))
        .with_file(path)
        .with_field("CompressedDataSize");
  if (compressed == 0)
    throw Error(Errc::format, fmt::format("no compressed data {}", where)).with_file(path).with_field("CompressedData");
#if BRICKYARD_HAVE_ZLIB
  return std::make_unique<MetaImageStreamSource>(path, h, offset, compressed, convert);
#else
  throw Error(Errc::unsupported, "compressed MetaImage data needs zlib; this brickyard was built without it")
      .with_file(path)
      .with_field("CompressedData");
#endif
}

}  // namespace brickyard
