#include "physics/diagnostics.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "physics/forces.hpp"
#include "physics/integrator.hpp"

namespace tissue::physics {

namespace {
double work_J(const Simulation& sim) { return sim.counters().external_work_J + sim.counters().prescribed_work_J; }
double energy_J(const Simulation& sim) { return sim.kinetic_energy_J() + sim.elastic_energy_J(); }

// The elastic energy a body holds when every spring's stretch is rounding
// alone: a stretch is |x_b - x_a| - L over coordinates of magnitude up to X,
// so a few units of X's last place, 4 eps X, come with it, and the springs
// hold 1/2 sum k (4 eps X)^2. A body stiff enough that its loads strain it
// less than that (the cantilever's 5 N at E = 1.8e19 Pa: 1e-17 m against
// coordinates of 0.1 m) holds that much energy whatever the integrator does,
// and it is noise, not a gain: at E = 1e9 Pa it is 1e-22 J against 1e-6 J.
double rounding_energy_J(const Body& body) {
  double extent_m = 0.0, stiffness_N_per_m = 0.0;
  for (const Vec3& x : body.x_m) extent_m = std::max(extent_m, x.cwiseAbs().maxCoeff());
  for (const double k : body.stiffness_N_per_m) stiffness_N_per_m += k;
  const double stretch_m = 4.0 * std::numeric_limits<double>::epsilon() * extent_m;
  return 0.5 * stiffness_N_per_m * stretch_m * stretch_m;
}
}  // namespace

EnergyBudget::EnergyBudget(const Simulation& sim)
    : energy0_J_(energy_J(sim)), work0_J_(work_J(sim)), adaptation0_J_(sim.counters().adaptation_energy_J) {}

double EnergyBudget::budget_J(const Simulation& sim) const {
  return energy0_J_ + std::max(0.0, work_J(sim) - work0_J_) + (sim.counters().adaptation_energy_J - adaptation0_J_);
}

double EnergyBudget::excess(const Simulation& sim) const {
  return energy_excess(energy_J(sim), budget_J(sim), sim.body());
}

double energy_excess(double energy, double budget, const Body& body) {
  // A non-finite energy or budget (an infinite mass, a NaN work) says nothing
  // is within bound: a NaN would read as "no excess" below, and std::max and
  // `>` drop it where the worst excess is kept.
  if (!std::isfinite(energy) || !std::isfinite(budget)) return std::numeric_limits<double>::infinity();
  // Below 1e-15 J, or below what rounding alone puts in the springs,
  // energies are noise of an almost-rest state or of a deformation smaller
  // than the coordinates resolve. The rounding floor is a pass over every
  // node and spring (batch runs check after every step), so it is summed
  // only for an energy above its budget: below, there is no gain to excuse.
  constexpr double kRestNoise_J = 1e-15;
  if (!(energy > kRestNoise_J)) return 0.0;
  if (energy <= budget) return energy / std::max(budget, kRestNoise_J) - 1.0;
  const double noise_J = std::max(kRestNoise_J, rounding_energy_J(body));
  return energy > noise_J ? energy / std::max(budget, noise_J) - 1.0 : 0.0;
}

EnergyAudit audit_steps(Simulation& sim, int steps) {
  EnergyAudit audit;
  const EnergyBudget budget(sim);
  for (int i = 0; i < steps; ++i) {
    const StepResult r = sim.step();
    if (!r.ok) {
      audit.refused = true;
      audit.error = r.error;
      break;
    }
    ++audit.steps_taken;
    if (!state_is_finite(sim.body())) {
      audit.nonfinite = true;
      break;
    }
    // Written so that a NaN excess would be kept, not dropped as std::max does.
    if (const double excess = budget.excess(sim); !(excess <= audit.worst_excess)) audit.worst_excess = excess;
  }
  audit.inverted_tets = inverted_tet_count(sim.body());
  return audit;
}

namespace {

// What a refusal of an audited run was, apart from the energy: the explicit
// rung's documented limits, or a fault (kFailed).
AuditOutcome refusal_outcome(const EnergyAudit& audit, bool explicit_rung) {
  // Every integrator rejects a non-finite step and keeps the old state: a
  // blow-up arrives here as a refusal, never as a non-finite state. The
  // explicit rung's refusals above its cap name the key (the step needs more
  // sub-steps, or a collapsing spring no stable sub-step within it).
  if (!explicit_rung) return AuditOutcome::kFailed;
  if (audit.error.find("integrator.max_substeps") != std::string::npos) return AuditOutcome::kRefusedAboveMaxSubsteps;
  // Its energy bound ("within its bound or refused"): the step that would
  // have ended above it was refused (Simulation::step).
  if (audit.error.find("integrator.explicit_energy_slack") != std::string::npos)
    return AuditOutcome::kRefusedAboveEnergyBound;
  return AuditOutcome::kFailed;
}

}  // namespace

AuditOutcome audit_outcome(const EnergyAudit& audit, double slack, bool explicit_rung) {
  if (!audit.within_energy_bound(slack)) return AuditOutcome::kFailed;
  return audit.refused ? refusal_outcome(audit, explicit_rung) : AuditOutcome::kOk;
}

std::string audit_outcome_label(const EnergyAudit& audit, double slack, bool explicit_rung) {
  // What failed the case comes first. The matrix's slack for the explicit
  // rung (0.05) is far below the bound at which the rung refuses (its
  // integrator.explicit_energy_slack, 1), and energy grows over many steps:
  // a run refused at that bound has nearly always exceeded the slack on an
  // accepted step before, and that growth is the failure, not the refusal.
  // !(<=): a NaN excess is not within the slack (audit_outcome fails it).
  const std::string energy = audit.nonfinite ? "NON-FINITE" : !(audit.worst_excess <= slack) ? "ENERGY-GROWTH" : "";
  if (!audit.refused) return energy.empty() ? "ok" : energy;
  const AuditOutcome refusal = refusal_outcome(audit, explicit_rung);
  // A fault's message says what broke (e.g. a rejected non-finite step).
  const std::string refused = refusal == AuditOutcome::kRefusedAboveEnergyBound   ? "refused above its energy bound"
                              : refusal == AuditOutcome::kRefusedAboveMaxSubsteps ? "refused above max_substeps"
                                                                                  : "refused: " + audit.error;
  if (!energy.empty()) return energy + ", then " + refused;
  return refusal == AuditOutcome::kFailed ? "FAILED, " + refused : refused;
}

}  // namespace tissue::physics
