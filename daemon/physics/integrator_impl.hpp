// Integrator implementations (internal to physics/; users go through
// make_integrator in integrator.hpp).
#pragma once

#include <Eigen/Core>
#include <Eigen/SparseCholesky>
#include <vector>

#include "physics/integrator.hpp"

namespace tissue::physics {

// Copy of the node state, restored when a step must be rejected.
class StateSave {
 public:
  void save(const Body& body) {
    x_ = body.x_m;
    v_ = body.v_m_per_s;
  }
  void restore(Body& body) const {
    std::copy(x_.begin(), x_.end(), body.x_m.begin());
    std::copy(v_.begin(), v_.end(), body.v_m_per_s.begin());
  }

 private:
  std::vector<Vec3> x_, v_;
};

class ExplicitIntegrator final : public Integrator {
 public:
  ExplicitIntegrator(const scene::IntegratorSpec& spec, const scene::MaterialSpec& material);
  StepOutcome step(Body& body, const std::vector<Vec3>& f_ext_N, double dt_s) override;
  void mesh_changed() override { bound_valid_ = false; }
  const char* name() const override { return "explicit"; }

 private:
  scene::IntegratorSpec spec_;
  double alpha_per_s_;
  bool bound_valid_ = false;
  double stable_dt_s_ = 0.0;
  std::vector<Vec3> force_;
  StateSave save_;
};

class ImplicitIntegrator final : public Integrator {
 public:
  ImplicitIntegrator(const scene::IntegratorSpec& spec, const scene::MaterialSpec& material);
  StepOutcome step(Body& body, const std::vector<Vec3>& f_ext_N, double dt_s) override;
  void mesh_changed() override {}
  const char* name() const override { return "implicit"; }

 private:
  // y = A p for the free nodes (kinematic entries of p must be zero).
  void apply(const Body& body, const std::vector<Vec3>& p, std::vector<Vec3>& y) const;

  scene::IntegratorSpec spec_;
  double alpha_per_s_;
  double h_ = 0.0;
  // Per edge: the system block B = h c d̂d̂ᵀ + h² S, S the clamped Hessian.
  std::vector<Eigen::Matrix3d> block_;
  std::vector<Vec3> force_, rhs_, dv_, r_, z_, p_, ap_, diag_inv_;
  StateSave save_;
};

class ProjectiveIntegrator final : public Integrator {
 public:
  ProjectiveIntegrator(const scene::IntegratorSpec& spec, const scene::MaterialSpec& material);
  StepOutcome step(Body& body, const std::vector<Vec3>& f_ext_N, double dt_s) override;
  void mesh_changed() override { factor_valid_ = false; }
  const char* name() const override { return "projective"; }

 private:
  void factor(const Body& body, double dt_s);

  scene::IntegratorSpec spec_;
  double alpha_per_s_;
  bool factor_valid_ = false;
  double factored_dt_s_ = 0.0;
  std::vector<int> dof_of_node_;  // free nodes → row, else -1
  std::vector<NodeId> node_of_dof_;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver_;
  Eigen::MatrixXd rhs_, solution_;
  std::vector<Vec3> inertial_, d_, x_prev_;
  StateSave save_;
};

}  // namespace tissue::physics
