// The deformable body: the adaptive mesh plus the mass-spring state that lives
// on it (the mutable "context"; the scene is the immutable "system").
//
// Arrays are indexed by mesh ids and sized to the mesh pools, so a split or
// merge updates only the entries it touches. Dead edges carry zero stiffness
// and damping, dead and kinematic nodes zero inverse mass: the force and
// solver loops run over the pools without branches on liveness.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "mesh/kuhn_mesh.hpp"
#include "scene/scene.hpp"

namespace tissue::physics {

using Vec3 = Eigen::Vector3d;
using mesh::EdgeId;
using mesh::NodeId;
using mesh::TetId;

enum class NodeKind : std::uint8_t { kFree, kFixed, kPrescribed, kDead };

class Body {
 public:
  // Builds the coarse mesh of the scene's object, refined uniformly to the
  // adaptivity's min_depth when adaptivity is on. Throws std::invalid_argument
  // for a box the lattice cannot hold.
  explicit Body(const scene::Scene& scene);

  const mesh::KuhnMesh& mesh() const { return mesh_; }
  const scene::Scene& scene() const { return scene_; }

  // Splits / merges one diamond (closure included for split) and carries the
  // state across. Mass moves with its momentum: a split's node z takes half
  // its mass from each end of its edge, a merge gives half of z's to each
  // end, and that mass keeps the velocity it had where it came from (a fixed
  // node's is zero, a prescribed node's its driver's). A free node joins the
  // mass it takes to its own, an inelastic collision (momentum kept, kinetic
  // energy can only drop): a new free node takes its edge's mean position and
  // velocity, a free end of a merged node v_e ← (m_e v_e + m_z v_z / 2) /
  // (m_e + m_z / 2). A fixed or prescribed node moves as its driver says
  // whatever mass it gains or loses: a new one takes its target
  // (place_kinematic_node). So:
  //  - where the nodes a change touches are all free, their momentum is
  //    kept and their kinetic energy can only drop (a split's by
  //    m_z |v_a − v_b|² / 8);
  //  - the free nodes gain momentum and kinetic energy only as mass that
  //    moved with a moving prescribed node becomes theirs (a split next to
  //    it, a merge of one): its momentum, and at most its kinetic energy
  //    (m |v_driver|² / 2 for the mass m); none where no driver moves (mass
  //    taken from a fixed node arrives at rest: it slows the node it joins,
  //    momentum unchanged);
  //  - what a kinematic node gains or loses (a free node's half merged into
  //    it, mass at its driver's velocity) is the world's.
  // The elastic energy does change with the springs (SimCounters::
  // adaptation_energy_J, which books the change in kinetic + elastic energy
  // of all nodes). Returns diamonds split / 1 for merge. A key the mesh
  // refuses (KuhnMesh::split, require_can_merge) throws std::invalid_argument
  // with the body unchanged.
  int split(mesh::Key diamond);
  void merge(mesh::Key diamond);

  // Per node (index = NodeId).
  std::vector<Vec3> x_m;                // position
  std::vector<Vec3> v_m_per_s;          // velocity
  std::vector<Vec3> rest_m;             // rest position (from the lattice, exact)
  std::vector<double> mass_kg;          // eq. (2)
  std::vector<double> inv_mass_per_kg;  // 0 for fixed, prescribed and dead nodes
  std::vector<NodeKind> kind;
  std::vector<std::int32_t> prescribed_index;  // into scene.prescribed, or -1
  std::vector<std::int64_t> changed_step;      // step at which a split created the node

  // Per edge (index = EdgeId); dead edges: a = b = 0, k = c = 0.
  std::vector<NodeId> edge_a, edge_b;
  std::vector<double> rest_length_m;
  std::vector<double> weighted_volume_m3;  // Σ w V of incident tets, eq. (3), from the exact sum (below)
  std::vector<double> stiffness_N_per_m;
  std::vector<double> damping_N_s_per_m;

  // Steps taken (the simulation sets it): the adaptivity stamps new nodes
  // with it, and it gives the state's time.
  std::int64_t step_index = 0;
  // Time of the state [s], step_index × dt as the simulation counts it: a
  // fixed or prescribed node a split creates is put where the drivers hold
  // the nodes of its region at this time, not at its edge's midpoint.
  double time_s() const { return static_cast<double>(step_index) * scene_.integrator.dt_s; }

  // Recomputes every mass, spring and damper from the mesh alone. The
  // incremental updates must agree with it (a test checks that).
  void rebuild_parameters();

  // Changes (to a value no other Body state ever had) whenever the mesh or
  // the spring parameters change: split, merge, rebuild_parameters. Copies
  // share it. Integrators key their per-topology caches (spring streams,
  // orderings) on it.
  std::uint64_t parameters_version() const { return parameters_version_; }

  // Σ w V share [m³] a tet at `depth` with corners v gives each of its edges
  // (kTetEdgeSlots order): its stiffness share is E · share / L². Stiffness
  // and mass are sums of such per-tet shares (eqs. (2), (3)); the body sums
  // them exactly, as integers 10⁴ w · 6V (weighted_volume_m3 is that sum
  // rounded once), so a spring's bits differ from the sum of these doubles.
  std::array<double, 6> tet_edge_shares_m3(const std::array<NodeId, 4>& v, int depth) const;

  // Springs (stiffness and damper) recomputed since construction, rebuilds
  // included: what a split or merge costs in parameter updates, which must
  // not grow with the mesh (a test compares it across mesh sizes).
  std::uint64_t edges_refreshed() const { return edges_refreshed_; }

  // Total mass [kg] and momentum [kg m/s] of all nodes.
  double total_mass_kg() const;
  Vec3 momentum_kg_m_per_s() const;

 private:
  void apply_log(const mesh::MeshChangeLog& log);
  void resize_to_mesh();
  // Throws std::invalid_argument (scene::SceneModelError) naming the key
  // path of a fixed, prescribed or load region that holds no node of the
  // starting mesh, of a prescribed region every node of which another region
  // holds, or of a load on no free node.
  void require_every_region_selects_a_node() const;
  void classify_node(NodeId n);
  // Puts a fixed or prescribed node on its target at time_s, moving as the
  // drivers move the other nodes of its region; leaves a free node alone.
  void place_kinematic_node(NodeId n);
  void refresh_edge(EdgeId e);
  // 10⁴ × the weight w of each edge of a tet at `depth` with corners v
  // (kTetEdgeSlots order).
  std::array<std::int64_t, 6> tet_edge_weights_e4(const std::array<NodeId, 4>& v, int depth) const;
  // Adds sign × a tet's shares 10⁴ w · 6V to its edges' exact sums.
  void add_tet_shares(const std::array<NodeId, 4>& v, int depth, const std::array<EdgeId, 6>& edges, int sign);

  scene::Scene scene_;
  mesh::KuhnMesh mesh_;
  std::uint64_t parameters_version_ = 0;
  std::uint64_t edges_refreshed_ = 0;
  // Per edge: Σ 10⁴ w · 6V of its incident tets, lattice units. Exact, so a
  // spring depends on its incident tets alone, not on the history of splits
  // and merges that made them (a floating running sum of per-tet shares,
  // minus the parent's and plus the children's and back, drifted by ulps:
  // the same mesh reached two ways had different bits). 128 bits: 10⁴ w ·
  // 6V can pass 2⁶³ on the deepest lattices.
  __extension__ using WeightedSixVolume = __int128;
  std::vector<WeightedSixVolume> weighted_six_volume_e4_;
  mesh::MeshChangeLog log_;            // reused: no allocation in steady state
  std::vector<EdgeId> touched_edges_;  // reused scratch
  std::vector<NodeId> touched_nodes_;
  std::vector<std::uint8_t> edge_touched_, node_touched_;
};

// Nodes with an inverse mass above zero (neither fixed, prescribed nor dead).
std::size_t free_node_count(const Body& body);

// The springs a step must run, in edge id order: live (stiffness above
// zero) with at least one free end. The integrators' spring streams and the
// frequency estimate are built from this one list.
std::vector<EdgeId> moving_springs(const Body& body);

}  // namespace tissue::physics
