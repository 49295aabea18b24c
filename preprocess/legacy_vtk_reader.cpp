// Legacy VTK files (.vtk, "# vtk DataFile Version x.y") holding an UNSTRUCTURED_GRID, ASCII or
// BINARY (big-endian). CELLS in the classic layout (a count, then the indices, per cell) and in
// the 5.1 layout (OFFSETS and CONNECTIVITY arrays). POINT_DATA scalars and 1-component FIELD
// arrays become point arrays; everything else (vectors, tensors, CELL_DATA, METADATA) is read
// past by its size, so a file is either understood to its end or refused with the line at fault.

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "core/error.h"
#include "preprocess/mesh_readers.h"
#include "preprocess/text_scanner.h"

namespace brickyard {
namespace {

using mesh_io::iequals;
using mesh_io::Scanner;

enum class VtkType { u8, i8, u16, i16, u32, i32, u64, i64, f32, f64, string };

int type_size(VtkType t) {
  switch (t) {
    case VtkType::u8: case VtkType::i8: return 1;
    case VtkType::u16: case VtkType::i16: return 2;
    case VtkType::u32: case VtkType::i32: case VtkType::f32: return 4;
    case VtkType::u64: case VtkType::i64: case VtkType::f64: return 8;
    case VtkType::string: return 1;
  }
  return 1;
}

// "long" and "unsigned_long" are 8 bytes: VTK writes sizeof(long), which is 8 on LP64 systems.
// "vtkIdType" arrays are written as 32-bit ints by vtkDataWriter.
VtkType parse_type(Scanner& s, std::string_view name, std::string_view what) {
  static constexpr std::pair<std::string_view, VtkType> table[] = {
      {"unsigned_char", VtkType::u8},  {"char", VtkType::i8},          {"signed_char", VtkType::i8},
      {"unsigned_short", VtkType::u16}, {"short", VtkType::i16},       {"unsigned_int", VtkType::u32},
      {"int", VtkType::i32},            {"unsigned_long", VtkType::u64}, {"long", VtkType::i64},
      {"float", VtkType::f32},          {"double", VtkType::f64},       {"vtktypeint64", VtkType::i64},
      {"vtktypeuint64", VtkType::u64},  {"vtktypeint32", VtkType::i32}, {"vtktypeuint32", VtkType::u32},
      {"vtkidtype", VtkType::i32},      {"string", VtkType::string},    {"utf8_string", VtkType::string},
  };
  for (const auto& [n, t] : table)
    if (iequals(name, n)) return t;
  if (iequals(name, "bit"))
    throw Error(Errc::unsupported, fmt::format("line {}: {} has type bit, which is not read", s.line_number(), what))
        .with_file(s.path());
  s.fail(fmt::format("unknown data type '{}' for {}", name, what));
}

// %XX escapes in VTK names ("my%20array" is "my array").
std::string decode_name(std::string_view raw) {
  std::string out;
  for (size_t i = 0; i < raw.size(); ++i) {
    if (raw[i] == '%' && i + 2 < raw.size()) {
      const std::string hex(raw.substr(i + 1, 2));
      char* end = nullptr;
      const long v = std::strtol(hex.c_str(), &end, 16);
      if (end == hex.c_str() + 2) {
        out.push_back(char(v));
        i += 2;
        continue;
      }
    }
    out.push_back(raw[i]);
  }
  return out;
}

bool is_top_keyword(std::string_view k) {
  for (std::string_view t : {"POINTS", "CELLS", "CELL_TYPES", "POINT_DATA", "CELL_DATA", "DATASET"})
    if (iequals(k, t)) return true;
  return false;
}

class LegacyVtkReader {
 public:
  explicit LegacyVtkReader(const std::string& path) : s_(path) { mesh_.source = path; mesh_.format = "vtk"; }

  MeshData read() {
    header();
    while (!s_.at_end()) {
      const std::string_view kw = s_.token("a keyword");
      if (iequals(kw, "POINTS")) points();
      else if (iequals(kw, "CELLS")) cells();
      else if (iequals(kw, "CELL_TYPES")) cell_types();
      else if (iequals(kw, "POINT_DATA")) attributes(count("POINT_DATA"), true);
      else if (iequals(kw, "CELL_DATA")) attributes(count("CELL_DATA"), false);
      else if (iequals(kw, "FIELD")) field(false, 0);
      else if (iequals(kw, "METADATA")) skip_metadata();
      else s_.fail(fmt::format("unknown keyword '{}'", kw));
    }
    build_cells();
    return std::move(mesh_);
  }

 private:
  // Step 1: the three header lines and the DATASET line.
  void header() {
    const std::string_view first = s_.line();
    if (first.size() < 22 || !iequals(first.substr(0, 22), "# vtk DataFile Version"))
      throw Error(Errc::format, "line 1: not a legacy VTK file (expected '# vtk DataFile Version x.y')").with_file(s_.path());
    (void)s_.line();  // title
    const std::string_view mode = s_.token("ASCII or BINARY");
    if (iequals(mode, "BINARY")) binary_ = true;
    else if (!iequals(mode, "ASCII")) s_.fail(fmt::format("'{}' where ASCII or BINARY was expected", mode));
    const std::string_view ds = s_.token("DATASET");
    if (!iequals(ds, "DATASET")) s_.fail(fmt::format("'{}' where DATASET was expected", ds));
    const std::string_view kind = s_.token("the dataset type");
    if (!iequals(kind, "UNSTRUCTURED_GRID"))
      throw Error(Errc::unsupported, fmt::format("dataset {}: only UNSTRUCTURED_GRID is read from legacy VTK files", kind))
          .with_file(s_.path());
  }

  uint64_t count(std::string_view what) {
    const int64_t n = s_.integer(fmt::format("the count of {}", what));
    if (n < 0) s_.fail(fmt::format("{} has a negative count {}", what, n));
    return uint64_t(n);
  }

  // After a header line's last token: binary data starts on the next line.
  void end_header() {
    if (binary_) s_.skip_line();
  }

  // Reads n values of type t, handing each to put() as V (double or int64_t).
  template <typename V, typename Put>
  void read_values(VtkType t, uint64_t n, std::string_view what, Put&& put) {
    if (t == VtkType::string) s_.fail(fmt::format("{} is a string array where numbers are needed", what));
    s_.check_count(n, binary_ ? uint64_t(type_size(t)) : 2, what);
    if (!binary_) {
      for (uint64_t i = 0; i < n; ++i) put(s_.number<V>(what));
      return;
    }
    const char* p = s_.bytes(n * uint64_t(type_size(t)), what);
    const bool swap = std::endian::native == std::endian::little;
    for (uint64_t i = 0; i < n; ++i) {
      switch (t) {
        case VtkType::u8: put(V(mesh_io::load_binary<uint8_t>(p + i, swap))); break;
        case VtkType::i8: put(V(mesh_io::load_binary<int8_t>(p + i, swap))); break;
        case VtkType::u16: put(V(mesh_io::load_binary<uint16_t>(p + 2 * i, swap))); break;
        case VtkType::i16: put(V(mesh_io::load_binary<int16_t>(p + 2 * i, swap))); break;
        case VtkType::u32: put(V(mesh_io::load_binary<uint32_t>(p + 4 * i, swap))); break;
        case VtkType::i32: put(V(mesh_io::load_binary<int32_t>(p + 4 * i, swap))); break;
        case VtkType::u64: put(V(mesh_io::load_binary<uint64_t>(p + 8 * i, swap))); break;
        case VtkType::i64: put(V(mesh_io::load_binary<int64_t>(p + 8 * i, swap))); break;
        case VtkType::f32: put(V(mesh_io::load_binary<float>(p + 4 * i, swap))); break;
        case VtkType::f64: put(V(mesh_io::load_binary<double>(p + 8 * i, swap))); break;
        case VtkType::string: break;
      }
    }
  }

  std::vector<double> reals(VtkType t, uint64_t n, std::string_view what) {
    std::vector<double> out;
    s_.check_count(n, binary_ ? uint64_t(type_size(t)) : 2, what);
    out.reserve(n);
    read_values<double>(t, n, what, [&](double v) { out.push_back(v); });
    return out;
  }
  std::vector<int64_t> ints(VtkType t, uint64_t n, std::string_view what) {
    std::vector<int64_t> out;
    s_.check_count(n, binary_ ? uint64_t(type_size(t)) : 2, what);
    out.reserve(n);
    if (t == VtkType::f32 || t == VtkType::f64) s_.fail(fmt::format("{} has a floating-point type", what));
    read_values<int64_t>(t, n, what, [&](int64_t v) { out.push_back(v); });
    return out;
  }

  // Skips n values (strings: one a line in ASCII; not readable in binary).
  void skip_values(VtkType t, uint64_t n, std::string_view what) {
    if (t == VtkType::string) {
      if (binary_)
        throw Error(Errc::unsupported, fmt::format("line {}: binary string array {} is not read", s_.line_number(), what))
            .with_file(s_.path());
      s_.skip_line();
      for (uint64_t i = 0; i < n; ++i) {
        if (s_.remaining() == 0) s_.fail(fmt::format("the file ends inside string array {}", what));
        s_.skip_line();
      }
      return;
    }
    if (binary_) {
      s_.check_count(n, uint64_t(type_size(t)), what);
      (void)s_.bytes(n * uint64_t(type_size(t)), what);
    } else {
      s_.check_count(n, 2, what);
      for (uint64_t i = 0; i < n; ++i) (void)s_.token(what);
    }
  }

  void points() {
    const uint64_t n = count("POINTS");
    const VtkType t = parse_type(s_, s_.token("the type of POINTS"), "POINTS");
    end_header();
    if (n > std::numeric_limits<uint64_t>::max() / 4) s_.fail("POINTS count is too large");
    mesh_.points = reals(t, 3 * n, "POINTS");
  }

  void cells() {
    const uint64_t a = count("CELLS"), b = count("CELLS (size)");
    if (s_.next_is("OFFSETS")) {  // VTK 5.1: CELLS <offsets> <connectivity>
      (void)s_.token("OFFSETS");
      const VtkType ot = parse_type(s_, s_.token("the type of OFFSETS"), "OFFSETS");
      end_header();
      offsets_ = ints(ot, a, "OFFSETS");
      if (s_.accept("METADATA")) skip_metadata();
      if (!s_.accept("CONNECTIVITY")) s_.fail("CONNECTIVITY expected after OFFSETS");
      const VtkType ct = parse_type(s_, s_.token("the type of CONNECTIVITY"), "CONNECTIVITY");
      end_header();
      conn_ = ints(ct, b, "CONNECTIVITY");
      if (offsets_.empty()) offsets_.push_back(0);
      for (size_t i = 0; i + 1 < offsets_.size(); ++i)
        if (offsets_[i] < 0 || offsets_[i + 1] < offsets_[i] || uint64_t(offsets_[i + 1]) > conn_.size())
          s_.fail(fmt::format("OFFSETS: cell {} has offsets {}..{} outside the {} CONNECTIVITY entries", i, offsets_[i],
                              offsets_[i + 1], conn_.size()));
      return;
    }
    end_header();
    const std::vector<int64_t> flat = ints(VtkType::i32, b, "CELLS");
    s_.check_count(a, 0, "CELLS");
    offsets_.assign(1, 0);
    offsets_.reserve(a + 1);
    conn_.clear();
    conn_.reserve(flat.size());
    size_t at = 0;
    for (uint64_t c = 0; c < a; ++c) {
      if (at >= flat.size()) s_.fail(fmt::format("CELLS says {} cells in {} numbers, but they end at cell {}", a, b, c));
      const int64_t k = flat[at++];
      if (k < 0 || uint64_t(k) > flat.size() - at)
        s_.fail(fmt::format("CELLS: cell {} says {} points, more than the {} numbers left", c, k, flat.size() - at));
      conn_.insert(conn_.end(), flat.begin() + std::ptrdiff_t(at), flat.begin() + std::ptrdiff_t(at + size_t(k)));
      at += size_t(k);
      offsets_.push_back(int64_t(conn_.size()));
    }
    if (at != flat.size()) s_.fail(fmt::format("CELLS says size {} but its {} cells use {}", b, a, at));
  }

  void cell_types() {
    const uint64_t n = count("CELL_TYPES");
    end_header();
    types_ = ints(VtkType::i32, n, "CELL_TYPES");
    have_types_ = true;
  }

  // POINT_DATA or CELL_DATA attributes of n tuples; `keep`: point scalars become arrays.
  void attributes(uint64_t n, bool keep) {
    if (keep && !mesh_.points.empty() && n != mesh_.point_count())
      s_.fail(fmt::format("POINT_DATA says {} points but POINTS has {}", n, mesh_.point_count()));
    while (!s_.at_end()) {
      const std::optional<std::string_view> next = s_.peek_token();
      if (is_top_keyword(*next)) return;
      const std::string_view kw = s_.token("an attribute");
      if (iequals(kw, "SCALARS")) scalars(n, keep);
      else if (iequals(kw, "FIELD")) field(keep, n);
      else if (iequals(kw, "METADATA")) skip_metadata();
      else if (iequals(kw, "COLOR_SCALARS")) {
        (void)s_.token("the name of COLOR_SCALARS");
        const uint64_t m = count("COLOR_SCALARS components");
        end_header();
        skip_values(binary_ ? VtkType::u8 : VtkType::f32, mul(n, m), "COLOR_SCALARS");
      } else if (iequals(kw, "LOOKUP_TABLE")) {
        (void)s_.token("the name of LOOKUP_TABLE");
        const uint64_t m = count("LOOKUP_TABLE");
        end_header();
        skip_values(binary_ ? VtkType::u8 : VtkType::f32, mul(m, 4), "LOOKUP_TABLE");
      } else if (iequals(kw, "VECTORS") || iequals(kw, "NORMALS") || iequals(kw, "TENSORS") ||
                 iequals(kw, "TENSORS6") || iequals(kw, "GLOBAL_IDS") || iequals(kw, "PEDIGREE_IDS") ||
                 iequals(kw, "EDGE_FLAGS") || iequals(kw, "TEXTURE_COORDINATES")) {
        const std::string what(kw);
        (void)s_.token(fmt::format("the name of {}", what));
        uint64_t per = iequals(kw, "TENSORS") ? 9 : iequals(kw, "TENSORS6") ? 6 : (iequals(kw, "VECTORS") || iequals(kw, "NORMALS")) ? 3 : 1;
        if (iequals(kw, "TEXTURE_COORDINATES")) per = count("TEXTURE_COORDINATES dimension");
        const VtkType t = parse_type(s_, s_.token(fmt::format("the type of {}", what)), what);
        end_header();
        skip_values(t, mul(n, per), what);
      } else {
        s_.fail(fmt::format("unknown keyword '{}' in {}", kw, keep ? "POINT_DATA" : "CELL_DATA"));
      }
    }
  }

  uint64_t mul(uint64_t a, uint64_t b) {
    if (b != 0 && a > std::numeric_limits<uint64_t>::max() / b / 8) s_.fail(fmt::format("a count of {} x {} is too large", a, b));
    return a * b;
  }

  void scalars(uint64_t n, bool keep) {
    const std::string name = decode_name(s_.token("the name of SCALARS"));
    const VtkType t = parse_type(s_, s_.token("the type of SCALARS"), fmt::format("SCALARS {}", name));
    uint64_t ncomp = 1;
    if (!s_.next_is("LOOKUP_TABLE")) {
      const std::optional<std::string_view> p = s_.peek_token();
      if (p && !p->empty() && std::isdigit(static_cast<unsigned char>(p->front()))) ncomp = count("SCALARS components");
    }
    if (s_.accept("LOOKUP_TABLE")) (void)s_.token("the lookup table's name");
    end_header();
    const std::string what = fmt::format("SCALARS {}", name);
    if (!keep || ncomp != 1) {
      skip_values(t, mul(n, ncomp), what);
      return;
    }
    mesh_.arrays.push_back(PointArray{name, reals(t, n, what), 0});
  }

  // FIELD name k: k arrays "name ncomp ntuples type" with their values (NULL_ARRAY for none).
  void field(bool keep, uint64_t n) {
    (void)s_.token("the name of FIELD");
    const uint64_t k = count("FIELD arrays");
    for (uint64_t i = 0; i < k; ++i) {
      const std::string name = decode_name(s_.token("a FIELD array's name"));
      if (iequals(name, "NULL_ARRAY")) continue;
      const uint64_t ncomp = count(fmt::format("components of FIELD array {}", name));
      const uint64_t ntuples = count(fmt::format("tuples of FIELD array {}", name));
      const std::string what = fmt::format("FIELD array {}", name);
      const VtkType t = parse_type(s_, s_.token(fmt::format("the type of {}", what)), what);
      end_header();
      if (keep && ncomp == 1 && ntuples == n && t != VtkType::string)
        mesh_.arrays.push_back(PointArray{name, reals(t, ntuples, what), 0});
      else
        skip_values(t, mul(ncomp, ntuples), what);
      if (s_.next_is("METADATA")) {
        (void)s_.token("METADATA");
        skip_metadata();
      }
    }
  }

  // METADATA: lines up to the first empty one (COMPONENT_NAMES, INFORMATION ...).
  void skip_metadata() {
    s_.skip_line();
    while (s_.remaining() > 0) {
      const std::string_view l = s_.line();
      if (l.find_first_not_of(" \t\r") == std::string_view::npos) return;
    }
  }

  // Step 3: cells by type; voxels reordered into hexahedra, other types counted by name.
  void build_cells() {
    if (offsets_.empty() && !have_types_) return;
    const uint64_t ncells = offsets_.empty() ? 0 : offsets_.size() - 1;
    if (types_.size() != ncells)
      throw Error(Errc::format, fmt::format("CELL_TYPES gives {} types for {} CELLS", types_.size(), ncells))
          .with_file(s_.path());
    mesh_.cell_types.reserve(ncells);
    mesh_.connectivity.reserve(conn_.size());
    for (uint64_t c = 0; c < ncells; ++c) {
      const int64_t* v = conn_.data() + offsets_[c];
      const int64_t nv = offsets_[c + 1] - offsets_[c];
      std::optional<MeshCellType> type;
      int want = 0;
      switch (types_[c]) {
        case 10: type = MeshCellType::tetra; want = 4; break;
        case 11: case 12: type = MeshCellType::hexahedron; want = 8; break;
        case 13: type = MeshCellType::wedge; want = 6; break;
        case 14: type = MeshCellType::pyramid; want = 5; break;
        default: ++mesh_.rejected_cells[reject_name(types_[c])]; continue;
      }
      if (nv != want)
        throw Error(Errc::format, fmt::format("cell {}: VTK type {} needs {} points but has {}", c, types_[c], want, nv))
            .with_file(s_.path());
      if (types_[c] == 11) {
        const std::array<int64_t, 8> hex{v[0], v[1], v[3], v[2], v[4], v[5], v[7], v[6]};
        mesh_.add_cell(*type, {hex.data(), 8});
      } else {
        mesh_.add_cell(*type, {v, size_t(want)});
      }
    }
  }

  static std::string reject_name(int64_t t) {
    switch (t) {
      case 1: return "vertex";
      case 2: return "poly vertex";
      case 3: return "line";
      case 4: return "poly line";
      case 5: return "triangle";
      case 6: return "triangle strip";
      case 7: return "polygon";
      case 8: return "pixel";
      case 9: return "quad";
      case 24: return "quadratic tetra";
      case 25: return "quadratic hexahedron";
      case 42: return "polyhedron";
      default: return fmt::format("VTK type {}", t);
    }
  }

  Scanner s_;
  MeshData mesh_;
  bool binary_ = false;
  std::vector<int64_t> offsets_, conn_, types_;
  bool have_types_ = false;
};

}  // namespace

MeshData read_legacy_vtk(const std::string& path) {
  return LegacyVtkReader(path).read();
}

}  // namespace brickyard
