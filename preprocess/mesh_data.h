#pragma once
/// @file mesh_data.h
/// @brief An unstructured mesh as a reader delivers it (points, cells of any type, point
/// arrays, time steps), and the tetrahedral mesh the clustered store is built from: cells split
/// into tetrahedra, validated, one scalar per vertex and time step.
///
/// Readers (one file each: .vtu/.pvd, legacy .vtk, gmsh .msh, TetGen .node/.ele) fill a
/// MeshData and know nothing of tetrahedra or validation; tetrahedralize() does both, the
/// same way for every format, so a hex mesh cracks in no reader.

#include <cstdint>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "core/math.h"

namespace brickyard {

/// @brief The cell types a mesh may hold; everything else is counted by its name and rejected.
/// Vertex order is VTK's (gmsh and TetGen use the same for these four).
enum class MeshCellType : uint8_t {
  tetra,       ///< 4 vertices
  hexahedron,  ///< 8: bottom quad 0-1-2-3, top quad 4-5-6-7 (4 above 0)
  wedge,       ///< 6: triangles 0-1-2 and 3-4-5 (3 above 0)
  pyramid,     ///< 5: base quad 0-1-2-3, apex 4
};
constexpr int vertex_count(MeshCellType t) {
  switch (t) {
    case MeshCellType::tetra: return 4;
    case MeshCellType::hexahedron: return 8;
    case MeshCellType::wedge: return 6;
    case MeshCellType::pyramid: return 5;
  }
  return 0;
}
std::string_view to_string(MeshCellType t);

/// @brief One scalar point array: a value per point (one component; readers reduce vectors to
/// their magnitude only when asked to, never silently).
struct PointArray {
  std::string name;
  std::vector<double> values;
  int step = 0;  ///< the time step (file of a .pvd collection) it belongs to
};

/// @brief What a reader delivers.
struct MeshData {
  std::string source;            ///< the file read, named in errors and recorded as provenance
  std::string format;            ///< "vtu", "vtk", "msh2", "msh4", "tetgen", "pvd", "procedural"
  std::vector<double> points;    ///< x, y, z of every point
  std::vector<MeshCellType> cell_types;
  std::vector<uint64_t> cell_offsets{0};  ///< cell c's vertices: connectivity[offsets[c], offsets[c+1])
  std::vector<int64_t> connectivity;      ///< point indices as the file gives them (checked later)
  /// Cells of other types the file held, counted by type name ("triangle", "VTK type 42", ...):
  /// not volume cells, so not rendered; reported and, when nothing else is left, an error.
  std::map<std::string, uint64_t> rejected_cells;
  /// Scalar point arrays in file order, each tagged with its step. A single file is step 0
  /// (its time-varying data, if any, is arrays whose names differ only by a trailing step
  /// number); a .pvd collection's file s gives the arrays of step s.
  std::vector<PointArray> arrays;
  int steps = 1;  ///< files in a collection; 1 for a single file
  /// Moving vertices: the points of steps 1, 2, ... when they differ from `points` (empty when
  /// the vertices do not move). Same count and cells in every step, else the reader refuses.
  std::vector<std::vector<double>> step_points;
  std::vector<double> step_times;  ///< a .pvd's timestep attributes, when it has them

  uint64_t point_count() const { return points.size() / 3; }
  uint64_t cell_count() const { return cell_types.size(); }
  /// @brief Appends a cell of vertex_count(t) vertices.
  void add_cell(MeshCellType t, std::span<const int64_t> vertices);
  void add_cell(MeshCellType t, std::initializer_list<int64_t> vertices) { add_cell(t, {vertices.begin(), vertices.size()}); }
};

/// @brief Which point arrays become the mesh's time steps.
struct ArraySelection {
  std::string name;            ///< --array: this array (or the series name+N); "" = the first array
  bool all_steps = true;       ///< numbered arrays (name0, name_1, name.2 ...) become time steps
};

/// @brief What validation found, per kind, with the first few cell ids of each.
struct MeshReport {
  struct Kind {
    uint64_t count = 0;
    std::vector<uint64_t> first_cells;  ///< up to 5 ids of the input cells at fault
  };
  uint64_t input_cells = 0, input_points = 0;
  std::map<std::string, uint64_t> split;  ///< cells split into tets by type ("hexahedron" -> count)
  uint64_t split_tets = 0;                ///< tets those cells became
  uint64_t centre_points = 0;             ///< points added at the centres of split cells
  std::map<std::string, uint64_t> rejected_cells;  ///< from the reader
  Kind zero_volume, duplicate_vertex, index_out_of_range, nonfinite_point, nonfinite_scalar;
  uint64_t reoriented = 0;                ///< inverted tets turned around (kept)
  bool no_scalars = false;                ///< the mesh had no scalar point array: values are 0
  uint64_t tets = 0;                      ///< valid tetrahedra kept

  uint64_t skipped() const {
    return zero_volume.count + duplicate_vertex.count + index_out_of_range.count + nonfinite_point.count +
           nonfinite_scalar.count;
  }
  /// @brief Lines a user reads: "1000 hexahedron -> 12000 tets", "3 zero volume (cells 4, 9, 12)".
  std::vector<std::string> lines() const;
  /// @brief The same as a JSON object (text), recorded in the store's manifest.
  std::string to_json() const;
};

/// @brief A valid tetrahedral mesh: every tet has positive volume, four distinct in-range
/// vertices with finite positions and scalars, and its vertices in positive orientation
/// ((p1-p0) x (p2-p0)) . (p3-p0) > 0.
struct TetMesh {
  std::vector<float> positions;             ///< 3 per vertex, world coordinates (step 0)
  std::vector<std::vector<float>> step_positions;  ///< moving vertices: steps 1, 2, ... (else empty)
  std::vector<std::vector<float>> scalars;  ///< per time step, 1 per vertex
  std::vector<uint32_t> tets;               ///< 4 vertex indices per tet
  std::string array_name;                   ///< the scalar's name (the first step's array)
  std::vector<std::string> step_names;      ///< each step's array (or file)
  MeshReport report;

  uint64_t vertex_count() const { return positions.size() / 3; }
  uint64_t tet_count() const { return tets.size() / 4; }
  int time_steps() const { return int(scalars.size()); }
  Box3d bounds() const;
};

/// @brief Splits cells into tets, picks the scalar arrays, validates, re-orients.
/// Hexahedra, wedges and pyramids are split around a point added at their centre (its scalar
/// the mean of the cell's, which is the trilinear value there): each quad face becomes two
/// triangles by the diagonal through its lowest-numbered vertex, so the two cells sharing a
/// face split it alike and no crack opens, whatever the cells' orientation. A hexahedron
/// becomes 12 tets, a wedge 8 (3 quads of 2, 2 triangles), a pyramid 2 (no centre point).
/// @throws Error(format) naming the source when no valid tet is left (saying why) or when
/// the chosen array does not exist (listing those that do).
TetMesh tetrahedralize(MeshData&& data, const ArraySelection& selection);

/// @brief The signed volume of a tet, times 6.
double tet_volume6(const Vec3d& a, const Vec3d& b, const Vec3d& c, const Vec3d& d);

}  // namespace brickyard
