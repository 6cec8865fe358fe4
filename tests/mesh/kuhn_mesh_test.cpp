#include "mesh/kuhn_mesh.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>
#include <random>
#include <set>

#include "mesh/mesh_test_support.hpp"
#include "mesh/refine_ops.hpp"

namespace tissue::mesh {
namespace {

using testing::check_bookkeeping;
using testing::check_conformity;
using testing::mesh_sets;

void expect_valid(const KuhnMesh& mesh, const std::string& where) {
  const auto conformity = check_conformity(mesh);
  ASSERT_TRUE(conformity.problems.empty()) << where << ": " << conformity.problems.front();
  const auto bookkeeping = check_bookkeeping(mesh);
  ASSERT_TRUE(bookkeeping.empty()) << where << ": " << bookkeeping.front();
}

int diamond_list_length(const KuhnMesh& mesh, Key d) {
  const EdgeId e = mesh.find_edge(d);
  if (e == kInvalidId) return 0;
  int n = 0;
  for (TetId t = mesh.edge(e).diamond_head; t != kInvalidId; t = mesh.tet(t).next_in_diamond) ++n;
  return n;
}

TEST(KuhnMesh, CoarseBoxMatchesPaperLowResolution) {
  KuhnMesh mesh({4, 4, 4, 0.025, 9});
  EXPECT_EQ(mesh.node_count(), 125u);  // paper Table 1, "Low"
  EXPECT_EQ(mesh.tet_count(), 384u);
  expect_valid(mesh, "coarse");
}

TEST(KuhnMesh, RejectsBadBoxesWithTheFieldName) {
  auto message_of = [](const BoxSpec& s) {
    try {
      KuhnMesh m(s);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("no exception");
  };
  EXPECT_NE(message_of({0, 1, 1, 0.1, 9}).find("cubes_x"), std::string::npos);
  EXPECT_NE(message_of({1, -2, 1, 0.1, 9}).find("cubes_y"), std::string::npos);
  EXPECT_NE(message_of({1, 1, 0, 0.1, 9}).find("cubes_z"), std::string::npos);
  EXPECT_NE(message_of({1, 1, 1, 0.0, 9}).find("cube_size_m"), std::string::npos);
  EXPECT_NE(message_of({1, 1, 1, NAN, 9}).find("cube_size_m"), std::string::npos);
  EXPECT_NE(message_of({1, 1, 1, -INFINITY, 9}).find("cube_size_m"), std::string::npos);
  EXPECT_NE(message_of({1, 1, 1, 0.1, -1}).find("max_depth"), std::string::npos);
  EXPECT_NE(message_of({1, 1, 1, 0.1, 61}).find("max_depth"), std::string::npos);
  // 2^18 cubes along x leave room for one level of coarse halving, not three.
  EXPECT_NE(message_of({1 << 18, 1, 1, 0.1, 9}).find("max_depth"), std::string::npos);
  EXPECT_NE(message_of({1 << 20, 1, 1, 0.1, 0}).find("overflow"), std::string::npos);
  // Depths whose coarse exponent would shift a 64-bit count by 64 or more
  // (undefined; x86 masked the shift and a second test refused them).
  EXPECT_NE(message_of({1, 1, 1, 0.1, 1000}).find("max_depth"), std::string::npos);
  EXPECT_NE(message_of({1, 1, 1, 0.1, std::numeric_limits<int>::max()}).find("max_depth"), std::string::npos);
  // At least nine levels (three full cycles) on a realistic box, and many more on a small one.
  EXPECT_NO_THROW(KuhnMesh({16, 16, 16, 0.01, 30}));
  EXPECT_NO_THROW(KuhnMesh({1, 1, 1, 0.01, 57}));
}

// NUMERICS.md §1 type table: sorted edge lengths / H, volume and max/min.
TEST(KuhnMesh, BisectionTypeTableHoldsForEveryDepth) {
  KuhnMesh mesh({1, 1, 1, 1.0, 9});
  const double H = static_cast<double>(mesh.domain().coarse_cube());
  const double r2 = std::sqrt(2.0), r3 = std::sqrt(3.0), h3 = std::sqrt(3.0) / 2;
  const std::array<std::array<double, 6>, 3> table{
      {{1, 1, 1, r2, r2, r3}, {h3, h3, h3, 1, 1, r2}, {0.5, std::sqrt(0.5), std::sqrt(0.5), h3, h3, 1}}};
  const std::array<double, 3> ratio{r3, 2 * r2 / r3, 2.0};
  for (int depth = 0; depth <= 9; ++depth) {
    refine_uniform(mesh, depth);
    const double scale = H / std::pow(2.0, depth / 3);
    mesh.for_each_tet([&](TetId t, const Tet& tet) {
      ASSERT_EQ(tet.depth, depth);
      const auto len = testing::sorted_edge_lengths(mesh, t);
      for (int i = 0; i < 6; ++i) EXPECT_NEAR(len[i] / scale, table[depth % 3][i], 1e-12) << "depth " << depth;
      EXPECT_NEAR(len[5] / len[0], ratio[depth % 3], 1e-12);
      // The refinement edge is the unique longest edge: Maubach = longest-edge bisection.
      const Vec3i& a = mesh.node(tet.v[0]).lattice;
      const Vec3i& b = mesh.node(tet.v[maubach_tag(depth)]).lattice;
      double l2 = 0;
      for (int k = 0; k < 3; ++k) l2 += double(a[k] - b[k]) * double(a[k] - b[k]);
      EXPECT_NEAR(std::sqrt(l2), len[5], 1e-12);
      EXPECT_LT(len[4], len[5]);
      EXPECT_EQ(testing::signed_six_volume(mesh, mesh.oriented_vertices(t)), mesh.six_volume_at_depth(depth));
    });
    EXPECT_EQ(mesh.tet_count(), 6u << depth);
    // Volume table: 1/6, 1/12, 1/24, 1/48 … of H^3.
    EXPECT_DOUBLE_EQ(static_cast<double>(mesh.six_volume_at_depth(depth)) / 6.0 / (H * H * H),
                     1.0 / (6.0 * std::pow(2.0, depth)));
  }
}

TEST(KuhnMesh, ThreeBisectionsGiveHalvedTypeOneTets) {
  KuhnMesh mesh({1, 1, 1, 1.0, 9});
  std::set<std::array<double, 6>> shapes0, shapes3;
  mesh.for_each_tet([&](TetId t, const Tet&) { shapes0.insert(testing::sorted_edge_lengths(mesh, t)); });
  refine_uniform(mesh, 3);
  mesh.for_each_tet([&](TetId t, const Tet&) {
    auto len = testing::sorted_edge_lengths(mesh, t);
    for (double& l : len) l *= 2;
    shapes3.insert(len);
  });
  EXPECT_EQ(shapes0, shapes3);
  EXPECT_EQ(mesh.tet_count(), 48u);
}

// Before and after a split, the sorted lists differ by the diamond's tets
// (removed) and their children (added, one deeper, each with the new node):
// corners sorted, lists sorted, whatever TetIds the mesh reused.
TEST(KuhnMesh, SortedLiveTetsGiveWhatASplitRemovedAndAdded) {
  KuhnMesh mesh({2, 2, 2, 1.0, 6});
  const std::int64_t H = mesh.domain().coarse_cube();
  const Key diagonal = vertex_key({H / 2, H / 2, H / 2});  // the first cube's: its 6 tets
  const std::vector<SortedTet> before = sorted_live_tets(mesh);
  ASSERT_EQ(before.size(), mesh.tet_count());
  ASSERT_EQ(mesh.split(diagonal), 1);
  const std::vector<SortedTet> after = sorted_live_tets(mesh);
  ASSERT_EQ(after.size(), mesh.tet_count());
  for (const auto* list : {&before, &after}) {
    EXPECT_TRUE(std::is_sorted(list->begin(), list->end()));
    for (const auto& [corners, depth] : *list) EXPECT_TRUE(std::is_sorted(corners.begin(), corners.end()));
  }
  std::vector<SortedTet> removed, added;
  std::set_difference(before.begin(), before.end(), after.begin(), after.end(), std::back_inserter(removed));
  std::set_difference(after.begin(), after.end(), before.begin(), before.end(), std::back_inserter(added));
  ASSERT_EQ(removed.size(), 6u);
  ASSERT_EQ(added.size(), 12u);
  const NodeId centre = mesh.find_node(diagonal);
  ASSERT_NE(centre, kInvalidId);
  for (const auto& [corners, depth] : removed) EXPECT_EQ(depth, 0);
  for (const auto& [corners, depth] : added) {
    EXPECT_EQ(depth, 1);
    EXPECT_NE(std::find(corners.begin(), corners.end(), centre), corners.end());
  }
}

TEST(KuhnMesh, DiamondSizesInteriorAndBoundary) {
  KuhnMesh mesh({3, 3, 3, 1.0, 9});
  const std::int64_t H = mesh.domain().coarse_cube();
  auto key = [&](double x, double y, double z) {
    return vertex_key({std::int64_t(x * H), std::int64_t(y * H), std::int64_t(z * H)});
  };
  auto members_when_complete = [&](Key d) {
    std::array<Key, 4> parents{};
    const int n = diamond_parents(mesh.domain(), mesh.diamond_info(d), &parents);
    for (int i = 0; i < n; ++i) mesh.split(parents[i]);
    return diamond_list_length(mesh, d);
  };
  EXPECT_EQ(members_when_complete(key(1.5, 1.5, 1.5)), 6);  // cube diagonal
  EXPECT_EQ(members_when_complete(key(2.0, 1.5, 1.5)), 4);  // interior face diagonal
  EXPECT_EQ(members_when_complete(key(0.0, 1.5, 1.5)), 2);  // face diagonal on the box
  EXPECT_EQ(members_when_complete(key(2.0, 2.0, 1.5)), 8);  // interior axis edge
  EXPECT_EQ(members_when_complete(key(0.0, 2.0, 1.5)), 4);  // axis edge on a box face
  EXPECT_EQ(members_when_complete(key(0.0, 0.0, 1.5)), 2);  // axis edge on a box edge
  // One level finer: a half-size cube's diagonal.
  EXPECT_EQ(members_when_complete(key(1.75, 1.75, 1.75)), 6);
  expect_valid(mesh, "after diamond probes");

  // After uniform refinement, every diamond list is complete and one depth.
  std::map<int, std::set<int>> sizes_by_phase;
  for (int depth : {3, 4, 5}) {
    refine_uniform(mesh, depth);
    mesh.for_each_edge([&](EdgeId, const Edge& e) {
      if (e.diamond_head == kInvalidId) return;
      const Key d = edge_key(mesh.node(e.a).lattice, mesh.node(e.b).lattice);
      const DiamondInfo info = mesh.diamond_info(d);
      EXPECT_EQ(diamond_list_length(mesh, d), diamond_tet_count(mesh.domain(), info));
      sizes_by_phase[info.phase].insert(diamond_list_length(mesh, d));
      for (TetId t = e.diamond_head; t != kInvalidId; t = mesh.tet(t).next_in_diamond)
        EXPECT_EQ(mesh.tet(t).depth, info.depth);
    });
  }
  EXPECT_EQ(sizes_by_phase[0], (std::set<int>{6}));
  EXPECT_EQ(sizes_by_phase[1], (std::set<int>{2, 4}));
  EXPECT_EQ(sizes_by_phase[2], (std::set<int>{2, 4, 8}));
}

TEST(KuhnMesh, SplitAndMergeRejectBadRequestsClearly) {
  KuhnMesh mesh({2, 2, 2, 1.0, 3});
  const std::int64_t H = mesh.domain().coarse_cube();
  // A coarse vertex, a point outside, a point off the lattice.
  EXPECT_THROW(mesh.split(vertex_key({H, H, H})), std::invalid_argument);
  EXPECT_THROW(mesh.split(vertex_key({5 * H, H / 2, H / 2})), std::invalid_argument);
  EXPECT_THROW(mesh.split(pack_doubled({1, 2, 2})), std::invalid_argument);
  // A face diamond with bit 63 set: split its parents, then failed to find
  // its edge under the other key (std::logic_error, the parents left split).
  EXPECT_THROW(mesh.split((Key{1} << 63) | vertex_key({H, H / 2, H / 2})), std::invalid_argument);
  EXPECT_EQ(mesh.tet_count(), 8u * 6u);
  // A coarse grid vertex has a node but is no diamond: refused as such.
  try {
    mesh.merge(vertex_key({H, 0, 0}));
    FAIL() << "merge of a coarse grid vertex must throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("coarse grid vertex"), std::string::npos) << e.what();
  }
  EXPECT_THROW(mesh.require_can_merge(~Key{0}), std::invalid_argument);
  const Key cube = vertex_key({H / 2, H / 2, H / 2});
  try {
    mesh.merge(cube);
    FAIL() << "merge of an unsplit diamond must throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("not split"), std::string::npos);
  }
  mesh.split(cube);
  const Key face = vertex_key({0, H / 2, H / 2});
  mesh.split(face);
  try {
    mesh.merge(cube);
    FAIL() << "merge with a split child must throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("child"), std::string::npos);
  }
  EXPECT_FALSE(mesh.can_merge(cube));
  EXPECT_TRUE(mesh.can_merge(face));
  // Max depth 3: depth-3 tets cannot be split.
  refine_uniform(mesh, 3);
  mesh.for_each_tet([&](TetId t, const Tet&) { EXPECT_FALSE(mesh.can_split(mesh.diamond_of(t))); });
  TetId any = 0;
  while (!mesh.tet_alive(any)) ++any;
  EXPECT_THROW(mesh.split(mesh.diamond_of(any)), std::invalid_argument);
  EXPECT_THROW(refine_uniform(mesh, 4), std::invalid_argument);
  expect_valid(mesh, "after rejected requests");
}

// Thousands of random split/merge operations keep the mesh conforming and the
// incremental volume sums exact; merging everything restores the coarse mesh.
class RandomChurn : public ::testing::TestWithParam<std::tuple<BoxSpec, unsigned>> {};

TEST_P(RandomChurn, StaysConformingAndReturnsToCoarse) {
  const auto [spec, seed] = GetParam();
  KuhnMesh mesh(spec);
  const auto coarse = mesh_sets(mesh);
  std::mt19937 rng(seed);
  int splits = 0, merges = 0;
  const std::size_t cap = 12000;  // keep the walk bounded so it both refines and coarsens
  for (int op = 1; op <= 3000; ++op) {
    const bool try_split = mesh.tet_count() < cap && (rng() % 100) < 55;
    if (try_split) {
      TetId t;
      do t = static_cast<TetId>(rng() % mesh.tet_capacity());
      while (!mesh.tet_alive(t));
      const Key d = mesh.diamond_of(t);
      if (mesh.can_split(d)) splits += mesh.split(d);
    } else {
      NodeId n;
      do n = static_cast<NodeId>(rng() % mesh.node_capacity());
      while (!mesh.node_alive(n));
      const Key d = mesh.node_key(n);
      if (mesh.node(n).edge_a != kInvalidId && mesh.can_merge(d)) {
        mesh.merge(d);
        ++merges;
      }
    }
    if (op % 250 == 0) expect_valid(mesh, "op " + std::to_string(op));
    if (HasFatalFailure()) return;
  }
  EXPECT_GT(splits, 200);
  EXPECT_GT(merges, 200);
  merge_all(mesh);
  expect_valid(mesh, "after merge_all");
  EXPECT_EQ(mesh_sets(mesh), coarse);
}

INSTANTIATE_TEST_SUITE_P(Shapes, RandomChurn,
                         ::testing::Values(std::make_tuple(BoxSpec{1, 1, 1, 0.1, 12}, 1u),
                                           std::make_tuple(BoxSpec{3, 2, 1, 0.1, 9}, 2u),
                                           std::make_tuple(BoxSpec{2, 3, 4, 0.05, 9}, 3u),
                                           std::make_tuple(BoxSpec{4, 1, 1, 0.1, 15}, 4u),
                                           std::make_tuple(BoxSpec{3, 3, 3, 0.1, 9}, 5u)));

// `ops` random splits, and a merge every third op, of live tets and nodes
// drawn from `seed`: a mesh split and merged unevenly.
void churn(KuhnMesh& mesh, unsigned seed, int ops) {
  std::mt19937 rng(seed);
  for (int op = 0; op < ops; ++op) {
    TetId t;
    do t = static_cast<TetId>(rng() % mesh.tet_capacity());
    while (!mesh.tet_alive(t));
    const Key d = mesh.diamond_of(t);
    if (mesh.can_split(d)) mesh.split(d);
    if (op % 3 == 0) {
      NodeId n;
      do n = static_cast<NodeId>(rng() % mesh.node_capacity());
      while (!mesh.node_alive(n));
      if (mesh.node(n).edge_a != kInvalidId && mesh.can_merge(mesh.node_key(n))) mesh.merge(mesh.node_key(n));
    }
  }
}

// The edges at a node found by lattice lookups are exactly those a walk over
// every edge finds, on meshes refined unevenly to several depths (including
// depths that are not a multiple of 3, whose tets are not Kuhn cubes') and
// partly merged back.
TEST(KuhnMesh, EdgesAtANodeByLookupAreTheEdgesAWalkFinds) {
  for (const BoxSpec& spec : {BoxSpec{2, 1, 1, 0.1, 7}, BoxSpec{1, 2, 3, 0.05, 12}}) {
    KuhnMesh mesh(spec);
    churn(mesh, 7, 1500);
    std::vector<std::set<EdgeId>> walked(mesh.node_capacity());
    mesh.for_each_edge([&](EdgeId e, const Edge& edge) {
      walked[edge.a].insert(e);
      walked[edge.b].insert(e);
    });
    std::size_t checked = 0, deepest = 0;
    mesh.for_each_node([&](NodeId n, const Node& node) {
      std::set<EdgeId> found;
      mesh.for_each_edge_at_node(n, [&](EdgeId e, const Edge&) { EXPECT_TRUE(found.insert(e).second) << e; });
      EXPECT_EQ(found, walked[n]) << "node " << n << " at depth " << int(node.depth);
      ++checked;
      deepest = std::max<std::size_t>(deepest, node.depth);
    });
    EXPECT_GT(checked, 300u);
    EXPECT_GE(deepest, static_cast<std::size_t>(spec.max_depth - 1));  // the walk reached deep levels
    std::size_t dead_calls = 0;
    for (NodeId n = 0; n < mesh.node_capacity(); ++n)
      if (!mesh.node_alive(n)) mesh.for_each_edge_at_node(n, [&](EdgeId, const Edge&) { ++dead_calls; });
    EXPECT_EQ(dead_calls, 0u);
  }
}

// A mesh split and merged unevenly down to depth 12, for the questions an
// adaptation pass asks before it changes anything.
KuhnMesh churned_mesh() {
  KuhnMesh mesh({1, 2, 2, 0.05, 12});
  churn(mesh, 11, 600);
  return mesh;
}

// How many diamonds a split's closure holds is what split() then returns.
TEST(KuhnMesh, ClosureDiamondsCountWhatSplitThenSplits) {
  const KuhnMesh mesh = churned_mesh();
  std::vector<Key> closure;
  int longest = 0, splits_checked = 0;
  mesh.for_each_tet([&](TetId t, const Tet&) {
    if (t % 5 != 0) return;  // a sample: each check copies the mesh
    const Key d = mesh.diamond_of(t);
    const int predicted = mesh.closure_diamonds(d, closure);
    ASSERT_EQ(predicted, static_cast<int>(closure.size()));
    KuhnMesh copy = mesh;
    EXPECT_EQ(predicted, copy.can_split(d) ? copy.split(d) : 0);
    longest = std::max(longest, predicted);
    ++splits_checked;
  });
  EXPECT_GT(splits_checked, 50) << "longest " << longest;
  EXPECT_GE(longest, 5) << "the sample must hold closures longer than the diamond itself";
}

// The tets a merge restores, corners in Maubach order, are those merge()
// then adds; a diamond that cannot merge restores none.
TEST(KuhnMesh, MergeRestoresAreTheTetsMergeThenAdds) {
  const KuhnMesh mesh = churned_mesh();
  int merges_checked = 0, refused = 0;
  mesh.for_each_node([&](NodeId n, const Node& node) {
    if (node.edge_a == kInvalidId) return;
    const Key d = mesh.node_key(n);
    std::array<std::array<NodeId, 4>, 8> restored{};
    const int count = mesh.merge_restores(d, restored);
    if (!mesh.can_merge(d)) {
      EXPECT_EQ(count, 0);
      ++refused;
      return;
    }
    if (++merges_checked % 3 != 0) return;  // a sample, as above
    KuhnMesh copy = mesh;
    const auto before = sorted_live_tets(copy);
    copy.merge(d);
    std::vector<std::array<NodeId, 4>> added_by_merge, predicted;
    copy.for_each_tet([&](TetId, const Tet& tet) {
      auto sorted = tet.v;
      std::sort(sorted.begin(), sorted.end());
      if (!std::binary_search(before.begin(), before.end(), SortedTet{sorted, tet.depth}))
        added_by_merge.push_back(tet.v);
    });
    predicted.assign(restored.begin(), restored.begin() + count);
    std::sort(added_by_merge.begin(), added_by_merge.end());
    std::sort(predicted.begin(), predicted.end());
    EXPECT_EQ(predicted, added_by_merge) << "diamond of node " << n;
  });
  EXPECT_GT(merges_checked / 3, 20);
  EXPECT_GT(refused, 20);
}

TEST(KuhnMesh, RefineAllToMaxDepthThenMergeAllRestoresTheMesh) {
  KuhnMesh mesh({2, 1, 2, 0.1, 9});
  const auto before = mesh_sets(mesh);
  refine_uniform(mesh, 9);
  EXPECT_EQ(mesh.tet_count(), 6u * 4u * 512u);
  expect_valid(mesh, "max depth");
  merge_all(mesh);
  expect_valid(mesh, "merged");
  EXPECT_EQ(mesh_sets(mesh), before);
  EXPECT_EQ(mesh.node_count(), before.nodes.size());
}

// The change log, replayed in order, reproduces exactly the mesh's live sets,
// and every new node sits at the midpoint of the edge it reports.
TEST(KuhnMesh, ChangeLogReplaysToTheLiveMesh) {
  KuhnMesh mesh({3, 2, 2, 0.1, 9});
  std::set<NodeId> nodes;
  std::set<EdgeId> edges;
  std::set<TetId> tets;
  mesh.for_each_node([&](NodeId n, const Node&) { nodes.insert(n); });
  mesh.for_each_edge([&](EdgeId e, const Edge&) { edges.insert(e); });
  mesh.for_each_tet([&](TetId t, const Tet&) { tets.insert(t); });
  std::mt19937 rng(7);
  MeshChangeLog log;
  for (int op = 0; op < 600; ++op) {
    log.clear();
    if (rng() % 3 != 0) {
      TetId t;
      do t = static_cast<TetId>(rng() % mesh.tet_capacity());
      while (!mesh.tet_alive(t));
      if (mesh.can_split(mesh.diamond_of(t))) {
        const int n = mesh.split(mesh.diamond_of(t), &log);
        EXPECT_EQ(log.diamonds_split, n);
      }
    } else {
      NodeId n;
      do n = static_cast<NodeId>(rng() % mesh.node_capacity());
      while (!mesh.node_alive(n));
      if (mesh.node(n).edge_a != kInvalidId && mesh.can_merge(mesh.node_key(n))) mesh.merge(mesh.node_key(n), &log);
    }
    for (const MeshEvent& ev : log.events) {
      switch (ev.kind) {
        case MeshEvent::Kind::kNodeAdded: {
          ASSERT_TRUE(nodes.insert(ev.id).second);
          ASSERT_TRUE(nodes.count(ev.nodes[0]) && nodes.count(ev.nodes[1]));
          const Vec3i& a = mesh.node(ev.nodes[0]).lattice;
          const Vec3i& b = mesh.node(ev.nodes[1]).lattice;
          for (int k = 0; k < 3; ++k) EXPECT_EQ(2 * mesh.node(ev.id).lattice[k], a[k] + b[k]);
          break;
        }
        case MeshEvent::Kind::kNodeRemoved:
          ASSERT_EQ(nodes.erase(ev.id), 1u);
          break;
        case MeshEvent::Kind::kEdgeAdded:
          ASSERT_TRUE(edges.insert(ev.id).second);
          break;
        case MeshEvent::Kind::kEdgeRemoved:
          ASSERT_EQ(edges.erase(ev.id), 1u);
          break;
        case MeshEvent::Kind::kTetAdded:
          ASSERT_TRUE(tets.insert(ev.id).second);
          for (NodeId v : ev.nodes) ASSERT_TRUE(nodes.count(v));
          for (EdgeId e : ev.edges) ASSERT_TRUE(edges.count(e)) << "an added tet's edges exist when it is logged";
          break;
        case MeshEvent::Kind::kTetRemoved:
          ASSERT_EQ(tets.erase(ev.id), 1u);
          for (EdgeId e : ev.edges) ASSERT_TRUE(edges.count(e)) << "a removed tet is logged before its edges die";
          break;
      }
    }
  }
  std::set<NodeId> live_nodes;
  std::set<EdgeId> live_edges;
  std::set<TetId> live_tets;
  mesh.for_each_node([&](NodeId n, const Node&) { live_nodes.insert(n); });
  mesh.for_each_edge([&](EdgeId e, const Edge&) { live_edges.insert(e); });
  mesh.for_each_tet([&](TetId t, const Tet&) { live_tets.insert(t); });
  EXPECT_EQ(nodes, live_nodes);
  EXPECT_EQ(edges, live_edges);
  EXPECT_EQ(tets, live_tets);
}

// Splitting the finest diamond at a box corner forces its ancestors: the cost
// grows by a bounded number of splits per 3-level cycle (O(depth)).
TEST(KuhnMesh, ClosureCostIsLinearInDepth) {
  std::vector<int> splits_at_cycle;
  for (int depth = 3; depth <= 30; depth += 3) {
    KuhnMesh mesh({4, 4, 4, 0.1, 30});
    splits_at_cycle.push_back(refine_sphere(mesh, {{0.0, 0.0, 0.0}, 0.0}, depth));
    expect_valid(mesh, "corner depth " + std::to_string(depth));
  }
  std::vector<int> per_cycle;
  for (std::size_t i = 1; i < splits_at_cycle.size(); ++i)
    per_cycle.push_back(splits_at_cycle[i] - splits_at_cycle[i - 1]);
  // Every cycle costs the same bounded number of splits, independent of depth.
  const int first = per_cycle.front();
  EXPECT_GT(first, 0);
  EXPECT_LE(first, 12);
  for (int c : per_cycle) EXPECT_EQ(c, first) << "splits per cycle must not grow with depth";
}

TEST(KuhnMesh, TopologyVersionChangesWithEverySplitAndMergeAndIsUniquePerMesh) {
  KuhnMesh m(BoxSpec{2, 2, 2, 0.1, 4});
  const KuhnMesh other(BoxSpec{2, 2, 2, 0.1, 4});
  EXPECT_NE(m.topology_version(), other.topology_version());
  const Key d = m.diamond_of(0);
  const std::uint64_t v0 = m.topology_version();
  ASSERT_GT(m.split(d), 0);
  const std::uint64_t v1 = m.topology_version();
  EXPECT_NE(v1, v0);
  EXPECT_EQ(m.split(d), 0);  // already split: nothing changed
  EXPECT_EQ(m.topology_version(), v1);
  m.merge(d);
  EXPECT_NE(m.topology_version(), v1);
  EXPECT_NE(m.topology_version(), v0);  // the same tets as at v0, but versions never repeat
  const KuhnMesh copy = m;              // a copy has the same topology: the same version
  EXPECT_EQ(copy.topology_version(), m.topology_version());
}

}  // namespace
}  // namespace tissue::mesh
