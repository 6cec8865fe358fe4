// One simulation run of a scene: the step pipeline, readable top to bottom
// in Simulation::step():
//   kinematics (fixed/prescribed nodes) → external forces (gravity, loads)
//   → integrate (explicit | implicit | projective) → the implicit rung's
//   energy guard → work booked → adapt every K steps. Probes are read on
//   demand (probe_displacement_m), not in the step.
// Single-threaded, no I/O, deterministic: the same scene gives bit-identical
// results. Clients read the body and the statistics; only step() mutates.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
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
  bool solver_converged = true;  // see StepOutcome
  AdaptStats adapted;
};

struct SimCounters {
  std::int64_t steps = 0;
  std::int64_t splits = 0;
  std::int64_t merges = 0;
  std::int64_t refine_ceiling_passes = 0;  // adaptation passes stopped at adaptivity.max_tets
  std::int64_t rejected_steps = 0;         // non-finite or refused
  std::size_t peak_nodes = 0, peak_tets = 0, peak_springs = 0;
  double external_work_J = 0.0;  // work of loads and gravity on free nodes
  // Work the drivers of prescribed nodes did on the body: against the
  // springs and dampers at those nodes, at the end of each step (the force
  // backward Euler balances), times the step's prescribed displacement; and
  // the kinetic energy they gave their (massive) nodes.
  double prescribed_work_J = 0.0;
  // Σ over mesh changes (adaptation passes, split_diamond, merge_diamond) of
  // the change in kinetic + elastic energy they made. Springs on a changing
  // mesh are not energy-consistent: the per-type weights make each uniform
  // level isotropic, but a single face- or axis-diagonal diamond split changes
  // the energy of an affine deformation by up to ±75% of the diamond's share
  // (cube-diagonal splits too, for a normal strain mixed with a shear), and no
  // choice of per-type weights removes that; at a coarse mesh's equilibrium
  // the change is mostly an increase (README, "Energy across mesh changes").
  // So the energy the model
  // change made is kept apart from what the integrator did: a step never
  // adds energy beyond external_work_J; a mesh change adds this.
  double adaptation_energy_J = 0.0;
  double adaptation_energy_added_J = 0.0;  // the positive changes alone
  // What the integrator spent on the steps taken (the speed side of the
  // speed/accuracy knobs): explicit sub-steps, implicit CG or projective
  // local/global iterations, and the steps whose solver stopped at
  // cg_max_iterations short of cg_tolerance (the accuracy given up).
  std::int64_t substeps = 0, solver_iterations = 0;
  int max_substeps = 0, max_solver_iterations = 0;
  std::int64_t unconverged_steps = 0;
  std::int64_t offset_layout_steps = 0;     // explicit steps run on the offset layout
  std::int64_t verified_substep_steps = 0;  // explicit steps shortened by the measured deformation
  std::int64_t rerun_steps = 0;             // explicit steps run again with more sub-steps
  // Implicit steps whose end state held more energy than the state before
  // plus the work done on the body in the step, and the energy their
  // velocities gave up to remove that excess (Simulation::limit_energy).
  std::int64_t energy_limited_steps = 0;
  double energy_limited_J = 0.0;
  // Means over the steps taken (0 before the first).
  double substeps_per_step() const { return steps > 0 ? static_cast<double>(substeps) / steps : 0.0; }
  double solver_iterations_per_step() const { return steps > 0 ? static_cast<double>(solver_iterations) / steps : 0.0; }
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
  // steps. Mesh changes must go through Body::split/merge. Call it again
  // after a step before changing the state: it drops the energy the next
  // step would otherwise take from the last one. It also re-takes the
  // explicit energy bound's base from the state given (the next step is
  // checked against that state's energy, and any excess held so far is
  // forgiven), and has the explicit integrator measure r afresh (a state
  // set here moved nodes its r_rise_bound_ never saw). The daemon never
  // calls it; tests and benchmarks do.
  Body& mutable_body() {
    energy_known_ = false;
    energy_base_known_ = false;  // the explicit bound starts again from the state given
    integrator_->state_restored();
    return body_;
  }
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

  // --- Tool contact (scenes with a `tool` section; no contact state otherwise)
  bool has_tool() const { return tool_ != nullptr; }
  // The force the tool applies to the object from the next step on, shared by
  // barycentric `weights` over the touched triangle's `nodes`, its magnitude
  // clamped to tool.max_force_N. Held until changed or cleared. Returns false
  // (and applies nothing) when the scene has no tool, a node is dead, or the
  // force or a weight is non-finite: input from another thread never throws.
  bool set_tool_force(const std::array<NodeId, 3>& nodes, const std::array<double, 3>& weights, const Vec3& force_N);
  void clear_tool_force();
  // The force last applied through set_tool_force (after clamping), or zero.
  Vec3 tool_force_N() const { return tool_ && tool_->active ? tool_->force_N : Vec3::Zero(); }

  // --- Adaptation control for a real-time loop -----------------------------
  // Shedding: a loop that falls behind wall time pauses adaptation first.
  void set_adaptation_paused(bool paused) { adaptation_paused_ = paused; }
  bool adaptation_paused() const { return adaptation_paused_; }
  // Null when the scene has no adaptivity.
  Adaptivity* adaptivity() { return adaptivity_.get(); }

 private:
  struct ToolContact {
    scene::ToolSpec spec;
    bool active = false;
    std::array<NodeId, 3> nodes{};
    std::array<double, 3> weights{};
    Vec3 force_N = Vec3::Zero();
  };
  std::unique_ptr<ToolContact> tool_;  // null when the scene has no tool
  bool adaptation_paused_ = false;

  Body body_;
  std::unique_ptr<Integrator> integrator_;
  std::unique_ptr<Adaptivity> adaptivity_;  // null when the scene has no adaptivity
  LoadDistribution loads_;
  void mesh_changed();

  // Books the energy a mesh change made (adaptation_energy_J), given the
  // kinetic + elastic energy before it, and what the explicit bound counts
  // of it (mesh_change_J_).
  void book_mesh_change(double energy_before_J);
  double prescribed_kinetic_energy_J() const;  // of the prescribed nodes
  // The implicit rung's passivity guard: backward Euler linearises the
  // springs at the step's start, and where they turn far within a step (a
  // soft body under a large load at a long dt) the end state can hold more
  // energy than the start plus the work done on it (7.9x in one step),
  // or, with the CG capped at one iteration, without bound. When it does,
  // the free nodes' move is shortened until their positions fit the budget
  // and their velocities scaled down until the whole state does; counted in
  // SimCounters::energy_limited_*.
  void limit_energy(double energy_before_J, double driven_kinetic_before_J);
  // The work done on the body in the step now ending, from the state as it
  // is: the loads on free nodes, and the drivers of prescribed nodes.
  struct StepWork {
    double external_J = 0.0, prescribed_J = 0.0;
  };
  StepWork step_work(double driven_kinetic_before_J) const;
  // The explicit rung's energy bound ("within its bound or refused"):
  // symplectic Euler conserves a shadow energy O(h ω) from the true one,
  // but where its sub-steps lose accuracy (a node flung fast, a body
  // tumbling at a rate near the springs' ω) the energy grows without bound
  // although every sub-step is within the stable bound. The energy the body
  // holds is judged against what EnergyBudget (diagnostics.hpp) allows since
  // the base (construction, or the last mutable_body()), except that a mesh
  // change taking energy out of a body above its budget is booked in
  // proportion (book_mesh_change). Returns the refusal, or an empty string
  // when within integrator.explicit_energy_slack.
  std::string explicit_energy_refusal(const StepWork& work) const;
  // After a refusal, with the state before the step restored: "" when that
  // state is within the bound, else what the refusal adds to say it is not
  // (by how much, and that every retry is refused too). The bound is
  // checked once kEnergyCheckSubsteps sub-steps have run, so the state kept
  // was not checked unless the step before it was, and a gain between
  // checks leaves it over the bound; then the refusal repeats at every try
  // until the state is set afresh. Restoring the state of the last passing
  // check instead would mean rewinding time, the step count, the work
  // booked and any mesh change since (up to 31 sub-steps back, in a loop
  // others watch), for a retry that the same dynamics would most likely
  // refuse again; an energy pass on a refusal only says what holds.
  std::string kept_state_note() const;
  // The explicit bound's budget [J] with `step_work_J` of a step not yet
  // counted: base + the work since (0 while negative) + mesh_change_J_.
  double explicit_budget_J(double step_work_J) const;
  // Rebuilds prescribed_, driven_springs_ and prescribed_before_m_ from
  // kinematic_ (after a mesh or parameter change).
  void list_driven_springs();

  // A spring with a prescribed end: its ends' slots in prescribed_ (-1: not
  // prescribed), so the drivers' work needs no per-node array.
  struct DrivenSpring {
    EdgeId edge;
    std::int32_t a_slot, b_slot;
  };

  std::vector<Probe> probes_;
  std::vector<Vec3> f_ext_N_;
  std::vector<std::pair<NodeId, Vec3>> loaded_before_;  // free nodes with an external force, x before the step
  std::vector<NodeId> kinematic_;                       // fixed and prescribed nodes
  std::vector<NodeId> prescribed_;                      // the prescribed nodes of kinematic_
  std::vector<DrivenSpring> driven_springs_;            // springs with a prescribed end
  std::vector<Vec3> prescribed_before_m_;               // x of prescribed_[i] before the step
  std::vector<Vec3> kinematic_v_before_;                // v of kinematic_[i] before the step, restored on failure
  std::uint64_t kinematic_version_ = 0;                 // body parameters_version the list is for
  SimCounters counters_;
  double time_s_ = 0.0;
  // Kinetic + elastic energy of the state now, for the next step's guard;
  // computed again when a caller may have changed the state (mutable_body).
  bool limits_energy_ = false;
  bool energy_known_ = false;
  double energy_J_ = 0.0;
  // The explicit rung's bound (explicit_energy_refusal): the energy and work
  // at its base, the mesh changes' energy since as it books them
  // (book_mesh_change), and the state before a checked step, restored when
  // the step is refused (the integrator stores into the body on acceptance,
  // asking BeforeStore first; the bound is judged after). Checked once at
  // least kEnergyCheckSubsteps sub-steps have run since the last check,
  // counting the step's own: the energy
  // pass costs about one sub-step, +24-34 % on an R3 step of 3-4 checked
  // every step, a few % at this cadence (docs/scene-format.md).
  static constexpr std::int64_t kEnergyCheckSubsteps = 32;
  bool checks_explicit_energy_ = false;
  bool energy_base_known_ = false;
  double base_energy_J_ = 0.0, base_work_J_ = 0.0, mesh_change_J_ = 0.0;
  std::int64_t substeps_since_energy_check_ = 0;
  std::vector<Vec3> x_before_m_, v_before_m_per_s_;
};

}  // namespace tissue::physics
