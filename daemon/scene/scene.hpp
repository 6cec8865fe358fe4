// A scene: everything a simulation run needs to know, in SI units, already
// validated. Plain data; loaders (scene_yaml) fill it, the simulation reads it.
//
// Units are in the names. Positions are in metres in the object's frame: the
// box spans [0, cubes * cube_size_m] along each axis.
#pragma once

#include <array>
#include <cmath>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace tissue::scene {

using Vec3 = std::array<double, 3>;

// A scalar factor over time: 0 before start_s, a linear ramp to 1 over
// ramp_s, 1 until release_s, 0 from release_s on. Covers "constant"
// (defaults), "ramp" and "release at t".
struct TimeProfile {
  double start_s = 0.0;
  double ramp_s = 0.0;
  double release_s = std::numeric_limits<double>::infinity();

  double at(double t_s) const {
    if (t_s < start_s || t_s >= release_s) return 0.0;
    if (ramp_s <= 0.0) return 1.0;
    const double u = (t_s - start_s) / ramp_s;
    return u >= 1.0 ? 1.0 : u;
  }
};

// Region of rest-space points: an axis-aligned box (closed) or a sphere.
struct Region {
  enum class Kind { kBox, kSphere };
  Kind kind = Kind::kBox;
  Vec3 min_m{};  // box
  Vec3 max_m{};
  Vec3 centre_m{};  // sphere
  double radius_m = 0.0;

  static Region box(const Vec3& min_m, const Vec3& max_m) {
    Region r;
    r.kind = Kind::kBox;
    r.min_m = min_m;
    r.max_m = max_m;
    return r;
  }
  static Region sphere(const Vec3& centre_m, double radius_m) {
    Region r;
    r.kind = Kind::kSphere;
    r.centre_m = centre_m;
    r.radius_m = radius_m;
    return r;
  }

  bool contains(const Vec3& p, double tolerance_m) const {
    if (kind == Kind::kBox) {
      for (int a = 0; a < 3; ++a)
        if (p[a] < min_m[a] - tolerance_m || p[a] > max_m[a] + tolerance_m) return false;
      return true;
    }
    // hypot, not a sum of squares: a centre and radius near 1e308 would
    // square to inf <= inf and select every node.
    return std::hypot(p[0] - centre_m[0], p[1] - centre_m[1], p[2] - centre_m[2]) <= radius_m + tolerance_m;
  }
};

struct ObjectSpec {
  std::array<int, 3> cubes{4, 4, 4};
  double cube_size_m = 0.025;
};

enum class StiffnessLaw { kIsotropic, kPaper };
enum class DampingLaw { kRayleigh, kPaper };

struct MaterialSpec {
  double youngs_modulus_Pa = 5.0e4;
  double density_kg_per_m3 = 100.0;
  StiffnessLaw stiffness = StiffnessLaw::kIsotropic;
  DampingLaw damping = DampingLaw::kRayleigh;
  double rayleigh_alpha_per_s = 0.0;  // mass-proportional: c = alpha * m
  double rayleigh_beta_s = 0.01;      // stiffness-proportional: c = beta * k
};

// Nodes whose rest position lies in `region` never move.
struct FixedSpec {
  Region region;
};

// Nodes in `region` follow rest + profile(t) * displacement_m.
struct PrescribedSpec {
  std::string name;
  Region region;
  Vec3 displacement_m{};
  TimeProfile profile;
};

// total_force_N * profile(t), shared among the nodes in `region` by lumped
// mass (so the load is consistent as the mesh refines).
struct LoadSpec {
  std::string name;
  Region region;
  Vec3 total_force_N{};
  TimeProfile profile;
};

enum class RefineCriterion { kStrainEnergy, kStretch };

struct AdaptivitySpec {
  bool enabled = false;
  RefineCriterion criterion = RefineCriterion::kStrainEnergy;
  double refine_threshold_Pa = 4.0;  // strain-energy density Th
  double simplify_factor = 0.25;     // merge only below Th * factor
  double stretch_ratio = 1.05;       // kStretch: refine when any l/L or L/l exceeds it
  int min_depth = 0;
  int max_depth = 3;
  int every_steps = 5;               // adaptation cadence
  int max_ops_per_step = 64;         // split+merge budget per adaptation pass
  int min_age_steps = 20;            // a diamond that just changed is left alone
  double midpoint_tolerance = 1e-3;  // merge only when |z - mid| < tol * L
  // No split once the mesh holds this many leaf tets (a pass's closure may
  // pass it by a few). 4e6: about 0.8 GB at the measured <= 200 B per tet.
  int max_tets = 4'000'000;
};

enum class IntegratorKind { kExplicit, kImplicit, kProjective };

// Implicit CG preconditioner: kJacobi (diagonal) or kTwoLevel (Jacobi plus a
// coarse correction over ~27-node aggregates: dearer per iteration, but 5
// iterations beat 20 Jacobi ones, its iteration count stays flat as the mesh
// grows, and stiff large steps converge; docs/performance.md). kAuto, the
// default, takes two-level from ImplicitIntegrator::kAutoTwoLevelUnknowns
// free nodes on, re-deciding whenever the mesh changes.
enum class CgPreconditioner { kAuto, kJacobi, kTwoLevel };

// Arithmetic of the explicit rung's sub-steps. kFloat: single precision on
// displacements from rest (so strains keep ~7 digits), half the bytes and
// twice the SIMD lanes; the body's state stays double between steps.
enum class ExplicitPrecision { kDouble, kFloat };

struct IntegratorSpec {
  IntegratorKind kind = IntegratorKind::kImplicit;
  double dt_s = 1e-3;
  int max_substeps = 1000;      // explicit: refuse beyond this
  double substep_safety = 0.8;  // explicit: fraction of the stable bound
  // Explicit: a step ending with the body's energy above what it was given
  // (EnergyBudget) by more than this fraction is refused. Symplectic Euler's
  // energy swings by O(h ω) around its conserved shadow (0.37 under the
  // churn test at the default safety); 1 lets the body hold up to twice
  // what it was given before the rung refuses (docs/scene-format.md).
  double explicit_energy_slack = 1.0;
  ExplicitPrecision explicit_precision = ExplicitPrecision::kDouble;  // explicit
  double cg_tolerance = 1e-6;                                         // implicit: relative residual
  int cg_max_iterations = 100;                                        // implicit
  CgPreconditioner cg_preconditioner = CgPreconditioner::kAuto;       // implicit
};

struct ProbeSpec {
  std::string name;
  Vec3 rest_m{};
};

// A hand-held tool (the haptic probe) touching the object. Present only in
// scenes that want one: without it the simulation has no contact code at all
// and the daemon runs no haptic thread.
struct ToolSpec {
  double patch_radius_m = 0.02;     // surface handed to the haptic loop: this far around the tool
  double engage_distance_m = 0.01;  // build the contact model when the tool is this close to the surface
  double freeze_radius_m = 0.015;   // while engaged, adaptivity leaves diamonds this close to the contact alone
  double max_force_N = 20.0;        // force the tool may apply to the object (clamped, never exceeded)
};

// A scene value that is valid on its own but does not fit the mesh the
// scene builds (a region between nodes, a probe outside the object), found
// when the body is built. scene::model_error (scene_yaml.hpp) turns it into
// the SceneError of the file and of the --set that caused it.
class SceneModelError : public std::invalid_argument {
 public:
  SceneModelError(const std::string& key_path, const std::string& reason)
      : std::invalid_argument(key_path + ": " + reason), key_path_(key_path), reason_(reason) {}
  const std::string& key_path() const { return key_path_; }
  const std::string& reason() const { return reason_; }

 private:
  std::string key_path_, reason_;
};

struct Scene {
  std::string source;                  // file the scene came from (for messages)
  std::vector<std::string> overrides;  // the --set texts applied to it, for messages
  // The YAML text the scene was built from, before the overrides. A running
  // scene is changed (`set`) and recorded from this text, never from the file
  // as it may have been edited since.
  std::string source_text;
  std::string name;
  ObjectSpec object;
  MaterialSpec material;
  Vec3 gravity_m_per_s2{0.0, 0.0, 0.0};
  std::vector<FixedSpec> fixed;
  std::vector<PrescribedSpec> prescribed;
  std::vector<LoadSpec> loads;
  AdaptivitySpec adaptivity;
  IntegratorSpec integrator;
  std::vector<ProbeSpec> probes;
  std::optional<ToolSpec> tool;
};

// Tetrahedra of the starting mesh: 6 per cube, refined to min_depth
// everywhere (each bisection doubles them). A double: it is compared with
// limits before anything that large is built.
inline double starting_tet_count(const Scene& s) {
  return 6.0 * static_cast<double>(s.object.cubes[0]) * static_cast<double>(s.object.cubes[1]) *
         static_cast<double>(s.object.cubes[2]) * std::exp2(static_cast<double>(s.adaptivity.min_depth));
}

}  // namespace tissue::scene
