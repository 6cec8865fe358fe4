// The full stability matrix of NUMERICS.md §3 (the CI runs a subset in
// tests/physics/stability_test.cpp): every rung (implicit with each
// preconditioner) x E in {1e3, 5e4, 1e6, 1e9} Pa
// x dt in {1e-5 .. 1/30} s x depth 0..3, on a small bar under gravity with
// one end fixed. Prints one line per case and a summary; exits 1 if any case
// failed (physics::audit_outcome): a non-finite state, energy gained without
// external work, or a refusal other than the explicit rung's above
// integrator.max_substeps (every integrator rejects a non-finite step and
// keeps the state, so a blow-up shows as a refusal: its message is printed).
// A run whose energy grew past the slack and was refused after is labelled
// by the growth first ("ENERGY-GROWTH, then refused above its energy
// bound"): the explicit rung refuses only far above the matrix's 0.05.
// Explicit rows say whether the run reached the tightened (Lanczos) sub-step,
// which a mesh gets after ~300-400 sub-steps unchanged: more --steps reach it
// at the small dt too.
//
//   ./build/release/bench/stability_matrix [--steps N]   (N > 0, default 100)
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "physics/diagnostics.hpp"
#include "physics/integrator_impl.hpp"

using namespace tissue;

namespace {

// The whole of `text` as an integer in [1, 1e9]; 0 if it is not one.
int positive_steps(const char* text) {
  char* end = nullptr;
  const long v = std::strtol(text, &end, 10);
  return end != text && *end == '\0' && v >= 1 && v <= 1000000000 ? static_cast<int>(v) : 0;
}

}  // namespace

int main(int argc, char** argv) {
  int steps = 100;
  for (int i = 1; i < argc; ++i) {
    const bool is_steps = std::strcmp(argv[i], "--steps") == 0;
    if (is_steps && i + 1 < argc && (steps = positive_steps(argv[i + 1])) > 0) {
      ++i;
      continue;
    }
    if (is_steps)  // atoi read "--steps x" as 0 steps: every case "ok"
      std::fprintf(stderr, "%s: --steps %s: must be a whole number of steps >= 1\n", argv[0],
                   i + 1 < argc ? argv[i + 1] : "(no value)");
    else
      std::fprintf(stderr, "%s: unknown argument %s; usage: %s [--steps N]\n", argv[0], argv[i], argv[0]);
    return 2;
  }
  // Implicit once per preconditioner: these bars stay below the 1,000 free
  // nodes from which the default (auto) takes two-level, so it is asked for.
  // Explicit once per precision (integrator.explicit_precision).
  const scene::IntegratorKind kinds[] = {scene::IntegratorKind::kExplicit, scene::IntegratorKind::kExplicit,
                                         scene::IntegratorKind::kImplicit, scene::IntegratorKind::kImplicit,
                                         scene::IntegratorKind::kProjective};
  const scene::CgPreconditioner preconditioners[] = {
      scene::CgPreconditioner::kAuto, scene::CgPreconditioner::kAuto, scene::CgPreconditioner::kJacobi,
      scene::CgPreconditioner::kTwoLevel, scene::CgPreconditioner::kAuto};
  const char* names[] = {"explicit", "expl-f32", "implicit", "impl-2lvl", "projective"};
  int cases = 0, passed = 0, refused = 0, failed = 0;
  std::printf("%-10s %8s %9s %5s %6s %10s %8s %5s %s\n", "rung", "E_Pa", "dt_s", "depth", "steps", "excess", "inverted",
              "tight", "outcome");
  int tightened = 0;
  for (int k = 0; k < 5; ++k)
    for (double youngs : {1e3, 5e4, 1e6, 1e9})
      for (double dt : {1e-5, 1e-4, 1e-3, 1e-2, 1.0 / 30})
        for (int depth = 0; depth <= 3; ++depth) {
          scene::Scene s;
          s.object.cubes = {2, 1, 1};
          s.object.cube_size_m = 0.05;
          s.material.youngs_modulus_Pa = youngs;
          s.gravity_m_per_s2 = {0, 0, -9.81};
          s.fixed.push_back({scene::Region::box({0, 0, 0}, {0, 0.05, 0.05})});
          s.adaptivity.min_depth = depth;
          s.integrator.kind = kinds[k];
          s.integrator.cg_preconditioner = preconditioners[k];
          if (k == 1) s.integrator.explicit_precision = scene::ExplicitPrecision::kFloat;
          s.integrator.dt_s = dt;
          physics::Simulation sim(s);
          const physics::EnergyAudit a = physics::audit_steps(sim, steps);
          const double slack = k <= 1 ? 0.05 : 1e-6;
          const physics::AuditOutcome verdict = physics::audit_outcome(a, slack, k <= 1);
          const std::string outcome = physics::audit_outcome_label(a, slack, k <= 1);
          ++cases;
          if (verdict == physics::AuditOutcome::kFailed)
            ++failed;
          else if (verdict == physics::AuditOutcome::kRefusedAboveMaxSubsteps ||
                   verdict == physics::AuditOutcome::kRefusedAboveEnergyBound)
            ++refused;
          else
            ++passed;
          const auto* explicit_rung = dynamic_cast<const physics::ExplicitIntegrator*>(&sim.integrator());
          const bool tight = explicit_rung && explicit_rung->tightened();
          tightened += tight;
          std::printf("%-10s %8.0e %9.2e %5d %6d %10.2e %8zu %5s %s\n", names[k], youngs, dt, depth, a.steps_taken,
                      a.worst_excess, a.inverted_tets, explicit_rung ? (tight ? "yes" : "no") : "-", outcome.c_str());
        }
  std::printf(
      "\n%d cases (%d steps each): %d ok, %d refused (explicit above max_substeps or its energy bound), %d failed; %d "
      "explicit runs "
      "reached the tightened sub-step\n",
      cases, steps, passed, refused, failed, tightened);
  return failed == 0 ? 0 : 1;
}
