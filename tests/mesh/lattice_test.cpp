#include "mesh/lattice.hpp"

#include <gtest/gtest.h>

#include <random>

namespace tissue::mesh {
namespace {

LatticeDomain domain_3x3x3() {
  LatticeDomain d;
  d.cubes = {3, 3, 3};
  d.coarse_log2 = 3;  // H = 8
  return d;
}

TEST(Lattice, PackUnpackRoundTripsAndEdgeKeyIsDoubledMidpoint) {
  std::mt19937_64 rng(1);
  for (int i = 0; i < 1000; ++i) {
    const Vec3i p{std::int64_t(rng() % (kMaxLatticeCoord + 1)), std::int64_t(rng() % (kMaxLatticeCoord + 1)),
                  std::int64_t(rng() % (kMaxLatticeCoord + 1))};
    const Vec3i d = unpack_doubled(vertex_key(p));
    for (int a = 0; a < 3; ++a) EXPECT_EQ(d[a], 2 * p[a]);
  }
  // An edge's key equals the key of the vertex at its midpoint.
  EXPECT_EQ(edge_key({0, 0, 0}, {8, 8, 8}), vertex_key({4, 4, 4}));
  EXPECT_EQ(edge_key({2, 4, 6}, {4, 4, 6}), vertex_key({3, 4, 6}));
  EXPECT_NE(edge_key({0, 0, 0}, {1, 0, 0}), edge_key({0, 0, 0}, {0, 1, 0}));
}

TEST(Lattice, ClassifiesPhasesSizesAndDepths) {
  const LatticeDomain dom = domain_3x3x3();
  DiamondInfo info;
  ASSERT_TRUE(classify_diamond(dom, vertex_key({12, 12, 12}), &info, nullptr));  // coarse cube centre
  EXPECT_EQ(info.phase, 0);
  EXPECT_EQ(info.cube, 8);
  EXPECT_EQ(info.depth, 0);
  ASSERT_TRUE(classify_diamond(dom, vertex_key({16, 12, 12}), &info, nullptr));  // coarse face centre
  EXPECT_EQ(info.phase, 1);
  EXPECT_EQ(info.normal_axis, 0);
  EXPECT_EQ(info.depth, 1);
  ASSERT_TRUE(classify_diamond(dom, vertex_key({16, 16, 12}), &info, nullptr));  // coarse axis edge
  EXPECT_EQ(info.phase, 2);
  EXPECT_EQ(info.edge_axis, 2);
  EXPECT_EQ(info.depth, 2);
  ASSERT_TRUE(classify_diamond(dom, vertex_key({10, 10, 10}), &info, nullptr));  // half-size cube centre
  EXPECT_EQ(info.phase, 0);
  EXPECT_EQ(info.cube, 4);
  EXPECT_EQ(info.depth, 3);
  ASSERT_TRUE(classify_diamond(dom, vertex_key({9, 9, 9}), &info, nullptr));
  EXPECT_EQ(info.depth, 6);

  std::string why;
  EXPECT_FALSE(classify_diamond(dom, vertex_key({8, 16, 0}), &info, &why));  // coarse vertex
  EXPECT_NE(why.find("coarse"), std::string::npos);
  EXPECT_FALSE(classify_diamond(dom, vertex_key({28, 12, 12}), &info, &why));  // outside
  EXPECT_NE(why.find("outside"), std::string::npos);
  EXPECT_FALSE(classify_diamond(dom, pack_doubled({25, 24, 24}), &info, &why));  // off lattice
  EXPECT_NE(why.find("lattice"), std::string::npos);
  // Bit 63 is no coordinate's: such a key is not the diamond of its low bits.
  EXPECT_FALSE(classify_diamond(dom, (Key{1} << 63) | vertex_key({12, 12, 12}), &info, &why));
  EXPECT_NE(why.find("bits"), std::string::npos);
  EXPECT_FALSE(classify_diamond(dom, ~Key{0}, &info, &why));
}

TEST(Lattice, ParentsAndChildrenFollowTheHierarchyAndTheBoundary) {
  const LatticeDomain dom = domain_3x3x3();
  auto info_of = [&](Vec3i p) {
    DiamondInfo i;
    EXPECT_TRUE(classify_diamond(dom, vertex_key(p), &i, nullptr));
    return i;
  };
  std::array<Key, 4> parents{};
  std::array<Key, 8> children{};
  EXPECT_EQ(diamond_parents(dom, info_of({12, 12, 12}), &parents), 0);  // roots
  EXPECT_EQ(diamond_children(dom, info_of({12, 12, 12}), &children), 6);
  EXPECT_EQ(diamond_parents(dom, info_of({16, 12, 12}), &parents), 2);
  EXPECT_EQ(diamond_parents(dom, info_of({0, 12, 12}), &parents), 1);
  EXPECT_EQ(parents[0], vertex_key({4, 12, 12}));
  EXPECT_EQ(diamond_children(dom, info_of({16, 12, 12}), &children), 4);
  EXPECT_EQ(diamond_parents(dom, info_of({16, 16, 12}), &parents), 4);
  // On a box face: the interior face plus the two box-face diagonals through the edge.
  EXPECT_EQ(diamond_parents(dom, info_of({0, 16, 12}), &parents), 3);
  EXPECT_EQ(diamond_parents(dom, info_of({0, 0, 12}), &parents), 2);
  EXPECT_EQ(diamond_children(dom, info_of({16, 16, 12}), &children), 8);
  EXPECT_EQ(diamond_children(dom, info_of({0, 0, 12}), &children), 2);
  // A half-size cube's diagonal has three parents: the axis-edge centres among its corners.
  const DiamondInfo fine = info_of({10, 10, 10});
  ASSERT_EQ(diamond_parents(dom, fine, &parents), 3);
  std::set<Key> got(parents.begin(), parents.begin() + 3);
  EXPECT_EQ(got, (std::set<Key>{vertex_key({12, 8, 8}), vertex_key({8, 12, 8}), vertex_key({8, 8, 12})}));
  // Each parent lists this diamond among its children.
  for (Key p : got) {
    DiamondInfo pi;
    ASSERT_TRUE(classify_diamond(dom, p, &pi, nullptr));
    const int n = diamond_children(dom, pi, &children);
    EXPECT_NE(std::find(children.begin(), children.begin() + n, vertex_key({10, 10, 10})), children.begin() + n);
  }
  EXPECT_EQ(diamond_tet_count(dom, fine), 6);
  EXPECT_EQ(diamond_tet_count(dom, info_of({0, 0, 12})), 2);
}

}  // namespace
}  // namespace tissue::mesh
