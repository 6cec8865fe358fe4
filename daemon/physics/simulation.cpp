#include "physics/simulation.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "physics/diagnostics.hpp"
#include "physics/forces.hpp"

namespace tissue::physics {

Simulation::Simulation(const scene::Scene& scene)
    : body_(scene), integrator_(make_integrator(scene.integrator, scene.material)) {
  if (scene.adaptivity.enabled) adaptivity_ = std::make_unique<Adaptivity>(scene.adaptivity);
  if (scene.tool) {
    tool_ = std::make_unique<ToolContact>();
    tool_->spec = *scene.tool;
  }
  loads_.rebuild(body_);
  // The object's box as the mesh holds it (from the origin to its far corner).
  Vec3 box_max_m = Vec3::Zero();
  body_.mesh().for_each_node([&](NodeId n, const mesh::Node&) { box_max_m = box_max_m.cwiseMax(body_.rest_m[n]); });
  // Twice the check's room (probes.hpp): every probe the check accepts is moved.
  const double rounding_m = 2.0 * kProbeOutsideBoxTolerance * box_max_m.maxCoeff();
  for (std::size_t i = 0; i < scene.probes.size(); ++i) {
    const scene::ProbeSpec& p = scene.probes[i];
    // The scene check lets a probe lie outside the box by rounding (up to
    // kProbeOutsideBoxTolerance of its size). Locating it needs it inside to within a fraction of the
    // containing tet, which refinement makes as small as 2^-10 of a cube: a
    // probe 0.5 nm past a 512 mm object was refused at min_depth 6, or
    // aborted the run when refinement reached it. Such a point is moved
    // onto the box; one farther out is left for locate to refuse.
    Vec3 rest_m(p.rest_m[0], p.rest_m[1], p.rest_m[2]);
    for (int a = 0; a < 3; ++a)
      if (rest_m[a] >= -rounding_m && rest_m[a] <= box_max_m[a] + rounding_m)
        rest_m[a] = std::clamp(rest_m[a], 0.0, box_max_m[a]);
    probes_.emplace_back(p.name, rest_m);
    try {
      probes_.back().displacement_m(body_);  // locates it now: a bad probe fails at load time
    } catch (const std::invalid_argument& e) {
      throw scene::SceneModelError("probes[" + std::to_string(i) + "].rest_m", e.what());
    }
  }
  limits_energy_ = scene.integrator.kind == scene::IntegratorKind::kImplicit;
  checks_explicit_energy_ = scene.integrator.kind == scene::IntegratorKind::kExplicit;
  counters_.peak_nodes = body_.mesh().node_count();
  counters_.peak_tets = body_.mesh().tet_count();
  counters_.peak_springs = body_.mesh().edge_count();
}

void Simulation::book_mesh_change(double energy_before_J) {
  energy_J_ = kinetic_energy_J() + elastic_energy_J();
  energy_known_ = true;
  const double change_J = energy_J_ - energy_before_J;
  counters_.adaptation_energy_J += change_J;
  if (change_J > 0.0) counters_.adaptation_energy_added_J += change_J;
  // The explicit bound judges E / budget against the slack. A change that
  // takes energy out of a body holding more than its budget (the
  // integrator's gain, unchecked between checks or within the slack) takes
  // it from the budget and the excess alike. Booked in full against the
  // budget, the excess in joules stayed over a budget shrunk toward 0 (below
  // it when the change took more than the budget): a body 0.9 over before a
  // merge was 2.54 over after it (Simulation.AMergeNeitherForgives...), and
  // with slack 1 every later step was refused for good. So such a change is
  // booked in proportion, change × budget / E before: E / budget stays what
  // it was, the excess neither magnified nor forgiven. Not clamped at the
  // energy the change left (budget >= E after): that forgave the whole
  // excess at every merging pass, so a gain the checks let through (up to
  // the slack each time) could grow without bound across passes. A change
  // that adds energy, or takes it from a body within its budget, is booked
  // in full, as in adaptation_energy_J: the budget's room over the energy
  // stays what it was. (The batch audit, EnergyBudget, books every change
  // in full: it measures the excess, it refuses nothing.)
  if (checks_explicit_energy_ && energy_base_known_) {
    const double budget_J = explicit_budget_J(0.0);
    // A budget below 0 (only a gain and work given back reach it) is not lowered further.
    mesh_change_J_ += change_J < 0.0 && energy_before_J > budget_J
                          ? change_J * (std::max(0.0, budget_J) / energy_before_J)
                          : change_J;
  }
}

double Simulation::explicit_budget_J(double step_work_J) const {
  const double work_J = counters_.external_work_J + counters_.prescribed_work_J + step_work_J - base_work_J_;
  // As EnergyBudget::budget_J, the work taken as 0 while negative; the mesh
  // changes as book_mesh_change counts them for this bound.
  return base_energy_J_ + std::max(0.0, work_J) + mesh_change_J_;
}

StepResult Simulation::step() {
  StepResult result;
  const double dt = scene().integrator.dt_s;
  // The step count times dt, not a running sum: a sum drifts (0.1 summed
  // eight times is 0.7999999999999999), so a profile edge at an exact step
  // time would be crossed a step late. Refused steps do not count.
  const double t_next = static_cast<double>(counters_.steps + 1) * dt;

  if (kinematic_version_ != body_.parameters_version()) {
    kinematic_nodes(body_, kinematic_);
    kinematic_version_ = body_.parameters_version();
    loaded_before_.reserve(body_.x_m.size());  // no allocation in the steps until the next mesh change
    list_driven_springs();
    kinematic_v_before_.resize(kinematic_.size());  // a mesh change's allocation, not a step's
  }
  // The energy the step starts from, for the implicit rung's guard: taken
  // before the drivers set this step's velocities, as the cached value from
  // the last step was (their kinetic energy change is in the step's work).
  if (limits_energy_ && !energy_known_) energy_J_ = kinetic_energy_J() + elastic_energy_J();
  const double energy_before_J = energy_J_;
  // The explicit bound's base: the state as built or as a caller last set it.
  if (checks_explicit_energy_ && !energy_base_known_) {
    base_energy_J_ = kinetic_energy_J() + elastic_energy_J();
    base_work_J_ = counters_.external_work_J + counters_.prescribed_work_J;
    mesh_change_J_ = 0.0;
    energy_base_known_ = true;
    substeps_since_energy_check_ = kEnergyCheckSubsteps;  // the first step is checked
  }
  // A driver also gives its node the velocity of the track (kinematic nodes
  // keep their mass): that kinetic energy is its work too.
  const double driven_kinetic_before_J = prescribed_kinetic_energy_J();
  // Kept so that a refused or rejected step leaves the drivers' velocities
  // as they were ("on failure nothing changes").
  for (std::size_t i = 0; i < kinematic_.size(); ++i) kinematic_v_before_[i] = body_.v_m_per_s[kinematic_[i]];
  set_kinematic_velocities(body_, kinematic_, t_next, dt);
  for (std::size_t i = 0; i < prescribed_.size(); ++i) prescribed_before_m_[i] = body_.x_m[prescribed_[i]];
  loads_.external_forces(body_, t_next, f_ext_N_);
  if (tool_ && tool_->active)
    for (int i = 0; i < 3; ++i) f_ext_N_[tool_->nodes[i]] += tool_->weights[i] * tool_->force_N;
  // The external work needs the positions before the step of the free nodes
  // a force acts on only (a tip load: a few dozen nodes of thousands).
  loaded_before_.clear();
  for (std::size_t n = 0; n < f_ext_N_.size(); ++n)
    if (body_.inv_mass_per_kg[n] != 0.0 && !f_ext_N_[n].isZero(0.0))
      loaded_before_.push_back({static_cast<NodeId>(n), body_.x_m[n]});

  // Whether the step is checked is known once its sub-steps have run (they
  // bring those since the last check to kEnergyCheckSubsteps), so the rung
  // asks before it writes the body: the state the step started from is
  // kept then for a checked step only, and a step taking far more sub-steps
  // than the last (a rerun, a collapsing spring) is checked too.
  struct KeepIfChecked final : BeforeStore {
    Simulation& sim;
    bool kept = false;
    explicit KeepIfChecked(Simulation& s) : sim(s) {}
    void before_store(const Body& body, int substeps) override {
      if (sim.substeps_since_energy_check_ + substeps < kEnergyCheckSubsteps) return;
      sim.x_before_m_.assign(body.x_m.begin(), body.x_m.end());
      sim.v_before_m_per_s_.assign(body.v_m_per_s.begin(), body.v_m_per_s.end());
      kept = true;
    }
  } keep_if_checked(*this);
  // Cleared however the step ends: the hook lives in this frame.
  struct ClearHook {
    Integrator& integrator;
    ~ClearHook() { integrator.set_before_store(nullptr); }
  } clear_hook{*integrator_};
  integrator_->set_before_store(checks_explicit_energy_ ? &keep_if_checked : nullptr);
  const StepOutcome out = integrator_->step(body_, f_ext_N_, dt);
  result.substeps = out.substeps;
  result.solver_iterations = out.solver_iterations;
  result.solver_residual = out.solver_residual;
  result.solver_converged = out.solver_converged;
  if (!out.ok) {
    result.ok = false;
    result.error = out.error;
    ++counters_.rejected_steps;
    for (std::size_t i = 0; i < kinematic_.size(); ++i) body_.v_m_per_s[kinematic_[i]] = kinematic_v_before_[i];
    energy_known_ = false;  // taken again from the restored state, to be safe
    return result;
  }
  if (limits_energy_) limit_energy(energy_before_J, driven_kinetic_before_J);
  const StepWork work = step_work(driven_kinetic_before_J);
  if (checks_explicit_energy_) substeps_since_energy_check_ += out.substeps;
  if (checks_explicit_energy_ && substeps_since_energy_check_ >= kEnergyCheckSubsteps) {
    // The rung asks before it stores (ExplicitIntegrator::store, the same
    // count decides both), so a checked step always has its state kept; a
    // rung that did not could not be restored: a programming error.
    if (!keep_if_checked.kept)
      throw std::logic_error("Simulation::step: the explicit rung stored a checked step without keeping its state");
    substeps_since_energy_check_ = 0;
    if (std::string refusal = explicit_energy_refusal(work); !refusal.empty()) {
      result.ok = false;
      result.error = std::move(refusal);
      ++counters_.rejected_steps;
      // The step asked again is checked again: the state kept is where the
      // last refusal came from, not one known to be within the bound.
      substeps_since_energy_check_ = kEnergyCheckSubsteps;
      std::copy(x_before_m_.begin(), x_before_m_.end(), body_.x_m.begin());
      std::copy(v_before_m_per_s_.begin(), v_before_m_per_s_.end(), body_.v_m_per_s.begin());
      // Kept after the drivers set this step's velocities: theirs as before.
      for (std::size_t i = 0; i < kinematic_.size(); ++i) body_.v_m_per_s[kinematic_[i]] = kinematic_v_before_[i];
      integrator_->state_restored();  // r and its growth were of the refused state
      energy_known_ = false;
      result.error += kept_state_note();
      return result;
    }
  }
  counters_.external_work_J += work.external_J;
  counters_.prescribed_work_J += work.prescribed_J;

  counters_.substeps += out.substeps;
  counters_.max_substeps = std::max(counters_.max_substeps, out.substeps);
  counters_.solver_iterations += out.solver_iterations;
  counters_.max_solver_iterations = std::max(counters_.max_solver_iterations, out.solver_iterations);
  if (!out.solver_converged) ++counters_.unconverged_steps;
  if (out.offset_layout) ++counters_.offset_layout_steps;
  if (out.verified_substeps) ++counters_.verified_substep_steps;
  if (out.rerun) ++counters_.rerun_steps;

  time_s_ = t_next;
  ++counters_.steps;
  body_.step_index = counters_.steps;

  if (adaptivity_ && !adaptation_paused_ && counters_.steps % scene().adaptivity.every_steps == 0) {
    // The pass measures the elastic energy before it changes anything; the
    // energy after is summed only when it did change something.
    const double kinetic_before_J = kinetic_energy_J();
    result.adapted = adaptivity_->adapt(body_);
    counters_.splits += result.adapted.splits;
    counters_.merges += result.adapted.merges;
    if (result.adapted.ceiling_reached) ++counters_.refine_ceiling_passes;
    if (result.adapted.splits + result.adapted.merges > 0) {
      book_mesh_change(kinetic_before_J + result.adapted.elastic_energy_before_J);
      mesh_changed();
    }
  }
  return result;
}

Simulation::StepWork Simulation::step_work(double driven_kinetic_before_J) const {
  StepWork work;
  for (const auto& [n, x_before] : loaded_before_) work.external_J += f_ext_N_[n].dot(body_.x_m[n] - x_before);
  // A driver holds its node on the track against the springs and dampers
  // there: it pushes with minus their force.
  work.prescribed_J = prescribed_kinetic_energy_J() - driven_kinetic_before_J;
  for (const DrivenSpring& d : driven_springs_) {
    const Vec3 on_a_N = spring_force_on_a_N(body_, d.edge);
    if (d.a_slot >= 0)
      work.prescribed_J -= on_a_N.dot(body_.x_m[body_.edge_a[d.edge]] - prescribed_before_m_[d.a_slot]);
    if (d.b_slot >= 0)
      work.prescribed_J += on_a_N.dot(body_.x_m[body_.edge_b[d.edge]] - prescribed_before_m_[d.b_slot]);
  }
  return work;
}

std::string Simulation::explicit_energy_refusal(const StepWork& work) const {
  const double energy_J = kinetic_energy_J() + elastic_energy_J();
  const double budget_J = explicit_budget_J(work.external_J + work.prescribed_J);
  const double excess = energy_excess(energy_J, budget_J, body_);
  const double slack = scene().integrator.explicit_energy_slack;
  if (excess <= slack) return {};  // a NaN excess (never given: +inf instead) would be refused too
  std::ostringstream os;
  os.precision(3);
  os << "explicit integrator: energy " << energy_J << " J is " << 100.0 * excess << " % above its budget " << budget_J
     << " J (start + work + mesh changes), more than integrator.explicit_energy_slack = " << slack
     << " allows; step refused, previous state kept: lower integrator.substep_safety, add damping "
     << "(material.rayleigh_beta_s) or use the implicit integrator";
  return os.str();
}

std::string Simulation::kept_state_note() const {
  // The work and mesh changes up to the state kept: the refused step's work
  // was never counted, and no mesh change comes between the two.
  const double energy_J = kinetic_energy_J() + elastic_energy_J();
  const double budget_J = explicit_budget_J(0.0);
  const double excess = energy_excess(energy_J, budget_J, body_);
  if (excess <= scene().integrator.explicit_energy_slack) return {};
  std::ostringstream os;
  os.precision(3);
  os << "; the state kept is itself " << 100.0 * excess << " % above its budget (gained between checks, once "
     << kEnergyCheckSubsteps << " sub-steps have run), so every retry is refused too: start the scene afresh "
     << "(set, reset, load_scene or reload)";
  return os.str();
}

void Simulation::limit_energy(double energy_before_J, double driven_kinetic_before_J) {
  double kinetic_free_J = 0.0, kinetic_kinematic_J = 0.0;
  body_.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
    const double e = 0.5 * body_.mass_kg[n] * body_.v_m_per_s[n].squaredNorm();
    (body_.inv_mass_per_kg[n] != 0.0 ? kinetic_free_J : kinetic_kinematic_J) += e;
  });
  // What the body may hold at the end of the step, with room for rounding:
  // a step that dissipates nothing (an undamped body at rest, a rigid drift)
  // must not be touched.
  const auto budget_J = [&] {
    const StepWork w = step_work(driven_kinetic_before_J);
    const double work_J = w.external_J + w.prescribed_J;
    return energy_before_J + work_J + 1e-9 * std::max(std::abs(energy_before_J), std::abs(work_J)) + 1e-18;
  };
  double elastic_J = elastic_energy_J();
  energy_J_ = elastic_J + kinetic_free_J + kinetic_kinematic_J;
  energy_known_ = true;
  double budget = budget_J();
  if (!(energy_J_ > budget)) return;
  // Backward Euler moved each free node by h v. Where the excess is elastic
  // (the springs turned far within the step), shorten that move to θ h v,
  // θ halved until the positions fit the budget, down to θ = 0 (the free
  // nodes stay where they were; the kinematic ones follow their track).
  const double h = scene().integrator.dt_s;
  double theta = 1.0;
  const auto move_to = [&](double to) {  // the free nodes at θ h v from where they started
    const double by_s = (to - theta) * h;
    body_.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
      if (body_.inv_mass_per_kg[n] != 0.0) body_.x_m[n] += by_s * body_.v_m_per_s[n];
    });
    theta = to;
    elastic_J = elastic_energy_J();
    budget = budget_J();
  };
  const auto fits = [&] { return elastic_J + kinetic_kinematic_J <= budget; };
  double too_far = 1.0;  // the smallest θ known not to fit
  while (!fits() && theta > 0.0) {
    too_far = theta;
    move_to(theta > 1.0 / 1024 ? 0.5 * theta : 0.0);
  }
  // Halving finds a θ that fits within a factor of two; bisecting towards
  // the one that did not keeps the move (and the energy taken out) close to
  // what the budget allows (halving alone left one step 55 % under it).
  if (theta < too_far)
    for (int i = 0; i < 8; ++i) {
      const double fitting = theta, mid = 0.5 * (theta + too_far);
      move_to(mid);
      if (!fits()) {
        too_far = mid;
        move_to(fitting);
      }
    }
  // Velocities follow θ, then shrink until the kinetic energy fits the room
  // left. The drivers' work depends on the dampers at their nodes, hence on
  // these velocities: the budget is taken again after each scaling (twice is
  // enough for it to settle; a third pass changes nothing measurable).
  double scale = 1.0;  // applied so far to the free nodes' velocities
  for (int pass = 0; pass < 3; ++pass) {
    const double room_J = std::max(0.0, budget - elastic_J - kinetic_kinematic_J);
    const double held_J = scale * scale * kinetic_free_J;
    double next = pass == 0 ? theta : 1.0;
    if (next * next * held_J > room_J) next = held_J > 0.0 ? std::sqrt(room_J / held_J) : 0.0;
    if (next == 1.0) break;
    body_.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
      if (body_.inv_mass_per_kg[n] != 0.0) body_.v_m_per_s[n] *= next;
    });
    scale *= next;
    budget = budget_J();
  }
  const double energy_J = elastic_J + kinetic_kinematic_J + scale * scale * kinetic_free_J;
  ++counters_.energy_limited_steps;
  counters_.energy_limited_J += energy_J_ - energy_J;
  energy_J_ = energy_J;
}

double Simulation::prescribed_kinetic_energy_J() const {
  double energy_J = 0.0;
  for (const NodeId n : prescribed_) energy_J += 0.5 * body_.mass_kg[n] * body_.v_m_per_s[n].squaredNorm();
  return energy_J;
}

void Simulation::list_driven_springs() {
  prescribed_.clear();
  for (const NodeId n : kinematic_)
    if (body_.kind[n] == NodeKind::kPrescribed) prescribed_.push_back(n);
  prescribed_before_m_.resize(prescribed_.size());
  driven_springs_.clear();
  if (prescribed_.empty()) return;
  // Slots by node for the edge walk; a mesh change's cost, not a step's.
  std::vector<std::int32_t> slot(body_.x_m.size(), -1);
  for (std::size_t i = 0; i < prescribed_.size(); ++i) slot[prescribed_[i]] = static_cast<std::int32_t>(i);
  body_.mesh().for_each_edge([&](EdgeId e, const mesh::Edge& edge) {
    if (slot[edge.a] >= 0 || slot[edge.b] >= 0) driven_springs_.push_back({e, slot[edge.a], slot[edge.b]});
  });
}

void Simulation::mesh_changed() {
  integrator_->mesh_changed();
  // A node the tool pushed on merged away: release rather than push a reused id.
  if (tool_ && tool_->active)
    for (NodeId n : tool_->nodes)
      if (!body_.mesh().node_alive(n)) tool_->active = false;
  loads_.rebuild(body_);
  counters_.peak_nodes = std::max(counters_.peak_nodes, body_.mesh().node_count());
  counters_.peak_tets = std::max(counters_.peak_tets, body_.mesh().tet_count());
  counters_.peak_springs = std::max(counters_.peak_springs, body_.mesh().edge_count());
}

int Simulation::split_diamond(mesh::Key diamond) {
  const double before_J = kinetic_energy_J() + elastic_energy_J();
  const int n = body_.split(diamond);
  if (n > 0) book_mesh_change(before_J);
  counters_.splits += n;
  if (n > 0) mesh_changed();
  return n;
}

void Simulation::merge_diamond(mesh::Key diamond) {
  const double before_J = kinetic_energy_J() + elastic_energy_J();
  body_.merge(diamond);
  book_mesh_change(before_J);
  ++counters_.merges;
  mesh_changed();
}

bool Simulation::set_tool_force(const std::array<NodeId, 3>& nodes, const std::array<double, 3>& weights,
                                const Vec3& force_N) {
  if (!tool_) return false;
  if (!force_N.allFinite()) return false;
  double weight_sum = 0.0;
  for (int i = 0; i < 3; ++i) {
    if (!body_.mesh().node_alive(nodes[i]) || !std::isfinite(weights[i]) || weights[i] < 0.0) return false;
    weight_sum += weights[i];
  }
  if (!(weight_sum > 0.0)) return false;
  const double max_N = tool_->spec.max_force_N, norm = force_N.norm();
  tool_->nodes = nodes;
  for (int i = 0; i < 3; ++i) tool_->weights[i] = weights[i] / weight_sum;  // the whole force, no more
  tool_->force_N = norm > max_N ? Vec3(force_N * (max_N / norm)) : force_N;
  tool_->active = true;
  return true;
}

void Simulation::clear_tool_force() {
  if (tool_) tool_->active = false;
}

double Simulation::kinetic_energy_J() const { return physics::kinetic_energy_J(body_); }
double Simulation::elastic_energy_J() const { return physics::elastic_energy_J(body_); }

}  // namespace tissue::physics
