// Numerical health of a run: the check behind "stable at the extremes"
// (NUMERICS.md §3). Pass = no non-finite state, and the body never holds more
// energy than it started with plus the work done on it (loads, gravity,
// prescribed nodes' drivers) plus the energy its mesh changes made (within
// `slack`, relative); the explicit rung may instead refuse a step it cannot
// take.
#pragma once

#include <cstddef>
#include <string>

#include "physics/simulation.hpp"

namespace tissue::physics {

// What the body may hold from a given state on: the energy it had then, plus
// the work done on it since (loads, gravity, prescribed nodes' drivers; taken
// as 0 when negative) plus what its mesh changes made since (booked apart in
// SimCounters::adaptation_energy_J: the audit judges the steps, and every
// split or merge is in the budget with the exact energy it added or took).
class EnergyBudget {
 public:
  explicit EnergyBudget(const Simulation& sim);
  double budget_J(const Simulation& sim) const;
  // E / budget − 1 for the state `sim` is in now: <= 0 while the body holds no
  // more than was put in. 0 while E is rounding noise: of a body at rest, or
  // of one so stiff that its deformation is below what its coordinates
  // resolve (E at most 1/2 Σ k (4 ε max|x|)²); +inf when E or the budget is
  // not finite (never NaN).
  double excess(const Simulation& sim) const;

 private:
  double energy0_J_, work0_J_, adaptation0_J_;
};

// EnergyBudget::excess's arithmetic for an energy and a budget already
// taken (the explicit rung's bound in Simulation::step judges the same way):
// E / budget − 1, 0 while E is rounding noise of `body`, +inf when either is
// not finite.
double energy_excess(double energy_J, double budget_J, const Body& body);

struct EnergyAudit {
  int steps_taken = 0;
  bool refused = false;  // a step was refused or rejected (see error)
  std::string error;
  bool nonfinite = false;         // a non-finite state was seen (never after a step that reported ok)
  double worst_excess = 0.0;      // max over steps of E / (E0 + W_ext + E_adapt) − 1
  std::size_t inverted_tets = 0;  // at the end
  // The energy half of a verdict: finite, and never above E0 + W_ext +
  // E_adapt by more than `slack`. A refused run can be within it; whether
  // the refusal is harmless is audit_outcome's call.
  bool within_energy_bound(double slack) const { return !nonfinite && worst_excess <= slack; }
};

// Steps `sim` up to `steps` times and audits every step.
EnergyAudit audit_steps(Simulation& sim, int steps);

// How an audited run of the stability matrix ends (bench/stability_matrix
// and its CI subset, tests/physics/stability_test.cpp, both judge by this).
enum class AuditOutcome {
  kOk,                       // every step taken, finite, within the slack
  kRefusedAboveMaxSubsteps,  // the explicit rung refused a step needing more than integrator.max_substeps
  kRefusedAboveEnergyBound,  // the explicit rung refused a step ending above integrator.explicit_energy_slack
  kFailed,                   // anything else
};
AuditOutcome audit_outcome(const EnergyAudit& audit, double slack, bool explicit_rung);

// The stability matrix's outcome column for an audited run judged at
// `slack`: "ok", "NON-FINITE" or "ENERGY-GROWTH" for a run that took every
// step; a refusal as "refused above max_substeps", "refused above its energy
// bound" or "FAILED, refused: <message>"; and when the energy had failed the
// run before it was refused, that failure first: "ENERGY-GROWTH, then
// refused above its energy bound" (or "..., then refused: <message>").
std::string audit_outcome_label(const EnergyAudit& audit, double slack, bool explicit_rung);

}  // namespace tissue::physics
