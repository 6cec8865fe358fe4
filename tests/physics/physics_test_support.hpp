// Scenes built in code for the physics tests (no YAML: these tests pin the
// physics, not the loader).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "physics/simulation.hpp"
#include "scene/scene.hpp"

namespace tissue::physics::testing {

inline scene::Region box(scene::Vec3 min_m, scene::Vec3 max_m) { return scene::Region::box(min_m, max_m); }
inline scene::Region sphere(scene::Vec3 centre_m, double radius_m) { return scene::Region::sphere(centre_m, radius_m); }

// PERFORMANCE.md's beam: 0.4 x 0.1 x 0.1 m of 0.05 m cubes, x = 0 fixed,
// `tip_force_N` downward on the free face, probe `tip` at its centre.
scene::Scene beam_scene(double tip_force_N = 0.05);

// The seed paper's cantilever: 4x4x4 cubes of 0.025 m, x = 0 fixed, 5 N down
// on the free face released at `release_s`, adaptivity on (Th 20 Pa, depth 3).
scene::Scene cantilever_scene(double release_s = 1.0);

// A small free cube (no fixed nodes) for conservation tests.
scene::Scene free_cube_scene(int cubes = 2, int depth = 0);

// λmax(M⁻¹K) [1/s²] over the free nodes at rest, K along the springs' rest
// directions, by a dense symmetric eigensolver (small meshes only): the
// reference the stable-step bounds and the Lanczos estimate are held to.
double dense_rest_frequency2_per_s2(const Body& body);

// A beam (depth 1) with every free node jiggled, so springs are stretched
// (transverse term on), compressed (clamped off) and one collapsed onto its
// end (rest-direction fallback), and random velocities. damped = false: no
// spring has a damper (Rayleigh beta 0).
Body jiggled_beam(std::uint32_t seed, bool damped = true);

// Moves every free node by up to amplitude_m per axis and gives it a random
// velocity of up to speed_m_per_s per axis (seeded: the same every run).
void jiggle_free_nodes(Body& body, std::uint32_t seed, double amplitude_m, double speed_m_per_s);

// beam_scene with adaptivity on up to max_depth, and 40 randomly chosen
// diamonds split (mixed depths 0..max_depth).
Body randomly_refined_beam(std::uint32_t seed, int max_depth = 5);

// Random p over the free nodes of `state` (zero on kinematic ones), each
// component uniform in [-1, 1] (seeded: the same every run).
std::vector<Vec3> random_free_vector(const Body& state, std::uint32_t seed);

// Kinetic + elastic energy [J].
double total_energy_J(const Simulation& sim);

// Runs until time_s >= t_end_s; returns false (with `error`) on a failed step.
bool run_until(Simulation& sim, double t_end_s, std::string* error = nullptr);

}  // namespace tissue::physics::testing
