#include "dataset/tet.h"

#include <cstring>

#include <fmt/format.h>

#include "core/error.h"

namespace brickyard {

namespace {
constexpr size_t kHeaderBytes = 2 * sizeof(uint32_t);
}  // namespace

size_t TetClusterPage::bytes(uint32_t vertices, uint32_t tets) {
  return kHeaderBytes + size_t(vertices) * 4 * sizeof(float) + size_t(tets) * 4 * sizeof(uint32_t);
}

std::vector<std::byte> TetClusterPage::encode(std::span<const float> positions, std::span<const float> values,
                                              std::span<const uint32_t> corners) {
  if (positions.size() != 3 * values.size() || corners.size() % 4 != 0)
    throw Error(Errc::invalid_argument, fmt::format("a cluster of {} positions, {} values and {} corner indices is not "
                                                    "3 floats and 1 value a vertex, 4 indices a tetrahedron",
                                                    positions.size(), values.size(), corners.size()));
  const auto vertices = uint32_t(values.size()), tets = uint32_t(corners.size() / 4);
  for (uint32_t c : corners)
    if (c >= vertices)
      throw Error(Errc::invalid_argument, fmt::format("corner index {} is outside the cluster's {} vertices", c, vertices));
  std::vector<std::byte> page(bytes(vertices, tets));
  std::byte* p = page.data();
  std::memcpy(p, &vertices, sizeof vertices);
  std::memcpy(p + sizeof vertices, &tets, sizeof tets);
  p += kHeaderBytes;
  std::memcpy(p, positions.data(), positions.size_bytes());
  p += positions.size_bytes();
  std::memcpy(p, values.data(), values.size_bytes());
  p += values.size_bytes();
  std::memcpy(p, corners.data(), corners.size_bytes());
  return page;
}

TetClusterPage TetClusterPage::view(std::span<const std::byte> page) {
  TetClusterPage v;
  if (page.size() < kHeaderBytes) throw Error(Errc::corrupt, fmt::format("a cluster page of {} bytes has no header", page.size()));
  std::memcpy(&v.vertex_count, page.data(), sizeof v.vertex_count);
  std::memcpy(&v.tet_count, page.data() + sizeof v.vertex_count, sizeof v.tet_count);
  if (bytes(v.vertex_count, v.tet_count) > page.size())
    throw Error(Errc::corrupt, fmt::format("a cluster page of {} bytes cannot hold {} vertices and {} tetrahedra",
                                           page.size(), v.vertex_count, v.tet_count));
  // The page buffers come from new[] or the cache's pool (aligned to 64 bytes), and every part
  // is a multiple of 4 bytes, so the arrays are aligned for their types.
  const std::byte* p = page.data() + kHeaderBytes;
  v.positions = reinterpret_cast<const float*>(p);
  v.values = v.positions + 3 * size_t(v.vertex_count);
  v.corners = reinterpret_cast<const uint32_t*>(v.values + v.vertex_count);
  return v;
}

uint64_t TetView::tet_count() const {
  uint64_t n = 0;
  for (const TetCluster& c : clusters_) n += c.tets;
  return n;
}

}  // namespace brickyard
