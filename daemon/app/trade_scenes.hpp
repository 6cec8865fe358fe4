// The trade study's built-in scenes (built in code, SI units) and the mesh
// and integrator choices every run of it makes on a scene.
#pragma once

#include <string>

#include "scene/scene.hpp"

namespace tissue::app {

// How the mesh is chosen: uniform at `depth`, or adaptive from depth 0 with
// threshold th_Pa up to max_depth.
struct MeshChoice {
  bool adaptive = false;
  int depth = 0;
  double th_Pa = 20.0;
  int max_depth = 3;
};

// `m` as the scene's adaptivity: refined by strain-energy density whatever
// criterion the scene named.
void apply_mesh(scene::Scene& s, const MeshChoice& m);

// "explicit", "implicit", "projective" (the CSV's and the options' names).
const char* integrator_name(scene::IntegratorKind k);
// The kind named `s`; throws std::invalid_argument for another name.
scene::IntegratorKind integrator_kind(const std::string& s);

// Seed paper §4.1: 4^3 cubes of 2.5 cm, x = 0 fixed, 5 N down on x = 0.1,
// released at release_s. Probe 0 = tip (bottom edge centre), 1 = face centre.
scene::Scene paper_cantilever(const MeshChoice& m, scene::IntegratorKind kind, double dt_s, double release_s);

// PERFORMANCE.md beam: 8x2x2 cubes of 5 cm, x = 0 fixed, 0.05 N down on
// x = 0.4, gravity off. Probe 0 = tip (free face centre: the neutral axis).
// r_ladder: 12x3x3 cubes of 1/30 m instead, whose uniform depths 0, 3, 6, 9
// are PERFORMANCE.md's R1..R4 (cube edges 33, 17, 8.3, 4.2 mm).
scene::Scene performance_beam(const MeshChoice& m, scene::IntegratorKind kind, double dt_s, double ramp_s,
                              bool r_ladder = false);

}  // namespace tissue::app
