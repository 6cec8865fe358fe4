// The full stability matrix of NUMERICS.md §3 (the CI runs a subset in
// tests/physics/stability_test.cpp): every rung (implicit with each
// preconditioner) x E in {1e3, 5e4, 1e6, 1e9} Pa
// x dt in {1e-5 .. 1/30} s x depth 0..3, on a small bar under gravity with
// one end fixed. Prints one line per case and a summary; exits 1 if any case
// produced a non-finite state or gained energy without external work.
// Explicit rows say whether the run reached the tightened (Lanczos) sub-step,
// which a mesh gets after ~300-400 sub-steps unchanged: more --steps reach it
// at the small dt too.
//
//   ./build/release/bench/stability_matrix [--steps N]
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "physics/diagnostics.hpp"
#include "physics/integrator_impl.hpp"

using namespace tissue;

int main(int argc, char** argv) {
  int steps = 100;
  for (int i = 1; i + 1 < argc; ++i)
    if (std::strcmp(argv[i], "--steps") == 0) steps = std::atoi(argv[i + 1]);
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
          const char* outcome =
              a.nonfinite ? "NON-FINITE" : (a.worst_excess > slack ? "ENERGY-GROWTH" : (a.refused ? "refused" : "ok"));
          ++cases;
          if (a.nonfinite || a.worst_excess > slack)
            ++failed;
          else if (a.refused)
            ++refused;
          else
            ++passed;
          const auto* explicit_rung = dynamic_cast<const physics::ExplicitIntegrator*>(&sim.integrator());
          const bool tight = explicit_rung && explicit_rung->tightened();
          tightened += tight;
          std::printf("%-10s %8.0e %9.2e %5d %6d %10.2e %8zu %5s %s\n", names[k], youngs, dt, depth, a.steps_taken,
                      a.worst_excess, a.inverted_tets, explicit_rung ? (tight ? "yes" : "no") : "-", outcome);
        }
  std::printf(
      "\n%d cases: %d ok, %d refused (explicit above max_substeps), %d failed; %d explicit runs reached "
      "the tightened sub-step\n",
      cases, passed, refused, failed, tightened);
  return failed == 0 ? 0 : 1;
}
