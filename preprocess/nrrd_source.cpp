// NRRD volumes (http://teem.sourceforge.net/nrrd/format.html): a text header, then raw or
// gzip-compressed data, attached or in a detached data file. Raw data of a native type is
// memory-mapped through the raw source; other types are converted to f32 and gzip data is
// inflated slab by slab, so nothing is ever decompressed or converted whole.

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
#include <sstream>
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

// NRRD element types we read: the native ones, and others converted to f32.
enum class NrrdType { i8, u8, i16, u16, i32, u32, f32, f64 };

struct NrrdHeader {
  NrrdType type = NrrdType::u8;
  Vec3s dims{0};
  bool little_endian = true;
  std::string encoding = "raw";
  Vec3d spacing{1.0};
  Vec3d origin{0.0};
  std::string data_file;      // empty: attached
  uint64_t data_offset = 0;   // attached: bytes of header; detached: byte skip
  int64_t byte_skip = 0;
};

ElementType element_of(NrrdType t) {
  switch (t) {
    case NrrdType::i8: return ElementType::i8;
    case NrrdType::u8: return ElementType::u8;
    case NrrdType::i16: return ElementType::i16;
    case NrrdType::u16: return ElementType::u16;
    case NrrdType::i32: return ElementType::i32;
    case NrrdType::u32: return ElementType::u32;
    case NrrdType::f32: return ElementType::f32;
    case NrrdType::f64: return ElementType::f64;
  }
  return ElementType::u8;
}

size_t element_size(NrrdType t) {
  switch (t) {
    case NrrdType::i8: case NrrdType::u8: return 1;
    case NrrdType::i16: case NrrdType::u16: return 2;
    case NrrdType::i32: case NrrdType::u32: case NrrdType::f32: return 4;
    case NrrdType::f64: return 8;
  }
  return 1;
}

std::string trim(std::string s) {
  const auto a = s.find_first_not_of(" \t\r");
  const auto b = s.find_last_not_of(" \t\r");
  return a == std::string::npos ? std::string() : s.substr(a, b - a + 1);
}

NrrdType parse_type(const std::string& t, const std::string& path) {
  static const std::map<std::string, NrrdType> names = {
      {"signed char", NrrdType::i8}, {"int8", NrrdType::i8}, {"int8_t", NrrdType::i8},
      {"uchar", NrrdType::u8}, {"unsigned char", NrrdType::u8}, {"uint8", NrrdType::u8}, {"uint8_t", NrrdType::u8},
      {"short", NrrdType::i16}, {"short int", NrrdType::i16}, {"signed short", NrrdType::i16},
      {"signed short int", NrrdType::i16}, {"int16", NrrdType::i16}, {"int16_t", NrrdType::i16},
      {"ushort", NrrdType::u16}, {"unsigned short", NrrdType::u16}, {"unsigned short int", NrrdType::u16},
      {"uint16", NrrdType::u16}, {"uint16_t", NrrdType::u16},
      {"int", NrrdType::i32}, {"signed int", NrrdType::i32}, {"int32", NrrdType::i32}, {"int32_t", NrrdType::i32},
      {"uint", NrrdType::u32}, {"unsigned int", NrrdType::u32}, {"uint32", NrrdType::u32}, {"uint32_t", NrrdType::u32},
      {"float", NrrdType::f32}, {"double", NrrdType::f64}};
  auto it = names.find(t);
  if (it == names.end())
    throw Error(Errc::unsupported, fmt::format("NRRD type '{}' is not supported (8/16/32-bit integers, float, double)", t))
        .with_file(path)
        .with_field("type");
  return it->second;
}

std::vector<double> parse_doubles(const std::string& text, const std::string& path, const char* field) {
  std::vector<double> out;
  std::string cleaned = text;
  for (char& c : cleaned)
    if (c == '(' || c == ')' || c == ',') c = ' ';
  std::istringstream in(cleaned);
  std::string tok;
  while (in >> tok) {
    if (tok == "none" || tok == "nan") {
      out.push_back(NAN);
      continue;
    }
    try {
      size_t used = 0;
      out.push_back(std::stod(tok, &used));
      if (used != tok.size()) throw std::invalid_argument(tok);
    } catch (const std::exception&) {
      throw Error(Errc::format, fmt::format("'{}' is not a number", tok)).with_file(path).with_field(field);
    }
  }
  return out;
}

int64_t parse_integer(const std::string& text, const std::string& path, const char* field) {
  int64_t v = 0;
  const char* end = text.data() + text.size();
  const auto [p, ec] = std::from_chars(text.data(), end, v);
  if (ec == std::errc::result_out_of_range)
    throw Error(Errc::format, fmt::format("'{}' is out of range", text)).with_file(path).with_field(field);
  if (ec != std::errc() || p != end)
    throw Error(Errc::format, fmt::format("'{}' is not an integer", text)).with_file(path).with_field(field);
  return v;
}

NrrdHeader parse_header(const std::string& path) {
  check_readable_file(path);
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(Errc::io, fmt::format("cannot open: {}", std::strerror(errno))).with_file(path);
  std::string line;
  if (!std::getline(in, line) || line.rfind("NRRD000", 0) != 0)
    throw Error(Errc::format, "not a NRRD file (no NRRD000x magic)").with_file(path);
  NrrdHeader h;
  std::map<std::string, std::string> fields;
  bool ended = false;
  while (std::getline(in, line)) {
    line = trim(line);
    if (line.empty()) {
      ended = true;
      break;
    }
    if (line[0] == '#') continue;
    if (line.find(":=") != std::string::npos) continue;  // key/value pairs carry no geometry
    const auto colon = line.find(": ");
    if (colon == std::string::npos) throw Error(Errc::format, fmt::format("malformed header line '{}'", line)).with_file(path);
    std::string key = line.substr(0, colon);
    std::transform(key.begin(), key.end(), key.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    fields[key] = trim(line.substr(colon + 2));
    if (key == "data file" || key == "datafile") break;  // detached data: the header ends here
  }
  auto need = [&](const char* key) -> const std::string& {
    auto it = fields.find(key);
    if (it == fields.end()) throw Error(Errc::format, "missing required field").with_file(path).with_field(key);
    return it->second;
  };
  h.type = parse_type(need("type"), path);
  if (need("dimension") != "3")
    throw Error(Errc::unsupported, fmt::format("dimension {} (only 3D volumes)", need("dimension"))).with_file(path).with_field("dimension");
  const auto sizes = parse_doubles(need("sizes"), path, "sizes");
  // Below 2^53 each (exact as doubles, and convertible); the byte count is checked below.
  if (sizes.size() != 3 ||
      std::any_of(sizes.begin(), sizes.end(), [](double s) { return !(s >= 1 && s <= 0x1p53) || s != std::floor(s); }))
    throw Error(Errc::format, fmt::format("'{}' is not three positive sizes", need("sizes"))).with_file(path).with_field("sizes");
  h.dims = {int64_t(sizes[0]), int64_t(sizes[1]), int64_t(sizes[2])};
  uint64_t bytes = element_size(h.type);
  for (int a = 0; a < 3; ++a)
    if (__builtin_mul_overflow(bytes, uint64_t(h.dims[a]), &bytes) || bytes > uint64_t(INT64_MAX))
      throw Error(Errc::format, fmt::format("sizes {}x{}x{} overflow a 64-bit byte count", h.dims.x, h.dims.y, h.dims.z))
          .with_file(path)
          .with_field("sizes");
  h.encoding = need("encoding");
  if (h.encoding == "gz") h.encoding = "gzip";
  if (h.encoding != "raw" && h.encoding != "gzip")
    throw Error(Errc::unsupported, fmt::format("encoding '{}' is not supported (raw, gzip)", h.encoding))
        .with_file(path)
        .with_field("encoding");
  if (auto it = fields.find("endian"); it != fields.end()) {
    if (it->second != "little" && it->second != "big")
      throw Error(Errc::format, fmt::format("endian '{}'", it->second)).with_file(path).with_field("endian");
    h.little_endian = it->second == "little";
  } else if (element_size(h.type) > 1 && h.encoding == "raw") {
    throw Error(Errc::format, "missing required field for multi-byte data").with_file(path).with_field("endian");
  }
  if (auto it = fields.find("spacings"); it != fields.end()) {
    const auto s = parse_doubles(it->second, path, "spacings");
    if (s.size() != 3) throw Error(Errc::format, "expected 3 spacings").with_file(path).with_field("spacings");
    for (int a = 0; a < 3; ++a) h.spacing[a] = std::isfinite(s[size_t(a)]) ? s[size_t(a)] : 1.0;
  } else if (auto sd = fields.find("space directions"); sd != fields.end()) {
    const auto v = parse_doubles(sd->second, path, "space directions");
    if (v.size() != 9) throw Error(Errc::format, "expected 3 direction vectors").with_file(path).with_field("space directions");
    for (int a = 0; a < 3; ++a) h.spacing[a] = std::sqrt(v[size_t(3 * a)] * v[size_t(3 * a)] + v[size_t(3 * a + 1)] * v[size_t(3 * a + 1)] + v[size_t(3 * a + 2)] * v[size_t(3 * a + 2)]);
  }
  if (const std::string problem = spacing_problem(h.spacing); !problem.empty())
    throw Error(Errc::format, problem)
        .with_file(path)
        .with_field(fields.count("spacings") ? "spacings" : "space directions");
  if (auto it = fields.find("space origin"); it != fields.end()) {
    const auto o = parse_doubles(it->second, path, "space origin");
    if (o.size() != 3) throw Error(Errc::format, "expected 3 coordinates").with_file(path).with_field("space origin");
    h.origin = {o[0], o[1], o[2]};
  }
  if (auto it = fields.find("byte skip"); it != fields.end()) {
    h.byte_skip = parse_integer(it->second, path, "byte skip");
    if (h.byte_skip < -1)
      throw Error(Errc::format, fmt::format("byte skip {} (expected -1 or a number of bytes)", h.byte_skip))
          .with_file(path)
          .with_field("byte skip");
  }
  if (auto it = fields.find("data file"); it != fields.end()) h.data_file = it->second;
  if (auto it = fields.find("datafile"); it != fields.end()) h.data_file = it->second;
  if (h.data_file.empty()) {
    if (!ended) throw Error(Errc::format, "header never ends (no blank line before the data)").with_file(path);
    h.data_offset = uint64_t(in.tellg());
  } else {
    if (h.data_file.find("%") != std::string::npos || h.data_file == "LIST")
      throw Error(Errc::unsupported, "multi-file data is not supported").with_file(path).with_field("data file");
    fs::path data(h.data_file);
    if (data.is_relative()) data = fs::path(path).parent_path() / data;
    h.data_file = data.string();
  }
  return h;
}

/// Sequential byte reader over raw or gzip data, restartable.
class ByteStream {
 public:
  ByteStream(const std::string& file, uint64_t offset, bool gzip, const std::string& nrrd_path)
      : file_(file), offset_(offset), gzip_(gzip), nrrd_path_(nrrd_path) {
    open();
  }
  ~ByteStream() { close(); }

  void read(std::byte* out, size_t n) {
    size_t done = 0;
    while (done < n) {
      const size_t want = std::min<size_t>(n - done, size_t(1) << 30);
      ssize_t got = 0;
#if BRICKYARD_HAVE_ZLIB
      if (gzip_) got = gzread(gz_, out + done, unsigned(want));
      else
#endif
        got = ::read(fd_, out + done, want);
#if BRICKYARD_HAVE_ZLIB
      if (gzip_ && got < 0) {
        int code = 0;
        const char* why = gzerror(gz_, &code);
        throw Error(Errc::format, fmt::format("the gzip data is corrupt after {} decompressed bytes: {}", position_ + done,
                                              why && *why ? why : "zlib error"))
            .with_file(file_);
      }
#endif
      if (got <= 0)
        throw Error(Errc::format, fmt::format("{} ends after {} bytes but its sizes need {}: the file is truncated or its "
                                              "sizes are wrong",
                                              gzip_ ? "the decompressed data" : "the data", position_ + done, position_ + n))
            .with_file(gzip_ ? file_ : nrrd_path_);
      done += size_t(got);
    }
    position_ += n;
  }

  void restart() {
    close();
    open();
  }

 private:
  void open() {
    position_ = 0;
    check_readable_file(file_);
    fd_ = ::open(file_.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) throw Error(Errc::io, fmt::format("cannot open data: {}", std::strerror(errno))).with_file(file_);
    if (::lseek(fd_, off_t(offset_), SEEK_SET) < 0)
      throw Error(Errc::io, fmt::format("cannot seek: {}", std::strerror(errno))).with_file(file_);
#if BRICKYARD_HAVE_ZLIB
    if (gzip_) {
      // zlib reads data without a gzip header through unchanged: check the magic ourselves.
      unsigned char magic[2] = {0, 0};
      const ssize_t got = ::pread(fd_, magic, 2, off_t(offset_));
      if (got != 2 || magic[0] != 0x1f || magic[1] != 0x8b) {
        close();
        throw Error(Errc::format, got != 2 ? fmt::format("the header says encoding gzip, but no data follows at byte {}", offset_)
                                           : fmt::format("the header says encoding gzip, but the data at byte {} starts "
                                                         "with {:02x} {:02x}, not gzip's 1f 8b",
                                                         offset_, magic[0], magic[1]))
            .with_file(file_)
            .with_field("encoding");
      }
      gz_ = gzdopen(fd_, "rb");
      if (!gz_) throw Error(Errc::resource, "cannot start gzip decoding").with_file(file_);
      gzbuffer(gz_, 1 << 20);
      fd_ = -1;  // owned by gz_ now
    }
#else
    if (gzip_) throw Error(Errc::unsupported, "gzip NRRD needs zlib; this brickyard was built without it").with_file(nrrd_path_);
#endif
  }
  void close() {
#if BRICKYARD_HAVE_ZLIB
    if (gz_) gzclose(gz_);
    gz_ = nullptr;
#endif
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }

  std::string file_;
  uint64_t offset_;
  bool gzip_;
  std::string nrrd_path_;
  int fd_ = -1;
#if BRICKYARD_HAVE_ZLIB
  gzFile gz_ = nullptr;
#endif
  uint64_t position_ = 0;
};

/// Streams and converts: gzip data, or element types brickyard does not store natively.
class NrrdStreamSource final : public VolumeSource {
 public:
  NrrdStreamSource(const std::string& path, const NrrdHeader& h, uint64_t data_offset, const ConvertOptions& convert)
      : path_(path), h_(h), stream_(h.data_file.empty() ? path : h.data_file, data_offset, h.encoding == "gzip", path),
        element_(element_of(h.type)), type_(stored_type(element_)) {
    if (is_native(element_)) return;
    // One pass before the build: a conversion that would change values is refused first.
    conversion_ = scan_conversion(h_.dims, element_, [&](int64_t, int64_t, std::span<std::byte> out) {
      stream_.read(out.data(), out.size());
      if (!h_.little_endian) swap_element_bytes(out, size_of(element_));
    });
    check_conversion(*conversion_, convert, path_);
    stream_.restart();
  }
  std::string name() const override { return path_; }
  Vec3s dims() const override { return h_.dims; }
  ValueType type() const override { return type_; }
  Vec3d spacing() const override { return h_.spacing; }
  Vec3d origin() const override { return h_.origin; }
  bool may_contain_nonfinite() const override {
    return conversion_ ? conversion_->nonfinite > 0 : element_ == ElementType::f32;
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
    if (z0 != next_z_) throw Error(Errc::internal, "NRRD streams are read in order").with_file(path_);
    next_z_ = z1;
    const size_t n = size_t((z1 - z0) * h_.dims.x * h_.dims.y);
    const size_t es = element_size(h_.type);
    buffer_.resize(n * es);
    stream_.read(buffer_.data(), buffer_.size());
    if (!h_.little_endian) swap_element_bytes(buffer_, es);
    BY_CHECK_EQ(out.size(), n * size_of(type_));
    convert_elements(buffer_.data(), element_, n, out.data());
  }
  std::string describe_json() const override {
    std::error_code ec;
    const std::string data = h_.data_file.empty() ? path_ : h_.data_file;
    nlohmann::json j = {{"kind", "nrrd"}, {"path", path_}, {"encoding", h_.encoding},
                        {"bytes", uint64_t(fs::file_size(data, ec))}};
    if (conversion_) j["conversion"] = nlohmann::json::parse(conversion_->to_json());
    return j.dump();
  }
  uint64_t input_bytes() const override { return uint64_t(volume(h_.dims)) * element_size(h_.type); }

 private:
  std::string path_;
  NrrdHeader h_;
  ByteStream stream_;
  ElementType element_;
  ValueType type_;
  std::optional<ConversionReport> conversion_;
  std::vector<std::byte> buffer_;
  int64_t next_z_ = 0;
};

/// Native raw data: the raw source does the work (memory-mapped); this adds NRRD provenance.
class NrrdRawSource final : public VolumeSource {
 public:
  NrrdRawSource(const std::string& path, std::unique_ptr<VolumeSource> raw) : path_(path), raw_(std::move(raw)) {}
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
    auto j = nlohmann::json::parse(raw_->describe_json());
    j["kind"] = "nrrd";
    j["data"] = j["path"];
    j["path"] = path_;
    return j.dump();
  }

 private:
  std::string path_;
  std::unique_ptr<VolumeSource> raw_;
};

}  // namespace

std::unique_ptr<VolumeSource> open_nrrd_source(const std::string& path, const ConvertOptions& convert) {
  const NrrdHeader h = parse_header(path);
  const std::string data = h.data_file.empty() ? path : h.data_file;
  const uint64_t elements = uint64_t(volume(h.dims));
  const uint64_t bytes = elements * element_size(h.type);
  std::error_code ec;
  const uint64_t file_bytes = fs::file_size(data, ec);
  if (ec) throw Error(Errc::io, fmt::format("cannot read the data file: {}", ec.message())).with_file(data);

  // Where the data starts: after the header (attached) or after `byte skip` bytes; -1 means
  // "the last `bytes` bytes of the file" (raw only).
  uint64_t offset = h.data_file.empty() ? h.data_offset : 0;
  if (h.byte_skip == -1) {
    if (h.encoding != "raw") throw Error(Errc::format, "byte skip -1 needs raw encoding").with_file(path).with_field("byte skip");
    if (file_bytes < bytes)
      throw Error(Errc::format, fmt::format("data file has {} bytes, the sizes need {}", file_bytes, bytes)).with_file(data);
    offset = file_bytes - bytes;
  } else {
    offset += uint64_t(std::max<int64_t>(0, h.byte_skip));
    if (offset > file_bytes)
      throw Error(Errc::format, fmt::format("the data would start at byte {}, past the end of its {}-byte file", offset,
                                            file_bytes))
          .with_file(path)
          .with_field("byte skip");
  }

  if (h.encoding == "raw") {
    if (file_bytes != offset + bytes)
      throw Error(Errc::format, fmt::format("data is {}: {} bytes after the header, but {}x{}x{} needs {}",
                                            file_bytes < offset + bytes ? "truncated" : "longer than the sizes say",
                                            file_bytes - std::min(file_bytes, offset), h.dims.x, h.dims.y, h.dims.z, bytes))
          .with_file(path)
          .with_field("sizes");
    RawFileSpec spec;
    spec.dims = h.dims;
    spec.type = element_of(h.type);
    spec.convert = convert;
    spec.little_endian = h.little_endian;
    spec.header_bytes = offset;
    spec.spacing = h.spacing;
    spec.origin = h.origin;
    return std::make_unique<NrrdRawSource>(path, open_raw_source(data, spec));
  }
  if (h.encoding == "raw" && file_bytes < offset + bytes)
    throw Error(Errc::format, fmt::format("data is truncated: {} bytes after the header, {}x{}x{} needs {}",
                                          file_bytes - std::min(file_bytes, offset), h.dims.x, h.dims.y, h.dims.z, bytes))
        .with_file(path)
        .with_field("sizes");
  return std::make_unique<NrrdStreamSource>(path, h, offset, convert);
}

}  // namespace brickyard
