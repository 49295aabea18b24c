#include "dataset/tet.h"

#include <cstdint>
#include <cstring>

#include <fmt/format.h>

#include "core/error.h"

namespace brickyard {

namespace {
constexpr size_t kHeaderBytes = 4 * sizeof(uint32_t);
}  // namespace

size_t TetClusterPage::bytes(uint32_t vertices, uint32_t tets, uint32_t steps, uint32_t position_sets) {
  // Each factor fits easily; their product may not (2^30 vertices of 2^30 steps is 2^64 bytes,
  // which wraps to 0): saturate, so that no page is large enough for counts that do not fit.
  const size_t per_vertex = (3 * size_t(position_sets) + size_t(steps)) * sizeof(float);
  size_t vertex_bytes = 0, total = 0;
  if (__builtin_mul_overflow(size_t(vertices), per_vertex, &vertex_bytes) ||
      __builtin_add_overflow(kHeaderBytes + size_t(tets) * 4 * sizeof(uint32_t), vertex_bytes, &total))
    return SIZE_MAX;
  return total;
}

std::vector<std::byte> TetClusterPage::encode(std::span<const float> positions, std::span<const float> values,
                                              std::span<const uint32_t> corners, uint32_t steps) {
  const size_t vertex_count = steps ? values.size() / steps : 0;
  const bool fits = steps >= 1 && values.size() % steps == 0 && corners.size() % 4 == 0 &&
                    (positions.size() == 3 * vertex_count || positions.size() == 3 * vertex_count * steps);
  if (!fits)
    throw Error(Errc::invalid_argument, fmt::format("a cluster of {} positions, {} values, {} steps and {} corner indices is "
                                                    "not 3 floats a vertex (once or per step), 1 value a vertex and step, "
                                                    "4 indices a tetrahedron",
                                                    positions.size(), values.size(), steps, corners.size()));
  const auto vertices = uint32_t(vertex_count), tets = uint32_t(corners.size() / 4);
  const uint32_t position_sets = positions.size() == 3 * vertex_count ? 1 : steps;
  for (uint32_t c : corners)
    if (c >= vertices)
      throw Error(Errc::invalid_argument, fmt::format("corner index {} is outside the cluster's {} vertices", c, vertices));
  std::vector<std::byte> page(bytes(vertices, tets, steps, position_sets));
  std::byte* p = page.data();
  const uint32_t header[4] = {vertices, tets, steps, position_sets};
  std::memcpy(p, header, sizeof header);
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
  uint32_t header[4];
  std::memcpy(header, page.data(), sizeof header);
  v.vertex_count = header[0], v.tet_count = header[1], v.steps = header[2], v.position_sets = header[3];
  if (v.steps < 1 || (v.position_sets != 1 && v.position_sets != v.steps))
    throw Error(Errc::corrupt, fmt::format("a cluster page of {} steps and {} position sets", v.steps, v.position_sets));
  if (bytes(v.vertex_count, v.tet_count, v.steps, v.position_sets) > page.size())
    throw Error(Errc::corrupt, fmt::format("a cluster page of {} bytes cannot hold {} vertices and {} tetrahedra in {} steps",
                                           page.size(), v.vertex_count, v.tet_count, v.steps));
  // The page buffers come from new[] or the cache's pool (aligned to 64 bytes), and every part
  // is a multiple of 4 bytes, so the arrays are aligned for their types.
  const std::byte* p = page.data() + kHeaderBytes;
  v.positions = reinterpret_cast<const float*>(p);
  v.values = v.positions + 3 * size_t(v.vertex_count) * v.position_sets;
  v.corners = reinterpret_cast<const uint32_t*>(v.values + size_t(v.vertex_count) * v.steps);
  const size_t used = bytes(v.vertex_count, v.tet_count, v.steps, v.position_sets);
  v.tail = page.subspan(used);
  return v;
}

uint64_t TetView::tet_count() const {
  uint64_t n = 0;
  for (const TetCluster& c : clusters_) n += c.tets;
  return n;
}

}  // namespace brickyard
