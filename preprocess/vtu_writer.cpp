// The .vtu writer: a TetMesh as a VTK XML UnstructuredGrid, in any of VTK's four encodings
// (ASCII, inline base64, appended raw, appended base64), zlib blocks or not, UInt32 or UInt64
// block headers, written atomically through AtomicFile.
//
// Each array is encoded into its bytes first (appended offsets need the sizes of the arrays
// before it), then the XML and the appended section are written in one pass. Binary data is
// in the host's byte order, which the byte_order attribute names.

#include <zlib.h>

#include <algorithm>
#include <bit>
#include <cstring>
#include <filesystem>
#include <iterator>
#include <limits>
#include <string_view>
#include <vector>

#include <fmt/format.h>

#include "core/atomic_file.h"
#include "core/error.h"
#include "preprocess/mesh_readers.h"

namespace brickyard {
namespace {

namespace fs = std::filesystem;
using Encoding = VtuWriteOptions::Encoding;

constexpr size_t kBlockSize = 32768;  // uncompressed bytes per zlib block, VTK's default
constexpr uint8_t kVtkTetra = 10;

std::string base64(std::string_view bytes) {
  static constexpr char table[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  size_t i = 0;
  for (; i + 3 <= bytes.size(); i += 3) {
    const uint32_t v = uint32_t(uint8_t(bytes[i])) << 16 | uint32_t(uint8_t(bytes[i + 1])) << 8 | uint8_t(bytes[i + 2]);
    out += table[v >> 18];
    out += table[v >> 12 & 63];
    out += table[v >> 6 & 63];
    out += table[v & 63];
  }
  if (const size_t rest = bytes.size() - i; rest > 0) {
    uint32_t v = uint32_t(uint8_t(bytes[i])) << 16;
    if (rest == 2) v |= uint32_t(uint8_t(bytes[i + 1])) << 8;
    out += table[v >> 18];
    out += table[v >> 12 & 63];
    out += rest == 2 ? table[v >> 6 & 63] : '=';
    out += '=';
  }
  return out;
}

std::string xml_escape(std::string_view s) {
  std::string out;
  for (const char c : s) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

// One DataArray to write: its attributes and its values in host byte order.
struct OutArray {
  std::string type;  // "Float32", "Int64", "UInt8"
  std::string name;
  int components = 1;
  std::string bytes;
  std::string encoded;  // what goes into the file: text, base64 or raw block
};

template <typename T>
std::string as_bytes(const std::vector<T>& v) {
  return std::string(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(T));
}

class BlockEncoder {
 public:
  BlockEncoder(const std::string& path, const VtuWriteOptions& o) : path_(path), o_(o) {}

  void append_word(std::string& out, uint64_t v) const {
    if (o_.header64) {
      out.append(reinterpret_cast<const char*>(&v), 8);
      return;
    }
    if (v > std::numeric_limits<uint32_t>::max())
      throw Error(Errc::invalid_argument,
                  fmt::format("an array of {} bytes needs UInt64 headers (header64)", v)).with_file(path_);
    const uint32_t w = uint32_t(v);
    out.append(reinterpret_cast<const char*>(&w), 4);
  }

  /// The header and data of one array, raw; a compressed array's header apart from its data.
  void encode(std::string_view data, std::string& header, std::string& payload) const {
    if (!o_.compress) {
      append_word(header, data.size());
      payload.assign(data);
      return;
    }
    const size_t blocks = (data.size() + kBlockSize - 1) / kBlockSize;
    append_word(header, blocks);
    append_word(header, kBlockSize);
    append_word(header, data.size() % kBlockSize);
    std::string block;
    for (size_t b = 0; b < blocks; ++b) {
      const std::string_view in = data.substr(b * kBlockSize, kBlockSize);
      uLongf size = compressBound(uLong(in.size()));
      block.resize(size);
      const int rc = compress2(reinterpret_cast<Bytef*>(block.data()), &size,
                               reinterpret_cast<const Bytef*>(in.data()), uLong(in.size()), Z_DEFAULT_COMPRESSION);
      if (rc != Z_OK)
        throw Error(Errc::internal, fmt::format("zlib compress2 failed: {}", zError(rc))).with_file(path_);
      append_word(header, size);
      payload.append(block.data(), size);
    }
  }

  /// What the file holds for an array in a binary encoding.
  std::string block(std::string_view data) const {
    std::string header, payload;
    encode(data, header, payload);
    if (o_.encoding == Encoding::appended_raw) return header + payload;
    // base64: VTK encodes a compressed array's header apart from its blocks, an uncompressed
    // array's header together with its data.
    if (o_.compress) return base64(header) + base64(payload);
    return base64(header + payload);
  }

 private:
  const std::string& path_;
  const VtuWriteOptions& o_;
};

template <typename T>
std::string ascii_values(std::string_view bytes, int per_line) {
  std::string out;
  const size_t n = bytes.size() / sizeof(T);
  for (size_t i = 0; i < n; ++i) {
    T v;
    std::memcpy(&v, bytes.data() + i * sizeof(T), sizeof(T));
    if constexpr (sizeof(T) == 1) fmt::format_to(std::back_inserter(out), "{}", int(v));
    else fmt::format_to(std::back_inserter(out), "{}", v);
    out += (i + 1) % size_t(per_line) == 0 || i + 1 == n ? '\n' : ' ';
  }
  return out;
}

std::string ascii_array(const OutArray& a) {
  if (a.type == "Float32") return ascii_values<float>(a.bytes, a.components == 3 ? 6 : 8);
  if (a.type == "Int64") return ascii_values<int64_t>(a.bytes, 8);
  return ascii_values<uint8_t>(a.bytes, 16);
}

std::string step_name(const TetMesh& mesh, int s) {
  if (size_t(s) < mesh.step_names.size() && !mesh.step_names[size_t(s)].empty()) return mesh.step_names[size_t(s)];
  if (mesh.time_steps() == 1 && !mesh.array_name.empty()) return mesh.array_name;
  return fmt::format("scalar_{}", s);
}

// The path to write through, after refusing anything but a regular file or nothing.
std::string checked_target(const std::string& path) {
  std::error_code ec;
  const fs::file_status link = fs::symlink_status(path, ec);
  if (ec && link.type() != fs::file_type::not_found)
    throw Error(Errc::io, fmt::format("cannot inspect: {}", ec.message())).with_file(path);
  if (link.type() == fs::file_type::not_found || link.type() == fs::file_type::regular) return path;
  if (link.type() == fs::file_type::symlink) {
    const fs::file_status target = fs::status(path, ec);
    if (target.type() == fs::file_type::regular) return fs::canonical(path).string();  // keep the link
    throw Error(Errc::invalid_argument, "is a symbolic link to something other than a regular file; not replaced")
        .with_file(path);
  }
  throw Error(Errc::invalid_argument, "exists and is not a regular file (a directory or device?); not replaced")
      .with_file(path);
}

std::vector<OutArray> mesh_arrays(const std::string& path, const TetMesh& mesh) {
  const size_t nv = mesh.vertex_count(), nt = mesh.tet_count();
  if (mesh.positions.size() != 3 * nv || mesh.tets.size() != 4 * nt)
    throw Error(Errc::invalid_argument, "TetMesh positions or tets are not whole vertices or tets").with_file(path);
  std::vector<OutArray> arrays;
  for (int s = 0; s < mesh.time_steps(); ++s) {
    if (mesh.scalars[size_t(s)].size() != nv)
      throw Error(Errc::invalid_argument, fmt::format("step {} has {} scalars for {} vertices", s,
                                                      mesh.scalars[size_t(s)].size(), nv)).with_file(path);
    arrays.push_back({"Float32", step_name(mesh, s), 1, as_bytes(mesh.scalars[size_t(s)]), {}});
  }
  arrays.push_back({"Float32", "Points", 3, as_bytes(mesh.positions), {}});
  std::vector<int64_t> connectivity(mesh.tets.begin(), mesh.tets.end()), offsets(nt);
  for (size_t t = 0; t < nt; ++t) offsets[t] = int64_t(4 * (t + 1));
  arrays.push_back({"Int64", "connectivity", 1, as_bytes(connectivity), {}});
  arrays.push_back({"Int64", "offsets", 1, as_bytes(offsets), {}});
  arrays.push_back({"UInt8", "types", 1, std::string(nt, char(kVtkTetra)), {}});
  return arrays;
}

}  // namespace

void write_vtu(const std::string& path, const TetMesh& mesh, const VtuWriteOptions& options) {
  const std::string target = checked_target(path);
  std::vector<OutArray> arrays = mesh_arrays(path, mesh);
  const size_t steps = size_t(mesh.time_steps());

  // Encode every array; appended offsets follow from the sizes.
  const bool appended = options.encoding == Encoding::appended_raw || options.encoding == Encoding::appended_base64;
  const bool compressed = options.compress && options.encoding != Encoding::ascii;
  VtuWriteOptions o = options;
  o.compress = compressed;
  const BlockEncoder encoder(path, o);
  for (OutArray& a : arrays) a.encoded = options.encoding == Encoding::ascii ? ascii_array(a) : encoder.block(a.bytes);

  std::string xml = fmt::format(
      "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"{}\" byte_order=\"{}\" "
      "header_type=\"{}\"{}>\n  <UnstructuredGrid>\n    <Piece NumberOfPoints=\"{}\" NumberOfCells=\"{}\">\n",
      options.header64 ? "1.0" : "0.1", std::endian::native == std::endian::big ? "BigEndian" : "LittleEndian",
      options.header64 ? "UInt64" : "UInt32", compressed ? " compressor=\"vtkZLibDataCompressor\"" : "",
      mesh.vertex_count(), mesh.tet_count());
  const char* format = appended ? "appended" : options.encoding == Encoding::ascii ? "ascii" : "binary";
  uint64_t offset = 0;
  auto write_array = [&](const OutArray& a, const char* indent) {
    xml += fmt::format("{}<DataArray type=\"{}\" Name=\"{}\"{} format=\"{}\"", indent, a.type, xml_escape(a.name),
                       a.components > 1 ? fmt::format(" NumberOfComponents=\"{}\"", a.components) : "", format);
    if (appended) {
      xml += fmt::format(" offset=\"{}\"/>\n", offset);
      offset += a.encoded.size();
    } else {
      xml += fmt::format(">\n{}{}</DataArray>\n", a.encoded, options.encoding == Encoding::ascii ? "" : "\n");
    }
  };
  xml += steps ? fmt::format("      <PointData Scalars=\"{}\">\n", xml_escape(arrays[0].name)) : "      <PointData>\n";
  for (size_t s = 0; s < steps; ++s) write_array(arrays[s], "        ");
  xml += "      </PointData>\n      <CellData>\n      </CellData>\n      <Points>\n";
  write_array(arrays[steps], "        ");
  xml += "      </Points>\n      <Cells>\n";
  for (size_t k = steps + 1; k < arrays.size(); ++k) write_array(arrays[k], "        ");
  xml += "      </Cells>\n    </Piece>\n  </UnstructuredGrid>\n";

  AtomicFile file(target);
  if (appended) {
    xml += fmt::format("  <AppendedData encoding=\"{}\">\n   _",
                       options.encoding == Encoding::appended_raw ? "raw" : "base64");
    file.write(xml.data(), xml.size());
    for (const OutArray& a : arrays) file.write(a.encoded.data(), a.encoded.size());
    xml = "\n  </AppendedData>\n";
  }
  xml += "</VTKFile>\n";
  file.write(xml.data(), xml.size());
  file.commit();
}

}  // namespace brickyard
