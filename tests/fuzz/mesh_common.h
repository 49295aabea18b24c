#pragma once
// What the mesh targets share: one input split into the files a reader takes (kFileSeparator
// between them), the reader, then tetrahedralize() as `brickyard import-mesh` runs it. What
// tetrahedralize() accepts must be a valid TetMesh (in-range vertex indices, a scalar per
// vertex and step).

#include <cstdio>
#include <cstdlib>
#include <initializer_list>
#include <string>
#include <vector>

#include "preprocess/mesh_data.h"
#include "preprocess/mesh_readers.h"
#include "tests/fuzz/fuzz_util.h"

namespace brickyard::fuzz {

/// @brief Writes piece i of the input as names[i] in the temporary directory and reads
/// names[0] with `read`.
inline int run_mesh(const uint8_t* data, size_t size, std::initializer_list<const char*> names,
                    MeshData (*read)(const std::string&)) {
  const auto parts = split({reinterpret_cast<const char*>(data), size}, kFileSeparator, names.size());
  std::vector<std::string> paths;
  size_t i = 0;
  for (const char* name : names) paths.push_back(write_temp(name, parts[i++]));
  return run_one([&] {
    MeshData mesh = read(paths[0]);
    const TetMesh tets = tetrahedralize(std::move(mesh), ArraySelection{});
    const uint64_t n = tets.vertex_count();
    for (uint32_t v : tets.tets)
      if (v >= n) {
        std::fprintf(stderr, "fuzz: tetrahedralize() kept vertex %u of %llu\n", v, static_cast<unsigned long long>(n));
        std::abort();
      }
    for (const auto& s : tets.scalars)
      if (s.size() != n) {
        std::fprintf(stderr, "fuzz: tetrahedralize() kept %zu scalars for %llu vertices\n", s.size(),
                     static_cast<unsigned long long>(n));
        std::abort();
      }
  });
}

}  // namespace brickyard::fuzz
