// Choosing a mesh reader by the file's extension.

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <string_view>

#include <fmt/format.h>

#include "core/error.h"
#include "preprocess/mesh_readers.h"

namespace brickyard {
namespace {

using Reader = MeshData (*)(const std::string&);

struct ReaderEntry {
  std::string_view extension;
  Reader read;
};

constexpr ReaderEntry kReaders[] = {
    {".vtu", read_vtu},   {".pvd", read_pvd},    {".vtk", read_legacy_vtk},
    {".msh", read_gmsh},  {".node", read_tetgen}, {".ele", read_tetgen},
};

std::string lower_extension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return ext;
}

const ReaderEntry* find_reader(const std::string& path) {
  const std::string ext = lower_extension(path);
  for (const ReaderEntry& r : kReaders)
    if (r.extension == ext) return &r;
  return nullptr;
}

}  // namespace

MeshData read_mesh_file(const std::string& path) {
  if (const ReaderEntry* r = find_reader(path)) return r->read(path);
  std::string known;
  for (const ReaderEntry& r : kReaders) known += fmt::format("{}{}", known.empty() ? "" : " ", r.extension);
  const std::string ext = lower_extension(path);
  throw Error(Errc::unsupported,
              fmt::format("{} is not a mesh format brickyard reads (known: {})",
                          ext.empty() ? std::string("a file without an extension") : "'" + ext + "'", known))
      .with_file(path);
}

bool is_mesh_file(const std::string& path) { return find_reader(path) != nullptr; }

}  // namespace brickyard
