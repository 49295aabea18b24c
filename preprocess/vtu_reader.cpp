// VTK XML UnstructuredGrid (.vtu) and ParaView collection (.pvd) readers.
//
// The XML is parsed by expat into a small element tree. Raw appended data is not XML, so the
// parser is stopped at the <AppendedData> start tag and the bytes after its '_' marker are
// read directly. A DataArray's bytes (inline base64, appended raw or appended base64, zlib
// blocks or not) come out of one block reader; ASCII arrays are parsed to the same host-order
// bytes, so conversion to points, indices and scalars happens in one place.

#include <expat.h>
#include <zlib.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cctype>
#include <charconv>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <memory>
#include <optional>
#include <string_view>
#include <vector>

#include <fmt/format.h>

#include "core/atomic_file.h"
#include "core/error.h"
#include "preprocess/mesh_readers.h"

namespace brickyard {
namespace {

namespace fs = std::filesystem;

[[noreturn]] void fail(Errc code, const std::string& path, std::string message) {
  throw Error(code, std::move(message)).with_file(path);
}

bool is_space(char c) { return c == ' ' || c == '\n' || c == '\r' || c == '\t'; }

std::string read_whole_file(const std::string& path) {
  check_readable_file(path);
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) fail(Errc::io, path, fmt::format("cannot open: {}", std::strerror(errno)));
  std::string bytes;
  char buf[1 << 16];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) bytes.append(buf, n);
  const bool bad = std::ferror(f);
  const int err = errno;
  std::fclose(f);
  if (bad) fail(Errc::io, path, fmt::format("cannot read: {}", std::strerror(err)));
  return bytes;
}

// ---------------------------------------------------------------------------------------------
// XML tree (expat)

struct XmlElement {
  std::string name;
  std::vector<std::pair<std::string, std::string>> attributes;
  std::string text;  // character data, kept only for DataArray elements
  std::vector<std::unique_ptr<XmlElement>> children;
  uint64_t line = 0;

  const std::string* attr(std::string_view key) const {
    for (const auto& [k, v] : attributes)
      if (k == key) return &v;
    return nullptr;
  }
  const XmlElement* child(std::string_view n) const {
    for (const auto& c : children)
      if (c->name == n) return c.get();
    return nullptr;
  }
  std::vector<const XmlElement*> children_named(std::string_view n) const {
    std::vector<const XmlElement*> out;
    for (const auto& c : children)
      if (c->name == n) out.push_back(c.get());
    return out;
  }
};

struct XmlDocument {
  std::unique_ptr<XmlElement> root;
  std::string bytes;              // the whole file
  bool has_appended = false;
  std::string appended_encoding;  // "raw" or "base64"
  size_t appended_begin = 0;      // the byte after the '_' marker
};

struct ParseState {
  XML_Parser parser = nullptr;
  XmlDocument* doc = nullptr;
  std::vector<XmlElement*> stack;
  bool stopped_at_appended = false;
  size_t appended_tag_end = 0;
};

void XMLCALL on_start(void* user, const XML_Char* name, const XML_Char** attrs) {
  auto* s = static_cast<ParseState*>(user);
  auto e = std::make_unique<XmlElement>();
  e->name = name;
  e->line = XML_GetCurrentLineNumber(s->parser);
  for (int i = 0; attrs[i]; i += 2) e->attributes.emplace_back(attrs[i], attrs[i + 1]);
  XmlElement* raw = e.get();
  if (s->stack.empty()) s->doc->root = std::move(e);
  else s->stack.back()->children.push_back(std::move(e));
  s->stack.push_back(raw);
  if (raw->name == "AppendedData") {
    // Its content is not XML when raw: stop here and read the bytes after the tag directly.
    s->stopped_at_appended = true;
    s->appended_tag_end = size_t(XML_GetCurrentByteIndex(s->parser)) + size_t(XML_GetCurrentByteCount(s->parser));
    XML_StopParser(s->parser, XML_FALSE);
  }
}

void XMLCALL on_end(void* user, const XML_Char*) {
  auto* s = static_cast<ParseState*>(user);
  if (!s->stack.empty()) s->stack.pop_back();
}

void XMLCALL on_text(void* user, const XML_Char* text, int len) {
  auto* s = static_cast<ParseState*>(user);
  if (!s->stack.empty() && s->stack.back()->name == "DataArray") s->stack.back()->text.append(text, size_t(len));
}

XmlDocument parse_xml(const std::string& path) {
  XmlDocument doc;
  doc.bytes = read_whole_file(path);
  ParseState state;
  state.doc = &doc;
  std::unique_ptr<std::remove_pointer_t<XML_Parser>, decltype(&XML_ParserFree)> parser(XML_ParserCreate(nullptr),
                                                                                       &XML_ParserFree);
  if (!parser) fail(Errc::resource, path, "cannot create an XML parser");
  state.parser = parser.get();
  XML_SetUserData(parser.get(), &state);
  XML_SetElementHandler(parser.get(), on_start, on_end);
  XML_SetCharacterDataHandler(parser.get(), on_text);

  constexpr size_t chunk = size_t(1) << 26;  // XML_Parse takes an int length
  size_t pos = 0;
  do {
    const size_t n = std::min(chunk, doc.bytes.size() - pos);
    const bool final = pos + n == doc.bytes.size();
    if (XML_Parse(parser.get(), doc.bytes.data() + pos, int(n), final) == XML_STATUS_ERROR) {
      if (state.stopped_at_appended) break;
      fail(Errc::format, path,
           fmt::format("not well-formed XML at line {}, column {}: {}", XML_GetCurrentLineNumber(parser.get()),
                       XML_GetCurrentColumnNumber(parser.get()), XML_ErrorString(XML_GetErrorCode(parser.get()))));
    }
    pos += n;
  } while (pos < doc.bytes.size());
  if (!doc.root) fail(Errc::format, path, "no XML element found");

  if (state.stopped_at_appended) {
    const XmlElement* appended = state.stack.back();
    doc.has_appended = true;
    const std::string* enc = appended->attr("encoding");
    doc.appended_encoding = enc ? *enc : "";
    if (doc.appended_encoding != "raw" && doc.appended_encoding != "base64")
      fail(Errc::format, path,
           fmt::format("<AppendedData> encoding '{}' is neither 'raw' nor 'base64'", doc.appended_encoding));
    size_t at = state.appended_tag_end;
    while (at < doc.bytes.size() && is_space(doc.bytes[at])) ++at;
    if (at >= doc.bytes.size() || doc.bytes[at] != '_')
      fail(Errc::format, path, "<AppendedData> does not start with the '_' marker");
    doc.appended_begin = at + 1;
  }
  return doc;
}

// ---------------------------------------------------------------------------------------------
// Value types and byte sources

enum class VtkType { i8, u8, i16, u16, i32, u32, i64, u64, f32, f64 };

std::optional<VtkType> parse_vtk_type(std::string_view t) {
  static constexpr std::pair<std::string_view, VtkType> names[] = {
      {"Int8", VtkType::i8},   {"UInt8", VtkType::u8},   {"Int16", VtkType::i16},   {"UInt16", VtkType::u16},
      {"Int32", VtkType::i32}, {"UInt32", VtkType::u32}, {"Int64", VtkType::i64},   {"UInt64", VtkType::u64},
      {"Float32", VtkType::f32}, {"Float64", VtkType::f64}, {"Char", VtkType::i8}, {"UChar", VtkType::u8}};
  for (const auto& [n, v] : names)
    if (n == t) return v;
  return std::nullopt;
}

size_t type_size(VtkType t) {
  switch (t) {
    case VtkType::i8: case VtkType::u8: return 1;
    case VtkType::i16: case VtkType::u16: return 2;
    case VtkType::i32: case VtkType::u32: case VtkType::f32: return 4;
    case VtkType::i64: case VtkType::u64: case VtkType::f64: return 8;
  }
  return 1;
}

bool is_float(VtkType t) { return t == VtkType::f32 || t == VtkType::f64; }

// What every array of one file shares.
struct FileContext {
  std::string path;
  bool swap = false;      // file byte order differs from the host's
  bool header64 = false;  // header_type="UInt64"
  bool compressed = false;
  const XmlDocument* doc = nullptr;
};

// Bytes in file order, from raw bytes or base64 text.
class ByteSource {
 public:
  virtual ~ByteSource() = default;
  /// Appends `n` bytes to `out`, or throws naming `what`.
  virtual void read(size_t n, std::string& out, const std::string& what) = 0;
};

class RawSource : public ByteSource {
 public:
  RawSource(const FileContext& ctx, std::string_view bytes) : ctx_(ctx), bytes_(bytes) {}
  void read(size_t n, std::string& out, const std::string& what) override {
    if (n > bytes_.size() - pos_)
      fail(Errc::format, ctx_.path,
           fmt::format("{}: needs {} more bytes of appended data, the file has {} (truncated?)", what, n,
                       bytes_.size() - pos_));
    out.append(bytes_.data() + pos_, n);
    pos_ += n;
  }

 private:
  const FileContext& ctx_;
  std::string_view bytes_;
  size_t pos_ = 0;
};

// Decodes base64 group by group, so a header encoded apart from its data (padded on its own,
// as VTK writes compressed arrays) and one encoded together with it read alike.
class Base64Source : public ByteSource {
 public:
  Base64Source(const FileContext& ctx, std::string_view text) : ctx_(ctx), text_(text) {}
  void read(size_t n, std::string& out, const std::string& what) override {
    if (n > pending_.size() + (text_.size() - pos_) / 4 * 3 + 3)
      fail(Errc::format, ctx_.path,
           fmt::format("{}: needs {} bytes, the base64 text holds at most {} (truncated?)", what, n,
                       pending_.size() + (text_.size() - pos_) / 4 * 3));
    while (pending_.size() < n) decode_group(what);
    out.append(pending_, 0, n);
    pending_.erase(0, n);
  }

 private:
  static int value(char c) {
    if (c >= 'A' && c <= 'Z') return c - 'A';
    if (c >= 'a' && c <= 'z') return c - 'a' + 26;
    if (c >= '0' && c <= '9') return c - '0' + 52;
    if (c == '+') return 62;
    if (c == '/') return 63;
    return -1;
  }
  void decode_group(const std::string& what) {
    char group[4];
    for (int k = 0; k < 4; ++k) {
      while (pos_ < text_.size() && is_space(text_[pos_])) ++pos_;
      if (pos_ >= text_.size())
        fail(Errc::format, ctx_.path, fmt::format("{}: base64 data ends early (truncated)", what));
      group[k] = text_[pos_++];
    }
    int v[4];
    int pad = 0;
    for (int k = 0; k < 4; ++k) {
      if (group[k] == '=') {
        if (k < 2 || (k == 2 && group[3] != '='))
          fail(Errc::format, ctx_.path, fmt::format("{}: bad base64 padding '{}'", what, std::string_view(group, 4)));
        v[k] = 0;
        ++pad;
      } else if ((v[k] = value(group[k])) < 0 || pad) {
        const unsigned char c = static_cast<unsigned char>(group[k]);
        fail(Errc::format, ctx_.path,
             pad ? fmt::format("{}: bad base64 padding '{}'", what, std::string_view(group, 4))
                 : fmt::format("{}: invalid base64 character {} (0x{:02x})",
                               what, std::isprint(c) ? fmt::format("'{}'", char(c)) : std::string("?"), int(c)));
      }
    }
    const uint32_t bits = uint32_t(v[0]) << 18 | uint32_t(v[1]) << 12 | uint32_t(v[2]) << 6 | uint32_t(v[3]);
    pending_.push_back(char(bits >> 16));
    if (pad < 2) pending_.push_back(char(bits >> 8 & 0xff));
    if (pad < 1) pending_.push_back(char(bits & 0xff));
  }

  const FileContext& ctx_;
  std::string_view text_;
  size_t pos_ = 0;
  std::string pending_;
};

void swap_elements(std::string& bytes, size_t size) {
  if (size == 1) return;
  for (size_t i = 0; i + size <= bytes.size(); i += size) std::reverse(bytes.begin() + long(i), bytes.begin() + long(i + size));
}

uint64_t read_header_word(const FileContext& ctx, ByteSource& src, const std::string& what) {
  std::string b;
  const size_t n = ctx.header64 ? 8 : 4;
  src.read(n, b, what + " (block header)");
  if (ctx.swap) swap_elements(b, n);
  if (ctx.header64) {
    uint64_t v;
    std::memcpy(&v, b.data(), 8);
    return v;
  }
  uint32_t v;
  std::memcpy(&v, b.data(), 4);
  return v;
}

// One array's bytes, in file byte order: header and data, inflated when compressed.
std::string read_block(const FileContext& ctx, ByteSource& src, const std::string& what) {
  std::string out;
  if (!ctx.compressed) {
    src.read(size_t(read_header_word(ctx, src, what)), out, what);
    return out;
  }
  const uint64_t blocks = read_header_word(ctx, src, what);
  const uint64_t block_size = read_header_word(ctx, src, what);
  const uint64_t last_size = read_header_word(ctx, src, what);
  if (blocks > 0 && (block_size == 0 || last_size > block_size))
    fail(Errc::format, ctx.path,
         fmt::format("{}: compression header gives block size {} and last block size {}", what, block_size, last_size));
  std::vector<uint64_t> compressed_sizes;
  for (uint64_t b = 0; b < blocks; ++b) compressed_sizes.push_back(read_header_word(ctx, src, what));
  std::string packed;
  for (uint64_t b = 0; b < blocks; ++b) {
    const uint64_t expect = (b + 1 == blocks && last_size != 0) ? last_size : block_size;
    if (expect > compressed_sizes[b] * 1032 + 64)  // zlib expands at most ~1032:1
      fail(Errc::format, ctx.path,
           fmt::format("{}: block {} claims {} bytes from {} compressed bytes", what, b, expect, compressed_sizes[b]));
    packed.clear();
    src.read(size_t(compressed_sizes[b]), packed, fmt::format("{} (compressed block {})", what, b));
    const size_t at = out.size();
    out.resize(at + size_t(expect));
    uLongf got = uLongf(expect);
    const int rc = uncompress(reinterpret_cast<Bytef*>(out.data() + at), &got,
                              reinterpret_cast<const Bytef*>(packed.data()), uLong(packed.size()));
    if (rc == Z_BUF_ERROR && got == expect)
      fail(Errc::format, ctx.path,
           fmt::format("{}: zlib block {} inflates to more than the {} bytes its header says", what, b, expect));
    if (rc != Z_OK)
      fail(Errc::format, ctx.path, fmt::format("{}: zlib block {} does not inflate: {}", what, b, zError(rc)));
    if (got != expect)
      fail(Errc::format, ctx.path,
           fmt::format("{}: zlib block {} inflates to {} bytes, its header says {}", what, b, got, expect));
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// DataArray decoding

// An array's values in host byte order.
struct Decoded {
  VtkType type = VtkType::f64;
  size_t count = 0;
  std::string bytes;
};

template <typename T>
void parse_ascii_as(const FileContext& ctx, std::string_view text, Decoded& d, const std::string& what) {
  size_t pos = 0;
  std::vector<T> values;
  while (true) {
    while (pos < text.size() && is_space(text[pos])) ++pos;
    if (pos >= text.size()) break;
    size_t end = pos;
    while (end < text.size() && !is_space(text[end])) ++end;
    const std::string_view token = text.substr(pos, end - pos);
    bool ok;
    T v{};
    if constexpr (std::is_floating_point_v<T>) {
      double x;
      const auto r = std::from_chars(token.data(), token.data() + token.size(), x);
      ok = r.ec == std::errc() && r.ptr == token.data() + token.size();
      v = T(x);
    } else {
      const char* first = token.data() + (token[0] == '+' ? 1 : 0);
      const auto r = std::from_chars(first, token.data() + token.size(), v);
      ok = r.ec == std::errc() && r.ptr == token.data() + token.size();
    }
    if (!ok)
      fail(Errc::format, ctx.path,
           fmt::format("{}: ASCII value {} '{}' is not a valid {}", what, values.size(), token,
                       std::is_floating_point_v<T> ? "number" : "integer of its type"));
    values.push_back(v);
    pos = end;
  }
  d.count = values.size();
  d.bytes.assign(reinterpret_cast<const char*>(values.data()), values.size() * sizeof(T));
}

void parse_ascii(const FileContext& ctx, std::string_view text, Decoded& d, const std::string& what) {
  switch (d.type) {
    case VtkType::i8: return parse_ascii_as<int8_t>(ctx, text, d, what);
    case VtkType::u8: return parse_ascii_as<uint8_t>(ctx, text, d, what);
    case VtkType::i16: return parse_ascii_as<int16_t>(ctx, text, d, what);
    case VtkType::u16: return parse_ascii_as<uint16_t>(ctx, text, d, what);
    case VtkType::i32: return parse_ascii_as<int32_t>(ctx, text, d, what);
    case VtkType::u32: return parse_ascii_as<uint32_t>(ctx, text, d, what);
    case VtkType::i64: return parse_ascii_as<int64_t>(ctx, text, d, what);
    case VtkType::u64: return parse_ascii_as<uint64_t>(ctx, text, d, what);
    case VtkType::f32: return parse_ascii_as<float>(ctx, text, d, what);
    case VtkType::f64: return parse_ascii_as<double>(ctx, text, d, what);
  }
}

int components_of(const FileContext& ctx, const XmlElement& e, const std::string& what) {
  const std::string* c = e.attr("NumberOfComponents");
  if (!c) return 1;
  int n = 0;
  const auto r = std::from_chars(c->data(), c->data() + c->size(), n);
  if (r.ec != std::errc() || r.ptr != c->data() + c->size() || n < 1)
    fail(Errc::format, ctx.path, fmt::format("{}: NumberOfComponents '{}' is not a positive integer", what, *c));
  return n;
}

uint64_t parse_count(const FileContext& ctx, const XmlElement& e, const char* attr, const std::string& what) {
  const std::string* s = e.attr(attr);
  if (!s) fail(Errc::format, ctx.path, fmt::format("{} (line {}) has no {} attribute", what, e.line, attr));
  uint64_t v = 0;
  const auto r = std::from_chars(s->data(), s->data() + s->size(), v);
  if (r.ec != std::errc() || r.ptr != s->data() + s->size())
    fail(Errc::format, ctx.path, fmt::format("{}: {} '{}' is not a non-negative integer", what, attr, *s));
  return v;
}

Decoded decode_array(const FileContext& ctx, const XmlElement& e, const std::string& what) {
  Decoded d;
  const std::string* type = e.attr("type");
  if (!type) fail(Errc::format, ctx.path, fmt::format("{} (line {}) has no type attribute", what, e.line));
  const auto t = parse_vtk_type(*type);
  if (!t) fail(Errc::unsupported, ctx.path, fmt::format("{}: data type '{}' is not supported", what, *type));
  d.type = *t;
  const std::string* format = e.attr("format");
  const std::string fmt_name = format ? *format : "ascii";
  const size_t size = type_size(d.type);
  if (fmt_name == "ascii") {
    parse_ascii(ctx, e.text, d, what);
    return d;
  }
  if (fmt_name == "binary") {
    Base64Source src(ctx, e.text);
    d.bytes = read_block(ctx, src, what);
  } else if (fmt_name == "appended") {
    if (!ctx.doc->has_appended)
      fail(Errc::format, ctx.path, fmt::format("{} is appended but the file has no <AppendedData>", what));
    const uint64_t offset = parse_count(ctx, e, "offset", what);
    const std::string_view all(ctx.doc->bytes);
    if (offset >= all.size() - ctx.doc->appended_begin)
      fail(Errc::format, ctx.path,
           fmt::format("{}: appended offset {} is past the end of the file's {} bytes of appended data (truncated?)", what, offset,
                       all.size() - ctx.doc->appended_begin));
    const std::string_view data = all.substr(ctx.doc->appended_begin + size_t(offset));
    if (ctx.doc->appended_encoding == "raw") {
      RawSource src(ctx, data);
      d.bytes = read_block(ctx, src, what);
    } else {
      Base64Source src(ctx, data);
      d.bytes = read_block(ctx, src, what);
    }
  } else {
    fail(Errc::format, ctx.path, fmt::format("{}: format '{}' is not ascii, binary or appended", what, fmt_name));
  }
  if (d.bytes.size() % size != 0)
    fail(Errc::format, ctx.path,
         fmt::format("{}: {} bytes of data are not a whole number of {}-byte values", what, d.bytes.size(), size));
  if (ctx.swap) swap_elements(d.bytes, size);
  d.count = d.bytes.size() / size;
  return d;
}

template <typename Out, typename In>
void convert_from(const Decoded& d, std::vector<Out>& out) {
  out.resize(d.count);
  for (size_t i = 0; i < d.count; ++i) {
    In v;
    std::memcpy(&v, d.bytes.data() + i * sizeof(In), sizeof(In));
    out[i] = Out(v);
  }
}

std::vector<double> to_doubles(const Decoded& d) {
  std::vector<double> out;
  switch (d.type) {
    case VtkType::i8: convert_from<double, int8_t>(d, out); break;
    case VtkType::u8: convert_from<double, uint8_t>(d, out); break;
    case VtkType::i16: convert_from<double, int16_t>(d, out); break;
    case VtkType::u16: convert_from<double, uint16_t>(d, out); break;
    case VtkType::i32: convert_from<double, int32_t>(d, out); break;
    case VtkType::u32: convert_from<double, uint32_t>(d, out); break;
    case VtkType::i64: convert_from<double, int64_t>(d, out); break;
    case VtkType::u64: convert_from<double, uint64_t>(d, out); break;
    case VtkType::f32: convert_from<double, float>(d, out); break;
    case VtkType::f64: convert_from<double, double>(d, out); break;
  }
  return out;
}

std::vector<int64_t> to_integers(const FileContext& ctx, const Decoded& d, const std::string& what) {
  if (is_float(d.type)) fail(Errc::format, ctx.path, fmt::format("{} must be an integer array", what));
  std::vector<int64_t> out;
  switch (d.type) {
    case VtkType::i8: convert_from<int64_t, int8_t>(d, out); break;
    case VtkType::u8: convert_from<int64_t, uint8_t>(d, out); break;
    case VtkType::i16: convert_from<int64_t, int16_t>(d, out); break;
    case VtkType::u16: convert_from<int64_t, uint16_t>(d, out); break;
    case VtkType::i32: convert_from<int64_t, int32_t>(d, out); break;
    case VtkType::u32: convert_from<int64_t, uint32_t>(d, out); break;
    case VtkType::i64: convert_from<int64_t, int64_t>(d, out); break;
    case VtkType::u64: {
      std::vector<uint64_t> u;
      convert_from<uint64_t, uint64_t>(d, u);
      for (size_t i = 0; i < u.size(); ++i)
        if (u[i] > uint64_t(std::numeric_limits<int64_t>::max()))
          fail(Errc::format, ctx.path, fmt::format("{}: value {} ({}) is out of range", what, i, u[i]));
      out.assign(u.begin(), u.end());
      break;
    }
    default: break;
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// Cells and pieces

// VTK's names of the cell types (vtkCellType.h), for counting rejected cells.
std::string vtk_cell_name(int64_t type) {
  static const std::pair<int, const char*> names[] = {
      {0, "empty cell"}, {1, "vertex"}, {2, "poly vertex"}, {3, "line"}, {4, "poly line"}, {5, "triangle"},
      {6, "triangle strip"}, {7, "polygon"}, {8, "pixel"}, {9, "quad"}, {15, "pentagonal prism"},
      {16, "hexagonal prism"}, {21, "quadratic edge"}, {22, "quadratic triangle"}, {23, "quadratic quad"},
      {24, "quadratic tetra"}, {25, "quadratic hexahedron"}, {26, "quadratic wedge"},
      {27, "quadratic pyramid"}, {28, "biquadratic quad"}, {29, "triquadratic hexahedron"},
      {30, "quadratic linear quad"}, {31, "quadratic linear wedge"}, {32, "biquadratic quadratic wedge"},
      {33, "biquadratic quadratic hexahedron"}, {34, "biquadratic triangle"}, {35, "cubic line"},
      {36, "quadratic polygon"}, {37, "triquadratic pyramid"}, {41, "convex point set"}, {42, "polyhedron"},
      {68, "Lagrange curve"}, {69, "Lagrange triangle"}, {70, "Lagrange quadrilateral"},
      {71, "Lagrange tetrahedron"}, {72, "Lagrange hexahedron"}, {73, "Lagrange wedge"},
      {74, "Lagrange pyramid"}, {75, "Bezier curve"}, {76, "Bezier triangle"}, {77, "Bezier quadrilateral"},
      {78, "Bezier tetrahedron"}, {79, "Bezier hexahedron"}, {80, "Bezier wedge"}, {81, "Bezier pyramid"}};
  for (const auto& [id, name] : names)
    if (id == type) return name;
  return fmt::format("VTK type {}", type);
}

std::optional<MeshCellType> volume_cell_type(int64_t type) {
  switch (type) {
    case 10: return MeshCellType::tetra;
    case 11: return MeshCellType::hexahedron;  // voxel, reordered
    case 12: return MeshCellType::hexahedron;
    case 13: return MeshCellType::wedge;
    case 14: return MeshCellType::pyramid;
    default: return std::nullopt;
  }
}

const XmlElement* named_array(const XmlElement& parent, std::string_view name) {
  for (const XmlElement* a : parent.children_named("DataArray")) {
    const std::string* n = a->attr("Name");
    if (n && *n == name) return a;
  }
  return nullptr;
}

// Appends a piece's cells to `out`, their vertices offset by `point_base`.
void read_cells(const FileContext& ctx, const XmlElement* cells, uint64_t cell_count, const std::string& piece,
                int64_t point_base, MeshData& out) {
  if (cell_count == 0) return;
  if (!cells) fail(Errc::format, ctx.path, fmt::format("{} has {} cells but no <Cells>", piece, cell_count));
  std::vector<int64_t> arrays[3];
  const char* names[3] = {"connectivity", "offsets", "types"};
  for (int k = 0; k < 3; ++k) {
    const std::string what = fmt::format("{} Cells array '{}'", piece, names[k]);
    const XmlElement* e = named_array(*cells, names[k]);
    if (!e) fail(Errc::format, ctx.path, fmt::format("{}: <Cells> has no '{}' array", piece, names[k]));
    arrays[k] = to_integers(ctx, decode_array(ctx, *e, what), what);
  }
  const auto& [connectivity, offsets, types] = arrays;
  for (int k = 1; k < 3; ++k)
    if (arrays[k].size() != cell_count)
      fail(Errc::format, ctx.path,
           fmt::format("{}: Cells array '{}' has {} values, NumberOfCells is {}", piece, names[k], arrays[k].size(),
                       cell_count));
  int64_t begin = 0;
  for (uint64_t c = 0; c < cell_count; ++c) {
    const int64_t end = offsets[c];
    if (end < begin)
      fail(Errc::format, ctx.path,
           fmt::format("{}: Cells offsets decrease at cell {} ({} after {})", piece, c, end, begin));
    if (uint64_t(end) > connectivity.size())
      fail(Errc::format, ctx.path,
           fmt::format("{}: cell {} ends at offset {}, past the {} connectivity indices", piece, c, end,
                       connectivity.size()));
    const auto type = volume_cell_type(types[c]);
    if (!type) {
      ++out.rejected_cells[vtk_cell_name(types[c])];
    } else {
      const int n = vertex_count(*type);
      if (end - begin != n)
        fail(Errc::format, ctx.path,
             fmt::format("{}: cell {} ({}) has {} vertices, needs {}", piece, c,
                         types[c] == 11 ? std::string_view("voxel") : to_string(*type), end - begin, n));
      static constexpr int voxel_to_hex[8] = {0, 1, 3, 2, 4, 5, 7, 6};
      for (int i = 0; i < n; ++i)
        out.connectivity.push_back(connectivity[size_t(begin + (types[c] == 11 ? voxel_to_hex[i] : i))] + point_base);
      out.cell_types.push_back(*type);
      out.cell_offsets.push_back(out.connectivity.size());
    }
    begin = end;
  }
  if (uint64_t(begin) != connectivity.size())
    fail(Errc::format, ctx.path,
         fmt::format("{}: Cells connectivity has {} indices, the offsets use {}", piece, connectivity.size(), begin));
}

void read_point_data(const FileContext& ctx, const XmlElement* point_data, uint64_t point_count, size_t piece_index,
                     const std::string& piece, MeshData& out) {
  std::vector<bool> seen(out.arrays.size(), false);
  if (point_data) {
    size_t index = 0;
    for (const XmlElement* a : point_data->children_named("DataArray")) {
      const std::string* n = a->attr("Name");
      const std::string name = n ? *n : fmt::format("array{}", index);
      ++index;
      const std::string what = fmt::format("{} point array '{}'", piece, name);
      const std::string* type = a->attr("type");
      if (components_of(ctx, *a, what) != 1 || !type || !parse_vtk_type(*type)) continue;  // not a scalar
      std::vector<double> values = to_doubles(decode_array(ctx, *a, what));
      if (values.size() != point_count)
        fail(Errc::format, ctx.path,
             fmt::format("{} has {} values, NumberOfPoints is {}", what, values.size(), point_count));
      if (piece_index == 0) {
        out.arrays.push_back(PointArray{name, std::move(values), 0});
        continue;
      }
      for (size_t k = 0; k < out.arrays.size(); ++k)
        if (!seen[k] && out.arrays[k].name == name) {
          out.arrays[k].values.insert(out.arrays[k].values.end(), values.begin(), values.end());
          seen[k] = true;
          break;
        }
    }
  }
  for (size_t k = 0; k < seen.size(); ++k)
    if (!seen[k])
      fail(Errc::format, ctx.path,
           fmt::format("{} has no point array '{}' (the first piece has)", piece, out.arrays[k].name));
}

void read_piece(const FileContext& ctx, const XmlElement& p, size_t index, MeshData& out) {
  const std::string piece = fmt::format("Piece {}", index);
  const uint64_t point_count = parse_count(ctx, p, "NumberOfPoints", piece);
  const uint64_t cell_count = parse_count(ctx, p, "NumberOfCells", piece);
  const int64_t point_base = int64_t(out.point_count());
  if (point_count > 0) {
    const XmlElement* points = p.child("Points");
    const XmlElement* array = points ? points->child("DataArray") : nullptr;
    if (!array) fail(Errc::format, ctx.path, fmt::format("{} has {} points but no <Points> array", piece, point_count));
    const std::string what = fmt::format("{} Points", piece);
    if (int n = components_of(ctx, *array, what); n != 3)
      fail(Errc::format, ctx.path, fmt::format("{} has {} components, not 3", what, n));
    const std::vector<double> xyz = to_doubles(decode_array(ctx, *array, what));
    if (xyz.size() != 3 * point_count)
      fail(Errc::format, ctx.path,
           fmt::format("{} hold {} values, 3 x NumberOfPoints is {}", what, xyz.size(), 3 * point_count));
    out.points.insert(out.points.end(), xyz.begin(), xyz.end());
  }
  read_cells(ctx, p.child("Cells"), cell_count, piece, point_base, out);
  read_point_data(ctx, p.child("PointData"), point_count, index, piece, out);
}

const XmlElement& vtk_root(const XmlDocument& doc, const std::string& path, std::string_view want) {
  const XmlElement& root = *doc.root;
  if (root.name != "VTKFile")
    fail(Errc::format, path, fmt::format("not a VTK XML file: the root element is <{}>, not <VTKFile>", root.name));
  const std::string* type = root.attr("type");
  if (!type) fail(Errc::format, path, "<VTKFile> has no type attribute");
  if (*type != want)
    fail(Errc::unsupported, path,
         fmt::format("is a VTK XML {} file; only {} is read here", *type,
                     want == "Collection" ? "a Collection (.pvd)" : "UnstructuredGrid (.vtu)"));
  return root;
}

}  // namespace

MeshData read_vtu(const std::string& path) {
  const XmlDocument doc = parse_xml(path);
  const XmlElement& root = vtk_root(doc, path, "UnstructuredGrid");
  FileContext ctx;
  ctx.path = path;
  ctx.doc = &doc;
  const std::string* order = root.attr("byte_order");
  const std::string byte_order = order ? *order : "LittleEndian";
  if (byte_order != "LittleEndian" && byte_order != "BigEndian")
    fail(Errc::format, path, fmt::format("byte_order '{}' is neither LittleEndian nor BigEndian", byte_order));
  ctx.swap = (byte_order == "BigEndian") != (std::endian::native == std::endian::big);
  if (const std::string* h = root.attr("header_type")) {
    if (*h != "UInt32" && *h != "UInt64")
      fail(Errc::unsupported, path, fmt::format("header_type '{}' is not supported (UInt32, UInt64)", *h));
    ctx.header64 = *h == "UInt64";
  }
  if (const std::string* c = root.attr("compressor"); c && !c->empty()) {
    if (*c != "vtkZLibDataCompressor")
      fail(Errc::unsupported, path, fmt::format("compressor '{}' is not supported (vtkZLibDataCompressor)", *c));
    ctx.compressed = true;
  }
  const XmlElement* grid = root.child("UnstructuredGrid");
  if (!grid) fail(Errc::format, path, "<VTKFile type=\"UnstructuredGrid\"> has no <UnstructuredGrid> element");
  const auto pieces = grid->children_named("Piece");
  if (pieces.empty()) fail(Errc::format, path, "<UnstructuredGrid> has no <Piece>");

  MeshData out;
  out.source = path;
  out.format = "vtu";
  for (size_t i = 0; i < pieces.size(); ++i) read_piece(ctx, *pieces[i], i, out);
  return out;
}

MeshData read_pvd(const std::string& path) {
  const XmlDocument doc = parse_xml(path);
  const XmlElement& root = vtk_root(doc, path, "Collection");
  const XmlElement* collection = root.child("Collection");
  if (!collection) fail(Errc::format, path, "<VTKFile type=\"Collection\"> has no <Collection> element");
  struct Entry {
    std::string file;
    std::optional<double> time;
  };
  std::vector<Entry> entries;
  for (const XmlElement* d : collection->children_named("DataSet")) {
    const std::string* file = d->attr("file");
    if (!file || file->empty()) fail(Errc::format, path, fmt::format("<DataSet> at line {} has no file attribute", d->line));
    Entry e{*file, std::nullopt};
    if (const std::string* t = d->attr("timestep")) {
      double v;
      const auto r = std::from_chars(t->data(), t->data() + t->size(), v);
      if (r.ec != std::errc() || r.ptr != t->data() + t->size())
        fail(Errc::format, path, fmt::format("<DataSet> at line {}: timestep '{}' is not a number", d->line, *t));
      e.time = v;
    }
    entries.push_back(std::move(e));
  }
  if (entries.empty()) fail(Errc::format, path, "<Collection> lists no <DataSet>");
  const size_t timed = size_t(std::count_if(entries.begin(), entries.end(), [](const Entry& e) { return e.time.has_value(); }));
  if (timed != 0 && timed != entries.size())
    fail(Errc::format, path, "some <DataSet> elements have a timestep attribute and others do not");
  if (timed) std::stable_sort(entries.begin(), entries.end(), [](const Entry& a, const Entry& b) { return *a.time < *b.time; });

  const fs::path dir = fs::path(path).parent_path();
  MeshData out;
  bool moving = false;
  for (size_t s = 0; s < entries.size(); ++s) {
    const fs::path rel(entries[s].file);
    const std::string file = rel.is_absolute() ? rel.string() : (dir / rel).string();
    MeshData step = read_vtu(file);
    if (s == 0) {
      out = std::move(step);
      out.source = path;
      out.format = "pvd";
      out.step_points.clear();
    } else {
      if (step.point_count() != out.point_count())
        fail(Errc::format, path,
             fmt::format("step {} ({}) has {} points, step 0 has {}", s, file, step.point_count(), out.point_count()));
      if (step.cell_types != out.cell_types || step.cell_offsets != out.cell_offsets ||
          step.connectivity != out.connectivity || step.rejected_cells != out.rejected_cells)
        fail(Errc::format, path, fmt::format("step {} ({}) has other cells than step 0", s, file));
      for (PointArray& a : step.arrays) {
        a.step = int(s);
        out.arrays.push_back(std::move(a));
      }
      // Steps 1.. keep their points only once some step moves; earlier steps are copies.
      if (!moving && step.points != out.points) {
        moving = true;
        out.step_points.assign(s - 1, out.points);
      }
      if (moving) out.step_points.push_back(std::move(step.points));
    }
    if (timed) out.step_times.push_back(*entries[s].time);
  }
  out.steps = int(entries.size());
  return out;
}

}  // namespace brickyard
