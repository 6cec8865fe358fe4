#include "physics/probes.hpp"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <array>
#include <cmath>
#include <memory>
#include <random>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "physics/body.hpp"
#include "physics/physics_test_support.hpp"
#include "physics/simulation.hpp"

namespace tissue::physics {
namespace {

// A skewed tet, positively oriented, nowhere near the origin.
const Vec3 kA(0.1, 0.2, -0.3), kB(0.5, 0.1, -0.2), kC(0.2, 0.7, -0.1), kD(0.15, 0.3, 0.4);

std::array<double, 4> weights_of(const Vec3& p) { return barycentric(p, kA, kB, kC, kD); }

TEST(Probes, BarycentricOfEachVertexIsItsUnitWeight) {
  const std::array<Vec3, 4> corners = {kA, kB, kC, kD};
  for (int i = 0; i < 4; ++i) {
    const auto l = weights_of(corners[i]);
    for (int j = 0; j < 4; ++j) EXPECT_NEAR(l[j], i == j ? 1.0 : 0.0, 1e-14) << "vertex " << i << " weight " << j;
  }
}

TEST(Probes, BarycentricOfTheCentroidIsAQuarterEach) {
  const auto l = weights_of(0.25 * (kA + kB + kC + kD));
  for (int j = 0; j < 4; ++j) EXPECT_NEAR(l[j], 0.25, 1e-14) << "weight " << j;
}

// For any point, inside or out: the weights sum to one and mix the corners
// back into the point (linear precision).
TEST(Probes, BarycentricWeightsSumToOneAndReproduceThePoint) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < 100; ++i) {
    const Vec3 p(u(rng), u(rng), u(rng));
    const auto l = weights_of(p);
    EXPECT_NEAR(l[0] + l[1] + l[2] + l[3], 1.0, 1e-13) << p.transpose();
    const Vec3 back = l[0] * kA + l[1] * kB + l[2] * kC + l[3] * kD;
    EXPECT_NEAR((back - p).norm(), 0.0, 1e-13) << p.transpose();
  }
}

// Beyond the face opposite a vertex, that vertex's weight is negative (by
// how far past the face, in units of the vertex's height) and the others
// stay positive; a point inside has all four positive.
TEST(Probes, APointOutsideHasANegativeWeight) {
  const std::array<Vec3, 4> corners = {kA, kB, kC, kD};
  for (int i = 0; i < 4; ++i) {
    Vec3 face = Vec3::Zero();
    for (int j = 0; j < 4; ++j)
      if (j != i) face += corners[j] / 3.0;
    const Vec3 beyond = face + 0.25 * (face - corners[i]);  // a quarter height past the face
    const auto l = weights_of(beyond);
    EXPECT_NEAR(l[i], -0.25, 1e-13) << "vertex " << i;
    for (int j = 0; j < 4; ++j) {
      if (j == i) continue;
      EXPECT_GT(l[j], 0.0) << "vertex " << i << " weight " << j;
    }
  }
  const auto inside = weights_of(0.4 * kA + 0.3 * kB + 0.2 * kC + 0.1 * kD);
  EXPECT_NEAR(inside[0], 0.4, 1e-14);
  EXPECT_NEAR(inside[1], 0.3, 1e-14);
  EXPECT_NEAR(inside[2], 0.2, 1e-14);
  EXPECT_NEAR(inside[3], 0.1, 1e-14);
}

// A linear displacement field is read exactly anywhere in a mesh of mixed
// depths, wherever the containing tet is; name and rest point are kept.
TEST(Probes, ProbeReadsALinearFieldExactly) {
  Body body = testing::randomly_refined_beam(5);
  Eigen::Matrix3d g;
  g << 0.01, -0.02, 0.005, 0.03, 0.0, -0.01, -0.02, 0.015, 0.01;
  const Vec3 shift(1e-3, -2e-3, 5e-4);
  body.mesh().for_each_node(
      [&](NodeId n, const mesh::Node&) { body.x_m[n] = body.rest_m[n] + g * body.rest_m[n] + shift; });
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> along(0.0, 0.4), across(0.0, 0.1);
  for (int i = 0; i < 50; ++i) {
    const Vec3 p(along(rng), across(rng), across(rng));
    std::string name = "p";
    name += std::to_string(i);
    Probe probe(name, p);
    EXPECT_EQ(probe.name(), name);
    EXPECT_EQ(probe.rest_m(), p);
    EXPECT_NEAR((probe.displacement_m(body) - (g * p + shift)).norm(), 0.0, 1e-15) << p.transpose();
  }
}

// Only one node moved by δ: a probe on that node reads δ, one at the
// midpoint of one of its edges δ/2 (whichever tet around the edge holds it),
// and one on another node reads nothing.
TEST(Probes, ProbeMixesTheDisplacementsOfItsTetsNodes) {
  Body body(testing::free_cube_scene(2, 1));
  const Vec3 centre(0.05, 0.05, 0.05), delta(1e-3, -2e-3, 3e-3);
  NodeId moved = mesh::kInvalidId, corner = mesh::kInvalidId;
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
    if ((body.rest_m[n] - centre).norm() < 1e-12) moved = n;
    if (body.rest_m[n].norm() < 1e-12) corner = n;
  });
  ASSERT_NE(moved, mesh::kInvalidId);
  ASSERT_NE(corner, mesh::kInvalidId);
  body.x_m[moved] += delta;
  int edges = 0;
  body.mesh().for_each_edge([&](EdgeId, const mesh::Edge& edge) {
    if (edge.a != moved && edge.b != moved) return;
    Probe probe("mid", 0.5 * (body.rest_m[edge.a] + body.rest_m[edge.b]));
    EXPECT_NEAR((probe.displacement_m(body) - 0.5 * delta).norm(), 0.0, 1e-15) << "edge " << edge.a << "-" << edge.b;
    ++edges;
  });
  EXPECT_GT(edges, 6);
  Probe on_node("node", centre);
  EXPECT_NEAR((on_node.displacement_m(body) - delta).norm(), 0.0, 1e-15);
  Probe far("far", Vec3::Zero());
  EXPECT_EQ(far.displacement_m(body), Vec3::Zero());
}

// The probe at the cube's centre sits on the cube diagonal, shared by all
// six tets. Once read, the mesh is split there: the tet it had is gone (or
// its id reused with other nodes), the new centre node moves, and the probe
// follows it rather than the stale corners.
TEST(Probes, ProbeRelocatesAfterTheMeshChanges) {
  scene::Scene s = testing::free_cube_scene(1, 0);
  s.adaptivity.enabled = true;
  s.adaptivity.max_depth = 2;
  Body body(s);
  const Vec3 centre(0.025, 0.025, 0.025);
  Probe probe("centre", centre);
  EXPECT_EQ(probe.displacement_m(body), Vec3::Zero());

  const mesh::Key diagonal = body.mesh().diamond_of(0);
  ASSERT_GT(body.split(diagonal), 0);
  const NodeId z = body.mesh().find_node(diagonal);
  ASSERT_NE(z, mesh::kInvalidId);
  ASSERT_NEAR((body.rest_m[z] - centre).norm(), 0.0, 1e-15);
  const Vec3 delta(2e-3, 1e-3, -1e-3);
  body.x_m[z] += delta;
  EXPECT_NEAR((probe.displacement_m(body) - delta).norm(), 0.0, 1e-15);
}

// Node and tet ids are both reused: a merge frees a node and its tets, and
// a later split elsewhere can hand the same ids out again, so a live tet of
// the probe's old id with the probe's old vertex ids can be another tet, its
// new node somewhere else. A random walk of split/merge pairs finds one such
// pair; a probe read inside the old tet before it, under a linear field
// after it, must read the field at its own point, not through the stale
// weights at the new node.
TEST(Probes, AProbeIsRelocatedWhenItsTetIdAndVertexIdsComeBackAsAnotherTet) {
  scene::Scene s = testing::free_cube_scene(1, 0);
  s.adaptivity.enabled = true;
  s.adaptivity.max_depth = 4;
  Body body(s);
  std::mt19937 rng(18);
  using Corners = std::array<mesh::Vec3i, 4>;
  const auto corners_of = [](const Body& b, const mesh::Tet& tet) {
    Corners c;
    for (int i = 0; i < 4; ++i) c[i] = b.mesh().node(tet.v[i]).lattice;
    return c;
  };
  for (int pair = 0; pair < 1000; ++pair) {
    const Body before = body;
    // Two random operations (split or merge), recorded so they can be redone.
    std::vector<std::pair<bool, mesh::Key>> ops;
    for (int k = 0; k < 2; ++k) {
      const mesh::KuhnMesh& m = body.mesh();
      if (rng() % 2) {
        TetId t;
        do t = static_cast<TetId>(rng() % m.tet_capacity());
        while (!m.tet_alive(t));
        if (m.can_split(m.diamond_of(t))) {
          ops.emplace_back(true, m.diamond_of(t));
          body.split(m.diamond_of(t));
        }
      } else {
        NodeId n;
        do n = static_cast<NodeId>(rng() % m.node_capacity());
        while (!m.node_alive(n));
        if (m.node(n).edge_a != mesh::kInvalidId && m.can_merge(m.node_key(n))) {
          ops.emplace_back(false, m.node_key(n));
          body.merge(m.node_key(n));
        }
      }
    }
    TetId reused = mesh::kInvalidId;
    body.mesh().for_each_tet([&](TetId t, const mesh::Tet& tet) {
      if (reused == mesh::kInvalidId && before.mesh().tet_alive(t) && before.mesh().tet(t).v == tet.v &&
          corners_of(before, before.mesh().tet(t)) != corners_of(body, tet))
        reused = t;
    });
    if (reused == mesh::kInvalidId) continue;

    Body replay = before;
    const auto& v = before.mesh().tet(reused).v;
    const Vec3 inside = 0.25 * (before.rest_m[v[0]] + before.rest_m[v[1]] + before.rest_m[v[2]] + before.rest_m[v[3]]);
    Probe probe("reused", inside);
    EXPECT_EQ(probe.displacement_m(replay), Vec3::Zero());
    for (const auto& [split, key] : ops) split ? static_cast<void>(replay.split(key)) : replay.merge(key);
    ASSERT_EQ(replay.mesh().tet(reused).v, v) << "the replay must reuse the ids as the walk did";
    Eigen::Matrix3d g;
    g << 0.01, -0.02, 0.005, 0.03, 0.0, -0.01, -0.02, 0.015, 0.01;
    replay.mesh().for_each_node(
        [&](NodeId n, const mesh::Node&) { replay.x_m[n] = replay.rest_m[n] + g * replay.rest_m[n]; });
    EXPECT_NEAR((probe.displacement_m(replay) - g * inside).norm(), 0.0, 1e-15) << "after pair " << pair;
    return;
  }
  FAIL() << "no split/merge pair reused a tet id with its vertex ids; the walk needs another seed";
}

// A probe on the object's surface (a corner, a face) is inside; one a
// tenth of a millimetre outside is refused, naming the probe.
TEST(Probes, ProbesOnTheSurfaceAreInsideAndJustOutsideAreRefused) {
  Body body(testing::free_cube_scene(1, 1));
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) { body.x_m[n] = 1.5 * body.rest_m[n]; });
  for (const Vec3& p : {Vec3(0.05, 0.05, 0.05), Vec3(0.0, 0.03, 0.01), Vec3(0.02, 0.05, 0.04)}) {
    Probe probe("surface", p);
    EXPECT_NEAR((probe.displacement_m(body) - 0.5 * p).norm(), 0.0, 1e-15) << p.transpose();
  }
  Probe outside("just outside", Vec3(0.0501, 0.02, 0.02));
  try {
    outside.displacement_m(body);
    FAIL() << "a probe outside the object must be refused";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("just outside"), std::string::npos) << e.what();
  }
}

// The scene's checks let a probe lie outside the box by up to 1e-9 of its
// size; such a probe is located (on the nearest tet), not refused later by a
// tighter test of its own. One clearly outside is refused naming its key.
TEST(Probes, AProbeTheScenesChecksAcceptIsLocatedAndABadOneNamesItsKey) {
  // 4 x 4 x 4 cubes of 50 mm: the checks allow 0.2 nm, -4e-9 of a 50 mm tet.
  scene::Scene s = testing::free_cube_scene(4, 0);
  s.probes = {{"hair outside", {0.2 + 1.8e-10, 0.02, 0.02}}};
  EXPECT_NO_THROW(Simulation sim(s));
  s.probes = {{"fine", {0.01, 0.01, 0.01}}, {"far", {0.2001, 0.02, 0.02}}};
  try {
    Simulation sim(s);
    FAIL() << "a probe outside the object must be refused";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("probes[1].rest_m: probe 'far' lies outside the object"), std::string::npos)
        << e.what();
  }
}

// The scene check's tolerance is relative to the object (1e-9 of 512 mm is
// 0.512 nm), the locator's to the tet (-1e-6 of its size): 0.5 nm past the
// far face of 512 cubes of 1 mm is -5e-7 of a coarse tet but -2e-6 of a
// depth-6 one. That probe was refused at load at min_depth 6 ("probe
// 'probe0' lies outside the object") and, where refinement reached it
// mid-run, threw out of displacement_m and aborted the batch ("internal
// error"). Built into a Simulation, it sits on the box and reads as inside.
TEST(Probes, AProbeTheScenesChecksAcceptStaysLocatableAtEveryDepth) {
  scene::Scene s;
  s.object.cubes = {512, 1, 1};
  s.object.cube_size_m = 0.001;
  s.probes = {{"probe0", {0.5120000005, 0.0005, 0.0005}}};
  const Vec3 shift_m(1e-4, -2e-4, 3e-4);
  const auto reads_the_shift = [&](Simulation& sim) {
    Body& body = sim.mutable_body();
    body.mesh().for_each_node([&](NodeId n, const mesh::Node&) { body.x_m[n] = body.rest_m[n] + shift_m; });
    const Vec3 u = sim.probe_displacement_m(0);
    EXPECT_TRUE(u.allFinite()) << u.transpose();
    EXPECT_NEAR((u - shift_m).norm(), 0.0, 1e-15) << u.transpose();
  };

  // Refined uniformly at load.
  scene::Scene refined = s;
  refined.adaptivity.min_depth = 6;
  std::unique_ptr<Simulation> at_load;
  try {
    at_load = std::make_unique<Simulation>(refined);
  } catch (const std::invalid_argument& e) {
    ADD_FAILURE() << "min_depth 6: " << e.what();
  }
  if (at_load) reads_the_shift(*at_load);

  // Refined around it during the run: located on the coarse mesh, then the
  // leaf holding it split down to depth 6.
  scene::Scene adaptive = s;
  adaptive.adaptivity.enabled = true;
  adaptive.adaptivity.max_depth = 6;
  Simulation sim(adaptive);
  ASSERT_TRUE(sim.probe_displacement_m(0).allFinite());
  const Vec3 on_face(0.512, 0.0005, 0.0005);
  for (int depth = 0; depth < 6;) {
    const mesh::KuhnMesh& mesh = sim.body().mesh();
    TetId holder = mesh::kInvalidId;
    double best = -INFINITY;
    mesh.for_each_tet([&](TetId t, const mesh::Tet& tet) {
      const auto& v = tet.v;
      const Body& b = sim.body();
      const auto l = barycentric(on_face, b.rest_m[v[0]], b.rest_m[v[1]], b.rest_m[v[2]], b.rest_m[v[3]]);
      const double worst = std::min({l[0], l[1], l[2], l[3]});
      if (worst > best) {
        best = worst;
        holder = t;
      }
    });
    depth = mesh.tet(holder).depth;
    if (depth < 6) {
      ASSERT_GT(sim.split_diamond(mesh.diamond_of(holder)), 0);
    }
  }
  try {
    reads_the_shift(sim);
  } catch (const std::invalid_argument& e) {
    FAIL() << "refined to depth 6 mid-run: " << e.what();
  }
}

}  // namespace
}  // namespace tissue::physics
