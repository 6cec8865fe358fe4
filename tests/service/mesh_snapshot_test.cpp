#include "service/mesh_snapshot.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <optional>

#include "physics/forces.hpp"
#include "physics/physics_test_support.hpp"

namespace tissue::service {
namespace {

// The snapshot is the surface extract_surface gives for the current mesh,
// at the current positions, with each triangle's strain taken from the tet
// behind it.
void expect_matches_current_state(const physics::Simulation& sim, const MeshSnapshot& snap) {
  mesh::SurfaceMesh fresh;
  mesh::extract_surface(sim.body().mesh(), &fresh);
  ASSERT_EQ(snap.triangles, fresh.triangles);
  ASSERT_EQ(snap.vertices_m.size(), fresh.vertex_nodes.size());
  ASSERT_EQ(snap.vertex_level.size(), fresh.vertex_nodes.size());
  EXPECT_EQ(snap.sim_time_s, sim.time_s());
  for (std::size_t i = 0; i < fresh.vertex_nodes.size(); ++i) {
    const physics::Vec3& x = sim.body().x_m[fresh.vertex_nodes[i]];
    EXPECT_EQ(snap.vertices_m[i], (std::array<double, 3>{x.x(), x.y(), x.z()})) << "vertex " << i;
  }
  // Each vertex's level is the deepest tet behind a triangle at it, found
  // here per vertex from scratch.
  for (std::size_t i = 0; i < fresh.vertex_nodes.size(); ++i) {
    int deepest = -1;
    for (std::size_t t = 0; t < fresh.triangles.size(); ++t)
      for (const std::uint32_t v : fresh.triangles[t])
        if (v == i) deepest = std::max<int>(deepest, sim.body().mesh().tet(fresh.triangle_tet[t]).depth);
    ASSERT_GE(deepest, 0) << "vertex " << i << " is on no triangle";
    EXPECT_EQ(snap.vertex_level[i], deepest) << "vertex " << i;
  }
  ASSERT_EQ(snap.triangle_strain_energy_J_per_m3.size(), fresh.triangles.size());
  for (std::size_t t = 0; t < fresh.triangles.size(); ++t)
    EXPECT_EQ(snap.triangle_strain_energy_J_per_m3[t],
              static_cast<float>(physics::strain_energy_density_Pa(sim.body(), fresh.triangle_tet[t])))
        << "triangle " << t;
}

TEST(MeshSnapshot, HoldsTheSurfacePositionsLevelsAndStrainOfTheCurrentState) {
  physics::Simulation sim(physics::testing::cantilever_scene());
  for (int i = 0; i < 50; ++i) ASSERT_TRUE(sim.step().ok);
  SnapshotScratch scratch;
  MeshSnapshot snap;
  build_mesh_snapshot(sim, &scratch, &snap);
  expect_matches_current_state(sim, snap);
  float peak = 0.0f;
  for (const float e : snap.triangle_strain_energy_J_per_m3) peak = std::max(peak, e);
  EXPECT_GT(peak, 0.0f);  // the loaded cantilever is strained
  // The load refined the surface: a node of the starting lattice there shows
  // the depth of the tets around it, not 0 (the colouring's point).
  bool refined_lattice_node = false;
  for (std::size_t i = 0; i < snap.vertex_level.size(); ++i)
    if (sim.body().mesh().node(scratch.surface.vertex_nodes[i]).edge_a == mesh::kInvalidId && snap.vertex_level[i] > 0)
      refined_lattice_node = true;
  EXPECT_TRUE(refined_lattice_node);
}

// Extraction walks every leaf tet; it runs again only after the topology
// changed, and the reused surface still matches the moved nodes.
TEST(MeshSnapshot, ReusesTheSurfaceUntilTheTopologyChanges) {
  scene::Scene scene = physics::testing::cantilever_scene();
  scene.adaptivity.refine_threshold_Pa = 1e30;  // splits only when the test asks for one
  physics::Simulation sim(scene);
  SnapshotScratch scratch;
  MeshSnapshot snap;
  build_mesh_snapshot(sim, &scratch, &snap);
  EXPECT_EQ(scratch.extractions, 1u);
  const std::array<double, 3> first_vertex = snap.vertices_m.back();
  for (int step = 1; step <= 5; ++step) {
    ASSERT_TRUE(sim.step().ok);
    build_mesh_snapshot(sim, &scratch, &snap);
    EXPECT_EQ(scratch.extractions, 1u) << "after step " << step;
    expect_matches_current_state(sim, snap);
  }
  EXPECT_NE(snap.vertices_m.back(), first_vertex);  // the loaded end moved: positions are fresh
  // A split from outside the adaptivity: a new topology, a new surface.
  std::optional<mesh::Key> diamond;
  sim.body().mesh().for_each_tet([&](mesh::TetId t, const mesh::Tet&) {
    if (!diamond && sim.body().mesh().can_split(sim.body().mesh().diamond_of(t)))
      diamond = sim.body().mesh().diamond_of(t);
  });
  ASSERT_TRUE(diamond.has_value());
  const std::size_t tets_before = sim.body().mesh().tet_count();
  ASSERT_GT(sim.split_diamond(*diamond), 0);
  ASSERT_NE(sim.body().mesh().tet_count(), tets_before);
  const std::uint64_t extractions_before = scratch.extractions;
  build_mesh_snapshot(sim, &scratch, &snap);
  EXPECT_EQ(scratch.extractions, extractions_before + 1);
  expect_matches_current_state(sim, snap);
}

// Two meshes never share a topology version, so a scratch that saw one
// simulation's mesh re-extracts for another's (a reset or a new scene).
TEST(MeshSnapshot, ANewSimulationIsANewTopology) {
  physics::Simulation a(physics::testing::cantilever_scene());
  physics::Simulation b(physics::testing::free_cube_scene(2, 0));
  EXPECT_NE(a.body().mesh().topology_version(), b.body().mesh().topology_version());
  SnapshotScratch scratch;
  MeshSnapshot snap;
  build_mesh_snapshot(a, &scratch, &snap);
  build_mesh_snapshot(b, &scratch, &snap);
  EXPECT_EQ(scratch.extractions, 2u);
  expect_matches_current_state(b, snap);
}

}  // namespace
}  // namespace tissue::service
