// The parts of the `gigavoxels` back end, one at a time: its node tree's LRU replacement (never
// what the frame used, never the root), preintegrated transfer-function segments, corner
// lanes, lighting side by side, face lighting, cell groups and field bounds.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <random>
#include <set>
#include <string>

#include <fmt/format.h>

#include "renderers/common/cell_accessor.h"
#include "renderers/common/scene.h"
#include "renderers/common/shading.h"
#include "renderers/gigavoxels/cell_groups.h"
#include "renderers/gigavoxels/corner_lanes.h"
#include "renderers/gigavoxels/face_lighting.h"
#include "renderers/gigavoxels/field_bounds.h"
#include "renderers/gigavoxels/node_tree.h"
#include "renderers/gigavoxels/preintegrated.h"

namespace brickyard {
namespace {

using gigavoxels::kNoAddress;
using gigavoxels::Node;
using gigavoxels::NodeAddress;
using gigavoxels::NodeTree;

TEST(GigaVoxelsNodeTree, LruNeverEvictsWhatTheFrameUsedNorTheRoot) {
  // 1 + 4 blocks of 8 nodes, 1 + 3 bricks: far too small for what the frames below ask.
  NodeTree tree(2, 5, 4, 8);
  tree.set_root(Node::make_data(false), {});
  tree.begin_feedback(1);
  ASSERT_EQ(tree.allocate_brick(0), 0u);  // the root's brick: slot 0, always
  const uint32_t a = tree.subdivide(0);
  ASSERT_NE(a, kNoAddress);
  for (int i = 0; i < 8; ++i) tree.set_node(a + uint32_t(i), Node::make_data(false));
  const uint32_t b = tree.subdivide(a + 3);  // a grandchild block
  ASSERT_NE(b, kNoAddress);
  for (int i = 0; i < 8; ++i) tree.set_node(b + uint32_t(i), Node::make_data(false));
  EXPECT_EQ(tree.address_of(b + 1).depth, 2);
  EXPECT_EQ(tree.address_of(b + 1).x, 3);  // child 3 of the root is (1,1,0); its child 1 is (3,2,0)
  EXPECT_EQ(tree.address_of(b + 1).y, 2);
  const uint32_t s1 = tree.allocate_brick(b + 1);
  ASSERT_NE(s1, kNoAddress);
  tree.end_of_feedback();

  // Frame 2 uses only the grandchild: its block, its parent's block and its brick must survive
  // any number of allocations this frame; the others fail once everything else is taken.
  tree.begin_feedback(2);
  tree.mark_used(b + 1);
  tree.end_of_feedback();
  std::set<uint32_t> taken;
  for (int i = 0; i < 10; ++i) {
    const uint32_t c = tree.subdivide(a + 5);  // re-subdividing the same node: each call takes a fresh block
    if (c == kNoAddress) break;
    taken.insert(c / 8);
    for (int k = 0; k < 8; ++k) tree.set_node(c + uint32_t(k), Node::make_data(true));
  }
  EXPECT_EQ(taken.count(a / 8), 0u);
  EXPECT_EQ(taken.count(b / 8), 0u);
  EXPECT_EQ(taken.size(), 2u);  // the two blocks nobody used
  EXPECT_GT(tree.counters().failed_allocations, 0u);
  for (int i = 0; i < 5; ++i) {
    const uint32_t s = tree.allocate_brick(a + uint32_t(i));
    EXPECT_NE(s, s1);
    EXPECT_NE(s, 0u);
  }
  EXPECT_TRUE(tree.node(b + 1).has_brick());
  EXPECT_EQ(tree.node(b + 1).brick(), s1);
  EXPECT_TRUE(tree.node(0).has_children());
  EXPECT_TRUE(tree.node(0).has_brick());
  EXPECT_TRUE(tree.node(a + 3).has_children());

  // Frame 3 uses nothing: the grandchild's block can now go, and its parent loses the pointer.
  tree.begin_feedback(3);
  tree.end_of_feedback();
  for (int i = 0; i < 4; ++i) tree.subdivide(a + 6);
  EXPECT_FALSE(tree.node(a + 3).has_children());
  EXPECT_TRUE(tree.node(0).has_brick());
}

TEST(GigaVoxelsNodeTree, HoldsOnlyNodesReachableFromTheRootAtTheirAddress) {
  // The loader keeps the tree address of a node whose brick it asked for; by the time the brick
  // arrives the block may hold other nodes, or be cut off from the root with its parent's.
  // Each tree: 4 blocks (the root's, its children a, a grandchild block b, one free).
  struct Grown {
    std::unique_ptr<NodeTree> tree;
    uint32_t a, b;
  };
  const auto subdivide = [](NodeTree& tree, uint32_t address) {
    const uint32_t block = tree.subdivide(address);
    for (int i = 0; i < 8; ++i) tree.set_node(block + uint32_t(i), Node::make_data(false));
    return block;
  };
  const auto grow = [&] {
    Grown g{std::make_unique<NodeTree>(2, 4, 4, 8), 0, 0};
    g.tree->set_root(Node::make_data(false), {});
    g.tree->begin_feedback(1);
    g.a = subdivide(*g.tree, 0);
    g.b = subdivide(*g.tree, g.a + 3);
    g.tree->end_of_feedback();
    g.tree->begin_feedback(2);  // frame 2 uses nothing: every block may be taken
    g.tree->end_of_feedback();
    return g;
  };

  const Grown g = grow();
  NodeTree& tree = *g.tree;
  const NodeAddress at_b1 = tree.address_of(g.b + 1);
  EXPECT_TRUE(tree.holds(0, NodeAddress{}));
  EXPECT_TRUE(tree.holds(g.a + 3, tree.address_of(g.a + 3)));
  EXPECT_TRUE(tree.holds(g.b + 1, at_b1));
  EXPECT_FALSE(tree.holds(g.b + 1, tree.address_of(g.b + 2)));  // another node's address
  EXPECT_FALSE(tree.holds(1, NodeAddress{}));  // the root's block holds the root alone
  // The root's children move to a fresh block: the old one and its child block stay allocated
  // (with their parents and bases) but no descent reaches them.
  const uint32_t c = subdivide(tree, 0);
  ASSERT_NE(c / 8, g.a / 8);
  ASSERT_NE(c / 8, g.b / 8);
  EXPECT_TRUE(tree.holds(c + 3, tree.address_of(c + 3)));
  EXPECT_FALSE(tree.holds(g.a + 3, tree.address_of(g.a + 3)));
  EXPECT_FALSE(tree.holds(g.b + 1, at_b1));

  // The loader's case: the parent's block is taken by a subdivision, its nodes cleared, and the
  // child block is cut off.
  const Grown h = grow();
  const NodeAddress at_hb1 = h.tree->address_of(h.b + 1);
  subdivide(*h.tree, h.b);  // the free block first
  const uint32_t taken = subdivide(*h.tree, h.b + 2);  // then the least recently used: a's
  ASSERT_EQ(taken / 8, h.a / 8);
  EXPECT_FALSE(h.tree->node(0).has_children());
  EXPECT_FALSE(h.tree->holds(h.b + 1, at_hb1));
}

TEST(GigaVoxelsNodeTree, AFreeSlotIsTakenBeforeOneFilledLastFrame) {
  // A brick filled in frame 1 that frame 2's (bounded) feedback did not name is still more
  // recent than a slot never used: taking it would make two such nodes evict each other.
  NodeTree tree(2, 3, 5, 8);
  tree.set_root(Node::make_data(false), {});
  tree.begin_feedback(1);
  tree.end_of_feedback();
  const uint32_t children = tree.subdivide(0);
  ASSERT_NE(children, kNoAddress);
  for (int i = 0; i < 8; ++i) tree.set_node(children + uint32_t(i), Node::make_data(false));
  const uint32_t first = tree.allocate_brick(children);
  ASSERT_NE(first, kNoAddress);
  std::set<uint32_t> taken{first};
  for (uint64_t frame = 2; frame <= 4; ++frame) {  // each frame names nothing and fills one more brick
    tree.begin_feedback(frame);
    tree.end_of_feedback();
    const uint32_t slot = tree.allocate_brick(children + uint32_t(frame));
    ASSERT_NE(slot, kNoAddress);
    EXPECT_TRUE(taken.insert(slot).second) << "frame " << frame << " evicted slot " << slot << " while free slots remained";
  }
  EXPECT_TRUE(tree.node(children).has_brick());
  // All 4 slots are full now: the next brick evicts the least recently filled, the first.
  tree.begin_feedback(5);
  tree.end_of_feedback();
  EXPECT_EQ(tree.allocate_brick(children + 7), first);
  EXPECT_FALSE(tree.node(children).has_brick());
}

TEST(GigaVoxelsNodeTree, UsingANodeKeepsTheCoarserBricksRaysBlendWith) {
  // Quadrilinear filtering reads the bricks of the levels above the node a ray names: marking
  // the node must keep those too, and a full pool must say so before any brick is made.
  NodeTree tree(2, 4, 4, 8);
  tree.set_root(Node::make_data(false), {});
  tree.begin_feedback(1);
  tree.end_of_feedback();
  const uint32_t a = tree.subdivide(0);
  for (int i = 0; i < 8; ++i) tree.set_node(a + uint32_t(i), Node::make_data(false));
  const uint32_t b = tree.subdivide(a + 5);
  for (int i = 0; i < 8; ++i) tree.set_node(b + uint32_t(i), Node::make_data(false));
  const uint32_t parent_brick = tree.allocate_brick(a + 5);
  const uint32_t child_brick = tree.allocate_brick(b + 2);
  ASSERT_NE(parent_brick, kNoAddress);
  ASSERT_NE(child_brick, kNoAddress);
  tree.begin_feedback(2);
  tree.mark_used(b + 2);  // only the deepest node is named
  tree.end_of_feedback();
  EXPECT_TRUE(tree.brick_slot_available());  // one slot (of 1 + 3) is still free
  EXPECT_NE(tree.allocate_brick(b + 3), kNoAddress);
  EXPECT_FALSE(tree.brick_slot_available()) << "the only other bricks were used this frame";
  EXPECT_EQ(tree.allocate_brick(b + 4), kNoAddress);
  EXPECT_TRUE(tree.node(a + 5).has_brick());
  EXPECT_EQ(tree.node(a + 5).brick(), parent_brick);
  EXPECT_EQ(tree.node(b + 2).brick(), child_brick);
}

TEST(GigaVoxelsPreintegratedTf, SegmentsAreTheEmissionAbsorptionIntegralOfALinearRamp) {
  // Against quadrature of the ramp's extinction tau(v) = -ln(1 - opacity(v)) per voxel and its
  // extinction-weighted colour, over random segments: both orders, equal ends, ends outside the
  // points, ends next to the last transparent table entry (below it, segments return at once),
  // for a transfer function with a transparent start, one transparent up to an inner point,
  // and a step (every point at one value).
  const std::vector<std::vector<TfPoint>> functions = {
      {{0.2, {0.1f, 0.2f, 0.9f}, 0.0f}, {0.5, {0.2f, 0.9f, 0.3f}, 0.4f}, {0.8, {0.9f, 0.8f, 0.1f}, 0.1f}, {1.0, {1.0f, 0.3f, 0.2f}, 0.7f}},
      {{0.0, {0.1f, 0.2f, 0.9f}, 0.0f}, {0.3, {0.1f, 0.2f, 0.9f}, 0.0f}, {0.5, {0.2f, 0.9f, 0.3f}, 0.4f}, {1.0, {1.0f, 0.3f, 0.2f}, 0.7f}},
      {{0.5, {0.1f, 0.2f, 0.9f}, 0.0f}, {0.5, {1.0f, 0.3f, 0.2f}, 0.6f}}};
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> value(-0.1, 1.1), near(-1e-3, 1e-3), length(0.05, 4.0);
  for (size_t k = 0; k < functions.size(); ++k) {
    const TransferFunction tf(functions[k]);
    const gigavoxels::PreintegratedTf pre(tf);
    const double edge = k == 0 ? 0.2 : k == 1 ? 0.3 : 0.5;  // where opacity starts
    int transparent = 0;
    for (int trial = 0; trial < 400; ++trial) {
      float front = float(value(rng)), back = trial % 10 == 0 ? front : float(value(rng));
      if (trial % 7 == 0) front = float(edge * value(rng)), back = float(edge * value(rng));  // below the edge
      if (trial % 5 == 0) back = float(edge + near(rng));                                     // at the edge
      const double len = length(rng);
      const int n = 20000;
      double tau = 0;
      Vec3d ctau(0.0);
      if (k == 2) {  // the step, exactly: the last point's extinction over the part above it
        const double lo = std::min(front, back), hi = std::max(front, back);
        const double above = hi > 0.5 ? (hi - std::max(lo, 0.5)) / std::max(hi - lo, 1e-300) : 0.0;
        tau = -std::log(1.0 - 0.6) * (hi > lo ? above : double(front > 0.5));
        ctau = Vec3d(1.0, 0.3, 0.2) * tau;
      } else {
        for (int q = 0; q < n; ++q) {
          Vec3f c;
          float a;
          tf.eval(double(front) + (double(back) - double(front)) * (q + 0.5) / n, c, a);
          const double t = -std::log(1.0 - double(a));
          tau += t / n;
          ctau += Vec3d(c) * (t / n);
        }
      }
      Vec3f color;
      float alpha;
      pre.segment(front, back, len, color, alpha);
      const std::string what = fmt::format("function {} trial {}: {} to {} over {} voxels", k, trial, front, back, len);
      ASSERT_NEAR(alpha, 1.0 - std::exp(-tau * len), 2e-4) << what;
      if (tau == 0) {
        ++transparent;
        ASSERT_EQ(alpha, 0.0f) << what;
        continue;
      }
      if (tau < 1e-3) continue;  // the colour of next to nothing is ill-conditioned
      for (int c = 0; c < 3; ++c) ASSERT_NEAR(color[c], ctau[c] / tau, 2e-3) << what << " channel " << c;
    }
    EXPECT_GT(transparent, 20) << "function " << k;
  }
}

TEST(GigaVoxelsPreintegratedTf, OpacityIsOneMinusExpInFloatAcrossTheSeriesBoundary) {
  // Alpha in float: a series below 1/8 (where 1 - exp(-x) cancels), expf above. Dense around
  // the boundary and where the old one lay (2^-7), against double expm1.
  double worst_series = 0, worst_exp = 0;
  std::vector<double> xs = {0.0, 1e-30, 1e-12, 1e-6};
  for (int i = 0; i <= 4000; ++i) xs.push_back(std::exp2(-14.0 + 15.0 * i / 4000));  // 2^-14 .. 2
  for (int i = -200; i <= 200; ++i) xs.push_back(0.125 + i * 1e-6), xs.push_back(0x1p-7 + i * 1e-8);
  for (double x : {4.0, 16.0, 100.0, 1e6}) xs.push_back(x);
  for (const double xd : xs) {
    const float x = float(xd);
    const double want = -std::expm1(-double(x));
    const double got = gigavoxels::PreintegratedTf::opacity(x);
    if (want == 0) {
      ASSERT_EQ(got, 0.0) << x;
      continue;
    }
    const double rel = std::fabs(got - want) / want;
    (x < 0.125f ? worst_series : worst_exp) = std::max(x < 0.125f ? worst_series : worst_exp, rel);
    ASSERT_LE(rel, x < 0.125f ? 0x1p-22 : 0x1p-20) << "x = " << x;
  }
  std::cout << "[ measured ] opacity(): worst relative error " << worst_series << " below 1/8, " << worst_exp << " above\n";
}

TEST(GigaVoxelsPreintegratedTf, SegmentsSideBySideAreSegmentsOneByOne) {
  // Runs of 1 to 8 segments: values inside the points, outside them on either side, below the
  // last transparent entry, equal neighbours (the midpoint's extinction, left to segment()),
  // neighbours closer than a thousandth of a table entry, and NaN and infinite values.
  const TransferFunction tf({{0.2, {0.1f, 0.2f, 0.9f}, 0.0f}, {0.5, {0.2f, 0.9f, 0.3f}, 0.4f}, {1.0, {1.0f, 0.3f, 0.2f}, 0.7f}});
  const gigavoxels::PreintegratedTf pre(tf);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> value(-0.2f, 1.2f);
  std::uniform_real_distribution<double> length(0.01, 6.0);
  const float specials[] = {0.2f, 1.0f, 0.0f, -5.0f, 7.0f, std::numeric_limits<float>::infinity(), std::nanf("")};
  int close = 0, clear = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    float values[9];
    double lengths[8];
    for (int k = 0; k < 9; ++k) {
      values[k] = value(rng);
      if (k > 0 && trial % 3 == 0 && k % 2 == 0) values[k] = values[k - 1];                // equal
      if (k > 0 && trial % 5 == 0 && k % 3 == 0)  // a few ulps apart: closer than 1e-3 table entries
        values[k] = std::nextafter(std::nextafter(values[k - 1], 2.0f), 2.0f);
      if (trial % 13 == 0 && k % 2 == 1) values[k] = 1.0f + 0.3f * std::abs(values[k]);  // above the last point
      if (trial % 11 == 0 && k % 4 == 1) values[k] = specials[size_t(trial / 11 + k) % 7];  // special
      if (trial % 7 == 0) values[k] = 0.15f * values[k];                                  // clear
    }
    for (double& l : lengths) l = length(rng);
    const int n = 1 + trial % 8;
    Vec3f color[8];
    float alpha[8];
    pre.segments<8>(values, lengths, n, color, alpha);
    for (int k = 0; k < n; ++k) {
      Vec3f want_color;
      float want_alpha;
      pre.segment(values[k], values[k + 1], lengths[k], want_color, want_alpha);
      const std::string what = fmt::format("trial {} segment {}: {} to {} over {}", trial, k, values[k], values[k + 1], lengths[k]);
      ASSERT_EQ(alpha[k], want_alpha) << what;
      for (int c = 0; c < 3; ++c) ASSERT_EQ(color[k][c], want_color[c]) << what << " channel " << c;
      close += values[k] != values[k + 1] && std::abs(values[k] - values[k + 1]) < 1e-6f && want_alpha > 0;
      clear += want_alpha == 0;
    }
  }
  EXPECT_GT(close, 50);
  EXPECT_GT(clear, 500);
}

TEST(GigaVoxelsPreintegratedTf, OpacitiesSideBySideAreOpacityOneByOne) {
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> exponent(-30.0f, 8.0f);
  for (int trial = 0; trial < 2000; ++trial) {
    float x[8], got[8];
    for (float& v : x) v = std::exp2(exponent(rng));
    if (trial == 0) std::copy_n(std::begin({0.0f, 0.125f, 0.12499999f, 87.0f, 88.0f, 1e30f, 1e-40f, 0.5f}), 8, x);
    gigavoxels::PreintegratedTf::opacities(x, got);
    for (int k = 0; k < 8; ++k) ASSERT_EQ(got[k], gigavoxels::PreintegratedTf::opacity(x[k])) << "x = " << x[k];
  }
}

TEST(GigaVoxelsCornerLanes, CornersOfEightCellsAreTheirVoxels) {
  // Gathers (16-bit and float voxels) and single loads (8-bit) against the brick's own voxels,
  // for cells anywhere in it, the last cell included (its reads end at the brick's last voxel).
  const int32_t e = 10;
  const auto check = [&](auto zero) {
    using Voxel = decltype(zero);
    std::vector<Voxel> brick(size_t(e * e * e));
    // Every bit of a 16-bit voxel, fractions in float ones (a sign extension or a rounding would show).
    for (size_t i = 0; i < brick.size(); ++i) brick[i] = Voxel(double((i * 7919) % (sizeof(Voxel) == 1 ? 256 : 65536)) * (std::is_same_v<Voxel, float> ? 0.37 : 1.0));
    std::mt19937 rng(1);
    std::uniform_int_distribution<int32_t> coordinate(0, e - 2);
    for (int trial = 0; trial < 200; ++trial) {
      int32_t offset[8];
      for (int32_t& o : offset) o = (coordinate(rng) * e + coordinate(rng)) * e + coordinate(rng);
      if (trial == 0) offset[7] = ((e - 2) * e + (e - 2)) * e + (e - 2);
      float corner[8][8];
      gigavoxels::load_cell_corners(brick.data(), offset, e, corner);
      for (int k = 0; k < 8; ++k)
        for (int c = 0; c < 8; ++c) {
          const int32_t at = offset[k] + (c & 1) + ((c >> 1) & 1) * e + (c >> 2) * e * e;
          ASSERT_EQ(corner[c][k], float(brick[size_t(at)])) << "cell " << k << " corner " << c << " voxel size " << sizeof(Voxel);
        }
    }
  };
  check(uint8_t{});
  check(uint16_t{});
  check(float{});
}

TEST(GigaVoxelsShading, LightingOfGradientsSideBySideIsLightingOfGradientOneByOne) {
  // Whole and fractional shininess (repeated squaring in lanes, or std::pow).
  for (const float shininess : {32.0f, 7.0f, 1.0f, 12.5f}) {
    Shading sh;
    sh.shininess = shininess;
    const VolumeGeometry geo;
    const ShadingModel model(sh, geo);
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> u(-1.0, 1.0), scale(-6.0, 6.0);
    const Vec3d light = normalize(Vec3d(0.3, -0.8, 0.5)), half = ShadingModel::half_vector(normalize(Vec3d(-0.2, 0.1, 1.0)), light);
    for (int trial = 0; trial < 500; ++trial) {
      double g[3][8];
      for (int k = 0; k < 8; ++k) {
        const double s = std::pow(10.0, scale(rng));
        for (int a = 0; a < 3; ++a) g[a][k] = u(rng) * s;
      }
      float diffuse[8], specular[8];
      model.lighting_of_gradients(g, light, half, diffuse, specular);
      for (int k = 0; k < 8; ++k) {
        const Vec3d gk(g[0][k], g[1][k], g[2][k]);
        const ShadingModel::Lighting want = model.lighting_of_gradient(gk, 1 / length(gk), light, half);
        ASSERT_NEAR(diffuse[k], want.diffuse, 1e-6f) << "shininess " << shininess << " trial " << trial << " lane " << k;
        ASSERT_NEAR(specular[k], want.specular, 1e-6f) << "shininess " << shininess << " trial " << trial << " lane " << k;
      }
    }
  }
}

TEST(GigaVoxelsFaceLighting, EachEndStandsForItsOwnCellAndTheirMeanForTheCellsBetween) {
  using gigavoxels::CellPoint;
  // The front end's share of the lighting: before the first face plus half of the cells between.
  const auto front_lighting_weight = [](const CellPoint& a, const CellPoint& b) { return gigavoxels::face_crossings(a, b).front_weight(); };
  const auto at = [](double x, double y, double z) {
    CellPoint p;
    const double l[3] = {x, y, z};
    for (int k = 0; k < 3; ++k) p.cell[k] = int32_t(std::floor(l[k])), p.u[k] = float(l[k] - std::floor(l[k]));
    return p;
  };
  EXPECT_EQ(front_lighting_weight(at(2.2, 3.5, 4.5), at(2.9, 3.6, 4.4)), 0.5f);  // one cell
  EXPECT_NEAR(front_lighting_weight(at(2.7, 3.5, 4.5), at(3.7, 3.5, 4.5)), 0.3f, 1e-6);  // a face at 0.3
  EXPECT_NEAR(front_lighting_weight(at(3.7, 3.5, 4.5), at(2.7, 3.5, 4.5)), 0.7f, 1e-6);  // going down: at 0.7
  // Faces at 0.1 (x) and 0.6 (y): the front's 0.1 and half of the 0.5 between.
  EXPECT_NEAR(front_lighting_weight(at(2.9, 3.4, 4.5), at(3.9, 4.4, 4.5)), 0.35f, 1e-6);
  // Several faces of one axis (a step of 4 voxels): faces at 0.125 and 0.875.
  EXPECT_NEAR(front_lighting_weight(at(1.5, 3.5, 4.5), at(5.5, 3.5, 4.5)), 0.5f, 1e-6);
  EXPECT_NEAR(front_lighting_weight(at(1.9, 3.5, 4.5), at(5.9, 3.5, 4.5)), 0.5f * (0.025f + 0.775f), 1e-6);
  // An end on a face lies in the cell the segment leaves from or enters.
  EXPECT_EQ(front_lighting_weight(at(2.0, 3.5, 4.5), at(3.0, 3.5, 4.5)), 1.0f);
  EXPECT_EQ(front_lighting_weight(at(3.0, 3.5, 4.5), at(2.5, 3.5, 4.5)), 0.0f);

  // Random segments of up to 4 voxels in a 33-voxel brick, against the fractions found by
  // walking the segment in 2^14 parts.
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> pos(0.0, 32.999), delta(-4.0, 4.0);
  double worst = 0;
  // Runs of 8 segments side by side: each lane's crossings and weight are one at a time's.
  int32_t run_cell[3][9];
  float run_u[3][9];
  gigavoxels::FaceCrossings run_crossings[8];
  std::vector<float> one_by_one;
  std::vector<gigavoxels::FaceCrossings> crossings_one_by_one;
  double prev_l0[3] = {};
  for (int n = 0; n < 2000; ++n) {
    double l0[3], l1[3];
    for (int k = 0; k < 3; ++k) l0[k] = pos(rng), l1[k] = std::clamp(l0[k] + delta(rng) * (n % 4 == 0 ? 0.2 : 1.0), 0.0, 32.999);
    // Runs also repeat a point (a run's spare lanes do) or stay in its cell on some axes: the
    // lanes whose spans are 0.
    if (n % 9 > 0 && n % 3 == 1)
      for (int k = 0; k < 3; ++k) l0[k] = n % 6 == 1 || k == 0 ? prev_l0[k] : std::floor(prev_l0[k]) + 0.5 * (prev_l0[k] - std::floor(prev_l0[k]));
    std::copy_n(l0, 3, prev_l0);
    const CellPoint a = at(l0[0], l0[1], l0[2]), b = at(l1[0], l1[1], l1[2]);
    const float w = front_lighting_weight(a, b);
    if (n % 9 == 0) one_by_one.clear(), crossings_one_by_one.clear();
    for (int k = 0; k < 3; ++k) run_cell[k][n % 9] = a.cell[k], run_u[k][n % 9] = a.u[k];
    if (n % 9 > 0) {
      CellPoint prev;
      for (int k = 0; k < 3; ++k) prev.cell[k] = run_cell[k][n % 9 - 1], prev.u[k] = run_u[k][n % 9 - 1];
      one_by_one.push_back(front_lighting_weight(prev, a));
      crossings_one_by_one.push_back(gigavoxels::face_crossings(prev, a));
    }
    if (n % 9 == 8) {
      gigavoxels::face_crossings(run_cell, run_u, run_crossings);
      for (int k = 0; k < 8; ++k) {
        ASSERT_EQ(run_crossings[k].front_weight(), one_by_one[size_t(k)]) << "run ending at " << n << ", lane " << k;
        ASSERT_EQ(run_crossings[k].first, crossings_one_by_one[size_t(k)].first) << "run ending at " << n << ", lane " << k;
        ASSERT_EQ(run_crossings[k].last, crossings_one_by_one[size_t(k)].last) << "run ending at " << n << ", lane " << k;
        ASSERT_LE(run_crossings[k].first, run_crossings[k].last + (run_crossings[k].first == 1 && run_crossings[k].last == 0));
      }
    }
    ASSERT_GE(w, 0.0f);
    ASSERT_LE(w, 1.0f);
    const int parts = 1 << 14;
    int in_a = 0, in_b = 0;  // parts (from each end) before a face is crossed
    const auto cell_at = [&](int i, int k) { return std::floor(l0[k] + (l1[k] - l0[k]) * (i + 0.5) / parts); };
    for (int i = 0; i < parts; ++i, ++in_a)
      if (cell_at(i, 0) != a.cell[0] || cell_at(i, 1) != a.cell[1] || cell_at(i, 2) != a.cell[2]) break;
    for (int i = parts - 1; i >= 0; --i, ++in_b)
      if (cell_at(i, 0) != b.cell[0] || cell_at(i, 1) != b.cell[1] || cell_at(i, 2) != b.cell[2]) break;
    const double want = in_a == parts ? 0.5 : 0.5 * (double(in_a) / parts + 1 - double(in_b) / parts);
    worst = std::max(worst, std::abs(double(w) - want));
  }
  EXPECT_LT(worst, 2.0 / (1 << 14));
}

TEST(GigaVoxelsCellGroups, DistancesAreChessboardDistancesToTheNearestVisibleGroup) {
  // Against brute force on random grids of every density, the brick sizes' grid widths among
  // them (M = 8, 32 and 81 give 3, 9 and 21); with no visible group, every group is far.
  std::mt19937 rng(7);
  for (int g : {1, 2, 3, 5, 9, 21})
    for (double density : {0.0, 0.01, 0.1, 0.5}) {
      std::vector<uint8_t> d(size_t(g) * size_t(g) * size_t(g));
      std::bernoulli_distribution visible(density);
      for (uint8_t& v : d) v = visible(rng) ? 0 : 1;
      const std::vector<uint8_t> marks = d;
      gigavoxels::chessboard_distances(g, d.data());
      const auto at = [g](int x, int y, int z) { return (size_t(z) * size_t(g) + size_t(y)) * size_t(g) + size_t(x); };
      for (int z = 0; z < g; ++z)
        for (int y = 0; y < g; ++y)
          for (int x = 0; x < g; ++x) {
            int want = gigavoxels::kFarGroup;
            for (int qz = 0; qz < g; ++qz)
              for (int qy = 0; qy < g; ++qy)
                for (int qx = 0; qx < g; ++qx)
                  if (marks[at(qx, qy, qz)] == 0)
                    want = std::min(want, std::max({std::abs(qx - x), std::abs(qy - y), std::abs(qz - z)}));
            ASSERT_EQ(int(d[at(x, y, z)]), want) << "g " << g << " density " << density << " at " << x << "," << y << "," << z;
          }
    }
}

TEST(GigaVoxelsFieldBounds, BoundTheTrilinearFieldAlongEverySegment) {
  // Random bricks (smooth, rough and 8-bit quantised) and random segments through them: the
  // differences are the brute-force ones, and the field, sampled densely, never changes faster
  // than slope nor strays from the chord between the segment's ends by more than stray(dt),
  // across however many cell faces.
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const size_t e = 7;
  int tight = 0;
  for (int trial = 0; trial < 600; ++trial) {
    std::vector<float> v(e * e * e);
    const int kind = trial % 3;
    for (size_t z = 0; z < e; ++z)
      for (size_t y = 0; y < e; ++y)
        for (size_t x = 0; x < e; ++x) {
          const double smooth = std::sin(0.7 * double(x) + 0.4 * double(y * y) * 0.1 - 0.5 * double(z)) * 20;
          double val = kind == 0 ? smooth : kind == 1 ? 40 * unit(rng) : std::round(smooth + 100);
          v[(z * e + y) * e + x] = float(val);
        }
    const gigavoxels::BrickDifferences d = gigavoxels::brick_differences(v.data(), e);
    // Against brute force, and the 8-bit path against the float one on the quantised bricks.
    const auto at = [&](size_t x, size_t y, size_t z) { return double(v[(z * e + y) * e + x]); };
    double first[3] = {}, second[3] = {}, mixed[3] = {};
    for (size_t z = 0; z < e; ++z)
      for (size_t y = 0; y < e; ++y)
        for (size_t x = 0; x < e; ++x) {
          const size_t p[3] = {x, y, z};
          for (int a = 0; a < 3; ++a) {
            size_t q1[3] = {x, y, z}, q2[3] = {x, y, z};
            if (p[a] + 1 < e) q1[a] += 1, first[a] = std::max(first[a], std::abs(at(q1[0], q1[1], q1[2]) - at(x, y, z)));
            if (p[a] + 2 < e) {
              q2[a] += 2;
              second[a] = std::max(second[a], std::abs(at(q2[0], q2[1], q2[2]) - 2 * at(q1[0], q1[1], q1[2]) + at(x, y, z)));
            }
          }
          const int pairs[3][2] = {{0, 1}, {0, 2}, {1, 2}};
          for (int k = 0; k < 3; ++k) {
            const int i = pairs[k][0], j = pairs[k][1];
            if (p[i] + 1 >= e || p[j] + 1 >= e) continue;
            size_t qi[3] = {x, y, z}, qj[3] = {x, y, z}, qij[3] = {x, y, z};
            qi[i] += 1, qj[j] += 1, qij[i] += 1, qij[j] += 1;
            mixed[k] = std::max(mixed[k], std::abs(at(qij[0], qij[1], qij[2]) - at(qi[0], qi[1], qi[2]) - at(qj[0], qj[1], qj[2]) + at(x, y, z)));
          }
        }
    for (int a = 0; a < 3; ++a) {
      ASSERT_FLOAT_EQ(d.first[a], float(first[a])) << "trial " << trial;
      ASSERT_FLOAT_EQ(d.second[a], float(second[a])) << "trial " << trial;
      ASSERT_FLOAT_EQ(d.mixed[a], float(mixed[a])) << "trial " << trial;
    }
    if (kind == 2) {
      const std::vector<uint8_t> bytes(v.begin(), v.end());
      const gigavoxels::BrickDifferences d8 = gigavoxels::brick_differences(bytes.data(), e);
      for (int a = 0; a < 3; ++a) {
        ASSERT_EQ(d8.first[a], d.first[a]);
        ASSERT_EQ(d8.second[a], d.second[a]);
        ASSERT_EQ(d8.mixed[a], d.mixed[a]);
      }
    }
    // A segment from p0, w voxels per unit t, t in [0, dt], inside the brick's cells.
    double p0[3], w[3];
    const double dt = 0.25 + 2.5 * unit(rng);
    for (int a = 0; a < 3; ++a) {
      w[a] = (unit(rng) * 2 - 1) * (trial % 5 == 0 && a > 0 ? 0.0 : 1.0);
      const double lo = std::max(0.0, -w[a] * dt), hi = double(e - 1) - std::max(0.0, w[a] * dt);
      p0[a] = lo + (hi - lo) * unit(rng);
    }
    const gigavoxels::FieldBounds f = gigavoxels::field_bounds(d, w);
    const auto field = [&](double t) {
      double c[8], u[3];
      size_t i[3];
      for (int a = 0; a < 3; ++a) {
        const double p = std::clamp(p0[a] + w[a] * t, 0.0, double(e - 1));
        i[a] = std::min(size_t(p), e - 2);
        u[a] = p - double(i[a]);
      }
      for (int k = 0; k < 8; ++k)
        c[k] = v[((i[2] + size_t(k >> 2 & 1)) * e + i[1] + size_t(k >> 1 & 1)) * e + i[0] + size_t(k & 1)];
      return trilinear(c, u[0], u[1], u[2]);
    };
    const double f0 = field(0), f1 = field(dt);
    double worst_stray = 0;
    double prev = f0;
    const int n = 400;
    for (int k = 1; k <= n; ++k) {
      const double t = dt * k / n, ft = field(t);
      ASSERT_LE(std::abs(ft - prev), f.slope * dt / n * (1 + 1e-9) + 1e-9) << "trial " << trial << " at t " << t;
      worst_stray = std::max(worst_stray, std::abs(ft - (f0 + (f1 - f0) * t / dt)));
      prev = ft;
    }
    ASSERT_LE(worst_stray, f.stray(dt) * (1 + 1e-9) + 1e-9) << "trial " << trial << " kind " << kind;
    tight += worst_stray > 0.1 * f.stray(dt);
  }
  // Not vacuous: the bound is within a factor 10 of what the field does in many of them.
  EXPECT_GT(tight, 60);
}

}  // namespace
}  // namespace brickyard
