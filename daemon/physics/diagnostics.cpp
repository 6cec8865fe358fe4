#include "physics/diagnostics.hpp"

#include <algorithm>

#include "physics/forces.hpp"
#include "physics/integrator.hpp"

namespace tissue::physics {

EnergyAudit audit_steps(Simulation& sim, int steps) {
  EnergyAudit audit;
  const double e0 = sim.kinetic_energy_J() + sim.elastic_energy_J();
  const auto work_J = [&] { return sim.counters().external_work_J + sim.counters().prescribed_work_J; };
  const double w0 = work_J(), a0 = sim.counters().adaptation_energy_J;
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
    // What mesh changes made is booked apart (SimCounters::adaptation_energy_J):
    // the audit judges the steps, and every split or merge is in the budget
    // with the exact energy it added or took away.
    const double budget = e0 + std::max(0.0, work_J() - w0) + (sim.counters().adaptation_energy_J - a0);
    const double energy = sim.kinetic_energy_J() + sim.elastic_energy_J();
    // 1e-15 J: below that, energies are rounding noise of an almost-rest state.
    if (energy > 1e-15) audit.worst_excess = std::max(audit.worst_excess, energy / std::max(budget, 1e-15) - 1.0);
  }
  audit.inverted_tets = inverted_tet_count(sim.body());
  return audit;
}

}  // namespace tissue::physics
