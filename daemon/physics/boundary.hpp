// Boundary conditions of a scene applied to a body: kinematic nodes (fixed,
// prescribed displacement) and external forces (gravity, region loads).
#pragma once

#include <map>
#include <vector>

#include "mesh/surface.hpp"
#include "physics/body.hpp"

namespace tissue::physics {

// Sets the velocity of every kinematic node so that, moving with it for
// dt_s, it lands on its target at t_next_s: fixed nodes on their rest
// position, prescribed ones on rest + profile(t) * displacement.
void set_kinematic_velocities(Body& body, double t_next_s, double dt_s);
// The same for the listed nodes only (a list from kinematic_nodes: a step
// then touches the few boundary nodes, not every node of the mesh).
void set_kinematic_velocities(Body& body, const std::vector<NodeId>& kinematic, double t_next_s, double dt_s);
// The live fixed and prescribed nodes, ascending; valid until the mesh changes.
void kinematic_nodes(const Body& body, std::vector<NodeId>& out);

// Splits each scene load among the nodes of its region. A surface load
// (region containing boundary triangles) is shared by lumped triangle area,
// a volume or point load by lumped mass; either way the share of a node does
// not depend on how finely the rest of the region is meshed.
// The nodes a load on `region` acts on, with unnormalised weights: the
// vertices of the boundary triangles wholly inside it, by lumped area; if
// there are none, the nodes inside it, by lumped mass. One rule for
// LoadDistribution and for the scene check that a load can act (Body).
std::map<NodeId, double> load_node_weights(const Body& body, const mesh::SurfaceMesh& surface,
                                           const scene::Region& region);

class LoadDistribution {
 public:
  // Recomputes the node shares; call after every mesh change.
  void rebuild(const Body& body);
  // f_ext = gravity * m + Σ loads * profile(t), for every node.
  void external_forces(const Body& body, double t_s, std::vector<Vec3>& f_ext_N) const;
  // Node ids and weights (summing to 1) of load i.
  const std::vector<std::pair<NodeId, double>>& shares(std::size_t load) const { return shares_[load]; }

 private:
  std::vector<std::vector<std::pair<NodeId, double>>> shares_;
};

}  // namespace tissue::physics
