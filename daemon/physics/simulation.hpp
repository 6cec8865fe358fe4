// One simulation run of a scene: the step pipeline, readable top to bottom
// in Simulation::step():
//   kinematics (fixed/prescribed nodes) → external forces (gravity, loads)
//   → integrate (explicit | implicit | projective) → adapt every K steps
//   → probes.
// Single-threaded, no I/O, deterministic: the same scene gives bit-identical
// results. Clients read the body and the statistics; only step() mutates.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "physics/adaptivity.hpp"
#include "physics/body.hpp"
#include "physics/boundary.hpp"
#include "physics/integrator.hpp"
#include "physics/probes.hpp"
#include "scene/scene.hpp"

namespace tissue::physics {

struct StepResult {
  bool ok = true;
  std::string error;  // why the step was refused or rejected (state unchanged)
  int substeps = 1;
  int solver_iterations = 0;
  double solver_residual = 0.0;
  AdaptStats adapted;
};

struct SimCounters {
  std::int64_t steps = 0;
  std::int64_t splits = 0;
  std::int64_t merges = 0;
  std::int64_t rejected_steps = 0;  // non-finite or refused
  std::size_t peak_nodes = 0, peak_tets = 0, peak_springs = 0;
  double external_work_J = 0.0;  // work of loads and gravity on free nodes
};

class Simulation {
 public:
  // Throws std::invalid_argument if the scene cannot be built (mesh limits,
  // a probe outside the object).
  explicit Simulation(const scene::Scene& scene);

  // Advances by integrator.dt_s. On failure nothing changes and the result
  // says why.
  StepResult step();

  double time_s() const { return time_s_; }
  const Body& body() const { return body_; }
  // For setting initial conditions (velocities, a deformed start) between
  // steps. Mesh changes must go through Body::split/merge.
  Body& mutable_body() { return body_; }
  // False when the scene asked for no adaptivity: no adaptivity state exists.
  bool adaptive() const { return adaptivity_ != nullptr; }
  const SimCounters& counters() const { return counters_; }
  const scene::Scene& scene() const { return body_.scene(); }
  const Integrator& integrator() const { return *integrator_; }
  std::size_t probe_count() const { return probes_.size(); }
  const std::string& probe_name(std::size_t i) const { return probes_[i].name(); }
  Vec3 probe_displacement_m(std::size_t i) { return probes_[i].displacement_m(body_); }

  // Mesh changes from outside the adaptivity (a tool, a test): keep the
  // integrator's caches and the load shares in step with the mesh.
  int split_diamond(mesh::Key diamond);
  void merge_diamond(mesh::Key diamond);

  double kinetic_energy_J() const;
  double elastic_energy_J() const;

 private:
  Body body_;
  std::unique_ptr<Integrator> integrator_;
  std::unique_ptr<Adaptivity> adaptivity_;  // null when the scene has no adaptivity
  LoadDistribution loads_;
  void mesh_changed();

  std::vector<Probe> probes_;
  std::vector<Vec3> f_ext_N_;
  std::vector<Vec3> x_before_;
  SimCounters counters_;
  double time_s_ = 0.0;
};

}  // namespace tissue::physics
