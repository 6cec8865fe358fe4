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

 private:
  void factor(const Body& body);

  bool factored_ = false;
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
