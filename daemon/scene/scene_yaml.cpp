#include "scene/scene_yaml.hpp"

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <map>
#include <optional>
#include <string_view>
#include <utility>
#include <vector>

#include "config/daemon_config_keys.hpp"
#include "mesh/kuhn_mesh.hpp"
#include "physics/probes.hpp"
#include "scene/scene_names.hpp"
#include "scene/yaml_util.hpp"
#include "util/text.hpp"

namespace tissue::scene {

namespace {

using yaml_util::Choices;
using yaml_util::count_of;
using yaml_util::describe;
using yaml_util::describe_kind;
using yaml_util::FieldMap;
using yaml_util::fmt_num;
using yaml_util::is_digit;
using yaml_util::join_index;
using yaml_util::join_key;
using yaml_util::printable;

// Largest scene file we read: a scene is a few kilobytes (the shipped ones
// 1-3 KB; one with every list at its limit, every key written, ~420 KB).
// 16 MiB took 48 s and 3.9 GB to parse, on the daemon's control thread,
// which feeds systemd's 5 s watchdog.
constexpr std::uintmax_t kMaxSceneFileBytes = 1u << 20;
// The most leaf tets a scene may ask for, at the start (cubes x 6 x
// 2^min_depth) or by refining (adaptivity.max_tets): about 4 GB (~200 bytes a
// tet with its springs and nodes). A typo such as cubes: [4000, 4000, 4], or
// max_tets: 2147483647 with a tiny threshold, ran into std::bad_alloc.
constexpr long long kMaxTets = 20'000'000;
constexpr long long kMaxTotalCubes = kMaxTets / 6;
// A cube's volume (cube_size³), mass (density x cube_size³) and its springs'
// stiffness scale (E x cube_size) must be ordinary doubles with room for
// refinement (2^-30), squares and sums: a density of 1e308 overflowed the
// lumped masses to inf, the free nodes stood still (1/inf = 0) and the
// report's kinetic energy was NaN (written as null) after a run that said it
// succeeded. The volume bounds the factors as well as the products: the body
// forms density x six-volume x unit x unit x unit and six-volume x unit³ left
// to right, each step between its first factor and the result, so with the
// volume in range the density is within [1e-200, 1e200] and E within about
// [1e-134, 1e134] as far as doubles go (the material caps below bound both
// from above far sooner), and every step stays an ordinary double (cube_size_m
// 1e-80 with density 1e308 passed the mass check and overflowed at
// density x six-volume; cube_size_m 2e-108 made every tet's volume, and so
// every stiffness, 0).
constexpr double kMinCubeScale = 1e-100, kMaxCubeScale = 1e100;
// Diamond, the stiffest solid, has E = 1.05e12 Pa; osmium, the densest,
// 22,590 kg/m³.
constexpr double kMaxYoungsModulus_Pa = 1e13, kMaxDensity_kg_per_m3 = 1e5;
// The float explicit rung keeps lengths, masses, 1/mass and stiffnesses in
// float: E = 1e48 Pa with density 1e48 passed the double range above, 1/m
// rounded to 0.0f and every free node froze (taken for kinematic) while the
// steps said ok. Each must lie in this range from the starting cube to the
// finest leaf (2^-max_depth), leaving ~1e8 of float's normal range
// (1.2e-38 .. 3.4e38) for products such as k x u; lengths are squared, so
// they keep to its square root.
constexpr double kMinFloatScale = 1e-30, kMaxFloatScale = 1e30;
constexpr double kMinFloatLength_m = 1e-15, kMaxFloatLength_m = 1e15;
// Rayleigh damping the body can form in double precision. The dampers
// (c = beta x k per spring, alpha x m per node) enter the rungs as ratios to
// the springs and masses, and those ratios are squared: the explicit rung's
// stable sub-step squares the damping ratio of the fastest mode (about beta
// x omega), the implicit rung's CG the dot products of a system of M (1 +
// alpha h) + h C + h² K. On the cantilever (omega 7.16e3 /s) beta 1e300 s
// made the explicit stable sub-step inf (one sub-step, then "state became
// non-finite"; from beta 1e151 s), beta 1e160 s stopped the implicit CG at
// 0 iterations with the body frozen (its steps fell short of the tolerance
// from 1e140 s), alpha 1e300 /s made its steps fall short too. So, as the
// cube scales, these products are kept within 1e100, leaving 1e208 of
// double's range for their squares and sums (a damping ratio of 1e100 is no
// material: the explicit rung refuses such a step at its sub-step cap):
//   beta x omega             the damping ratio of the fastest mode,
//   beta x omega² x dt_s     the dampers against the masses in one step,
//   alpha x dt_s             the mass damping in one step,
// with omega = sqrt(E / density) / (cube_size_m x 2^-depth), the frequency
// scale of the finest leaf the scene can reach.
constexpr double kMaxDampingScale = 1e100;
constexpr int kMaxDepthLimit = 30;
constexpr double kMinDt_s = 1e-7;
constexpr int kMaxSubsteps = 100'000;
constexpr std::size_t kMaxProbes = 1000;
// Regions are tested against every node (fixed, prescribed) or surface
// triangle (loads) whenever the mesh changes: 20,000 loads on 20³ cubes took
// 3 s a step, and a 1 MiB file holds ~10,000.
constexpr std::size_t kMaxRegionsPerList = 1000;
constexpr std::size_t kMaxNameLength = 64;
constexpr std::size_t kMaxSceneNameBytes = 200;  // the scene's own name (free text)

// ------------------------------------------------------------ YAML -> Scene

// Scene sections -> Scene; key checking and typed reads come from the shared Reader.
class Converter : public yaml_util::Reader {
 public:
  explicit Converter(const std::string& source) : Reader(source) {}

  // A top-level key that is no scene section but is, or is close to, a
  // daemon setting ("haptic.rate_hz" set on a scene, or under --config a
  // misspelt daemon key, which goes to the scene) says so; the plain
  // "unknown key" named the scene's sections only. A scene section's own
  // suggestion (fields()) comes first.
  void daemon_setting_hint(const YAML::Node& root, yaml_util::KeyList sections) const {
    for (auto it = root.begin(); it != root.end(); ++it) {
      if (!it->first.IsScalar()) continue;
      const std::string& name = it->first.Scalar();
      const bool plain =
          !name.empty() && name.size() <= kMaxNameLength && std::all_of(name.begin(), name.end(), [](char c) {
            return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-';
          });
      if (!plain || std::find(sections.begin(), sections.end(), name) != sections.end() ||
          yaml_util::suggest(name, sections))
        continue;
      const yaml_util::KeyList daemon_keys(config::kDaemonTopLevelKeys);
      std::optional<std::string_view> near;
      if (std::find(daemon_keys.begin(), daemon_keys.end(), name) != daemon_keys.end())
        near = name;
      else
        near = yaml_util::suggest(name, daemon_keys);
      if (near)
        fail(name, "unknown key " + printable(name) + " (did you mean the daemon setting '" + std::string(*near) +
                       "'? it belongs in the daemon config: tissued --config FILE, where --set routes it there; for a "
                       "running daemon: edit that file and reload it (SIGHUP)); "
                       "allowed keys: " +
                       yaml_util::join_list(sections));
    }
  }

  Scene scene(const YAML::Node& root) {
    if (!root.IsMap()) fail("", "a scene document must be a map of sections, got " + describe_kind(root));
    static constexpr std::array<std::string_view, 11> kSections{
        "name",  "object",     "material",   "gravity_m_per_s2", "fixed", "prescribed",
        "loads", "adaptivity", "integrator", "probes",           "tool"};
    daemon_setting_hint(root, kSections);
    const FieldMap f = fields(root, "", kSections);
    Scene s;
    s.source = source_;
    s.name = default_name(source_);
    opt(f, "name", "", s.name);
    if (s.name.empty()) fail("name", "must not be empty");

    const auto obj = f.find("object");
    if (obj == f.end()) fail("object", "missing required section (the object's cubes and cube_size_m)");
    object(obj->second, "object", s.object);
    if (const auto it = f.find("material"); it != f.end()) material(it->second, "material", s.material);
    opt(f, "gravity_m_per_s2", "", s.gravity_m_per_s2);
    if (const auto it = f.find("fixed"); it != f.end()) {
      for_each(it->second, "fixed", [&](const YAML::Node& n, const std::string& p) {
        const FieldMap g = fields(n, p, {"region"});
        FixedSpec spec;
        spec.region = region(require(g, "region", p), join_key(p, "region"));
        s.fixed.push_back(spec);
      });
    }
    if (const auto it = f.find("prescribed"); it != f.end()) {
      for_each(it->second, "prescribed", [&](const YAML::Node& n, const std::string& p) {
        const FieldMap g = fields(n, p, {"name", "region", "displacement_m", "profile"});
        PrescribedSpec spec;
        spec.name = "prescribed" + std::to_string(s.prescribed.size());
        opt(g, "name", p, spec.name);
        spec.region = region(require(g, "region", p), join_key(p, "region"));
        read(require(g, "displacement_m", p), join_key(p, "displacement_m"), spec.displacement_m);
        if (const auto pr = g.find("profile"); pr != g.end()) profile(pr->second, join_key(p, "profile"), spec.profile);
        s.prescribed.push_back(spec);
      });
    }
    if (const auto it = f.find("loads"); it != f.end()) {
      for_each(it->second, "loads", [&](const YAML::Node& n, const std::string& p) {
        const FieldMap g = fields(n, p, {"name", "region", "total_force_N", "profile"});
        LoadSpec spec;
        spec.name = "load" + std::to_string(s.loads.size());
        opt(g, "name", p, spec.name);
        spec.region = region(require(g, "region", p), join_key(p, "region"));
        read(require(g, "total_force_N", p), join_key(p, "total_force_N"), spec.total_force_N);
        if (const auto pr = g.find("profile"); pr != g.end()) profile(pr->second, join_key(p, "profile"), spec.profile);
        s.loads.push_back(spec);
      });
    }
    if (const auto it = f.find("adaptivity"); it != f.end()) adaptivity(it->second, "adaptivity", s.adaptivity);
    if (const auto it = f.find("integrator"); it != f.end()) integrator(it->second, "integrator", s.integrator);
    if (const auto it = f.find("probes"); it != f.end()) {
      for_each(it->second, "probes", [&](const YAML::Node& n, const std::string& p) {
        const FieldMap g = fields(n, p, {"name", "rest_m"});
        ProbeSpec spec;
        spec.name = "probe" + std::to_string(s.probes.size());
        opt(g, "name", p, spec.name);
        read(require(g, "rest_m", p), join_key(p, "rest_m"), spec.rest_m);
        s.probes.push_back(spec);
      });
    }
    if (const auto it = f.find("tool"); it != f.end()) {
      const FieldMap g =
          fields(it->second, "tool", {"patch_radius_m", "engage_distance_m", "freeze_radius_m", "max_force_N"});
      ToolSpec t;
      opt(g, "patch_radius_m", "tool", t.patch_radius_m);
      opt(g, "engage_distance_m", "tool", t.engage_distance_m);
      opt(g, "freeze_radius_m", "tool", t.freeze_radius_m);
      opt(g, "max_force_N", "tool", t.max_force_N);
      s.tool = t;
    }
    return s;
  }

 private:
  // The file's stem, unless a file name is not something a name may be
  // (bytes that are not UTF-8, control characters): then "scene".
  static std::string default_name(const std::string& source) {
    std::string stem = std::filesystem::path(source).stem().string();
    return stem.empty() || !util::why_not_clean_text(stem).empty() || stem.size() > kMaxSceneNameBytes
               ? std::string("scene")
               : stem;
  }

  void object(const YAML::Node& n, const std::string& p, ObjectSpec& o) const {
    const FieldMap f = fields(n, p, {"cubes", "cube_size_m"});
    read(require(f, "cubes", p), join_key(p, "cubes"), o.cubes);
    read(require(f, "cube_size_m", p), join_key(p, "cube_size_m"), o.cube_size_m);
  }

  void material(const YAML::Node& n, const std::string& p, MaterialSpec& m) const {
    const FieldMap f = fields(
        n, p,
        {"youngs_modulus_Pa", "density_kg_per_m3", "stiffness", "damping", "rayleigh_alpha_per_s", "rayleigh_beta_s"});
    opt(f, "youngs_modulus_Pa", p, m.youngs_modulus_Pa);
    opt(f, "density_kg_per_m3", p, m.density_kg_per_m3);
    opt_choice<StiffnessLaw>(f, "stiffness", p, kStiffnessLawNames, m.stiffness);
    opt_choice<DampingLaw>(f, "damping", p, kDampingLawNames, m.damping);
    opt(f, "rayleigh_alpha_per_s", p, m.rayleigh_alpha_per_s);
    opt(f, "rayleigh_beta_s", p, m.rayleigh_beta_s);
  }

  Region region(const YAML::Node& n, const std::string& p) const {
    const FieldMap f = fields(n, p, {"box", "sphere"});
    const auto box = f.find("box");
    const auto sphere = f.find("sphere");
    if ((box == f.end()) == (sphere == f.end()))
      fail(p,
           std::string("a region has exactly one of 'box' or 'sphere', got ") + (box == f.end() ? "neither" : "both"));
    Region r;
    if (box != f.end()) {
      const std::string bp = join_key(p, "box");
      const FieldMap b = fields(box->second, bp, {"min_m", "max_m"});
      r.kind = Region::Kind::kBox;
      read(require(b, "min_m", bp), join_key(bp, "min_m"), r.min_m);
      read(require(b, "max_m", bp), join_key(bp, "max_m"), r.max_m);
    } else {
      const std::string sp = join_key(p, "sphere");
      const FieldMap s = fields(sphere->second, sp, {"centre_m", "radius_m"});
      r.kind = Region::Kind::kSphere;
      read(require(s, "centre_m", sp), join_key(sp, "centre_m"), r.centre_m);
      read(require(s, "radius_m", sp), join_key(sp, "radius_m"), r.radius_m);
    }
    return r;
  }

  void profile(const YAML::Node& n, const std::string& p, TimeProfile& t) const {
    const FieldMap f = fields(n, p, {"start_s", "ramp_s", "release_s"});
    opt(f, "start_s", p, t.start_s);
    opt(f, "ramp_s", p, t.ramp_s);
    opt(f, "release_s", p, t.release_s);
  }

  void adaptivity(const YAML::Node& n, const std::string& p, AdaptivitySpec& a) const {
    const FieldMap f =
        fields(n, p,
               {"enabled", "criterion", "refine_threshold_Pa", "simplify_factor", "stretch_ratio", "min_depth",
                "max_depth", "every_steps", "max_ops_per_step", "min_age_steps", "midpoint_tolerance", "max_tets"});
    opt(f, "enabled", p, a.enabled);
    opt_choice<RefineCriterion>(f, "criterion", p, kRefineCriterionNames, a.criterion);
    opt(f, "refine_threshold_Pa", p, a.refine_threshold_Pa);
    opt(f, "simplify_factor", p, a.simplify_factor);
    opt(f, "stretch_ratio", p, a.stretch_ratio);
    opt(f, "min_depth", p, a.min_depth);
    opt(f, "max_depth", p, a.max_depth);
    opt(f, "every_steps", p, a.every_steps);
    opt(f, "max_ops_per_step", p, a.max_ops_per_step);
    opt(f, "max_tets", p, a.max_tets);
    opt(f, "min_age_steps", p, a.min_age_steps);
    opt(f, "midpoint_tolerance", p, a.midpoint_tolerance);
  }

  void integrator(const YAML::Node& n, const std::string& p, IntegratorSpec& g) const {
    const FieldMap f = fields(n, p,
                              {"kind", "dt_s", "max_substeps", "substep_safety", "explicit_energy_slack",
                               "explicit_precision", "cg_tolerance", "cg_max_iterations", "cg_preconditioner"});
    opt_choice<IntegratorKind>(f, "kind", p, kIntegratorNames, g.kind);
    opt(f, "dt_s", p, g.dt_s);
    opt(f, "max_substeps", p, g.max_substeps);
    opt(f, "substep_safety", p, g.substep_safety);
    opt(f, "explicit_energy_slack", p, g.explicit_energy_slack);
    opt_choice<ExplicitPrecision>(f, "explicit_precision", p, kExplicitPrecisionNames, g.explicit_precision);
    opt(f, "cg_tolerance", p, g.cg_tolerance);
    opt(f, "cg_max_iterations", p, g.cg_max_iterations);
    opt_choice<CgPreconditioner>(f, "cg_preconditioner", p, kCgPreconditionerNames, g.cg_preconditioner);
  }
};

// ------------------------------------------------------------- validation

class Validator : private yaml_util::ValueChecks<Validator> {
  friend class yaml_util::ValueChecks<Validator>;

 public:
  explicit Validator(const Scene& s) : s_(s) {}

  void run() {
    // The scene's name reaches JSON reports, HDF5 events and terminals as
    // given (it may hold spaces and any script; the sub-names below are
    // stricter: they label columns).
    if (const std::string why = util::why_not_clean_text(s_.name); !why.empty()) fail("name", why);
    if (s_.name.size() > kMaxSceneNameBytes)
      fail("name", "too long (" + std::to_string(s_.name.size()) + " bytes, at most " +
                       std::to_string(kMaxSceneNameBytes) + ")");
    const ObjectSpec& o = s_.object;
    long long total = 1;
    for (int a = 0; a < 3; ++a) {
      at_least(o.cubes[a], 1, join_index("object.cubes", a));
      // The mesh's lattice keys bound each axis (object.cubes: [2000000, 1, 1]
      // was refused by the mesh without the key's name).
      if (o.cubes[a] > mesh::kMaxCubesPerAxis)
        fail(join_index("object.cubes", a), "must be <= " + std::to_string(mesh::kMaxCubesPerAxis) +
                                                " cubes along one axis, what the mesh's lattice keys hold (got " +
                                                std::to_string(o.cubes[a]) + ")");
      total *= o.cubes[a];
      if (total > kMaxTotalCubes)
        fail("object.cubes", "too many cubes (more than " + std::to_string(kMaxTotalCubes) + " in total)");
    }
    total_cubes_ = total;
    positive(o.cube_size_m, "object.cube_size_m");
    for (int a = 0; a < 3; ++a) {
      extent_[a] = o.cubes[a] * o.cube_size_m;
      if (!std::isfinite(extent_[a]))
        fail("object.cube_size_m", "the object's size (object.cubes x cube_size_m) overflows: " +
                                       std::to_string(o.cubes[a]) + " x " + fmt_num(o.cube_size_m) + " m");
    }
    // Probes and regions may lie outside the box by rounding (probes.hpp).
    tolerance_ = physics::kProbeOutsideBoxTolerance * std::max({extent_[0], extent_[1], extent_[2]});
    const auto beyond_double = [&](double given) {
      return ", outside [" + fmt_num(kMinCubeScale) + ", " + fmt_num(kMaxCubeScale) +
             "]: beyond what the simulation holds in double precision (got " + fmt_num(given) + ")";
    };
    const double cube_m3 = o.cube_size_m * o.cube_size_m * o.cube_size_m;
    if (!(cube_m3 >= kMinCubeScale && cube_m3 <= kMaxCubeScale))
      fail("object.cube_size_m", "a cube's volume in m³ would be " + fmt_num(cube_m3) + beyond_double(o.cube_size_m));

    const MaterialSpec& m = s_.material;
    positive(m.youngs_modulus_Pa, "material.youngs_modulus_Pa");
    positive(m.density_kg_per_m3, "material.density_kg_per_m3");
    const auto representable = [&](double value, double given, const char* key, const std::string& what) {
      if (!(value >= kMinCubeScale && value <= kMaxCubeScale))
        fail(key, "with object.cube_size_m " + fmt_num(o.cube_size_m) + ", " + what + " would be " + fmt_num(value) +
                      beyond_double(given));
    };
    representable(m.density_kg_per_m3 * cube_m3, m.density_kg_per_m3, "material.density_kg_per_m3",
                  "a cube's mass in kg");
    representable(m.youngs_modulus_Pa * o.cube_size_m, m.youngs_modulus_Pa, "material.youngs_modulus_Pa",
                  "the cube's spring stiffness scale (E x cube size) in N/m");
    // Past any real material (a typo, or units not SI). Representable, but a
    // load strains so stiff a body less than its coordinates resolve and so
    // heavy a one moves less than that in a step: the state is rounding, and
    // the projective rung, whose velocities are position differences, turned
    // it into energy (density 1.8e19: kinetic energy 1e5 times the work done,
    // and growing).
    if (m.youngs_modulus_Pa > kMaxYoungsModulus_Pa)
      fail("material.youngs_modulus_Pa", "must be <= " + fmt_num(kMaxYoungsModulus_Pa) +
                                             " Pa (ten times diamond's; got " + fmt_num(m.youngs_modulus_Pa) + ")");
    if (m.density_kg_per_m3 > kMaxDensity_kg_per_m3)
      fail("material.density_kg_per_m3", "must be <= " + fmt_num(kMaxDensity_kg_per_m3) +
                                             " kg/m³ (four times osmium's; got " + fmt_num(m.density_kg_per_m3) + ")");
    enumerator(static_cast<int>(m.stiffness), 2, "material.stiffness");
    enumerator(static_cast<int>(m.damping), 2, "material.damping");
    non_negative(m.rayleigh_alpha_per_s, "material.rayleigh_alpha_per_s");
    non_negative(m.rayleigh_beta_s, "material.rayleigh_beta_s");

    finite(s_.gravity_m_per_s2, "gravity_m_per_s2");

    const auto bounded = [&](std::size_t count, const char* key) {
      if (count > kMaxRegionsPerList)
        fail(key, "too many (" + std::to_string(count) + ", at most " + std::to_string(kMaxRegionsPerList) + ")");
    };
    bounded(s_.fixed.size(), "fixed");
    bounded(s_.prescribed.size(), "prescribed");
    bounded(s_.loads.size(), "loads");
    for (std::size_t i = 0; i < s_.fixed.size(); ++i) region(s_.fixed[i].region, join_index("fixed", i) + ".region");
    for (std::size_t i = 0; i < s_.prescribed.size(); ++i) {
      const PrescribedSpec& p = s_.prescribed[i];
      const std::string kp = join_index("prescribed", i);
      name(p.name, kp + ".name");
      region(p.region, kp + ".region");
      finite(p.displacement_m, kp + ".displacement_m");
      profile(p.profile, kp + ".profile");
    }
    for (std::size_t i = 0; i < s_.loads.size(); ++i) {
      const LoadSpec& l = s_.loads[i];
      const std::string kp = join_index("loads", i);
      name(l.name, kp + ".name");
      region(l.region, kp + ".region");
      finite(l.total_force_N, kp + ".total_force_N");
      profile(l.profile, kp + ".profile");
    }

    const AdaptivitySpec& a = s_.adaptivity;
    enumerator(static_cast<int>(a.criterion), 2, "adaptivity.criterion");
    positive(a.refine_threshold_Pa, "adaptivity.refine_threshold_Pa");
    open_unit(a.simplify_factor, "adaptivity.simplify_factor");
    finite(a.stretch_ratio, "adaptivity.stretch_ratio");
    if (!(a.stretch_ratio > 1.0))
      fail("adaptivity.stretch_ratio", "must be > 1 (got " + fmt_num(a.stretch_ratio) + ")");
    at_least(a.min_depth, 0, "adaptivity.min_depth");
    // The mesh starts refined to min_depth everywhere: 6 · 2^min_depth tets
    // per cube, bounded as the cubes are (min_depth 30 asked for 6e9 tets per
    // cube and ran out of memory instead of being refused).
    if (a.min_depth <= kMaxDepthLimit) {
      const double tets = starting_tet_count(s_);
      if (tets > static_cast<double>(kMaxTets))
        fail("adaptivity.min_depth", "the starting mesh would have " + fmt_num(tets) + " tetrahedra (" +
                                         std::to_string(total_cubes_) + " cubes x 6 x 2^" +
                                         std::to_string(a.min_depth) + "), more than " + std::to_string(kMaxTets));
    }
    // Before min <= max: a negative max_depth was reported at min_depth.
    at_least(a.max_depth, 0, "adaptivity.max_depth");
    if (a.max_depth > kMaxDepthLimit)
      fail("adaptivity.max_depth",
           "must be <= " + std::to_string(kMaxDepthLimit) + " (got " + std::to_string(a.max_depth) + ")");
    if (a.min_depth > a.max_depth)
      fail("adaptivity.min_depth",
           "must be <= max_depth (" + std::to_string(a.max_depth) + ") (got " + std::to_string(a.min_depth) + ")");
    // The mesh is built for the deepest level the scene can reach (min_depth
    // when adaptivity is off); its lattice keys hold fewer levels the more
    // cubes there are along an axis.
    {
      const long long largest = std::max({o.cubes[0], o.cubes[1], o.cubes[2]});
      const int depth_limit = mesh::max_lattice_depth(largest);
      const bool by_max = a.enabled;
      const int depth = by_max ? a.max_depth : a.min_depth;
      if (depth > depth_limit)
        fail(by_max ? "adaptivity.max_depth" : "adaptivity.min_depth",
             "must be <= " + std::to_string(depth_limit) + " for " + std::to_string(largest) +
                 " cubes along an axis, what the mesh's lattice keys hold (got " + std::to_string(depth) + ")");
    }
    at_least(a.every_steps, 1, "adaptivity.every_steps");
    at_least(a.max_ops_per_step, 1, "adaptivity.max_ops_per_step");
    at_least(a.max_tets, 1, "adaptivity.max_tets");
    if (a.max_tets > kMaxTets)
      fail("adaptivity.max_tets",
           "must be <= " + std::to_string(kMaxTets) + " (about 4 GB of mesh; got " + std::to_string(a.max_tets) + ")");
    at_least(a.min_age_steps, 0, "adaptivity.min_age_steps");
    positive(a.midpoint_tolerance, "adaptivity.midpoint_tolerance");

    const IntegratorSpec& g = s_.integrator;
    enumerator(static_cast<int>(g.kind), 3, "integrator.kind");
    positive(g.dt_s, "integrator.dt_s");
    if (g.dt_s > 1.0) fail("integrator.dt_s", "must be <= 1 s (got " + fmt_num(g.dt_s) + ")");
    // 1e-300 s was accepted: 120,000 steps later the time had not moved.
    if (g.dt_s < kMinDt_s)
      fail("integrator.dt_s", "must be >= " + fmt_num(kMinDt_s) + " s (got " + fmt_num(g.dt_s) +
                                  "; the explicit integrator takes sub-steps below dt itself)");
    at_least(g.max_substeps, 1, "integrator.max_substeps");
    // One step is not interruptible: 2^31 sub-steps ran one step for minutes.
    if (g.max_substeps > kMaxSubsteps)
      fail("integrator.max_substeps",
           "must be <= " + std::to_string(kMaxSubsteps) + " (got " + std::to_string(g.max_substeps) + ")");
    finite(g.substep_safety, "integrator.substep_safety");
    if (!(g.substep_safety > 0.0 && g.substep_safety <= 1.0))
      fail("integrator.substep_safety", "must be in (0, 1] (got " + fmt_num(g.substep_safety) + ")");
    // Above 0 so that the swing symplectic Euler makes on a legitimate run
    // (O(h ω), 0.37 in the churn test) is never refused; finite so that
    // the bound exists ("within its bound or refused").
    finite(g.explicit_energy_slack, "integrator.explicit_energy_slack");
    positive(g.explicit_energy_slack, "integrator.explicit_energy_slack");
    open_unit(g.cg_tolerance, "integrator.cg_tolerance");
    at_least(g.cg_max_iterations, 1, "integrator.cg_max_iterations");
    if (g.kind == IntegratorKind::kExplicit && g.explicit_precision == ExplicitPrecision::kFloat) float_range();
    damping_range();
    // After dt_s is known good: whether each profile acts at some step.
    for (std::size_t i = 0; i < s_.prescribed.size(); ++i)
      profile_acts(s_.prescribed[i].profile, join_index("prescribed", i) + ".profile", "displacement");
    for (std::size_t i = 0; i < s_.loads.size(); ++i)
      profile_acts(s_.loads[i].profile, join_index("loads", i) + ".profile", "force");

    for (std::size_t i = 0; i < s_.probes.size(); ++i) {
      const ProbeSpec& p = s_.probes[i];
      const std::string kp = join_index("probes", i);
      name(p.name, kp + ".name");
      finite(p.rest_m, kp + ".rest_m");
      for (int ax = 0; ax < 3; ++ax)
        if (p.rest_m[ax] < -tolerance_ || p.rest_m[ax] > extent_[ax] + tolerance_)
          fail(kp + ".rest_m", "the point lies outside the object " + object_box() + " (a typo?)");
    }

    if (s_.tool) {
      positive(s_.tool->patch_radius_m, "tool.patch_radius_m");
      positive(s_.tool->engage_distance_m, "tool.engage_distance_m");
      non_negative(s_.tool->freeze_radius_m, "tool.freeze_radius_m");
      positive(s_.tool->max_force_N, "tool.max_force_N");
    }

    unique_names(s_.prescribed, "prescribed");
    unique_names(s_.loads, "loads");
    unique_names(s_.probes, "probes");
    // Each probe is located in the mesh after every step: 20,000 took 2 s per step.
    if (s_.probes.size() > kMaxProbes)
      fail("probes", "too many (" + std::to_string(s_.probes.size()) + ", at most " + std::to_string(kMaxProbes) + ")");
  }

 private:
  // explicit_precision float: the quantities the float rung holds, at the
  // starting cube and at the finest leaf, within float's range (see
  // kMinFloatScale). Runs after the material, object and adaptivity checks.
  void float_range() const {
    const ObjectSpec& o = s_.object;
    const MaterialSpec& m = s_.material;
    const double leaf = std::exp2(-static_cast<double>(std::max(s_.adaptivity.min_depth, s_.adaptivity.max_depth)));
    const double mass_kg = m.density_kg_per_m3 * o.cube_size_m * o.cube_size_m * o.cube_size_m;
    const double gravity =
        std::sqrt(s_.gravity_m_per_s2[0] * s_.gravity_m_per_s2[0] + s_.gravity_m_per_s2[1] * s_.gravity_m_per_s2[1] +
                  s_.gravity_m_per_s2[2] * s_.gravity_m_per_s2[2]);
    const auto in_float = [&](double largest, double smallest, double lo, double hi, const std::string& what) {
      if (largest <= hi && smallest >= lo) return;
      fail("integrator.explicit_precision",
           "float cannot hold " + what + ": from " + fmt_num(smallest) + " to " + fmt_num(largest) +
               " (finest leaf to starting cube, adaptivity depth up to " +
               std::to_string(std::max(s_.adaptivity.min_depth, s_.adaptivity.max_depth)) + "), outside [" +
               fmt_num(lo) + ", " + fmt_num(hi) + "]; use explicit_precision double or other units");
    };
    in_float(o.cube_size_m, o.cube_size_m * leaf, kMinFloatLength_m, kMaxFloatLength_m,
             "the spring lengths in m (object.cube_size_m)");
    in_float(m.youngs_modulus_Pa * o.cube_size_m, m.youngs_modulus_Pa * o.cube_size_m * leaf, kMinFloatScale,
             kMaxFloatScale, "the spring stiffnesses in N/m (material.youngs_modulus_Pa x object.cube_size_m)");
    const double leaf_mass_kg = mass_kg * leaf * leaf * leaf;
    in_float(mass_kg, leaf_mass_kg, kMinFloatScale, kMaxFloatScale,
             "the node masses in kg (material.density_kg_per_m3 x object.cube_size_m^3)");
    in_float(1.0 / leaf_mass_kg, 1.0 / mass_kg, kMinFloatScale, kMaxFloatScale,
             "the inverse node masses in 1/kg (material.density_kg_per_m3 x object.cube_size_m^3)");
    if (gravity > 0.0)
      in_float(gravity * mass_kg, gravity * leaf_mass_kg, kMinFloatScale, kMaxFloatScale,
               "the gravity forces in N (gravity_m_per_s2 x a node's mass)");
  }

  // Rayleigh damping within what the body holds in double precision (see
  // kMaxDampingScale). Runs after the material, object, adaptivity and
  // integrator checks: all its factors are finite and positive by then.
  void damping_range() const {
    const MaterialSpec& m = s_.material;
    const double dt_s = s_.integrator.dt_s;
    const auto said = [](double v) {  // derived figures to 3 digits, as a person reads them
      char text[32];
      std::snprintf(text, sizeof text, "%.3g", v);
      return std::string(text);
    };
    const auto beyond = [&](const char* key, double given, const std::string& what, double value) {
      if (value <= kMaxDampingScale) return;
      fail(key, what + " would be " + said(value) + ", above " + fmt_num(kMaxDampingScale) +
                    ": beyond what the simulation holds in double precision (got " + fmt_num(given) + ")");
    };
    // beta is the dampers' only when they follow Rayleigh's law (material.damping).
    if (m.damping == DampingLaw::kRayleigh) {
      const int depth = std::max(s_.adaptivity.min_depth, s_.adaptivity.max_depth);
      // sqrt of each: E / density can overflow (E up to 1e13, density down to ~1e-200).
      const double leaf_m = s_.object.cube_size_m * std::exp2(-static_cast<double>(depth));
      const double omega_per_s = std::sqrt(m.youngs_modulus_Pa) / std::sqrt(m.density_kg_per_m3) / leaf_m;
      const std::string omega = "omega = sqrt(E / density) / leaf size = " + said(omega_per_s) +
                                " /s at adaptivity depth " + std::to_string(depth);
      const double ratio = m.rayleigh_beta_s * omega_per_s;  // finite or inf, never NaN (beta, omega finite)
      beyond("material.rayleigh_beta_s", m.rayleigh_beta_s,
             "the dampers' damping ratio of the finest leaf (beta x omega, " + omega + ")", ratio);
      beyond("material.rayleigh_beta_s", m.rayleigh_beta_s,
             "the dampers against the masses in one step (beta x omega² x integrator.dt_s, " + omega + ")",
             ratio * (omega_per_s * dt_s));
    }
    beyond("material.rayleigh_alpha_per_s", m.rayleigh_alpha_per_s,
           "the mass damping in one step (alpha x integrator.dt_s)", m.rayleigh_alpha_per_s * dt_s);
  }

  [[noreturn]] void fail(const std::string& path, const std::string& reason) const {
    throw SceneError(s_.source, path, reason);
  }

  void open_unit(double v, const std::string& path) const {
    finite(v, path);
    if (!(v > 0.0 && v < 1.0)) fail(path, "must be in (0, 1) (got " + fmt_num(v) + ")");
  }
  void at_least(int v, int lo, const std::string& path) const {
    if (v < lo) fail(path, "must be >= " + std::to_string(lo) + " (got " + std::to_string(v) + ")");
  }
  void enumerator(int v, int count, const std::string& path) const {
    if (v < 0 || v >= count) fail(path, "invalid enumerator value " + std::to_string(v));
  }

  // Names label outputs (probe columns, recorded series): keep them short and plain.
  void name(const std::string& n, const std::string& path) const {
    if (n.empty()) fail(path, "must not be empty");
    if (n.size() > kMaxNameLength)
      fail(path,
           "too long (" + std::to_string(n.size()) + " characters, at most " + std::to_string(kMaxNameLength) + ")");
    for (const char ch : n) {
      const bool ok =
          (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') || is_digit(ch) || ch == '_' || ch == '-' || ch == '.';
      if (!ok) fail(path, "bad name " + printable(n) + ": use only letters, digits, '_', '-' and '.'");
    }
  }

  std::string object_box() const {
    return "box [0, " + fmt_num(extent_[0]) + "] x [0, " + fmt_num(extent_[1]) + "] x [0, " + fmt_num(extent_[2]) +
           "] m";
  }

  void region(const Region& r, const std::string& path) const {
    switch (r.kind) {
      case Region::Kind::kBox: {
        const std::string bp = path + ".box";
        finite(r.min_m, bp + ".min_m");
        finite(r.max_m, bp + ".max_m");
        for (std::size_t a = 0; a < 3; ++a)
          if (r.min_m[a] > r.max_m[a])
            fail(bp, "min_m[" + std::to_string(a) + "] > max_m[" + std::to_string(a) + "] (" + fmt_num(r.min_m[a]) +
                         " > " + fmt_num(r.max_m[a]) + ")");
        for (std::size_t a = 0; a < 3; ++a)
          if (r.max_m[a] < -tolerance_ || r.min_m[a] > extent_[a] + tolerance_)
            fail(path, "the box lies entirely outside the object " + object_box() + " (a typo?)");
        return;
      }
      case Region::Kind::kSphere: {
        const std::string sp = path + ".sphere";
        finite(r.centre_m, sp + ".centre_m");
        non_negative(r.radius_m, sp + ".radius_m");
        std::array<double, 3> gap{};  // from the object's box, per axis
        for (std::size_t a = 0; a < 3; ++a) {
          const double c = r.centre_m[a];
          gap[a] = c < 0.0 ? -c : (c > extent_[a] ? c - extent_[a] : 0.0);
        }
        // hypot: squares of a 1e308 centre and radius overflow to inf > inf
        // (false), and the far sphere passed as if it touched the object.
        if (std::hypot(gap[0], gap[1], gap[2]) > r.radius_m + tolerance_)
          fail(path, "the sphere lies entirely outside the object " + object_box() + " (a typo?)");
        return;
      }
    }
    fail(path, "invalid region kind " + std::to_string(static_cast<int>(r.kind)));
  }

  void profile(const TimeProfile& t, const std::string& path) const {
    finite(t.start_s, path + ".start_s");
    if (t.start_s < 0.0) fail(path + ".start_s", "must be >= 0 (got " + fmt_num(t.start_s) + ")");
    non_negative(t.ramp_s, path + ".ramp_s");
    if (std::isnan(t.release_s)) fail(path + ".release_s", "must be a number or .inf (got nan)");
    if (!(t.release_s > t.start_s))
      fail(path + ".release_s", "must be > start_s (" + fmt_num(t.start_s) + ") (got " + fmt_num(t.release_s) + ")");
  }

  // A profile is sampled at step ends only (Simulation::step and the drivers:
  // t = k · dt_s, k >= 1, the step count times dt): a release before the
  // first step end after start_s left the load or displacement out of every
  // step, silently (dt_s 0.01 with {start_s: 0.002, release_s: 0.008} did no
  // work and exited 0). Runs after the profile's own checks and dt_s's.
  void profile_acts(const TimeProfile& t, const std::string& path, const char* what) const {
    const double dt_s = s_.integrator.dt_s;
    // From 2^52 steps on, k · dt_s no longer steps by one dt; no run gets there.
    const double first_k = std::floor(t.start_s / dt_s);
    if (first_k >= 0x1p52) return;
    // The step ends at and after start_s: k · dt_s exactly as the simulation
    // forms it, from one below the rounded quotient (the division may round
    // up across an integer) on; the ramp is 0 at start_s, so one more.
    bool in_window = false;
    for (int i = -1; i <= 3; ++i) {
      const double k = std::max(1.0, first_k + i);
      const double t_s = k * dt_s;
      if (t_s >= t.release_s) break;
      if (t_s < t.start_s) continue;
      in_window = true;
      if (t.at(t_s) > 0.0) return;
    }
    const std::string window = "[start_s, release_s) = [" + fmt_num(t.start_s) + ", " + fmt_num(t.release_s) + ") s";
    fail(path + ".release_s",
         (in_window ? "the profile is still 0 at the step ends in " + window + " (its ramp, ramp_s " +
                          fmt_num(t.ramp_s) + ", rises from 0 at start_s)"
                    : "no step end (a multiple k >= 1 of integrator.dt_s " + fmt_num(dt_s) + " s) falls in " + window) +
             ": profiles are sampled at step ends only, so this " + what +
             " would never act; widen the window or lower integrator.dt_s");
  }

  template <class T>
  void unique_names(const std::vector<T>& items, const std::string& list) const {
    std::map<std::string_view, std::size_t> seen;
    for (std::size_t i = 0; i < items.size(); ++i) {
      const auto [it, fresh] = seen.emplace(items[i].name, i);
      if (!fresh)
        fail(join_index(list, i) + ".name",
             "duplicate name " + printable(items[i].name) + " (also " + join_index(list, it->second) + ".name)");
    }
  }

  const Scene& s_;
  std::array<double, 3> extent_{};
  double tolerance_ = 0.0;
  long long total_cubes_ = 1;
};

// ---------------------------------------------------------------- documents

const yaml_util::DocumentKind kSceneDocument{"scene", "a scene needs at least an 'object' section"};

Scene build(const std::string& yaml_text, const std::string& source, const std::vector<std::string>& overrides) {
  return yaml_util::convert_document<SceneError>(yaml_text, source, overrides, kSceneDocument,
                                                 [&](const YAML::Node& root) {
                                                   Scene s = Converter(source).scene(root);
                                                   validate_scene(s);
                                                   s.overrides = overrides;
                                                   s.source_text = yaml_text;
                                                   return s;
                                                 });
}

std::string read_file(const std::string& path) {
  return yaml_util::read_text_file_as<SceneFileUnreadable>(path, kMaxSceneFileBytes, "scene file");
}

}  // namespace

void validate_scene(const Scene& s) { Validator(s).run(); }

Scene parse_scene(const std::string& yaml_text, const std::string& source_name) {
  return build(yaml_text, source_name, {});
}

Scene parse_scene_with_overrides(const std::string& yaml_text, const std::string& source_name,
                                 const std::vector<std::string>& overrides) {
  return build(yaml_text, source_name, overrides);
}

Scene load_scene_file(const std::string& path) { return build(read_file(path), path, {}); }

SceneError model_error(const Scene& scene, const SceneModelError& e) {
  std::vector<yaml_util::Override> parsed;
  for (const std::string& text : scene.overrides) {
    try {
      parsed.push_back(yaml_util::parse_override(text, scene.source, kSceneDocument));
    } catch (const std::exception&) {
      // It parsed when the scene was loaded; nothing to blame if not.
    }
  }
  return SceneError(scene.source, e.key_path(), yaml_util::blame_override(parsed, e.key_path(), e.reason()));
}

Scene load_scene_file_with_overrides(const std::string& path, const std::vector<std::string>& overrides) {
  return build(read_file(path), path, overrides);
}

std::vector<std::string> with_override_replacing(const std::vector<std::string>& overrides, const std::string& added,
                                                 const std::string& source) {
  std::string added_path;
  try {
    added_path = yaml_util::parse_override(added, source, kSceneDocument).path;
  } catch (const yaml_util::PathError& e) {
    throw SceneError(e.source(), e.key_path(), e.reason());
  }
  const auto moot = [&](const std::string& text) {
    std::string path;
    try {
      path = yaml_util::parse_override(text, source, kSceneDocument).path;
    } catch (const yaml_util::PathError&) {
      return false;  // it was applied before, so it parses; keep it if not
    }
    return yaml_util::path_within(path, added_path);
  };
  std::vector<std::string> out;
  for (const std::string& o : overrides)
    if (!moot(o)) out.push_back(o);
  out.push_back(added);
  return out;
}

}  // namespace tissue::scene