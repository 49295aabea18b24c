#pragma once
/// @file tet_builder.h
/// @brief The clustered store of a tetrahedral mesh: spatially coherent clusters of a few
/// thousand tets, each one LZ4 page record (its vertices, its scalars for every time step, its
/// tets by local index), and a cluster table (bounds, per-step value ranges, counts).
///
/// A cluster source hands out clusters by index, from any thread: a whole mesh partitioned
/// top-down (median split along the longest axis, in parallel), or a procedural mesh that
/// generates each cluster from scratch, so that meshes larger than memory stream through a
/// window of clusters. The builder encodes a window in parallel and writes it in order; the
/// store claims to be complete only in its last transaction.

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "fields/field.h"
#include "preprocess/builder.h"
#include "preprocess/mesh_data.h"

namespace brickyard {

class Progress;

/// @brief One cluster: P x V x 3 positions (P = 1, or one set per step for moving vertices),
/// S x V scalars (step-major), 4 local vertex indices per tet.
struct ClusterData {
  std::vector<float> positions, values;
  std::vector<uint32_t> corners;
  uint32_t vertex_count() const { return uint32_t(corners.empty() ? 0 : positions.size() / 3); }
};

class TetClusterSource {
 public:
  virtual ~TetClusterSource() = default;
  /// @brief What messages call it: a path, or "mesh fbm".
  virtual std::string name() const = 0;
  /// @brief Provenance as a JSON object.
  virtual std::string describe_json() const = 0;
  virtual int time_steps() const = 0;
  virtual bool moving() const { return false; }
  virtual std::string array_name() const = 0;
  virtual std::vector<std::string> step_names() const = 0;
  virtual uint64_t cluster_count() const = 0;
  virtual uint64_t tet_count() const = 0;
  virtual uint64_t vertex_count() const = 0;  ///< distinct vertices of the mesh
  /// @brief Cluster i (positions of vertices_per_set(), values, corners). Thread-safe.
  virtual void cluster(uint64_t i, ClusterData& out) const = 0;
  /// @brief What the readers and validation found (recorded in the manifest).
  virtual const MeshReport& report() const = 0;
  /// @brief Bytes of input, for throughput figures.
  virtual uint64_t input_bytes() const = 0;
};

/// @brief A whole mesh, partitioned into clusters of at most `cluster_tets` tets.
std::unique_ptr<TetClusterSource> partition_mesh(TetMesh&& mesh, uint32_t cluster_tets, std::string name,
                                                 std::string source_json, uint64_t input_bytes);

/// @brief A procedural mesh: `field` sampled at the vertices of a grid of cells^3 cubes over
/// its domain, each cube split into 6 tets (Kuhn: every cube alike, so shared faces agree),
/// interior vertices jittered by up to `jitter` cells along each axis (deterministically, the
/// same in every cluster that shares them); the whole replicated replicate^3 times side by
/// side (the "bucky-like" scalability scene). Time steps: the field moved by `step_shift` of
/// the domain along x per step; with `move`, the vertices move too: at step s, x by
/// move * s * sin(2 pi y) and y by move * s * sin(2 pi z) (fractions of the domain; a shear
/// that keeps volume), the values staying with the vertices; a tet the motion folds (cells
/// too coarse for the displacement) is an error naming --move.
/// Clusters are blocks of cubes, generated on demand.
struct ProceduralMeshSpec {
  std::string field;
  FieldParamValues params;
  int64_t cells = 32;
  double jitter = 0;
  int replicate = 1;
  int steps = 1;
  double step_shift = 0.05;
  double move = 0;
  uint64_t seed = 1;
};
std::unique_ptr<TetClusterSource> make_procedural_mesh(const ProceduralMeshSpec& spec, uint32_t cluster_tets);

/// The leaf size of the BVHs `import --bvh` stores (tet_bvh's default).
inline constexpr uint32_t kStoredBvhLeafSize = 12;

struct TetBuildOptions {
  uint32_t cluster_tets = 8192;
  bool store_bvh = false;  ///< each cluster's BVH after its tetrahedra (dataset/tet_bvh.h)
  uint64_t map_size = 0;  ///< initial LMDB map size; 0 picks one from the mesh size
  bool map_growth = true;
  uint64_t batch_bytes = uint64_t(32) << 20;
  bool force = false;
};

/// @brief Builds (or rebuilds) the tetrahedral store in `dir` from `source`.
BuildResult build_tet_store(const TetClusterSource& source, const std::string& dir, const TetBuildOptions& options,
                            Progress* progress = nullptr);

}  // namespace brickyard
