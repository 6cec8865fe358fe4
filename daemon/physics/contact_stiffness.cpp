#include "physics/contact_stiffness.hpp"

#include <Eigen/LU>
#include <stdexcept>
#include <string>

namespace tissue::physics {

namespace {
constexpr double kRegularisation_per_s2 = 1.0;  // M / (1 s)^2, see the header
}  // namespace

void ContactStiffness::factor(const Body& body) {
  const mesh::KuhnMesh& mesh = body.mesh();
  dof_of_node_.assign(body.x_m.size(), -1);
  int dofs = 0;
  for (std::size_t n = 0; n < body.x_m.size(); ++n)
    if (mesh.node_alive(static_cast<NodeId>(n)) && body.inv_mass_per_kg[n] != 0.0) {
      dof_of_node_[n] = dofs;
      dofs += 3;
    }
  local_bound_ = dofs > 3 * kMaxCondensedFreeNodes;
  if (local_bound_) {  // answered by own_block_N_per_m: nothing to factor
    factored_ = true;
    return;
  }
  factored_ = false;  // until the factorisation below succeeds (an exception leaves it false)

  std::vector<Eigen::Triplet<double>> entries;
  entries.reserve(static_cast<std::size_t>(dofs) * 3 + 36 * mesh.edge_count());
  for (std::size_t n = 0; n < dof_of_node_.size(); ++n)
    if (dof_of_node_[n] >= 0)
      for (int i = 0; i < 3; ++i)
        entries.emplace_back(dof_of_node_[n] + i, dof_of_node_[n] + i, kRegularisation_per_s2 * body.mass_kg[n]);
  mesh.for_each_edge([&](EdgeId e, const mesh::Edge& edge) {
    const double k = body.stiffness_N_per_m[e];
    if (k == 0.0) return;
    const Vec3 d = (body.rest_m[edge.b] - body.rest_m[edge.a]).normalized();
    const Mat3 block = k * d * d.transpose();
    const int da = dof_of_node_[edge.a], db = dof_of_node_[edge.b];
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        if (da >= 0) entries.emplace_back(da + i, da + j, block(i, j));
        if (db >= 0) entries.emplace_back(db + i, db + j, block(i, j));
        if (da >= 0 && db >= 0) {
          entries.emplace_back(da + i, db + j, -block(i, j));
          entries.emplace_back(db + i, da + j, -block(i, j));
        }
      }
  });
  Eigen::SparseMatrix<double> k_matrix(dofs, dofs);
  k_matrix.setFromTriplets(entries.begin(), entries.end());
  ldlt_.compute(k_matrix);
  if (ldlt_.info() != Eigen::Success)
    throw std::runtime_error("contact stiffness: the stiffness matrix could not be factored");
  factored_ = true;
  ++factorizations_;
}

Mat3 ContactStiffness::own_block_N_per_m(const Body& body, NodeId node) const {
  Mat3 k_cc = kRegularisation_per_s2 * body.mass_kg[node] * Mat3::Identity();
  // The node's own edges by lattice lookup: a tool sliding over a big mesh
  // asks for a new node every few steps, and walking every edge for each
  // took O(E) of the sim thread.
  body.mesh().for_each_edge_at_node(node, [&](EdgeId e, const mesh::Edge& edge) {
    const Vec3 d = (body.rest_m[edge.b] - body.rest_m[edge.a]).normalized();
    k_cc += body.stiffness_N_per_m[e] * d * d.transpose();
  });
  return k_cc;
}

Mat3 ContactStiffness::stiffness_N_per_m_at_node(const Body& body, NodeId node) {
  if (!body.mesh().node_alive(node))
    throw std::invalid_argument("contact stiffness: node " + std::to_string(node) + " is not in the mesh");
  if (!factored_ || dof_of_node_.size() != body.x_m.size()) {
    factor(body);
    cached_node_ = mesh::kInvalidId;
  }
  if (node == cached_node_) return cached_;
  const int dof = dof_of_node_[node];
  if (dof < 0) return kRigid_N_per_m * Mat3::Identity();
  if (local_bound_) {
    cached_ = own_block_N_per_m(body, node);
    cached_node_ = node;
    return cached_;
  }
  rhs_.setZero(ldlt_.rows(), 3);
  for (int i = 0; i < 3; ++i) rhs_(dof + i, i) = 1.0;
  solution_ = ldlt_.solve(rhs_);
  ++solves_;
  const Mat3 compliance = solution_.block<3, 3>(dof, 0);
  const Mat3 symmetric = 0.5 * (compliance + compliance.transpose());
  cached_ = symmetric.inverse();
  cached_node_ = node;
  return cached_;
}

}  // namespace tissue::physics
