#pragma once
/// @file mesh_readers.h
/// @brief Readers of unstructured meshes (one .cpp each) and the .vtu writer. Every reader
/// throws Error naming the file (and, where it helps, the line, element or array) for
/// anything it cannot read: truncated files, wrong counts, bad numbers, broken base64 or zlib
/// streams. Indices are delivered as the file gives them (0-based); tetrahedralize() checks
/// them.

#include <string>

#include "preprocess/mesh_data.h"

namespace brickyard {

/// @brief A VTK XML UnstructuredGrid (.vtu): ASCII, binary (base64) and appended (raw or
/// base64) data, zlib-compressed or not, UInt32/UInt64 headers, Int8..Float64 arrays.
MeshData read_vtu(const std::string& path);
/// @brief A ParaView collection (.pvd) of .vtu files: file s gives step s (arrays tagged
/// step s, moving points in step_points, `timestep` attributes in step_times).
MeshData read_pvd(const std::string& path);
/// @brief A legacy VTK file (.vtk) holding an UNSTRUCTURED_GRID, ASCII or BINARY.
MeshData read_legacy_vtk(const std::string& path);
/// @brief A gmsh mesh (.msh), format 2.2 or 4.1, ASCII or binary, with $NodeData scalars
/// (one array per view; several time steps of a view become numbered arrays NAME_0 ...).
MeshData read_gmsh(const std::string& path);
/// @brief A TetGen mesh: PATH.node with PATH.ele beside it (either may be given); node
/// attributes become arrays attr0, attr1 ...
MeshData read_tetgen(const std::string& path);
/// @brief The reader for a file's extension (.vtu .pvd .vtk .msh .node .ele); Error(unsupported)
/// naming the extensions known otherwise.
MeshData read_mesh_file(const std::string& path);
/// @brief Whether a path names a mesh file read_mesh_file() knows.
bool is_mesh_file(const std::string& path);

struct VtuWriteOptions {
  enum class Encoding { ascii, binary, appended_raw, appended_base64 };
  Encoding encoding = Encoding::appended_raw;
  bool compress = false;      ///< zlib blocks (vtkZLibDataCompressor)
  bool header64 = false;      ///< UInt64 block headers (header_type="UInt64")
};
/// @brief Writes a tet mesh as a .vtu (Float32 points, Int64 connectivity, one Float32 point
/// array per time step named as in step_names), atomically: a temporary file renamed over
/// `path`, which must be a regular file or absent.
void write_vtu(const std::string& path, const TetMesh& mesh, const VtuWriteOptions& options = {});

}  // namespace brickyard
