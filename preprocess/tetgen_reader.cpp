// TetGen meshes: PATH.node (points and their attributes) with PATH.ele (tetrahedra) beside it.
// Either file, or the shared basename, may be given. '#' starts a comment anywhere. Indices
// start at 0 or 1, as the .node file's first index says; the .ele indices are made 0-based with
// that base (and delivered unchecked: tetrahedralize() checks the range). Second-order tets (10
// nodes) keep their 4 corners; region attributes of tets are cell data and are not read.

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "core/error.h"
#include "preprocess/mesh_readers.h"
#include "preprocess/text_scanner.h"

namespace brickyard {
namespace {

using mesh_io::Scanner;

uint64_t header_count(Scanner& s, std::string_view what) {
  const int64_t v = s.integer(what);
  if (v < 0) s.fail(fmt::format("{} is negative ({})", what, v));
  return uint64_t(v);
}

// The .node file: points (and the index base) and attributes attr0, attr1 ...
int64_t read_nodes(const std::string& path, MeshData& mesh) {
  Scanner s(path, true);
  const uint64_t n = header_count(s, "the number of points");
  const int64_t dim = s.integer("the dimension");
  const uint64_t nattr = header_count(s, "the number of attributes");
  const uint64_t nmarkers = header_count(s, "the number of boundary markers");
  if (dim != 3)
    throw Error(Errc::unsupported, fmt::format("line 1: dimension {}: only 3-dimensional TetGen meshes are read", dim)).with_file(path);
  if (nmarkers > 1) s.fail(fmt::format("{} boundary markers per point (0 or 1 expected)", nmarkers));
  s.check_count(n, 8, "the number of points");
  s.check_count(nattr, 2, "the number of attributes");
  s.check_count(n * (4 + nattr + nmarkers), 2, "the point count times the numbers per point");
  mesh.points.reserve(3 * n);
  const size_t first_array = mesh.arrays.size();
  for (uint64_t a = 0; a < nattr; ++a) {
    mesh.arrays.push_back(PointArray{fmt::format("attr{}", a), {}, 0});
    mesh.arrays.back().values.reserve(n);
  }
  int64_t base = 0;
  for (uint64_t i = 0; i < n; ++i) {
    const int64_t index = s.integer("a point index");
    if (i == 0) {
      if (index != 0 && index != 1) s.fail(fmt::format("the first point index is {} (0 or 1 expected)", index));
      base = index;
    } else if (index != base + int64_t(i)) {
      s.fail(fmt::format("point index {} where {} was expected", index, base + int64_t(i)));
    }
    for (int c = 0; c < 3; ++c) mesh.points.push_back(s.real("a point coordinate"));
    for (uint64_t a = 0; a < nattr; ++a) mesh.arrays[first_array + a].values.push_back(s.real("a point attribute"));
    if (nmarkers) (void)s.integer("a boundary marker");
  }
  return base;
}

// The .ele file: tetrahedra, made 0-based with the .node file's base.
void read_elements(const std::string& path, int64_t base, MeshData& mesh) {
  Scanner s(path, true);
  const uint64_t n = header_count(s, "the number of tetrahedra");
  const int64_t per = s.integer("the nodes per tetrahedron");
  const uint64_t nregion = header_count(s, "the number of region attributes");
  if (per != 4 && per != 10) s.fail(fmt::format("{} nodes per tetrahedron (4 or 10 expected)", per));
  s.check_count(n, 10, "the number of tetrahedra");
  s.check_count(nregion, 2, "the number of region attributes");
  mesh.cell_types.reserve(n);
  mesh.cell_offsets.reserve(n + 1);
  mesh.connectivity.reserve(4 * n);
  int64_t v[10];
  for (uint64_t t = 0; t < n; ++t) {
    (void)s.integer("a tetrahedron index");
    for (int64_t k = 0; k < per; ++k) v[k] = s.integer("a tetrahedron's node index") - base;
    for (uint64_t a = 0; a < nregion; ++a) (void)s.real("a region attribute");
    mesh.add_cell(MeshCellType::tetra, {v, 4});
  }
}

}  // namespace

MeshData read_tetgen(const std::string& path) {
  const std::filesystem::path p(path);
  const std::string ext = p.extension().string();
  const std::string base = (ext == ".node" || ext == ".ele") ? (p.parent_path() / p.stem()).string() : path;
  MeshData mesh;
  mesh.source = path;
  mesh.format = "tetgen";
  const int64_t index_base = read_nodes(base + ".node", mesh);
  read_elements(base + ".ele", index_base, mesh);
  return mesh;
}

}  // namespace brickyard
