// The stiffness a tool feels at one node of the object: static condensation
// of the whole body onto that node (NUMERICS.md §5). With K the stiffness
// matrix of the free nodes, the compliance seen at node c is the 3x3 block
// C_cc of K^-1, and K_c = C_cc^-1. Unlike a k-ring patch guess it includes
// global bending, which a patch over-estimates by 1.3-2.2x.
//
// K is the linear (small-displacement) spring stiffness, sum of k d d^T over
// springs with d the rest direction, so it changes only with the mesh: it is
// factored once per mesh change (sparse LDL^T) and each query is three
// back-substitutions. A tiny mass term M / (1 s)^2 regularises objects with no
// fixed node (their rigid motions would make K singular); it changes K_c by
// about m / 1 s^2, i.e. < 1e-3 N/m for gram-scale nodes.
//
// The factorisation grows much faster than the mesh (Eigen's simplicial
// LDL^T, a lattice clamped on one face, `g++ -O2` program over this class,
// 2026-11-26): 1,728 free-or-fixed nodes 0.12 s, 2,744 0.35 s, 3,375 0.72 s,
// 4,913 1.7 s, 9,261 15 s, 17,576 89 s. It runs on the sim thread at every
// mesh change, so above kMaxCondensedFreeNodes free nodes the answer is the
// node's own block K_cc instead: an upper bound of the condensed K_c (in the
// PSD order: condensing only takes stiffness away), which the haptic side
// clamps at device.limits.max_stiffness_N_per_m anyway. It feels stiffer
// than the object is in bending, and never stalls the simulation.
#pragma once

#include <Eigen/Core>
#include <Eigen/SparseCholesky>
#include <vector>

#include "physics/body.hpp"

namespace tissue::physics {

using Mat3 = Eigen::Matrix3d;

class ContactStiffness {
 public:
  // A kinematic (fixed or prescribed) node is rigid: it reports this
  // stiffness on the diagonal (finite, so downstream arithmetic stays finite;
  // haptic safety clamps rendered stiffness far below it).
  static constexpr double kRigid_N_per_m = 1e9;
  // Above this many free nodes K is not factored (see the top of the file).
  static constexpr int kMaxCondensedFreeNodes = 3000;

  // K_c at `node` (symmetric positive definite). Refactors first when the
  // mesh changed since the last call (mesh_changed()). Throws
  // std::invalid_argument for a dead node.
  Mat3 stiffness_N_per_m_at_node(const Body& body, NodeId node);
  void mesh_changed() {
    factored_ = false;
    cached_node_ = mesh::kInvalidId;
  }
  // How many times K was factored (tests and stats).
  int factorizations() const { return factorizations_; }
  // How many times K_c was solved for (repeated queries of a node are cached).
  int solves() const { return solves_; }
  // Whether the last answer was the node's own block K_cc (a body with more
  // than kMaxCondensedFreeNodes free nodes) rather than the condensed K_c.
  bool local_bound() const { return local_bound_; }

 private:
  void factor(const Body& body);
  // K_cc: the springs at `node`, k d d^T over its edges, plus the
  // regularisation. O(1) in the mesh size (KuhnMesh::for_each_edge_at_node).
  Mat3 own_block_N_per_m(const Body& body, NodeId node) const;

  bool factored_ = false;
  bool local_bound_ = false;
  // The last answer: a tool pressing one spot asks for the same node every
  // step, and K (hence K_c) changes only with the mesh.
  NodeId cached_node_ = mesh::kInvalidId;
  Mat3 cached_ = Mat3::Zero();
  int factorizations_ = 0;
  int solves_ = 0;
  std::vector<int> dof_of_node_;  // first of three unknowns, -1 for kinematic and dead nodes
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt_;
  Eigen::MatrixXd rhs_, solution_;
};

}  // namespace tissue::physics
