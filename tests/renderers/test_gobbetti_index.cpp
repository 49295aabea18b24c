// The `gobbetti` spatial index against brute force: random adaptive cuts on layouts of
// several shapes (non-power-of-two dims, thin volumes, one brick), the tree checked against
// the cut, every link against the leaves found geometrically across each face, and the
// stackless traversal against a plain 3D DDA over the finest brick grid, mapped to the leaves
// and merged, on random, axis-parallel, corner, edge, face, inside, missing and single-point
// rays. The reference decides "which side of a plane" with the crossing formula
// (P - o) / d that the index's contract names, so the two agree on intervals bit for bit;
// the comparison still allows 1e-9 relative.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <unordered_map>
#include <vector>

#include "core/error.h"
#include "renderers/gobbetti/spatial_index.h"
#include "dataset/grid.h"

namespace brickyard::gobbetti {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// --- cuts ---------------------------------------------------------------------------

/// A random adaptive cut of about `target` leaves (at most 3/4 of the finest bricks, so that it
/// stays adaptive): from the root, refine (a) random leaves and (b) the leaf holding a point
/// near a focus, so that deep leaves sit beside coarse ones.
std::vector<CutLeaf> random_cut(const GridLayout& layout, size_t target, std::mt19937_64& rng) {
  target = std::min(target, size_t(layout.brick_count(layout.finest())) * 3 / 4);
  std::vector<BrickKey> leaves = {BrickKey{}};
  const double domain = std::ldexp(double(layout.brick_size), layout.finest());
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const Vec3d focus(u(rng) * domain, u(rng) * domain, u(rng) * domain);
  std::normal_distribution<double> near(0.0, 0.08 * domain);
  for (int attempt = 0; attempt < 20000 && leaves.size() < target; ++attempt) {
    size_t pick = size_t(rng() % leaves.size());
    if (rng() % 2) {
      const Vec3d p = focus + Vec3d(near(rng), near(rng), near(rng));
      for (size_t i = 0; i < leaves.size(); ++i) {
        const BrickKey& k = leaves[i];
        const double s = std::ldexp(double(layout.brick_size), layout.finest() - int(k.level));
        if (p.x >= k.x * s && p.x < (k.x + 1) * s && p.y >= k.y * s && p.y < (k.y + 1) * s && p.z >= k.z * s &&
            p.z < (k.z + 1) * s) {
          pick = i;
          break;
        }
      }
    }
    const BrickKey k = leaves[pick];
    if (int(k.level) == layout.finest()) continue;
    leaves[pick] = leaves.back();
    leaves.pop_back();
    for (int c = 0; c < 8; ++c)
      if (layout.contains(k.child(c))) leaves.push_back(k.child(c));
  }
  std::shuffle(leaves.begin(), leaves.end(), rng);
  std::vector<CutLeaf> cut;
  for (size_t i = 0; i < leaves.size(); ++i) cut.push_back({leaves[i], uint32_t(1000 + 7 * i)});
  return cut;
}

/// Every brick of the finest level: the finest uniform cut.
std::vector<CutLeaf> finest_cut(const GridLayout& layout) {
  std::vector<CutLeaf> cut;
  for (int64_t i = 0; i < layout.brick_count(layout.finest()); ++i)
    cut.push_back({layout.key_at(layout.finest(), i), uint32_t(i)});
  return cut;
}

// --- the reference: leaves by finest cell, a DDA over the finest cells ------------------

struct RefLeaf {
  BrickKey key;
  uint32_t payload;
  bool outside;
};

/// The cut seen from the finest brick grid of the whole domain cube (outside cells too).
struct Reference {
  GridLayout layout;
  int64_t n = 0;  // cells per axis
  double M = 0, domain = 0;
  std::vector<RefLeaf> leaves;    // the cut's leaves, then the "outside" leaves found
  std::vector<int32_t> cell_leaf; // index into leaves, per finest cell (x fastest)

  Reference(const GridLayout& l, const std::vector<CutLeaf>& cut) : layout(l) {
    n = int64_t(1) << layout.finest();
    M = layout.brick_size;
    domain = M * double(n);
    std::unordered_map<uint64_t, int32_t> by_code;
    for (const CutLeaf& c : cut) {
      by_code[c.key.code()] = int32_t(leaves.size());
      leaves.push_back({c.key, c.payload, false});
    }
    cell_leaf.resize(size_t(n * n * n));
    for (int64_t z = 0; z < n; ++z)
      for (int64_t y = 0; y < n; ++y)
        for (int64_t x = 0; x < n; ++x) {
          // The cell's leaf: its first ancestor, from the root down, that is a leaf of the
          // cut, or not a brick of the layout at all (then that brick is an outside leaf).
          int32_t found = -1;
          for (int level = 0; level <= layout.finest() && found < 0; ++level) {
            const int s = layout.finest() - level;
            const BrickKey k{uint32_t(level), uint32_t(x >> s), uint32_t(y >> s), uint32_t(z >> s)};
            if (!layout.contains(k)) {
              auto [it, inserted] = by_code.try_emplace(k.code(), int32_t(leaves.size()));
              if (inserted) leaves.push_back({k, SpatialIndex::kOutsidePayload, true});
              found = it->second;
            } else if (auto it = by_code.find(k.code()); it != by_code.end()) {
              found = it->second;
            }
          }
          cell_leaf[size_t((z * n + y) * n + x)] = found;
        }
  }

  Box3d box(const BrickKey& k) const {
    const double s = std::ldexp(M, layout.finest() - int(k.level));
    const Vec3d lo(k.x * s, k.y * s, k.z * s);
    return {lo, lo + Vec3d(s)};
  }

  static double plane_t(double p, double o, double d) { return (p - o) / d; }

  /// Walks the finest cells with a DDA (Amanatides and Woo), crossing parameters recomputed
  /// from the origin by the contract's formula; drops pieces of zero length, merges pieces of
  /// one leaf. The start cell counts, per axis, the planes the ray is above at t0.
  std::vector<LeafVisit> walk(const Vec3d& o, const Vec3d& d, double t0, double t1) const {
    std::vector<LeafVisit> out;
    for (int a = 0; a < 3; ++a) {
      if (!std::isfinite(o[a]) || !std::isfinite(d[a])) return out;
      if (d[a] == 0) {
        if (o[a] < 0 || o[a] > domain) return out;
        continue;
      }
      double tn = plane_t(0, o[a], d[a]), tf = plane_t(domain, o[a], d[a]);
      if (d[a] < 0) std::swap(tn, tf);
      t0 = std::max(t0, tn);
      t1 = std::min(t1, tf);
    }
    if (!(t0 <= t1)) return out;
    int64_t cell[3];
    for (int a = 0; a < 3; ++a) {
      cell[a] = 0;
      for (int64_t k = 1; k < n; ++k) {
        const double p = double(k) * M;
        const bool above = d[a] > 0 ? plane_t(p, o[a], d[a]) <= t0 : d[a] < 0 ? plane_t(p, o[a], d[a]) > t0 : o[a] >= p;
        if (above) cell[a] = k;
      }
    }
    auto add = [&](double ta, double tb) {
      const RefLeaf& l = leaves[size_t(cell_leaf[size_t((cell[2] * n + cell[1]) * n + cell[0])])];
      if (!out.empty() && out.back().key == l.key) {
        out.back().tb = tb;
        return;
      }
      out.push_back(LeafVisit{0, l.key, l.payload, l.outside, ta, tb});
    };
    if (t0 == t1) {
      add(t0, t1);
      return out;
    }
    double next[3];
    auto crossing = [&](int a) {
      if (d[a] == 0) return kInf;
      return plane_t(double(d[a] > 0 ? cell[a] + 1 : cell[a]) * M, o[a], d[a]);
    };
    for (int a = 0; a < 3; ++a) next[a] = crossing(a);
    double ta = t0;
    for (;;) {
      const int axis = next[0] <= next[1] ? (next[0] <= next[2] ? 0 : 2) : (next[1] <= next[2] ? 1 : 2);
      const double tb = std::min(next[axis], t1);
      if (tb > ta) add(ta, tb);
      if (!(next[axis] < t1)) break;
      cell[axis] += d[axis] > 0 ? 1 : -1;
      if (cell[axis] < 0 || cell[axis] >= n) break;
      next[axis] = crossing(axis);
      ta = std::max(ta, tb);
    }
    return out;
  }
};

std::string describe_ray(const Vec3d& o, const Vec3d& d, double t0, double t1) {
  std::ostringstream os;
  os.precision(17);
  os << "org " << o << " dir " << d << " t [" << t0 << ", " << t1 << "]";
  return os.str();
}

std::string describe(const std::vector<LeafVisit>& v) {
  std::ostringstream os;
  os.precision(17);
  for (const LeafVisit& x : v)
    os << "\n  " << x.key << (x.outside ? " outside" : "") << " payload " << x.payload << " [" << x.ta << ", " << x.tb << "]";
  return os.str();
}

bool nearly_equal(double a, double b) { return a == b || std::abs(a - b) <= 1e-9 * std::max(1.0, std::abs(b)); }

::testing::AssertionResult traversal_matches(const SpatialIndex& index, const Reference& ref, const Vec3d& o,
                                             const Vec3d& d, double t0, double t1) {
  std::vector<LeafVisit> got;
  index.traverse(o, d, t0, t1, [&](const LeafVisit& v) {
    got.push_back(v);
    return got.size() < 100000;
  });
  const std::vector<LeafVisit> want = ref.walk(o, d, t0, t1);
  bool same = got.size() == want.size();
  for (size_t i = 0; same && i < got.size(); ++i) {
    same = got[i].key == want[i].key && got[i].payload == want[i].payload && got[i].outside == want[i].outside &&
           nearly_equal(got[i].ta, want[i].ta) && nearly_equal(got[i].tb, want[i].tb) && index.key(got[i].node) == got[i].key &&
           index.payload(got[i].node) == got[i].payload && index.is_leaf(got[i].node);
  }
  if (same) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << describe_ray(o, d, t0, t1) << "\nindex:" << describe(got)
                                       << "\nreference:" << describe(want);
}

// --- layouts and rays ---------------------------------------------------------------

struct Shape {
  Vec3s dims;
  int brick_size;
};
const Shape kShapes[] = {
    {{100, 37, 64}, 8},   // the brief's example: 5 levels, ragged on every axis
    {{200, 130, 90}, 8},  // 6 levels
    {{65, 3, 20}, 8},     // chains of inner nodes with one brick child each
    {{9, 1, 1}, 8},       // a line of two bricks
    {{64, 64, 64}, 8},    // a power of two: no outside leaves
    {{300, 17, 9}, 16},   // M = 16, flat
    {{5, 8, 3}, 8},       // one brick, one level
};

/// Random rays of every kind the contract names, on the brick grid of the reference.
class RayMaker {
 public:
  RayMaker(const Reference& ref, std::mt19937_64& rng) : ref_(ref), rng_(rng) {}

  double uniform(double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng_); }
  /// A grid plane coordinate: a multiple of M (or of a coarser node size) in [0, domain].
  double plane() {
    const int64_t step = int64_t(1) << (rng_() % (ref_.layout.finest() + 1));
    return double((int64_t(rng_() % uint64_t(ref_.n + 1)) / step) * step) * ref_.M;
  }
  /// A dyadic coordinate (quarter voxels) around the domain, so differences are exact.
  double dyadic(double lo, double hi) { return std::floor(uniform(lo, hi) * 4) / 4; }
  Vec3d point_around() {
    const double D = ref_.domain;
    return {uniform(-0.5 * D, 1.5 * D), uniform(-0.5 * D, 1.5 * D), uniform(-0.5 * D, 1.5 * D)};
  }
  Vec3d point_inside() { return {uniform(0, ref_.domain), uniform(0, ref_.domain), uniform(0, ref_.domain)}; }
  Vec3d grid_point() { return {plane(), plane(), plane()}; }
  Vec3d direction() {
    std::normal_distribution<double> g;
    return {g(rng_), g(rng_), g(rng_)};
  }
  double sign() { return rng_() % 2 ? 1.0 : -1.0; }

  struct Ray {
    Vec3d o, d;
    double t0, t1;
  };

  static constexpr int kKinds = 12;
  /// Ray kind k (0..kKinds-1).
  Ray make(int kind) {
    const double D = ref_.domain;
    switch (kind) {
      case 0:  // random, from around the domain
        return {point_around(), direction(), 0.0, kInf};
      case 1: {  // random, starting inside, clipped both ways
        const double t0 = uniform(-D, D);
        return {point_inside(), direction(), t0, t0 + uniform(0, 2 * D)};
      }
      case 2: {  // axis-parallel, one or two zero components, origin sometimes on grid planes
        Vec3d o = point_around(), d = direction();
        const int zeros = 1 + int(rng_() % 2), first = int(rng_() % 3);
        for (int i = 0; i < zeros; ++i) {
          const int a = (first + i) % 3;
          d[a] = 0;
          o[a] = rng_() % 2 ? plane() : uniform(0, D);
        }
        return {o, d, -kInf, kInf};
      }
      case 3: {  // exactly axis-aligned along an edge line of the grid, or inside a face plane
        Vec3d o = grid_point(), d(0.0);
        const int a = int(rng_() % 3);
        d[a] = sign() * (rng_() % 3 + 1);
        o[a] = dyadic(-D, 2 * D);
        if (rng_() % 2) {  // inside a face plane: one more direction component, off-grid origin
          const int b = (a + 1 + int(rng_() % 2)) % 3;
          d[b] = sign() * (rng_() % 5 + 1) / 4.0;
          o[b] = dyadic(0, D);
        }
        return {o, d, -kInf, kInf};
      }
      case 4: {  // through a grid corner, from a dyadic origin: exact direction, exact ties
        const Vec3d corner = grid_point();
        const Vec3d o(dyadic(-0.5 * D, 1.5 * D), dyadic(-0.5 * D, 1.5 * D), dyadic(-0.5 * D, 1.5 * D));
        if (o == corner) return {o, Vec3d(1, 1, 1), 0, kInf};
        return {o, corner - o, -kInf, kInf};
      }
      case 5: {  // grid point to grid point: diagonals through many corners and edges
        const Vec3d a = grid_point(), b = grid_point();
        if (a == b) return {a, Vec3d(-1, 1, -1), 0, kInf};
        return {a, b - a, rng_() % 2 ? 0.0 : -kInf, kInf};
      }
      case 6: {  // pure diagonals with integer slopes from grid points
        const Vec3d o = grid_point();
        const Vec3d d(sign() * (rng_() % 3), sign() * (rng_() % 3), sign() * (1 + rng_() % 2));
        return {o, d, uniform(-D, 0), kInf};
      }
      case 7: {  // misses: outside and pointing away
        Vec3d o = point_around(), d = direction();
        const int a = int(rng_() % 3);
        if (rng_() % 2) {
          o[a] = -1 - uniform(0, D);
          d[a] = -std::abs(d[a]);
        } else {
          o[a] = D + 1 + uniform(0, D);
          d[a] = std::abs(d[a]);
        }
        return {o, d, 0, kInf};
      }
      case 8: {  // a single point: t0 == t1, on grid points or anywhere
        const Vec3d o = rng_() % 2 ? grid_point() : point_inside();
        const double t = rng_() % 2 ? 0.0 : uniform(-1, 1);
        return {o, direction(), t, t};
      }
      case 10: {  // towards a grid corner from an arbitrary origin: misses it by rounding only
        const Vec3d o = point_around();
        const Vec3d d = grid_point() - o;
        return {o, d, rng_() % 2 ? 0.0 : -kInf, kInf};
      }
      case 11: {  // starting where an arbitrary ray crosses a grid plane (by the crossing formula)
        const Vec3d o = point_around();
        const Vec3d d = rng_() % 2 ? direction() : grid_point() - o;
        const int a = int(rng_() % 3);
        if (d[a] == 0) return {o, d, 0, kInf};
        const double t0 = (plane() - o[a]) / d[a];
        return {o, d, t0, rng_() % 4 ? kInf : t0};
      }
      default: {  // starting exactly on a face, an edge or a corner, random direction
        Vec3d o = grid_point();
        for (int a = 0; a < 3; ++a)
          if (rng_() % 2) o[a] = dyadic(0, D);
        return {o, direction(), 0, rng_() % 2 ? kInf : uniform(0, D)};
      }
    }
  }

 private:
  const Reference& ref_;
  std::mt19937_64& rng_;
};

// --- tests --------------------------------------------------------------------------

/// Checks the tree against the cut: every leaf once with its payload, outside leaves exactly
/// the missing children, children contiguous and in BrickKey::child order.
void expect_tree_matches(const SpatialIndex& index, const GridLayout& layout, const std::vector<CutLeaf>& cut) {
  std::unordered_map<uint64_t, uint32_t> payload_of;
  for (const CutLeaf& c : cut) payload_of[c.key.code()] = c.payload;
  ASSERT_EQ(index.cut_leaf_count(), cut.size());
  // 8 children per inner node: nodes = 1 + 8 inner = inner + leaves.
  ASSERT_EQ(index.node_count() % 8, 1u);
  ASSERT_EQ(index.node_count(), (index.node_count() - 1) / 8 + index.cut_leaf_count() + index.outside_leaf_count());
  std::vector<int> parents(index.node_count(), 0);
  size_t leaves_seen = 0, outside_seen = 0;
  EXPECT_EQ(index.key(0), BrickKey{});
  for (uint32_t i = 0; i < index.node_count(); ++i) {
    const BrickKey k = index.key(i);
    if (index.is_inner(i)) {
      EXPECT_TRUE(layout.contains(k)) << k;
      EXPECT_EQ(payload_of.count(k.code()), 0u) << k;
      const uint32_t first = index.first_child(i);
      ASSERT_LE(first + 8, index.node_count());
      for (int c = 0; c < 8; ++c) {
        EXPECT_EQ(index.key(first + uint32_t(c)), k.child(c));
        ++parents[first + uint32_t(c)];
      }
    } else if (index.is_outside(i)) {
      ++outside_seen;
      EXPECT_FALSE(layout.contains(k)) << k;
      EXPECT_TRUE(layout.contains(k.parent())) << k;
      EXPECT_EQ(index.payload(i), SpatialIndex::kOutsidePayload);
    } else {
      ++leaves_seen;
      auto it = payload_of.find(k.code());
      ASSERT_NE(it, payload_of.end()) << k << " is a leaf of the index, not of the cut";
      EXPECT_EQ(index.payload(i), it->second) << k;
    }
  }
  EXPECT_EQ(parents[0], 0);
  for (uint32_t i = 1; i < index.node_count(); ++i) EXPECT_EQ(parents[i], 1) << "node " << i;
  EXPECT_EQ(leaves_seen, cut.size());
  EXPECT_EQ(outside_seen, index.outside_leaf_count());
}

/// Checks every leaf's six links against the leaves found geometrically across each face:
/// one leaf as large or larger -> that leaf; several smaller ones -> the inner node at the
/// leaf's own level that encloses them; beyond the domain -> null.
void expect_links_match_geometry(const SpatialIndex& index, const Reference& ref) {
  std::unordered_map<uint64_t, uint32_t> node_of;
  for (uint32_t i = 0; i < index.node_count(); ++i) node_of[index.key(i).code()] = i;
  // The leaves of the reference (the cut and the outside leaves it found) are the index's.
  size_t index_leaves = 0;
  for (uint32_t i = 0; i < index.node_count(); ++i) index_leaves += index.is_leaf(i);
  ASSERT_EQ(index_leaves, ref.leaves.size());
  std::vector<Box3d> boxes;
  for (const RefLeaf& l : ref.leaves) {
    ASSERT_TRUE(node_of.count(l.key.code())) << l.key;
    ASSERT_TRUE(index.is_leaf(node_of[l.key.code()])) << l.key;
    boxes.push_back(ref.box(l.key));
  }
  for (size_t li = 0; li < ref.leaves.size(); ++li) {
    const BrickKey k = ref.leaves[li].key;
    const uint32_t node = node_of[k.code()];
    const Box3d b = boxes[li];
    for (int face = 0; face < 6; ++face) {
      const int a = face / 2;
      const bool positive = face % 2;
      const uint32_t link = index.link(node, face);
      const double plane = positive ? b.hi[a] : b.lo[a];
      if (plane == 0.0 || plane == ref.domain) {  // the face lies on the domain's boundary
        EXPECT_EQ(link, SpatialIndex::kNullLink) << k << " face " << face;
        continue;
      }
      // Leaves across the face, touching it with positive area.
      std::vector<size_t> across;
      for (size_t j = 0; j < ref.leaves.size(); ++j) {
        const Box3d& o = boxes[j];
        if ((positive ? o.lo[a] : o.hi[a]) != plane) continue;
        bool overlap = true;
        for (int e = 0; e < 3; ++e)
          if (e != a && !(o.lo[e] < b.hi[e] && b.lo[e] < o.hi[e])) overlap = false;
        if (overlap) across.push_back(j);
      }
      ASSERT_FALSE(across.empty()) << k << " face " << face;
      BrickKey want;
      if (across.size() == 1 && ref.leaves[across[0]].key.level <= k.level) {
        want = ref.leaves[across[0]].key;
      } else {
        want = k;
        uint32_t& coord = a == 0 ? want.x : a == 1 ? want.y : want.z;
        coord = positive ? coord + 1 : coord - 1;
        // The node at this level encloses every leaf across, and they are all smaller.
        const Box3d enclosing = ref.box(want);
        for (size_t j : across) {
          EXPECT_GT(ref.leaves[j].key.level, k.level) << k << " face " << face;
          EXPECT_TRUE(enclosing.contains(boxes[j].lo) && enclosing.contains(boxes[j].hi)) << k << " face " << face;
        }
        ASSERT_TRUE(node_of.count(want.code())) << want;
        EXPECT_TRUE(index.is_inner(node_of[want.code()])) << want;
      }
      ASSERT_NE(link, SpatialIndex::kNullLink) << k << " face " << face;
      EXPECT_EQ(index.key(SpatialIndex::link_index(link)), want) << k << " face " << face;
      EXPECT_EQ(SpatialIndex::link_level(link), int(want.level)) << k << " face " << face;
    }
  }
}

TEST(GobbettiSpatialIndex, TreeHoldsEveryLeafOfRandomCutsOnceWithItsPayload) {
  std::mt19937_64 rng(11);
  for (const Shape& shape : kShapes) {
    const GridLayout layout = GridLayout::make(shape.dims, shape.brick_size);
    for (size_t target : {1ul, 20ul, 300ul, 2000ul}) {
      SCOPED_TRACE(::testing::Message() << shape.dims << " M " << shape.brick_size << " target " << target);
      const std::vector<CutLeaf> cut = random_cut(layout, target, rng);
      SpatialIndex index;
      index.build(layout, cut);
      expect_tree_matches(index, layout, cut);
      // The cuts are adaptive: deep leaves beside coarse ones.
      uint32_t lo = 99, hi = 0;
      for (const CutLeaf& c : cut) lo = std::min(lo, c.key.level), hi = std::max(hi, c.key.level);
      if (target >= 300 && layout.brick_count(layout.finest()) >= 4 * int64_t(target)) {
        EXPECT_GE(hi - lo, 2u) << "levels " << lo << ".." << hi;
      }
    }
    SpatialIndex index;
    const std::vector<CutLeaf> cut = finest_cut(layout);
    index.build(layout, cut);
    expect_tree_matches(index, layout, cut);
  }
}

TEST(GobbettiSpatialIndex, NeighbourLinksMatchTheLeavesAcrossEachFace) {
  std::mt19937_64 rng(12);
  for (const Shape& shape : kShapes) {
    const GridLayout layout = GridLayout::make(shape.dims, shape.brick_size);
    for (size_t target : {1ul, 50ul, 600ul, 1500ul}) {
      SCOPED_TRACE(::testing::Message() << shape.dims << " M " << shape.brick_size << " target " << target);
      const std::vector<CutLeaf> cut = random_cut(layout, target, rng);
      SpatialIndex index;
      index.build(layout, cut);
      expect_links_match_geometry(index, Reference(layout, cut));
    }
  }
}

TEST(GobbettiSpatialIndex, TraversalVisitsTheLeavesOfAReferenceDdaOnEveryKindOfRay) {
  std::mt19937_64 rng(13);
  constexpr int kRaysPerKind = 500;
  for (const Shape& shape : kShapes) {
    const GridLayout layout = GridLayout::make(shape.dims, shape.brick_size);
    for (size_t target : {1ul, 80ul, 1000ul}) {
      SCOPED_TRACE(::testing::Message() << shape.dims << " M " << shape.brick_size << " target " << target);
      const std::vector<CutLeaf> cut = random_cut(layout, target, rng);
      SpatialIndex index;
      index.build(layout, cut);
      const Reference ref(layout, cut);
      RayMaker rays(ref, rng);
      int failures = 0;
      for (int kind = 0; kind < RayMaker::kKinds && failures < 3; ++kind)
        for (int i = 0; i < kRaysPerKind && failures < 3; ++i) {
          const RayMaker::Ray r = rays.make(kind);
          const auto result = traversal_matches(index, ref, r.o, r.d, r.t0, r.t1);
          EXPECT_TRUE(result) << "ray kind " << kind;
          failures += !result;
        }
    }
  }
}

TEST(GobbettiSpatialIndex, TraversalOfTheFinestCutIsTheDda) {
  std::mt19937_64 rng(14);
  const GridLayout layout = GridLayout::make({100, 37, 64}, 8);
  const std::vector<CutLeaf> cut = finest_cut(layout);
  SpatialIndex index;
  index.build(layout, cut);
  const Reference ref(layout, cut);
  RayMaker rays(ref, rng);
  for (int i = 0; i < 2000; ++i) {
    const RayMaker::Ray r = rays.make(i % RayMaker::kKinds);
    ASSERT_TRUE(traversal_matches(index, ref, r.o, r.d, r.t0, r.t1)) << "ray kind " << i % RayMaker::kKinds;
  }
}

TEST(GobbettiSpatialIndex, RaysOnFacesEdgesAndCornersFollowTheContract) {
  // One level-1 split of a 2-level layout: the domain is [0, 16]^3, children of size 8.
  const GridLayout layout = GridLayout::make({16, 16, 16}, 8);
  ASSERT_EQ(layout.levels, 2);
  std::vector<CutLeaf> cut;
  for (int c = 0; c < 8; ++c) cut.push_back({BrickKey{}.child(c), uint32_t(c)});
  SpatialIndex index;
  index.build(layout, cut);
  auto visits = [&](Vec3d o, Vec3d d, double t0, double t1) {
    std::vector<LeafVisit> v;
    index.traverse(o, d, t0, t1, [&](const LeafVisit& x) {
      v.push_back(x);
      return true;
    });
    return v;
  };
  // Along the edge x = y = 8 in +z: the cells above both planes.
  auto v = visits({8, 8, -1}, {0, 0, 1}, 0, kInf);
  ASSERT_EQ(v.size(), 2u);
  EXPECT_EQ(v[0].payload, 3u);
  EXPECT_EQ(v[1].payload, 7u);
  EXPECT_EQ(v[0].ta, 1.0);
  EXPECT_EQ(v[0].tb, 9.0);
  EXPECT_EQ(v[1].tb, 17.0);
  // In the domain's upper face x = 16: the last cell, not outside.
  v = visits({16, 1, 1}, {0, 1, 0}, 0, kInf);
  ASSERT_EQ(v.size(), 2u);
  EXPECT_EQ(v[0].payload, 1u);
  EXPECT_EQ(v[1].payload, 3u);
  // The main diagonal through the centre corner: two cells, the zero-length ones unreported.
  v = visits({0, 0, 0}, {1, 1, 1}, 0, kInf);
  ASSERT_EQ(v.size(), 2u);
  EXPECT_EQ(v[0].payload, 0u);
  EXPECT_EQ(v[1].payload, 7u);
  EXPECT_EQ(v[0].tb, 8.0);
  EXPECT_EQ(v[1].ta, 8.0);
  EXPECT_EQ(v[1].tb, 16.0);
  // The other way: starts on the upper corner, moving down.
  v = visits({16, 16, 16}, {-1, -1, -1}, 0, kInf);
  ASSERT_EQ(v.size(), 2u);
  EXPECT_EQ(v[0].payload, 7u);
  EXPECT_EQ(v[1].payload, 0u);
  // A single point on the centre corner: the cell the direction points into.
  v = visits({8, 8, 8}, {-1, 1, -1}, 0, 0);
  ASSERT_EQ(v.size(), 1u);
  EXPECT_EQ(v[0].payload, 2u);
  EXPECT_EQ(v[0].ta, 0.0);
  EXPECT_EQ(v[0].tb, 0.0);
  // Grazing the domain along an outer edge, and touching it at a corner only.
  v = visits({0, 0, -5}, {0, 0, 1}, 0, kInf);
  ASSERT_EQ(v.size(), 2u);
  EXPECT_EQ(v[0].payload, 0u);
  v = visits({-1, 1, 15}, {1, -1, 1}, 0, kInf);
  ASSERT_EQ(v.size(), 1u);  // touches [0,16]^3 at (0, 0, 16) only: a single point
  EXPECT_EQ(v[0].payload, 4u);
  EXPECT_EQ(v[0].ta, 1.0);
  EXPECT_EQ(v[0].ta, v[0].tb);
  // Misses, an empty interval, NaN and infinite input.
  EXPECT_TRUE(visits({-1, 20, 5}, {1, 0, 0}, 0, kInf).empty());
  EXPECT_TRUE(visits({5, 5, 5}, {1, 0, 0}, 3, 2).empty());
  EXPECT_TRUE(visits({5, 5, 5}, {1, 0, 0}, std::nan(""), 2).empty());
  EXPECT_TRUE(visits({5, std::nan(""), 5}, {1, 0, 0}, 0, kInf).empty());
  EXPECT_TRUE(visits({5, 5, 5}, {kInf, 0, 0}, 0, kInf).empty());
  // A zero direction: the point's leaf for the whole interval.
  v = visits({5, 9, 5}, {0, 0, 0}, -2, 3);
  ASSERT_EQ(v.size(), 1u);
  EXPECT_EQ(v[0].payload, 2u);
  EXPECT_EQ(v[0].ta, -2.0);
  EXPECT_EQ(v[0].tb, 3.0);
}

TEST(GobbettiSpatialIndex, OutsideLeavesAreCrossedBecauseCoarseLeavesReachFurther) {
  // 100 voxels in x, M = 8: the finest level has 13 bricks (to x = 104), level 3 has 7 (to
  // 112). Refine one level-3 brick at x = 6 and keep its +y neighbour coarse: a ray along +y
  // at x = 108 crosses an outside leaf, then the coarse leaf.
  const GridLayout layout = GridLayout::make({100, 37, 64}, 8);
  ASSERT_EQ(layout.levels, 5);
  std::vector<CutLeaf> cut;
  std::vector<BrickKey> todo = {BrickKey{}};
  const BrickKey refined{3, 6, 0, 0};
  while (!todo.empty()) {
    const BrickKey k = todo.back();
    todo.pop_back();
    const bool split = k.level < 3 || k == refined;
    if (!split) {
      cut.push_back({k, uint32_t(cut.size())});
      continue;
    }
    for (int c = 0; c < 8; ++c)
      if (layout.contains(k.child(c))) todo.push_back(k.child(c));
  }
  SpatialIndex index;
  index.build(layout, cut);
  std::vector<LeafVisit> v;
  index.traverse({108, 1, 1}, {0, 1, 0}, 0, kInf, [&](const LeafVisit& x) {
    v.push_back(x);
    return true;
  });
  // Level 3 has 3 bricks in y (to 48), level 2 has 2 (to 64), level 1 one (to 64).
  struct Want {
    BrickKey key;
    bool outside;
    double ta, tb;
  };
  const Want want[] = {{{4, 13, 0, 0}, true, 0, 7},    {{4, 13, 1, 0}, true, 7, 15},
                       {{3, 6, 1, 0}, false, 15, 31},  {{3, 6, 2, 0}, false, 31, 47},
                       {{3, 6, 3, 0}, true, 47, 63},   {{1, 1, 1, 0}, true, 63, 127}};
  ASSERT_EQ(v.size(), std::size(want)) << describe(v);
  for (size_t i = 0; i < v.size(); ++i) {
    EXPECT_EQ(v[i].key, want[i].key) << i;
    EXPECT_EQ(v[i].outside, want[i].outside) << i;
    EXPECT_EQ(v[i].ta, want[i].ta) << i;
    EXPECT_EQ(v[i].tb, want[i].tb) << i;
  }
}

TEST(GobbettiSpatialIndex, VisitorReturningFalseStopsTheWalk) {
  const GridLayout layout = GridLayout::make({100, 37, 64}, 8);
  const std::vector<CutLeaf> cut = finest_cut(layout);
  SpatialIndex index;
  index.build(layout, cut);
  int calls = 0;
  index.traverse({-1, 3, 3}, {1, 0, 0}, 0, kInf, [&](const LeafVisit&) { return ++calls < 3; });
  EXPECT_EQ(calls, 3);
}

TEST(GobbettiSpatialIndex, WalksEndOnExtremeRays) {
  // Tiny and huge direction components, far origins: every walk ends within its bound and
  // reports ordered, non-overlapping, positive pieces.
  std::mt19937_64 rng(15);
  const GridLayout layout = GridLayout::make({200, 130, 90}, 8);
  const std::vector<CutLeaf> cut = random_cut(layout, 1500, rng);
  SpatialIndex index;
  index.build(layout, cut);
  const double D = index.domain_size();
  const double scales[] = {1e-300, 1e-30, 1e-9, 1, 1e9, 1e300, 5e-324};
  std::uniform_real_distribution<double> u(-1, 1);
  for (int i = 0; i < 3000; ++i) {
    Vec3d d(u(rng) * scales[rng() % 7], u(rng) * scales[rng() % 7], u(rng) * scales[rng() % 7]);
    Vec3d o(D * (0.5 + u(rng)), D * (0.5 + u(rng)), D * (0.5 + u(rng)));
    if (i % 3 == 0) o = o * 1e12;
    size_t steps = 0;
    double last = -kInf;
    bool ordered = true;
    index.traverse(o, d, -kInf, kInf, [&](const LeafVisit& v) {
      ordered &= v.ta >= last && (v.tb > v.ta || v.ta == v.tb);
      last = v.tb;
      return ++steps < 1000000;
    });
    EXPECT_TRUE(ordered) << describe_ray(o, d, -kInf, kInf);
    EXPECT_LE(steps, size_t(3 * 32 + 1)) << describe_ray(o, d, -kInf, kInf);
  }
}

TEST(GobbettiSpatialIndex, OneBrickLayoutIsOneLeaf) {
  const GridLayout layout = GridLayout::make({5, 8, 3}, 8);
  ASSERT_EQ(layout.levels, 1);
  SpatialIndex index;
  const CutLeaf root{BrickKey{}, 42};
  index.build(layout, std::span(&root, 1));
  ASSERT_EQ(index.node_count(), 1u);
  EXPECT_TRUE(index.is_leaf(0));
  EXPECT_FALSE(index.is_outside(0));
  EXPECT_EQ(index.payload(0), 42u);
  for (int f = 0; f < 6; ++f) EXPECT_EQ(index.link(0, f), SpatialIndex::kNullLink);
  std::vector<LeafVisit> v;
  index.traverse({-2, 4, 4}, {1, 0, 0}, 0, kInf, [&](const LeafVisit& x) {
    v.push_back(x);
    return true;
  });
  ASSERT_EQ(v.size(), 1u);
  EXPECT_EQ(v[0].payload, 42u);
  EXPECT_EQ(v[0].ta, 2.0);
  EXPECT_EQ(v[0].tb, 10.0);
}

TEST(GobbettiSpatialIndex, RejectsOverlapsGapsDuplicatesAndForeignKeys) {
  const GridLayout layout = GridLayout::make({100, 37, 64}, 8);
  std::mt19937_64 rng(16);
  std::vector<CutLeaf> cut = random_cut(layout, 200, rng);
  SpatialIndex index;
  auto expect_rejected = [&](const std::vector<CutLeaf>& bad, const std::string& words) {
    try {
      index.build(layout, bad);
      ADD_FAILURE() << "accepted a cut with " << words;
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), Errc::invalid_argument);
      EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
    }
  };
  expect_rejected({}, "covered by no leaf");
  std::vector<CutLeaf> bad = cut;
  bad.push_back(cut[5]);
  expect_rejected(bad, "given twice");
  bad = cut;
  bad.erase(bad.begin() + 3);
  expect_rejected(bad, "covered by no leaf");
  bad = cut;
  bad.push_back({cut[0].key.parent(), 1});  // a leaf and its parent, either order
  expect_rejected(bad, "leaves overlap");
  std::reverse(bad.begin(), bad.end());
  expect_rejected(bad, "leaves overlap");
  bad = cut;
  const auto deep = std::find_if(cut.begin(), cut.end(), [](const CutLeaf& c) { return c.key.level >= 2; });
  ASSERT_NE(deep, cut.end());
  bad.push_back({deep->key.parent().parent(), 1});  // a leaf and its grandparent, either order
  expect_rejected(bad, "leaves overlap");
  std::reverse(bad.begin(), bad.end());
  expect_rejected(bad, "leaves overlap");
  bad = cut;
  bad.push_back({BrickKey{}, 1});  // the root beside everything
  expect_rejected(bad, "leaves overlap");
  expect_rejected({{BrickKey{}, 1}, {BrickKey{}, 2}}, "given twice");
  bad = cut;
  bad.push_back({BrickKey{4, 13, 0, 0}, 1});  // outside the layout
  expect_rejected(bad, "not a brick of the layout");
  bad = cut;
  bad.push_back({BrickKey{7, 0, 0, 0}, 1});  // below the finest level
  expect_rejected(bad, "not a brick of the layout");
  // The index is still usable after a rejected build.
  index.build(layout, cut);
  expect_tree_matches(index, layout, cut);
}

TEST(GobbettiSpatialIndex, RebuildingReusesStorageAndForgetsThePreviousCut) {
  std::mt19937_64 rng(17);
  const GridLayout big = GridLayout::make({200, 130, 90}, 8), small = GridLayout::make({65, 3, 20}, 8);
  SpatialIndex index;
  const std::vector<CutLeaf> large_cut = random_cut(big, 3000, rng);
  index.build(big, large_cut);
  const size_t bytes = index.bytes();
  for (int frame = 0; frame < 4; ++frame) {
    const bool use_small = frame % 2 == 0;
    const GridLayout& layout = use_small ? small : big;
    const std::vector<CutLeaf> cut = random_cut(layout, use_small ? 40 : 2000, rng);
    index.build(layout, cut);
    expect_tree_matches(index, layout, cut);
    const Reference ref(layout, cut);
    RayMaker rays(ref, rng);
    for (int i = 0; i < 200; ++i) {
      const RayMaker::Ray r = rays.make(i % RayMaker::kKinds);
      ASSERT_TRUE(traversal_matches(index, ref, r.o, r.d, r.t0, r.t1));
    }
  }
  index.build(big, large_cut);
  EXPECT_EQ(index.bytes(), bytes);  // the largest frame's storage, kept and reused
}

}  // namespace
}  // namespace brickyard::gobbetti
