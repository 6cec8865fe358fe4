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

struct EnergyAudit {
  int steps_taken = 0;
  bool refused = false;  // a step was refused or rejected (see error)
  std::string error;
  bool nonfinite = false;         // a non-finite state was seen (never after a step that reported ok)
  double worst_excess = 0.0;      // max over steps of E / (E0 + W_ext + E_adapt) − 1
  std::size_t inverted_tets = 0;  // at the end
  bool passed(double slack) const { return !nonfinite && worst_excess <= slack; }
};

// Steps `sim` up to `steps` times and audits every step.
EnergyAudit audit_steps(Simulation& sim, int steps);

}  // namespace tissue::physics
