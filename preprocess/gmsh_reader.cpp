// gmsh meshes (.msh), MSH 2.x and 4.1, ASCII and binary: $Nodes, $Elements and $NodeData;
// every other section ($Entities, $PhysicalNames, $Periodic ...) is passed over to its $End.
//
// Node tags may be sparse in either version: elements and data keep the tags as read, and one
// pass at the end maps them to dense point indices (-1 for a tag no node has, which
// tetrahedralize() reports as out of range). Vertex order: gmsh's 4-node tetrahedron (4),
// hexahedron (5) and pyramid (7) number their vertices as VTK does. Its prism (6) has the
// reference nodes (0,0,0) (1,0,0) (0,1,0) (0,0,1) (1,0,1) (0,1,1), which are exactly
// vtkWedge's parametric coordinates (vtkWedgeCellPCoords): triangle 0-1-2, then 3-4-5 with
// vertex i+3 above vertex i, so a prism is a wedge without reordering.
//
// Binary layout (both versions): the $MeshFormat line is followed by the int 1 that tells the
// byte order; MSH 2 counts are ASCII lines and its records ints and doubles; MSH 4.1 sizes
// and tags are size_t (the data-size field), entity fields ints. $NodeData headers are ASCII
// and their records an int node tag and doubles (gmsh's PViewDataGModel::readMSH).

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include <fmt/format.h>

#include "core/error.h"
#include "preprocess/mesh_readers.h"
#include "preprocess/text_scanner.h"

namespace brickyard {
namespace {

using mesh_io::Scanner;

struct ElementType {
  int nodes = 0;  ///< 0: unknown to us
  std::optional<MeshCellType> cell;
  const char* name = nullptr;
};

ElementType element_type(int64_t t) {
  switch (t) {
    case 1: return {2, std::nullopt, "line"};
    case 2: return {3, std::nullopt, "triangle"};
    case 3: return {4, std::nullopt, "quad"};
    case 4: return {4, MeshCellType::tetra, "tetrahedron"};
    case 5: return {8, MeshCellType::hexahedron, "hexahedron"};
    case 6: return {6, MeshCellType::wedge, "prism"};
    case 7: return {5, MeshCellType::pyramid, "pyramid"};
    case 8: return {3, std::nullopt, "3-node line"};
    case 9: return {6, std::nullopt, "6-node triangle"};
    case 10: return {9, std::nullopt, "9-node quad"};
    case 11: return {10, std::nullopt, "10-node tetrahedron"};
    case 12: return {27, std::nullopt, "27-node hexahedron"};
    case 13: return {18, std::nullopt, "18-node prism"};
    case 14: return {14, std::nullopt, "14-node pyramid"};
    case 15: return {1, std::nullopt, "point"};
    case 16: return {8, std::nullopt, "8-node quad"};
    case 17: return {20, std::nullopt, "20-node hexahedron"};
    case 18: return {15, std::nullopt, "15-node prism"};
    case 19: return {13, std::nullopt, "13-node pyramid"};
    case 20: return {9, std::nullopt, "9-node triangle"};
    case 21: return {10, std::nullopt, "10-node triangle"};
    case 26: return {4, std::nullopt, "4-node line"};
    case 29: return {20, std::nullopt, "20-node tetrahedron"};
    default: return {};
  }
}

// One $NodeData block: a view's values at one time step.
struct NodeView {
  std::string name;
  int64_t step = 0;
  std::vector<std::pair<uint64_t, double>> values;  ///< node tag, value
};

class GmshReader {
 public:
  explicit GmshReader(const std::string& path) : s_(path) { mesh_.source = path; }

  MeshData read() {
    if (s_.at_end() || s_.token("$MeshFormat") != "$MeshFormat")
      throw Error(Errc::format, "not a gmsh file: it does not start with $MeshFormat").with_file(s_.path());
    mesh_format();
    while (!s_.at_end()) {
      const std::string name(s_.token("a section"));
      if (name.size() < 2 || name[0] != '$') s_.fail(fmt::format("'{}' where a section ($Name) was expected", name));
      const std::string section = name.substr(1);
      if (section == "Nodes") major_ == 2 ? nodes2() : nodes4();
      else if (section == "Elements") major_ == 2 ? elements2() : elements4();
      else if (section == "NodeData") node_data();
      else if (section == "MeshFormat") s_.fail("a second $MeshFormat section");
      else if (!s_.skip_past("$End" + section)) s_.fail(fmt::format("section {} has no $End{}", name, section));
      else continue;
      expect_end(section);
    }
    finish();
    return std::move(mesh_);
  }

 private:
  void expect_end(const std::string& section) {
    const std::string want = "$End" + section;
    const std::string_view got = s_.token(want);
    if (got != want)
      s_.fail(fmt::format("'{}' where {} was expected (the section holds more or fewer records than it says)", got, want));
  }

  // Step 1: "version file-type data-size", and in binary the int 1 that gives the byte order.
  void mesh_format() {
    const std::string_view version = s_.token("the MSH version");
    const double v = [&] {
      double x = 0;
      const auto [end, ec] = std::from_chars(version.data(), version.data() + version.size(), x);
      if (ec != std::errc() || end != version.data() + version.size()) s_.fail(fmt::format("'{}' is not an MSH version", version));
      return x;
    }();
    if (v >= 2.0 && v < 3.0) major_ = 2;
    else if (std::abs(v - 4.1) < 1e-9) major_ = 4;
    else
      throw Error(Errc::unsupported, fmt::format("MSH version {} is not read (2.x and 4.1 are)", version)).with_file(s_.path());
    mesh_.format = major_ == 2 ? "msh2" : "msh4";
    const int64_t file_type = s_.integer("the file type");
    const int64_t data_size = s_.integer("the data size");
    if (file_type != 0 && file_type != 1) s_.fail(fmt::format("file type {} is neither 0 (ASCII) nor 1 (binary)", file_type));
    binary_ = file_type == 1;
    if (major_ == 4 && (data_size == 4 || data_size == 8)) size_bytes_ = int(data_size);
    else if (binary_ && data_size != 8) s_.fail(fmt::format("data size {} (8 expected)", data_size));
    if (binary_) {
      s_.skip_line();
      const int32_t one = s_.binary<int32_t>(false, "the byte-order int");
      if (one == 1) swap_ = false;
      else if (mesh_io::load_binary<int32_t>(reinterpret_cast<const char*>(&one), true) == 1) swap_ = true;
      else s_.fail_binary(fmt::format("the byte-order int is {}, not 1", one));
    }
    expect_end("MeshFormat");
  }

  // Readers of one value: ASCII token, or binary int / size_t / double.
  int64_t read_int(std::string_view what) {
    return binary_ ? int64_t(s_.binary<int32_t>(swap_, what)) : s_.integer(what);
  }
  uint64_t read_size(std::string_view what) {  // MSH 4.1 size_t (tags, counts)
    if (!binary_) {
      const int64_t v = s_.integer(what);
      if (v < 0) s_.fail(fmt::format("{} is negative ({})", what, v));
      return uint64_t(v);
    }
    return size_bytes_ == 8 ? s_.binary<uint64_t>(swap_, what) : uint64_t(s_.binary<uint32_t>(swap_, what));
  }
  double read_double(std::string_view what) { return binary_ ? s_.binary<double>(swap_, what) : s_.real(what); }
  uint64_t ascii_count(std::string_view what) {
    const int64_t n = s_.integer(what);
    if (n < 0) s_.fail(fmt::format("{} is negative ({})", what, n));
    return uint64_t(n);
  }

  void add_node(uint64_t tag, double x, double y, double z) {
    node_tags_.push_back(tag);
    mesh_.points.insert(mesh_.points.end(), {x, y, z});
  }

  void nodes2() {
    const uint64_t n = ascii_count("the $Nodes count");
    s_.check_count(n, binary_ ? 28 : 8, "$Nodes");
    if (binary_) s_.skip_line();
    node_tags_.reserve(node_tags_.size() + n);
    mesh_.points.reserve(mesh_.points.size() + 3 * n);
    for (uint64_t i = 0; i < n; ++i) {
      const int64_t tag = read_int("a node tag");
      const double x = read_double("a node's x"), y = read_double("a node's y"), z = read_double("a node's z");
      if (tag < 0) s_.fail(fmt::format("node tag {} is negative", tag));
      add_node(uint64_t(tag), x, y, z);
    }
  }

  void nodes4() {
    if (binary_) s_.skip_line();
    const uint64_t blocks = read_size("the $Nodes block count"), n = read_size("the $Nodes count");
    (void)read_size("the minimum node tag");
    (void)read_size("the maximum node tag");
    s_.check_count(n, binary_ ? 32 : 8, "$Nodes");
    s_.check_count(blocks, binary_ ? 20 : 8, "$Nodes blocks");
    node_tags_.reserve(node_tags_.size() + n);
    mesh_.points.reserve(mesh_.points.size() + 3 * n);
    uint64_t total = 0;
    for (uint64_t b = 0; b < blocks; ++b) {
      const int64_t dim = read_int("an entity dimension");
      (void)read_int("an entity tag");
      const int64_t parametric = read_int("the parametric flag");
      const uint64_t count = read_size("a block's node count");
      if (count > n - total) s_.fail(fmt::format("$Nodes block {} holds {} nodes, more than the {} the section says", b, count, n));
      for (uint64_t i = 0; i < count; ++i) node_tags_.push_back(read_size("a node tag"));
      const int extra = parametric ? int(std::clamp<int64_t>(dim, 0, 3)) : 0;
      for (uint64_t i = 0; i < count; ++i) {
        for (int c = 0; c < 3; ++c) mesh_.points.push_back(read_double("a node coordinate"));
        for (int c = 0; c < extra; ++c) (void)read_double("a parametric coordinate");
      }
      total += count;
    }
    if (total != n) s_.fail(fmt::format("$Nodes says {} nodes but its blocks hold {}", n, total));
  }

  // One element with raw node tags (mapped in finish()).
  void add_element(int64_t type, const ElementType& info, const std::vector<int64_t>& tags) {
    if (!info.cell) {
      ++mesh_.rejected_cells[info.name ? std::string(info.name) : fmt::format("gmsh type {}", type)];
      return;
    }
    mesh_.add_cell(*info.cell, {tags.data(), size_t(info.nodes)});
  }

  void elements2() {
    const uint64_t n = ascii_count("the $Elements count");
    s_.check_count(n, binary_ ? 16 : 8, "$Elements");
    std::vector<int64_t> tags;
    if (!binary_) {
      for (uint64_t e = 0; e < n; ++e) {
        (void)s_.integer("an element number");
        const int64_t type = s_.integer("an element type");
        const int64_t ntags = s_.integer("an element's tag count");
        if (ntags < 0 || ntags > 1000) s_.fail(fmt::format("element {} says {} tags", e, ntags));
        for (int64_t t = 0; t < ntags; ++t) (void)s_.integer("an element tag");
        const ElementType info = element_type(type);
        if (info.nodes == 0) {  // unknown type: the rest of its line
          s_.skip_line();
          add_element(type, info, tags);
          continue;
        }
        tags.resize(size_t(info.nodes));
        for (int i = 0; i < info.nodes; ++i) tags[size_t(i)] = s_.integer("an element's node tag");
        add_element(type, info, tags);
      }
      return;
    }
    s_.skip_line();
    for (uint64_t done = 0; done < n;) {
      const int64_t type = read_int("an element type");
      const int64_t count = read_int("an element block count");
      const int64_t ntags = read_int("an element's tag count");
      const ElementType info = element_type(type);
      if (info.nodes == 0) s_.fail_binary(fmt::format("unknown element type {} in binary $Elements", type));
      if (count < 0 || uint64_t(count) > n - done || ntags < 0 || ntags > 1000)
        s_.fail_binary(fmt::format("element block of {} elements with {} tags after {} of {}", count, ntags, done, n));
      tags.resize(size_t(info.nodes));
      for (int64_t e = 0; e < count; ++e) {
        for (int64_t t = 0; t < 1 + ntags; ++t) (void)read_int("an element number or tag");
        for (int i = 0; i < info.nodes; ++i) tags[size_t(i)] = read_int("an element's node tag");
        add_element(type, info, tags);
      }
      done += uint64_t(count);
    }
  }

  void elements4() {
    if (binary_) s_.skip_line();
    const uint64_t blocks = read_size("the $Elements block count"), n = read_size("the $Elements count");
    (void)read_size("the minimum element tag");
    (void)read_size("the maximum element tag");
    s_.check_count(n, binary_ ? 16 : 4, "$Elements");
    s_.check_count(blocks, binary_ ? 20 : 8, "$Elements blocks");
    std::vector<int64_t> tags;
    uint64_t total = 0;
    for (uint64_t b = 0; b < blocks; ++b) {
      (void)read_int("an entity dimension");
      (void)read_int("an entity tag");
      const int64_t type = read_int("an element type");
      const uint64_t count = read_size("a block's element count");
      if (count > n - total) s_.fail(fmt::format("$Elements block {} holds {} elements, more than the {} the section says", b, count, n));
      const ElementType info = element_type(type);
      if (info.nodes == 0 && binary_) s_.fail_binary(fmt::format("unknown element type {} in binary $Elements", type));
      tags.resize(size_t(info.nodes));
      for (uint64_t e = 0; e < count; ++e) {
        (void)read_size("an element tag");
        if (info.nodes == 0) {
          s_.skip_line();
        } else {
          for (int i = 0; i < info.nodes; ++i) tags[size_t(i)] = int64_t(read_size("an element's node tag"));
        }
        add_element(type, info, tags);
      }
      total += count;
    }
    if (total != n) s_.fail(fmt::format("$Elements says {} elements but its blocks hold {}", n, total));
  }

  // $NodeData: string tags (view name), real tags (time), integer tags (step, components,
  // count[, partition]), then "tag value..." records. Only 1-component views are kept.
  void node_data() {
    NodeView view;
    const uint64_t nstr = ascii_count("the $NodeData string tag count");
    for (uint64_t i = 0; i < nstr; ++i) {
      (void)s_.at_end();
      std::string_view l = s_.line();
      while (!l.empty() && (l.back() == ' ' || l.back() == '\t')) l.remove_suffix(1);
      if (l.size() >= 2 && l.front() == '"' && l.back() == '"') l = l.substr(1, l.size() - 2);
      if (i == 0) view.name = std::string(l);
    }
    const uint64_t nreal = ascii_count("the $NodeData real tag count");
    for (uint64_t i = 0; i < nreal; ++i) (void)s_.real("a $NodeData real tag");
    const uint64_t nint = ascii_count("the $NodeData integer tag count");
    if (nint < 3) s_.fail(fmt::format("$NodeData has {} integer tags (time step, components and count needed)", nint));
    std::array<int64_t, 3> ints{};
    for (uint64_t i = 0; i < nint; ++i) {
      const int64_t v = s_.integer("a $NodeData integer tag");
      if (i < 3) ints[i] = v;
    }
    view.step = ints[0];
    const int64_t ncomp = ints[1], count = ints[2];
    if (ncomp < 1 || ncomp > 9) s_.fail(fmt::format("$NodeData '{}' has {} components", view.name, ncomp));
    if (count < 0) s_.fail(fmt::format("$NodeData '{}' has a negative count {}", view.name, count));
    s_.check_count(uint64_t(count), binary_ ? 4 + 8 * uint64_t(ncomp) : 4, fmt::format("$NodeData '{}'", view.name));
    if (binary_) s_.skip_line();
    if (ncomp == 1) view.values.reserve(size_t(count));
    for (int64_t i = 0; i < count; ++i) {
      const int64_t tag = read_int(fmt::format("a node tag in $NodeData '{}'", view.name));
      double v = 0;
      for (int64_t c = 0; c < ncomp; ++c) v = read_double(fmt::format("a value in $NodeData '{}'", view.name));
      if (tag < 0) s_.fail(fmt::format("$NodeData '{}': node tag {} is negative", view.name, tag));
      if (ncomp == 1) view.values.emplace_back(uint64_t(tag), v);
    }
    if (ncomp == 1) views_.push_back(std::move(view));
  }

  // Step 3: node tags to dense indices, in the cells and the views.
  void finish() {
    const size_t n = node_tags_.size();
    uint64_t max_tag = 0;
    for (uint64_t t : node_tags_) max_tag = std::max(max_tag, t);
    std::vector<int64_t> dense;
    std::unordered_map<uint64_t, int64_t> sparse;
    const bool use_dense = max_tag <= 4 * uint64_t(n) + 1024;
    if (use_dense) dense.assign(size_t(max_tag) + 1, -1);
    for (size_t i = 0; i < n; ++i) {
      const bool fresh = use_dense ? std::exchange(dense[size_t(node_tags_[i])], int64_t(i)) == -1
                                   : sparse.emplace(node_tags_[i], int64_t(i)).second;
      if (!fresh) throw Error(Errc::format, fmt::format("$Nodes: node tag {} appears twice", node_tags_[i])).with_file(s_.path());
    }
    const auto index = [&](uint64_t tag) -> int64_t {
      if (use_dense) return tag < dense.size() ? dense[size_t(tag)] : -1;
      const auto it = sparse.find(tag);
      return it == sparse.end() ? -1 : it->second;
    };
    for (int64_t& v : mesh_.connectivity) v = v < 0 ? -1 : index(uint64_t(v));
    // Views: blocks of the same name and step (partitions) merge; several steps of a name
    // become NAME_0, NAME_1 ... in file order.
    std::map<std::pair<std::string, int64_t>, size_t> slot;
    std::map<std::string, std::vector<size_t>> steps_of;
    for (NodeView& view : views_) {
      auto [it, fresh] = slot.emplace(std::make_pair(view.name, view.step), mesh_.arrays.size());
      if (fresh) {
        steps_of[view.name].push_back(mesh_.arrays.size());
        mesh_.arrays.push_back(PointArray{view.name, std::vector<double>(n, std::nan("")), 0});
      }
      std::vector<double>& values = mesh_.arrays[it->second].values;
      for (const auto& [tag, v] : view.values) {
        const int64_t i = index(tag);
        if (i < 0)
          throw Error(Errc::format, fmt::format("$NodeData '{}': node tag {} is not in $Nodes", view.name, tag)).with_file(s_.path());
        values[size_t(i)] = v;
      }
    }
    for (const auto& [name, ids] : steps_of)
      if (ids.size() > 1)
        for (size_t k = 0; k < ids.size(); ++k) mesh_.arrays[ids[k]].name = fmt::format("{}_{}", name, k);
  }

  Scanner s_;
  MeshData mesh_;
  int major_ = 2;
  bool binary_ = false, swap_ = false;
  int size_bytes_ = 8;
  std::vector<uint64_t> node_tags_;  ///< dense index -> tag
  std::vector<NodeView> views_;
};

}  // namespace

MeshData read_gmsh(const std::string& path) {
  return GmshReader(path).read();
}

}  // namespace brickyard
