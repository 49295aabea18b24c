#include "preprocess/mesh_data.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <limits>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/error.h"

namespace brickyard {

std::string_view to_string(MeshCellType t) {
  switch (t) {
    case MeshCellType::tetra: return "tetra";
    case MeshCellType::hexahedron: return "hexahedron";
    case MeshCellType::wedge: return "wedge";
    case MeshCellType::pyramid: return "pyramid";
  }
  return "?";
}

void MeshData::add_cell(MeshCellType t, std::span<const int64_t> vertices) {
  BY_CHECK_EQ(int(vertices.size()), vertex_count(t));
  cell_types.push_back(t);
  connectivity.insert(connectivity.end(), vertices.begin(), vertices.end());
  cell_offsets.push_back(connectivity.size());
}

double tet_volume6(const Vec3d& a, const Vec3d& b, const Vec3d& c, const Vec3d& d) {
  return dot(cross(b - a, c - a), d - a);
}

Box3d TetMesh::bounds() const {
  Box3d b;
  b.lo = Vec3d(std::numeric_limits<double>::infinity());
  b.hi = Vec3d(-std::numeric_limits<double>::infinity());
  auto add = [&](const std::vector<float>& p) {
    for (size_t i = 0; i + 2 < p.size(); i += 3)
      for (int a = 0; a < 3; ++a) b.lo[a] = std::min(b.lo[a], double(p[i + a])), b.hi[a] = std::max(b.hi[a], double(p[i + a]));
  };
  add(positions);
  for (const auto& p : step_positions) add(p);
  return b;
}

namespace {

std::string cell_list(const MeshReport::Kind& k) {
  std::string s;
  for (uint64_t c : k.first_cells) s += (s.empty() ? "" : ", ") + std::to_string(c);
  return k.count > k.first_cells.size() ? s + ", ..." : s;
}

void note(MeshReport::Kind& k, uint64_t cell) {
  if (k.first_cells.empty() || k.first_cells.back() != cell) {
    if (k.first_cells.size() < 5) k.first_cells.push_back(cell);
  }
  ++k.count;
}

/// A name split into a series base and a trailing step number: "T_12" -> ("T", 12).
std::optional<std::pair<std::string, long>> series_member(const std::string& name) {
  size_t end = name.size();
  while (end > 0 && std::isdigit(static_cast<unsigned char>(name[end - 1]))) --end;
  if (end == name.size() || end == 0 || name.size() - end > 9) return std::nullopt;
  const long n = std::stol(name.substr(end));
  size_t base_end = end;
  if (name[base_end - 1] == '_' || name[base_end - 1] == '.' || name[base_end - 1] == '-') --base_end;
  if (base_end == 0) return std::nullopt;
  return std::make_pair(name.substr(0, base_end), n);
}

/// The arrays that become the steps, in step order.
std::vector<const PointArray*> select_arrays(const MeshData& data, const ArraySelection& sel, std::string& name) {
  std::vector<const PointArray*> out;
  auto known = [&] {
    std::string s;
    for (const PointArray& a : data.arrays)
      if (a.step == 0) s += (s.empty() ? "" : ", ") + a.name;
    return s.empty() ? std::string("none") : s;
  };
  if (data.arrays.empty()) {
    if (!sel.name.empty())
      throw Error(Errc::format, fmt::format("no point array '{}': the mesh has no scalar point data", sel.name))
          .with_file(data.source)
          .with_field("--array");
    return out;  // geometry only: tetrahedralize() gives every vertex 0
  }
  if (data.steps > 1) {
    name = sel.name.empty() ? data.arrays.front().name : sel.name;
    for (int s = 0; s < data.steps; ++s) {
      auto it = std::find_if(data.arrays.begin(), data.arrays.end(),
                             [&](const PointArray& a) { return a.step == s && a.name == name; });
      if (it == data.arrays.end())
        throw Error(Errc::format, fmt::format("time step {} has no point array '{}'", s, name)).with_file(data.source)
            .with_field("--array");
      out.push_back(&*it);
      if (!sel.all_steps) break;
    }
    return out;
  }
  auto exact = std::find_if(data.arrays.begin(), data.arrays.end(), [&](const PointArray& a) { return a.name == sel.name; });
  std::string base;
  if (!sel.name.empty() && exact != data.arrays.end()) {
    name = sel.name;
    return {&*exact};
  }
  if (!sel.name.empty()) {
    base = sel.name;
  } else {
    const auto m = series_member(data.arrays.front().name);
    if (!m || !sel.all_steps) {
      name = data.arrays.front().name;
      return {&data.arrays.front()};
    }
    base = m->first;
  }
  std::vector<std::pair<long, const PointArray*>> series;
  for (const PointArray& a : data.arrays)
    if (const auto m = series_member(a.name); m && m->first == base) series.emplace_back(m->second, &a);
  if (series.empty())
    throw Error(Errc::format, fmt::format("no point array '{}' (arrays: {})", sel.name, known()))
        .with_file(data.source)
        .with_field("--array");
  std::stable_sort(series.begin(), series.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  name = base;
  for (const auto& [n, a] : series) {
    out.push_back(a);
    if (!sel.all_steps) break;
  }
  if (series.size() == 1 && sel.name.empty()) name = series.front().second->name;
  return out;
}

/// Splits a quad (a, b, c, d in cyclic order) by the diagonal through its lowest-numbered
/// vertex, so both cells that share it choose the same diagonal.
std::array<std::array<int64_t, 3>, 2> split_quad(int64_t a, int64_t b, int64_t c, int64_t d) {
  const int64_t lo = std::min({a, b, c, d});
  if (lo == a || lo == c) return {{{a, b, c}, {a, c, d}}};
  return {{{a, b, d}, {b, c, d}}};
}

}  // namespace

std::vector<std::string> MeshReport::lines() const {
  std::vector<std::string> out;
  out.push_back(fmt::format("read {} cells, {} points", input_cells, input_points));
  for (const auto& [type, n] : split)
    out.push_back(fmt::format("{} {} -> {} tets", n, type,
                              n * (type == "hexahedron" ? 12 : type == "wedge" ? 8 : 2)));
  if (centre_points) out.push_back(fmt::format("{} points added at the centres of split cells", centre_points));
  for (const auto& [type, n] : rejected_cells) out.push_back(fmt::format("{} {} cells rejected (not volume cells)", n, type));
  auto kind = [&](const Kind& k, const char* what) {
    if (k.count) out.push_back(fmt::format("{} tets skipped: {} (cells {})", k.count, what, cell_list(k)));
  };
  kind(index_out_of_range, "vertex index out of range");
  kind(duplicate_vertex, "duplicate vertex index");
  kind(nonfinite_point, "NaN or Inf coordinates");
  kind(nonfinite_scalar, "NaN or Inf scalars");
  kind(zero_volume, "zero volume");
  if (reoriented) out.push_back(fmt::format("{} inverted tets re-oriented", reoriented));
  if (no_scalars) out.push_back("no scalar point array: every vertex's value is 0 (geometry only)");
  out.push_back(fmt::format("{} valid tets", tets));
  return out;
}

std::string MeshReport::to_json() const {
  nlohmann::json j;
  j["input_cells"] = input_cells;
  j["input_points"] = input_points;
  j["split"] = split;
  j["split_tets"] = split_tets;
  j["centre_points"] = centre_points;
  j["rejected_cells"] = rejected_cells;
  auto kind = [](const Kind& k) { return nlohmann::json{{"count", k.count}, {"first_cells", k.first_cells}}; };
  j["skipped"] = {{"index_out_of_range", kind(index_out_of_range)}, {"duplicate_vertex", kind(duplicate_vertex)},
                  {"nonfinite_point", kind(nonfinite_point)},       {"nonfinite_scalar", kind(nonfinite_scalar)},
                  {"zero_volume", kind(zero_volume)}};
  j["reoriented"] = reoriented;
  j["no_scalars"] = no_scalars;
  j["tets"] = tets;
  return j.dump();
}

TetMesh tetrahedralize(MeshData&& data, const ArraySelection& selection) {
  TetMesh mesh;
  MeshReport& rep = mesh.report;
  const uint64_t n_points = data.point_count();
  rep.input_cells = data.cell_count();
  rep.input_points = n_points;
  rep.rejected_cells = data.rejected_cells;
  if (data.points.size() != 3 * n_points)
    throw Error(Errc::internal, "a reader delivered points that are not triples").with_file(data.source);
  if (data.cell_offsets.size() != data.cell_types.size() + 1 || data.cell_offsets.back() != data.connectivity.size())
    throw Error(Errc::internal, "a reader delivered inconsistent cell offsets").with_file(data.source);

  std::vector<const PointArray*> arrays = select_arrays(data, selection, mesh.array_name);
  PointArray zeros{"none", std::vector<double>(n_points, 0.0)};
  if (arrays.empty()) {
    arrays.push_back(&zeros);
    mesh.array_name = zeros.name;
    rep.no_scalars = true;
  }
  for (const PointArray* a : arrays) {
    if (a->values.size() != n_points)
      throw Error(Errc::format, fmt::format("point array '{}' has {} values for {} points", a->name, a->values.size(), n_points))
          .with_file(data.source);
    mesh.step_names.push_back(data.steps > 1 ? fmt::format("{}@{}", a->name, a->step) : a->name);
  }
  const size_t steps = arrays.size();
  const bool moving = data.steps > 1 && !data.step_points.empty() && steps > 1;
  if (moving)
    for (size_t s = 1; s < steps; ++s)
      if (data.step_points.size() < s || data.step_points[s - 1].size() != data.points.size())
        throw Error(Errc::format, fmt::format("time step {} has not the {} points of step 0", s, n_points)).with_file(data.source);

  // Every point keeps its index; split cells add their centres after the input points.
  std::vector<double> points = std::move(data.points);
  std::vector<std::vector<double>> step_points;
  if (moving) step_points.assign(data.step_points.begin(), data.step_points.begin() + long(steps - 1));
  std::vector<std::vector<double>> values(steps);
  for (size_t s = 0; s < steps; ++s) values[s] = arrays[s]->values;

  auto finite_point = [&](int64_t v) {
    for (int a = 0; a < 3; ++a)
      if (!std::isfinite(float(points[size_t(v) * 3 + a]))) return false;
    for (const auto& sp : step_points)
      for (int a = 0; a < 3; ++a)
        if (!std::isfinite(float(sp[size_t(v) * 3 + a]))) return false;
    return true;
  };
  auto finite_scalar = [&](int64_t v) {
    for (const auto& vs : values)
      if (!std::isfinite(float(vs[size_t(v)]))) return false;
    return true;
  };
  auto add_centre = [&](const int64_t* cv, int n) {
    auto mean = [&](std::vector<double>& p) {
      Vec3d c(0.0);
      for (int i = 0; i < n; ++i) c += Vec3d(p[size_t(cv[i]) * 3], p[size_t(cv[i]) * 3 + 1], p[size_t(cv[i]) * 3 + 2]);
      c = c / double(n);
      p.insert(p.end(), {c.x, c.y, c.z});
    };
    mean(points);
    for (auto& sp : step_points) mean(sp);
    for (auto& vs : values) {
      double m = 0;
      for (int i = 0; i < n; ++i) m += vs[size_t(cv[i])];
      vs.push_back(m / n);
    }
    ++rep.centre_points;
    return int64_t(points.size() / 3 - 1);
  };

  if (n_points + data.cell_count() >= std::numeric_limits<uint32_t>::max())
    throw Error(Errc::unsupported, fmt::format("{} points: more than 32-bit indices hold", n_points)).with_file(data.source);
  std::vector<std::array<int64_t, 4>> candidates;  // per input cell
  std::vector<uint32_t> kept;                       // 4 per tet, before renumbering
  for (uint64_t c = 0; c < data.cell_count(); ++c) {
    const MeshCellType type = data.cell_types[c];
    const int64_t* cv = data.connectivity.data() + data.cell_offsets[c];
    const int n = int(data.cell_offsets[c + 1] - data.cell_offsets[c]);
    if (n != vertex_count(type))
      throw Error(Errc::internal, fmt::format("cell {} of type {} has {} vertices", c, to_string(type), n)).with_file(data.source);
    bool in_range = true, finite = true, finite_values = true;
    for (int i = 0; i < n; ++i) {
      if (cv[i] < 0 || uint64_t(cv[i]) >= n_points) {
        in_range = false;
        break;
      }
      finite = finite && finite_point(cv[i]);
      finite_values = finite_values && finite_scalar(cv[i]);
    }
    const uint64_t tets_of_cell = type == MeshCellType::tetra ? 1 : type == MeshCellType::hexahedron ? 12
                                : type == MeshCellType::wedge ? 8 : 2;
    if (!in_range || !finite || !finite_values) {
      MeshReport::Kind& k = !in_range ? rep.index_out_of_range : !finite ? rep.nonfinite_point : rep.nonfinite_scalar;
      for (uint64_t i = 0; i < tets_of_cell; ++i) note(k, c);
      continue;
    }
    candidates.clear();
    if (type == MeshCellType::tetra) {
      candidates.push_back({cv[0], cv[1], cv[2], cv[3]});
    } else {
      ++rep.split[std::string(to_string(type))];
      rep.split_tets += tets_of_cell;
      if (type == MeshCellType::pyramid) {
        for (const auto& t : split_quad(cv[0], cv[1], cv[2], cv[3])) candidates.push_back({t[0], t[1], t[2], cv[4]});
      } else {
        const int64_t centre = add_centre(cv, n);
        static constexpr int kHexQuads[6][4] = {{0, 1, 2, 3}, {4, 5, 6, 7}, {0, 1, 5, 4}, {1, 2, 6, 5}, {2, 3, 7, 6}, {3, 0, 4, 7}};
        static constexpr int kWedgeQuads[3][4] = {{0, 1, 4, 3}, {1, 2, 5, 4}, {2, 0, 3, 5}};
        auto quad = [&](const int* q) {
          for (const auto& t : split_quad(cv[q[0]], cv[q[1]], cv[q[2]], cv[q[3]])) candidates.push_back({t[0], t[1], t[2], centre});
        };
        if (type == MeshCellType::hexahedron) {
          for (const auto& q : kHexQuads) quad(q);
        } else {
          for (const auto& q : kWedgeQuads) quad(q);
          candidates.push_back({cv[0], cv[1], cv[2], centre});
          candidates.push_back({cv[3], cv[4], cv[5], centre});
        }
      }
    }
    for (auto t : candidates) {
      if (t[0] == t[1] || t[0] == t[2] || t[0] == t[3] || t[1] == t[2] || t[1] == t[3] || t[2] == t[3]) {
        note(rep.duplicate_vertex, c);
        continue;
      }
      // Judged on the coordinates the store keeps (float), in every step.
      auto volume_in = [&](const std::vector<double>& p, double& scale) {
        Vec3d q[4];
        for (int i = 0; i < 4; ++i)
          for (int a = 0; a < 3; ++a) q[i][a] = double(float(p[size_t(t[size_t(i)]) * 3 + a]));
        scale = 0;
        for (int i = 0; i < 4; ++i)
          for (int j = i + 1; j < 4; ++j) scale = std::max(scale, length(q[j] - q[i]));
        return tet_volume6(q[0], q[1], q[2], q[3]);
      };
      double scale;
      const double v6 = volume_in(points, scale);
      // A tet flatter than this (relative to its longest edge) has no usable gradient.
      const double flat = 1e-9 * scale * scale * scale;
      bool degenerate = !(std::abs(v6) > flat);
      for (const auto& sp : step_points) {
        double s2;
        const double w6 = volume_in(sp, s2);
        degenerate = degenerate || !(std::abs(w6) > 1e-9 * s2 * s2 * s2) || (w6 > 0) != (v6 > 0);
      }
      if (degenerate) {
        note(rep.zero_volume, c);
        continue;
      }
      if (v6 < 0) {
        std::swap(t[2], t[3]);
        ++rep.reoriented;
      }
      for (int64_t v : t) kept.push_back(uint32_t(v));
    }
  }
  // The reader's cells are not needed past here: free them before the mesh is built.
  const bool had_cells = data.cell_count() > 0;
  std::vector<int64_t>().swap(data.connectivity);
  std::vector<uint64_t>().swap(data.cell_offsets);
  std::vector<MeshCellType>().swap(data.cell_types);
  rep.tets = kept.size() / 4;
  if (rep.tets == 0) {
    const std::string why = had_cells                   ? "every cell was skipped"
                            : rep.rejected_cells.empty() ? "the file holds no cells"
                                                         : "the file holds no volume cells (tetra, hexahedron, wedge, pyramid)";
    std::string detail;
    for (const std::string& l : rep.lines()) detail += "; " + l;
    throw Error(Errc::format, fmt::format("no valid tetrahedron is left: {}{}", why, detail)).with_file(data.source);
  }

  // Keep only the points the tets use, in first-use order (coherent, and no orphans).
  constexpr uint32_t kUnused = std::numeric_limits<uint32_t>::max();
  std::vector<uint32_t> renumber(points.size() / 3, kUnused);
  uint32_t next = 0;
  std::vector<uint32_t> order;
  for (uint32_t& v : kept) {  // renumbered in place: kept becomes the mesh's tets
    if (renumber[v] == kUnused) {
      renumber[v] = next++;
      order.push_back(v);
    }
    v = renumber[v];
  }
  mesh.tets = std::move(kept);
  auto gather = [&](const std::vector<double>& p) {
    std::vector<float> out(order.size() * 3);
    for (size_t i = 0; i < order.size(); ++i)
      for (int a = 0; a < 3; ++a) out[i * 3 + a] = float(p[size_t(order[i]) * 3 + a]);
    return out;
  };
  mesh.positions = gather(points);
  for (const auto& sp : step_points) mesh.step_positions.push_back(gather(sp));
  mesh.scalars.resize(steps);
  for (size_t s = 0; s < steps; ++s) {
    mesh.scalars[s].resize(order.size());
    for (size_t i = 0; i < order.size(); ++i) mesh.scalars[s][i] = float(values[s][size_t(order[i])]);
  }
  return mesh;
}

}  // namespace brickyard
