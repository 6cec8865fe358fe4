#include "scene/scene_yaml.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <exception>
#include <fstream>
#include <iostream>
#include <iterator>
#include <limits>
#include <memory>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "physics/body.hpp"
#include "physics/simulation.hpp"
#include "physics/spring_law.hpp"
#include "support/process_support.hpp"

namespace tissue::scene {
namespace {

using tissue::testing::TempDir;
using tissue::testing::write_text;

std::string scene_path(const std::string& file) { return std::string(TISSUE_SOURCE_DIR) + "/config/scenes/" + file; }

std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  EXPECT_TRUE(in) << "cannot open " << path;
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// A valid scene using every section; error cases are one edit away from it.
const std::string kBase = R"(name: base
object:
  cubes: [4, 4, 4]
  cube_size_m: 0.025
material:
  youngs_modulus_Pa: 5.0e4
  density_kg_per_m3: 100
  stiffness: isotropic
  damping: rayleigh
  rayleigh_alpha_per_s: 0.0
  rayleigh_beta_s: 0.003
gravity_m_per_s2: [0, 0, 0]
fixed:
  - region: {box: {min_m: [0, 0, 0], max_m: [0, 0.1, 0.1]}}
prescribed:
  - name: poke
    region: {sphere: {centre_m: [0.1, 0.05, 0.05], radius_m: 0.001}}
    displacement_m: [0, 0, -0.01]
    profile: {start_s: 0, ramp_s: 0.5, release_s: .inf}
loads:
  - name: tip
    region: {box: {min_m: [0.1, 0, 0], max_m: [0.1, 0.1, 0.1]}}
    total_force_N: [0, 0, -5]
    profile: {release_s: 1.0}
adaptivity:
  enabled: true
  criterion: strain_energy
  refine_threshold_Pa: 20
  simplify_factor: 0.25
  stretch_ratio: 1.05
  min_depth: 0
  max_depth: 3
  every_steps: 5
  max_ops_per_step: 64
  min_age_steps: 20
  midpoint_tolerance: 1.0e-3
integrator:
  kind: implicit
  dt_s: 0.001
  max_substeps: 1000
  substep_safety: 0.8
  explicit_energy_slack: 1.0
  cg_tolerance: 1.0e-6
  cg_max_iterations: 100
probes:
  - name: tip
    rest_m: [0.1, 0.05, 0.05]
)";

const std::string kMinimal = "object: {cubes: [4, 4, 4], cube_size_m: 0.025}\n";

// kBase with the one occurrence of `from` replaced by `to`.
std::string base_with(const std::string& from, const std::string& to) {
  const auto at = kBase.find(from);
  EXPECT_NE(at, std::string::npos) << "'" << from << "' is not in kBase";
  EXPECT_EQ(kBase.find(from, at + 1), std::string::npos) << "'" << from << "' is not unique in kBase";
  if (at == std::string::npos) return kBase;
  std::string out = kBase;
  out.replace(at, from.size(), to);
  return out;
}

// Parsing must throw a SceneError naming the source, exactly `key_path`, and
// containing `reason_word`. Returns the message for further checks.
std::string expect_error(const std::string& yaml, const std::string& key_path, const std::string& reason_word,
                         const std::vector<std::string>& overrides = {}) {
  try {
    parse_scene_with_overrides(yaml, "test.yaml", overrides);
  } catch (const SceneError& e) {
    const std::string what = e.what();
    EXPECT_EQ(e.source(), "test.yaml") << what;
    EXPECT_EQ(e.key_path(), key_path) << what;
    EXPECT_EQ(what.rfind("test.yaml: ", 0), 0u) << what;
    if (!key_path.empty()) {
      EXPECT_NE(what.find("test.yaml: " + key_path + ": "), std::string::npos) << what;
    }
    EXPECT_NE(e.reason().find(reason_word), std::string::npos) << what;
    EXPECT_NE(what.find(reason_word), std::string::npos) << what;
    return what;
  } catch (const std::exception& e) {
    ADD_FAILURE() << "expected SceneError, got another exception: " << e.what();
    return {};
  }
  ADD_FAILURE() << "expected SceneError at '" << key_path << "' (" << reason_word << "), but the scene parsed:\n"
                << yaml;
  return {};
}

// ------------------------------------------------------------ shipped scenes

TEST(SceneYaml, CantileverSceneLoadsWithThePapersValues) {
  const Scene s = load_scene_file(scene_path("cantilever.yaml"));
  EXPECT_EQ(s.source, scene_path("cantilever.yaml"));
  EXPECT_EQ(s.name, "cantilever");
  EXPECT_EQ(s.object.cubes, (std::array<int, 3>{4, 4, 4}));
  EXPECT_DOUBLE_EQ(s.object.cube_size_m, 0.025);
  EXPECT_DOUBLE_EQ(s.material.youngs_modulus_Pa, 5.0e4);
  EXPECT_DOUBLE_EQ(s.material.density_kg_per_m3, 100.0);
  EXPECT_EQ(s.material.stiffness, StiffnessLaw::kIsotropic);
  EXPECT_EQ(s.material.damping, DampingLaw::kRayleigh);
  EXPECT_DOUBLE_EQ(s.material.rayleigh_beta_s, 0.003);
  EXPECT_EQ(s.gravity_m_per_s2, (Vec3{0, 0, 0}));
  ASSERT_EQ(s.fixed.size(), 1u);
  EXPECT_EQ(s.fixed[0].region.kind, Region::Kind::kBox);
  EXPECT_EQ(s.fixed[0].region.min_m, (Vec3{0, 0, 0}));
  EXPECT_EQ(s.fixed[0].region.max_m, (Vec3{0, 0.1, 0.1}));
  EXPECT_TRUE(s.prescribed.empty());
  ASSERT_EQ(s.loads.size(), 1u);
  EXPECT_EQ(s.loads[0].region.kind, Region::Kind::kBox);
  EXPECT_EQ(s.loads[0].region.min_m, (Vec3{0.1, 0, 0}));
  EXPECT_EQ(s.loads[0].region.max_m, (Vec3{0.1, 0.1, 0.1}));
  EXPECT_EQ(s.loads[0].total_force_N, (Vec3{0, 0, -5}));
  EXPECT_DOUBLE_EQ(s.loads[0].profile.start_s, 0.0);
  EXPECT_DOUBLE_EQ(s.loads[0].profile.ramp_s, 0.0);
  EXPECT_DOUBLE_EQ(s.loads[0].profile.release_s, 1.0);
  EXPECT_EQ(s.loads[0].profile.at(0.5), 1.0);
  EXPECT_EQ(s.loads[0].profile.at(1.0), 0.0);
  EXPECT_TRUE(s.adaptivity.enabled);
  EXPECT_EQ(s.adaptivity.criterion, RefineCriterion::kStrainEnergy);
  EXPECT_DOUBLE_EQ(s.adaptivity.refine_threshold_Pa, 20.0);
  EXPECT_EQ(s.adaptivity.max_depth, 3);
  EXPECT_EQ(s.adaptivity.every_steps, 5);
  EXPECT_EQ(s.integrator.kind, IntegratorKind::kImplicit);
  EXPECT_DOUBLE_EQ(s.integrator.dt_s, 0.001);
  ASSERT_EQ(s.probes.size(), 2u);
  EXPECT_EQ(s.probes[0].name, "tip");
  EXPECT_EQ(s.probes[0].rest_m, (Vec3{0.1, 0.05, 0.0}));
  EXPECT_EQ(s.probes[1].name, "tip_centre");
  EXPECT_EQ(s.probes[1].rest_m, (Vec3{0.1, 0.05, 0.05}));
}

TEST(SceneYaml, ContactSceneLoadsWithThePapersValues) {
  const Scene s = load_scene_file(scene_path("contact.yaml"));
  EXPECT_EQ(s.name, "contact");
  EXPECT_EQ(s.object.cubes, (std::array<int, 3>{4, 4, 4}));
  EXPECT_DOUBLE_EQ(s.object.cube_size_m, 0.025);
  EXPECT_DOUBLE_EQ(s.material.youngs_modulus_Pa, 5.0e4);
  EXPECT_DOUBLE_EQ(s.material.density_kg_per_m3, 100.0);
  ASSERT_EQ(s.fixed.size(), 1u);
  EXPECT_EQ(s.fixed[0].region.max_m, (Vec3{0, 0.1, 0.1}));
  EXPECT_TRUE(s.loads.empty());
  ASSERT_EQ(s.prescribed.size(), 1u);
  const PrescribedSpec& p = s.prescribed[0];
  EXPECT_EQ(p.region.kind, Region::Kind::kSphere);
  EXPECT_EQ(p.region.centre_m, (Vec3{0.1, 0.05, 0.05}));
  EXPECT_DOUBLE_EQ(p.region.radius_m, 1e-4);
  EXPECT_EQ(p.displacement_m, (Vec3{0, 0, -0.01}));
  EXPECT_DOUBLE_EQ(p.profile.ramp_s, 0.5);
  EXPECT_TRUE(std::isinf(p.profile.release_s));
  EXPECT_DOUBLE_EQ(p.profile.at(0.25), 0.5);
  EXPECT_TRUE(s.adaptivity.enabled);
  EXPECT_DOUBLE_EQ(s.adaptivity.refine_threshold_Pa, 20.0);
  EXPECT_EQ(s.adaptivity.max_depth, 3);
  ASSERT_EQ(s.probes.size(), 1u);
  EXPECT_EQ(s.probes[0].rest_m, (Vec3{0.1, 0.05, 0.05}));
}

TEST(SceneYaml, BeamSceneLoadsWithTheBenchmarkValues) {
  const Scene s = load_scene_file(scene_path("beam.yaml"));
  EXPECT_EQ(s.name, "beam");
  EXPECT_EQ(s.object.cubes, (std::array<int, 3>{8, 2, 2}));
  EXPECT_DOUBLE_EQ(s.object.cube_size_m, 0.05);
  EXPECT_DOUBLE_EQ(s.material.youngs_modulus_Pa, 5.0e4);
  EXPECT_DOUBLE_EQ(s.material.density_kg_per_m3, 100.0);
  EXPECT_DOUBLE_EQ(s.material.rayleigh_beta_s, 0.01);
  EXPECT_EQ(s.gravity_m_per_s2, (Vec3{0, 0, 0}));
  ASSERT_EQ(s.fixed.size(), 1u);
  EXPECT_EQ(s.fixed[0].region.max_m, (Vec3{0, 0.1, 0.1}));
  ASSERT_EQ(s.loads.size(), 1u);
  EXPECT_EQ(s.loads[0].region.min_m, (Vec3{0.4, 0, 0}));
  EXPECT_EQ(s.loads[0].region.max_m, (Vec3{0.4, 0.1, 0.1}));
  EXPECT_EQ(s.loads[0].total_force_N, (Vec3{0, 0, -0.05}));
  EXPECT_EQ(s.loads[0].profile.at(0.0), 1.0);  // constant
  EXPECT_EQ(s.loads[0].profile.at(1e6), 1.0);
  EXPECT_FALSE(s.adaptivity.enabled);
  EXPECT_EQ(s.integrator.kind, IntegratorKind::kImplicit);
  EXPECT_DOUBLE_EQ(s.integrator.dt_s, 0.001);
  ASSERT_EQ(s.probes.size(), 1u);
  EXPECT_EQ(s.probes[0].name, "tip");
  EXPECT_EQ(s.probes[0].rest_m, (Vec3{0.4, 0.05, 0.05}));
}

// ------------------------------------------------------- values and defaults

TEST(SceneYaml, EveryKeyOfTheBaseSceneIsRead) {
  const Scene s = parse_scene(kBase, "test.yaml");
  EXPECT_EQ(s.source, "test.yaml");
  EXPECT_EQ(s.name, "base");
  EXPECT_DOUBLE_EQ(s.material.rayleigh_beta_s, 0.003);  // not the struct default 0.01
  ASSERT_EQ(s.prescribed.size(), 1u);
  EXPECT_EQ(s.prescribed[0].name, "poke");
  EXPECT_DOUBLE_EQ(s.prescribed[0].region.radius_m, 0.001);
  EXPECT_TRUE(std::isinf(s.prescribed[0].profile.release_s));
  EXPECT_TRUE(s.adaptivity.enabled);
  EXPECT_DOUBLE_EQ(s.adaptivity.refine_threshold_Pa, 20.0);  // not the struct default 4
  EXPECT_DOUBLE_EQ(s.adaptivity.midpoint_tolerance, 1e-3);
  EXPECT_EQ(s.adaptivity.min_age_steps, 20);
  EXPECT_DOUBLE_EQ(s.integrator.cg_tolerance, 1e-6);
  EXPECT_EQ(s.integrator.cg_max_iterations, 100);

  EXPECT_EQ(s.integrator.cg_preconditioner, CgPreconditioner::kAuto);  // the default
  EXPECT_EQ(parse_scene(base_with("cg_max_iterations: 100", "cg_max_iterations: 100\n  cg_preconditioner: jacobi"),
                        "test.yaml")
                .integrator.cg_preconditioner,
            CgPreconditioner::kJacobi);
  EXPECT_EQ(
      parse_scene(base_with("cg_max_iterations: 100", "cg_max_iterations: 100\n  cg_preconditioner: auto"), "test.yaml")
          .integrator.cg_preconditioner,
      CgPreconditioner::kAuto);
  const Scene p = parse_scene(
      base_with("cg_max_iterations: 100", "cg_max_iterations: 5\n  cg_preconditioner: two_level"), "test.yaml");
  EXPECT_EQ(p.integrator.cg_preconditioner, CgPreconditioner::kTwoLevel);
  expect_error(base_with("cg_max_iterations: 100", "cg_max_iterations: 5\n  cg_preconditioner: multigrid"),
               "integrator.cg_preconditioner", "unknown value");
  EXPECT_EQ(s.integrator.explicit_precision, ExplicitPrecision::kDouble);  // the default
  EXPECT_EQ(parse_scene(base_with("cg_max_iterations: 100", "cg_max_iterations: 100\n  explicit_precision: float"),
                        "test.yaml")
                .integrator.explicit_precision,
            ExplicitPrecision::kFloat);
  expect_error(base_with("cg_max_iterations: 100", "cg_max_iterations: 100\n  explicit_precision: half"),
               "integrator.explicit_precision", "unknown value");
  const Scene t = parse_scene(base_with("kind: implicit", "kind: projective") + "", "test.yaml");
  EXPECT_EQ(t.integrator.kind, IntegratorKind::kProjective);
  const Scene u = parse_scene(base_with("criterion: strain_energy", "criterion: stretch"), "test.yaml");
  EXPECT_EQ(u.adaptivity.criterion, RefineCriterion::kStretch);
  const Scene v = parse_scene(
      base_with("stiffness: isotropic\n  damping: rayleigh", "stiffness: paper\n  damping: paper"), "test.yaml");
  EXPECT_EQ(v.material.stiffness, StiffnessLaw::kPaper);
  EXPECT_EQ(v.material.damping, DampingLaw::kPaper);
}

TEST(SceneYaml, OmittedSectionsTakeTheStructDefaultsAndTheNameIsTheFileStem) {
  const Scene s = parse_scene(kMinimal, "some/dir/my_scene.yaml");
  const Scene d;
  EXPECT_EQ(s.name, "my_scene");
  EXPECT_EQ(s.material.youngs_modulus_Pa, d.material.youngs_modulus_Pa);
  EXPECT_EQ(s.material.rayleigh_beta_s, d.material.rayleigh_beta_s);
  EXPECT_EQ(s.adaptivity.enabled, d.adaptivity.enabled);
  EXPECT_EQ(s.adaptivity.refine_threshold_Pa, d.adaptivity.refine_threshold_Pa);
  EXPECT_EQ(s.adaptivity.max_depth, d.adaptivity.max_depth);
  EXPECT_EQ(s.integrator.kind, d.integrator.kind);
  EXPECT_EQ(s.integrator.dt_s, d.integrator.dt_s);
  EXPECT_EQ(s.gravity_m_per_s2, d.gravity_m_per_s2);
  EXPECT_TRUE(s.fixed.empty() && s.loads.empty() && s.prescribed.empty() && s.probes.empty());

  // Unnamed list entries get distinct default names.
  const Scene n = parse_scene(kMinimal + "probes: [{rest_m: [0, 0, 0]}, {rest_m: [0.1, 0.1, 0.1]}]\n", "x.yaml");
  ASSERT_EQ(n.probes.size(), 2u);
  EXPECT_EQ(n.probes[0].name, "probe0");
  EXPECT_EQ(n.probes[1].name, "probe1");
}

TEST(SceneYaml, NumbersFollowYamlSpelling) {
  // Integers are accepted where a real is expected, and .inf for release_s.
  const Scene s = parse_scene(kMinimal +
                                  "gravity_m_per_s2: [+2., .5, -9.81e0]\n"
                                  "loads: [{region: {box: {min_m: [0,0,0], max_m: [1,1,1]}},"
                                  " total_force_N: [1, 2, 3], profile: {release_s: .Inf}}]\n",
                              "x.yaml");
  EXPECT_EQ(s.gravity_m_per_s2, (Vec3{2, 0.5, -9.81}));
  EXPECT_TRUE(std::isinf(s.loads[0].profile.release_s));
  // But an integer field does not take a real, nor a number a quoted string.
  expect_error(base_with("max_depth: 3", "max_depth: 2.5"), "adaptivity.max_depth", "expected an integer");
  expect_error(base_with("youngs_modulus_Pa: 5.0e4", "youngs_modulus_Pa: \"5.0e4\""), "material.youngs_modulus_Pa",
               "expected a number");
  expect_error(base_with("youngs_modulus_Pa: 5.0e4", "youngs_modulus_Pa: 1e999"), "material.youngs_modulus_Pa",
               "out of range");
  expect_error(base_with("max_substeps: 1000", "max_substeps: 99999999999"), "integrator.max_substeps", "out of range");
  expect_error(base_with("dt_s: 0.001", "dt_s: 1ms"), "integrator.dt_s", "expected a number");
}

// ------------------------------------------------------------------ errors

TEST(SceneYamlErrors, MessageFormatIsSourceKeyPathReason) {
  try {
    parse_scene(base_with("youngs_modulus_Pa: 5.0e4", "youngs_modulus_Pa: -5"), "config/scenes/x.yaml");
    FAIL() << "no error";
  } catch (const SceneError& e) {
    EXPECT_STREQ(e.what(), "config/scenes/x.yaml: material.youngs_modulus_Pa: must be > 0 (got -5)");
    EXPECT_EQ(e.source(), "config/scenes/x.yaml");
    EXPECT_EQ(e.key_path(), "material.youngs_modulus_Pa");
    EXPECT_EQ(e.reason(), "must be > 0 (got -5)");
  }
}

// The float explicit rung holds 1/mass and stiffness in float: a material
// within double's range but beyond float's is refused there (it froze every
// free node, 1/m rounding to 0.0f, while the steps said ok), and accepted in
// double or by the other integrators.
TEST(SceneYamlErrors, FloatExplicitPrecisionRefusesQuantitiesBeyondFloat) {
  // Within the loader's material bounds (E <= 1e13 Pa, density <= 1e5 kg/m³)
  // and float's lengths, the springs leave float's range at the soft end and
  // the masses at the large end: cubes of 1e12 m weigh 1e41 kg.
  const auto scene_with = [](const std::string& integrator, const std::string& modulus, const std::string& density,
                             const std::string& cube_size = "0.025") {
    std::string yaml = base_with("kind: implicit", integrator);
    yaml.replace(yaml.find("youngs_modulus_Pa: 5.0e4"), 24, "youngs_modulus_Pa: " + modulus);
    yaml.replace(yaml.find("density_kg_per_m3: 100"), 22, "density_kg_per_m3: " + density);
    yaml.replace(yaml.find("cube_size_m: 0.025"), 18, "cube_size_m: " + cube_size);
    return yaml;
  };
  const std::string in_float = "kind: explicit\n  explicit_precision: float";
  const std::string in_double = "kind: explicit\n  explicit_precision: double";
  const std::string what = expect_error(scene_with(in_float, "1e-30", "100"), "integrator.explicit_precision", "float");
  EXPECT_NE(what.find("N/m"), std::string::npos) << what;  // names the quantity out of range
  EXPECT_NO_THROW(parse_scene(scene_with(in_double, "1e-30", "100"), "test.yaml"));
  EXPECT_NO_THROW(parse_scene(scene_with("kind: implicit", "1e-30", "100"), "test.yaml"));
  // The mass alone: 1/m would round to 0.0f.
  const std::string mass =
      expect_error(scene_with(in_float, "5.0e4", "1e5", "1e12"), "integrator.explicit_precision", "kg");
  EXPECT_NE(mass.find("masses"), std::string::npos) << mass;
  EXPECT_NO_THROW(parse_scene(scene_with(in_double, "5.0e4", "1e5", "1e12"), "test.yaml"));
  EXPECT_NO_THROW(parse_scene(scene_with(in_float, "5.0e4", "100"), "test.yaml"));  // an ordinary scene
}

TEST(SceneYamlErrors, UnknownTopLevelKey) {
  const std::string what = expect_error(kBase + "colour: red\n", "colour", "unknown key");
  EXPECT_NE(what.find("allowed keys: name, object, material"), std::string::npos) << what;
}

TEST(SceneYamlErrors, UnknownNestedKeyListsTheAllowedKeysAndSuggestsOne) {
  const std::string what =
      expect_error(base_with("youngs_modulus_Pa:", "youngs_modulus:"), "material.youngs_modulus", "unknown key");
  EXPECT_NE(what.find("did you mean 'youngs_modulus_Pa'"), std::string::npos) << what;
  EXPECT_NE(what.find("allowed keys: youngs_modulus_Pa, density_kg_per_m3"), std::string::npos) << what;
  expect_error(base_with("{release_s: 1.0}", "{release: 1.0}"), "loads[0].profile.release", "unknown key");
  expect_error(base_with("centre_m:", "center_m:"), "prescribed[0].region.sphere.center_m", "unknown key");
}

TEST(SceneYamlErrors, WrongYamlType) {
  expect_error(base_with("dt_s: 0.001", "dt_s: {value: 0.001}"), "integrator.dt_s", "expected a number, got a map");
  expect_error(base_with("enabled: true", "enabled: \"true\""), "adaptivity.enabled", "expected a boolean");
  expect_error(base_with("enabled: true", "enabled: 1"), "adaptivity.enabled", "expected a boolean");
  expect_error(base_with("cube_size_m: 0.025", "cube_size_m: [0.025]"), "object.cube_size_m", "expected a number");
  expect_error(base_with("kind: implicit", "kind: [implicit]"), "integrator.kind", "expected one of");
  expect_error(base_with("name: base", "name: {a: b}"), "name", "expected a string");
  expect_error(kBase + "material: 5\n", "material", "duplicate key");
  expect_error(base_with("material:\n  youngs_modulus_Pa: 5.0e4", "mat:\n  youngs_modulus_Pa: 5.0e4"), "mat",
               "unknown key");
  expect_error(base_with("fixed:\n  - region:", "fixed:\n  region:"), "fixed", "expected a list");
  expect_error(base_with("dt_s: 0.001", "dt_s:"), "integrator.dt_s", "got null");
  expect_error("- object\n", "", "must be a map");
}

TEST(SceneYamlErrors, WrongListLength) {
  expect_error(base_with("total_force_N: [0, 0, -5]", "total_force_N: [0, -5]"), "loads[0].total_force_N",
               "expected a list of 3 numbers, got 2 items");
  expect_error(base_with("cubes: [4, 4, 4]", "cubes: [4, 4, 4, 4]"), "object.cubes", "3 integers");
}

TEST(SceneYamlErrors, NonFiniteNumbers) {
  expect_error(base_with("youngs_modulus_Pa: 5.0e4", "youngs_modulus_Pa: .nan"), "material.youngs_modulus_Pa",
               "finite");
  expect_error(base_with("total_force_N: [0, 0, -5]", "total_force_N: [0, 0, .inf]"), "loads[0].total_force_N[2]",
               "finite");
  expect_error(base_with("gravity_m_per_s2: [0, 0, 0]", "gravity_m_per_s2: [0, -.inf, 0]"), "gravity_m_per_s2[1]",
               "finite");
  expect_error(base_with("release_s: .inf", "release_s: .nan"), "prescribed[0].profile.release_s", "nan");
}

TEST(SceneYamlErrors, PhysicallyMeaninglessValues) {
  expect_error(base_with("youngs_modulus_Pa: 5.0e4", "youngs_modulus_Pa: 0"), "material.youngs_modulus_Pa",
               "must be > 0 (got 0)");
  expect_error(base_with("density_kg_per_m3: 100", "density_kg_per_m3: -1"), "material.density_kg_per_m3",
               "must be > 0 (got -1)");
  expect_error(base_with("dt_s: 0.001", "dt_s: 0"), "integrator.dt_s", "must be > 0");
  expect_error(base_with("dt_s: 0.001", "dt_s: 2"), "integrator.dt_s", "must be <= 1");
  expect_error(base_with("cubes: [4, 4, 4]", "cubes: [4, -4, 4]"), "object.cubes[1]", "must be >= 1 (got -4)");
  expect_error(base_with("cube_size_m: 0.025", "cube_size_m: 0"), "object.cube_size_m", "must be > 0");
  // The object's extent overflows: the cube size is to blame, not "object".
  expect_error(base_with("cube_size_m: 0.025", "cube_size_m: 1e308"), "object.cube_size_m",
               "the object's size (object.cubes x cube_size_m) overflows: 4 x 1e+308 m");
  expect_error(base_with("rayleigh_beta_s: 0.003", "rayleigh_beta_s: -0.1"), "material.rayleigh_beta_s", ">= 0");
  expect_error(base_with("radius_m: 0.001", "radius_m: -0.001"), "prescribed[0].region.sphere.radius_m", ">= 0");
  expect_error(base_with("ramp_s: 0.5", "ramp_s: -0.5"), "prescribed[0].profile.ramp_s", ">= 0");
  expect_error(base_with("{release_s: 1.0}", "{start_s: 2, release_s: 1.0}"), "loads[0].profile.release_s",
               "must be > start_s");
  expect_error(base_with("min_depth: 0", "min_depth: 4"), "adaptivity.min_depth", "must be <= max_depth");
  // The starting mesh is refined to min_depth everywhere: bounded like the cubes.
  expect_error(base_with("min_depth: 0\n  max_depth: 3", "min_depth: 30\n  max_depth: 30"), "adaptivity.min_depth",
               "the starting mesh would have 412316860416 tetrahedra (64 cubes x 6 x 2^30), more than 20000000");
  EXPECT_NO_THROW(parse_scene(base_with("min_depth: 0\n  max_depth: 3", "min_depth: 12\n  max_depth: 12"), "ok.yaml"));
  expect_error(base_with("max_depth: 3", "max_depth: 31"), "adaptivity.max_depth", "<= 30");
  // A negative max_depth was reported at min_depth ("must be <= max_depth (-1) (got 0)").
  expect_error(base_with("max_depth: 3", "max_depth: -1"), "adaptivity.max_depth", "must be >= 0 (got -1)");
  expect_error(base_with("simplify_factor: 0.25", "simplify_factor: 1"), "adaptivity.simplify_factor", "(0, 1)");
  expect_error(base_with("stretch_ratio: 1.05", "stretch_ratio: 1"), "adaptivity.stretch_ratio", "> 1");
  expect_error(base_with("every_steps: 5", "every_steps: 0"), "adaptivity.every_steps", ">= 1");
  expect_error(base_with("substep_safety: 0.8", "substep_safety: 1.5"), "integrator.substep_safety", "(0, 1]");
  // The explicit rung's energy bound: a fraction above the budget, > 0 so
  // that its O(h omega) swing is never refused, finite so that it bounds.
  expect_error(base_with("explicit_energy_slack: 1.0", "explicit_energy_slack: 0"), "integrator.explicit_energy_slack",
               "must be > 0 (got 0)");
  expect_error(base_with("explicit_energy_slack: 1.0", "explicit_energy_slack: -0.5"),
               "integrator.explicit_energy_slack", "must be > 0");
  expect_error(base_with("explicit_energy_slack: 1.0", "explicit_energy_slack: .inf"),
               "integrator.explicit_energy_slack", "finite");
  expect_error(base_with("explicit_energy_slack: 1.0", "explicit_energy_slack: many"),
               "integrator.explicit_energy_slack", "");
  expect_error(base_with("cg_tolerance: 1.0e-6", "cg_tolerance: 1"), "integrator.cg_tolerance", "(0, 1)");
}

TEST(SceneYamlErrors, BadEnumListsTheAllowedValues) {
  const std::string what = expect_error(base_with("kind: implicit", "kind: implict"), "integrator.kind",
                                        "allowed values: explicit, implicit, projective");
  EXPECT_NE(what.find("'implict'"), std::string::npos) << what;
  expect_error(base_with("stiffness: isotropic", "stiffness: iso"), "material.stiffness",
               "allowed values: isotropic, paper");
}

// Profiles are sampled at step ends, k · dt_s (Simulation::step): a window
// holding none where the profile is above 0 never acts. dt_s 0.01 with
// {start_s: 0.002, release_s: 0.008} ran, did no work and exited 0.
TEST(SceneYamlErrors, AProfileThatActsAtNoStepEndIsRefused) {
  expect_error(kBase, "loads[0].profile.release_s",
               "no step end (a multiple k >= 1 of integrator.dt_s 0.01 s) falls in [start_s, release_s) = [0.002, "
               "0.008) s: profiles are sampled at step ends only, so this force would never act",
               {"integrator.dt_s=0.01", "loads[0].profile.start_s=0.002", "loads[0].profile.release_s=0.008"});
  // Released before the first step end.
  expect_error(kBase, "loads[0].profile.release_s", "falls in [start_s, release_s) = [0, 5e-04) s",
               {"loads[0].profile.release_s=0.0005"});
  // A ramp is 0 at start_s: the one step end in the window is no use.
  expect_error(kBase, "prescribed[0].profile.release_s",
               "the profile is still 0 at the step ends in [start_s, release_s) = [0.01, 0.015) s (its ramp, ramp_s "
               "0.5, rises from 0 at start_s): profiles are sampled at step ends only, so this displacement would "
               "never act",
               {"integrator.dt_s=0.01", "prescribed[0].profile.start_s=0.01", "prescribed[0].profile.release_s=0.015"});
  // Step ends are the step count times dt_s, as the simulation forms them:
  // 3 x 0.1 is 0.30000000000000004, not in [0.3, 0.30000000000000004).
  expect_error(
      kBase, "loads[0].profile.release_s", "[0.3, 0.30000000000000004)",
      {"integrator.dt_s=0.1", "loads[0].profile.start_s=0.3", "loads[0].profile.release_s=0.30000000000000004"});

  // One step end in the window is enough, and the simulation acts there:
  // the load does work in the step ending at 0.02 s and in no other.
  const Scene one_step = parse_scene_with_overrides(
      kBase, "one_step.yaml",
      {"integrator.dt_s=0.01", "loads[0].profile.start_s=0.02", "loads[0].profile.release_s=0.0200001"});
  physics::Simulation sim(one_step);
  double work_before_J = 0.0;
  for (int step = 1; step <= 3; ++step) {
    ASSERT_TRUE(sim.step().ok);
    const double work_J = sim.counters().external_work_J;
    if (step == 2)
      EXPECT_GT(std::fabs(work_J - work_before_J), 0.0) << "the step ending at 0.02 s";
    else
      EXPECT_EQ(work_J, work_before_J) << "the step ending at " << sim.time_s() << " s";
    work_before_J = work_J;
  }
  // A ramp from start_s acts from the next step end on, if the window holds it.
  EXPECT_NO_THROW(parse_scene_with_overrides(
      kBase, "ok.yaml",
      {"integrator.dt_s=0.01", "prescribed[0].profile.start_s=0.01", "prescribed[0].profile.release_s=0.0200001"}));
  EXPECT_NO_THROW(parse_scene_with_overrides(
      kBase, "ok.yaml", {"integrator.dt_s=0.1", "loads[0].profile.start_s=0.3", "loads[0].profile.release_s=0.31"}));
}

TEST(SceneYamlErrors, Regions) {
  expect_error(base_with("max_m: [0, 0.1, 0.1]", "max_m: [-0.01, 0.1, 0.1]"), "fixed[0].region.box",
               "min_m[0] > max_m[0]");
  expect_error(base_with("{box: {min_m: [0.1, 0, 0], max_m: [0.1, 0.1, 0.1]}}",
                         "{box: {min_m: [0.5, 0, 0], max_m: [0.6, 0.1, 0.1]}}"),
               "loads[0].region", "outside the object");
  expect_error(base_with("centre_m: [0.1, 0.05, 0.05]", "centre_m: [0.1, 0.05, 0.2]"), "prescribed[0].region",
               "outside the object");
  expect_error(base_with("rest_m: [0.1, 0.05, 0.05]", "rest_m: [1.0, 0.05, 0.05]"), "probes[0].rest_m",
               "outside the object");
  expect_error(base_with("{box: {min_m: [0.1, 0, 0], max_m: [0.1, 0.1, 0.1]}}", "{}"), "loads[0].region",
               "exactly one of 'box' or 'sphere'");
  expect_error(
      base_with("{box: {min_m: [0.1, 0, 0], max_m: [0.1, 0.1, 0.1]}}",
                "{box: {min_m: [0.1, 0, 0], max_m: [0.1, 0.1, 0.1]}, sphere: {centre_m: [0,0,0], radius_m: 1}}"),
      "loads[0].region", "got both");
  expect_error(base_with("min_m: [0.1, 0, 0], ", ""), "loads[0].region.box.min_m", "missing required key");
  // A sphere far away whose numbers square past the largest double: its
  // squared distance and reach were both inf, and it passed as touching.
  const std::string far =
      base_with("centre_m: [0.1, 0.05, 0.05], radius_m: 0.001", "centre_m: [1e308, 1e308, 1e308], radius_m: 1e308");
  expect_error(far, "prescribed[0].region", "outside the object");
  EXPECT_NO_THROW(parse_scene(base_with("centre_m: [0.1, 0.05, 0.05]", "centre_m: [0.05, 0.05, 0.05]"), "t.yaml"));
  // Touching the box at a face, edge or corner is inside.
  EXPECT_NO_THROW(parse_scene(base_with("rest_m: [0.1, 0.05, 0.05]", "rest_m: [0.1, 0.1, 0.1]"), "test.yaml"));
  EXPECT_NO_THROW(parse_scene(base_with("centre_m: [0.1, 0.05, 0.05]", "centre_m: [0.101, 0.05, 0.05]"), "t.yaml"));
}

// The scene check lets a probe lie outside the box by rounding
// (physics::kProbeOutsideBoxTolerance of its largest extent) and the
// Simulation moves such a probe onto the box, with twice that room, since the
// two measure the box differently (cubes x cube_size_m, the mesh's lattice
// units x the unit's length). The one constant keeps them together: the
// farthest point the check accepts past every face, low and high, is located
// in a mesh refined to depth 6 (tets 2^-6 of a cube, where a fixed-tolerance
// locator refused 0.5 nm) and reads a uniform shift of the body exactly.
TEST(SceneYaml, EveryProbeTheCheckAcceptsIsLocatedAtEveryDepth) {
  struct Box {
    std::array<int, 3> cubes;
    double cube_size_m;
  };
  for (const Box& box : {Box{{512, 1, 1}, 0.001}, Box{{3, 7, 5}, 0.1 / 3}, Box{{4, 4, 4}, 0.025}}) {
    Scene s = parse_scene(kMinimal, "probe.yaml");
    s.object.cubes = box.cubes;
    s.object.cube_size_m = box.cube_size_m;
    s.adaptivity.min_depth = 6;
    s.adaptivity.max_depth = 6;
    const auto accepted = [&](const Vec3& rest_m) {
      Scene t = s;
      t.probes = {{"edge", rest_m}};
      try {
        validate_scene(t);
        return true;
      } catch (const SceneError&) {
        return false;
      }
    };
    const double largest_m = box.cube_size_m * *std::max_element(box.cubes.begin(), box.cubes.end());
    for (int a = 0; a < 3; ++a) {
      const double extent_m = box.cubes[a] * box.cube_size_m;
      Vec3 centre_m{};
      for (int b = 0; b < 3; ++b) centre_m[b] = 0.5 * box.cubes[b] * box.cube_size_m;
      for (const double side : {-1.0, 1.0}) {
        // From the stated edge, one ulp at a time to the last point accepted.
        Vec3 rest_m = centre_m;
        double& x = rest_m[a];
        x = side > 0 ? extent_m + physics::kProbeOutsideBoxTolerance * largest_m
                     : -physics::kProbeOutsideBoxTolerance * largest_m;
        const double outward = side * std::numeric_limits<double>::infinity();
        for (int i = 0; i < 64 && !accepted(rest_m); ++i) x = std::nextafter(x, -outward);
        ASSERT_TRUE(accepted(rest_m)) << "axis " << a << ": nothing accepted near the edge";
        for (int i = 0; i < 64; ++i) {
          Vec3 next_m = rest_m;
          next_m[a] = std::nextafter(x, outward);
          if (!accepted(next_m)) break;
          x = next_m[a];
        }
        Vec3 farther_m = rest_m;
        farther_m[a] = side * std::abs(x) * (1.0 + 1e-6);
        ASSERT_FALSE(accepted(farther_m)) << "the check accepts any point";
        std::ostringstream where;
        where.precision(17);
        where << box.cubes[0] << "x" << box.cubes[1] << "x" << box.cubes[2] << " cubes of " << box.cube_size_m
              << " m, axis " << a << ", probe at " << x << " m (box [0, " << extent_m << "])";
        Scene t = s;
        t.probes = {{"edge", rest_m}};
        std::unique_ptr<physics::Simulation> sim;
        try {
          sim = std::make_unique<physics::Simulation>(t);
        } catch (const std::exception& e) {
          ADD_FAILURE() << where.str() << ": " << e.what();
          continue;
        }
        physics::Body& body = sim->mutable_body();
        const physics::Vec3 shift_m(1e-4, -2e-4, 3e-4);
        body.mesh().for_each_node(
            [&](physics::NodeId n, const mesh::Node&) { body.x_m[n] = body.rest_m[n] + shift_m; });
        const physics::Vec3 u = sim->probe_displacement_m(0);
        EXPECT_NEAR((u - shift_m).norm(), 0.0, 1e-15) << where.str() << ": read " << u.transpose();
      }
    }
  }
}

TEST(SceneYamlErrors, DuplicateNames) {
  const std::string what =
      expect_error(kBase + "  - name: tip\n    rest_m: [0, 0, 0]\n", "probes[1].name", "duplicate");
  EXPECT_NE(what.find("probes[0].name"), std::string::npos) << what;
  expect_error(base_with("profile: {release_s: 1.0}\n",
                         "profile: {release_s: 1.0}\n  - name: tip\n    region: "
                         "{box: {min_m: [0,0,0], max_m: [0,0,0]}}\n    "
                         "total_force_N: [0, 0, 1]\n"),
               "loads[1].name", "duplicate");
  expect_error(base_with("name: tip\n    rest_m", "name: \"tip top\"\n    rest_m"), "probes[0].name", "bad name");
  // The same name in different lists is fine: kBase has a load and a probe called "tip".
  EXPECT_NO_THROW(parse_scene(kBase, "test.yaml"));
}

// The scene's own name is free text (spaces, any script) but must be text:
// it reaches the batch report's JSON, the session's UTF-8 events and
// terminals. A name that was not UTF-8 used to end a batch run after its
// last step with an internal error and no report.
TEST(SceneYamlErrors, TheScenesNameMustBeCleanText) {
  EXPECT_EQ(parse_scene(base_with("name: base", "name: Liver poke 3 (Stoß)"), "test.yaml").name, "Liver poke 3 (Stoß)");
  expect_error(base_with("name: base", "name: x\xff"), "name", "not UTF-8");  // a raw byte 0xff
  expect_error(base_with("name: base", "name: \"red\\e[31m\""), "name", "control character");
  expect_error(base_with("name: base", "name: \"two\\nlines\""), "name", "control character");
  expect_error(base_with("name: base", "name: " + std::string(201, 'n')), "name", "too long");
  // Through --set, blamed on it.
  const std::string what = expect_error(kBase, "name", "not UTF-8", {"name=x\xff"});
  EXPECT_NE(what.find("(set by the override"), std::string::npos) << what;
  // A file name that is not text gives the default name instead of an error.
  const std::string no_name = base_with("name: base\n", "");
  EXPECT_EQ(parse_scene(no_name, "/tmp/odd\xff.yaml").name, "scene");
  EXPECT_EQ(parse_scene(no_name, "/tmp/liver.yaml").name, "liver");
}

// Values that pass "positive" but would hang a run: a step of 1e-300 s (time
// never moved), 2^31 sub-steps in one uninterruptible step, 200,000 probes
// located after every step.
TEST(SceneYamlErrors, ValuesThatWouldHangARunAreRefused) {
  expect_error(kBase, "integrator.dt_s", "must be >= 1e-07", {"integrator.dt_s=1e-300"});
  expect_error(kBase, "integrator.max_substeps", "must be <= 100000", {"integrator.max_substeps=2147483647"});
  std::string many = "probes:\n";
  for (int i = 0; i < 1001; ++i) many += "  - {name: p" + std::to_string(i) + ", rest_m: [0.05, 0.05, 0.05]}\n";
  std::string text = kBase.substr(0, kBase.find("probes:")) + many;
  expect_error(text, "probes", "too many (1001, at most 1000)");
  // So are the region lists, each tested against the mesh at every change
  // (20,000 loads on 20³ cubes took 3 s a step).
  for (const char* list : {"fixed", "prescribed", "loads"}) {
    std::string regions = std::string(list) + ":\n";
    for (int i = 0; i < 1001; ++i)
      regions += std::string("  - {region: {box: {min_m: [0, 0, 0], max_m: [0.01, 0.01, 0.01]}}") +
                 (std::string(list) == "fixed" ? "" : ", name: r" + std::to_string(i)) +
                 (std::string(list) == "prescribed" ? ", displacement_m: [0, 0, 0]" : "") +
                 (std::string(list) == "loads" ? ", total_force_N: [0, 0, 0]" : "") + "}\n";
    expect_error(kMinimal + regions, list, "too many (1001, at most 1000)");
  }
  EXPECT_EQ(parse_scene_with_overrides(kBase, "test.yaml", {"adaptivity.max_tets=5000"}).adaptivity.max_tets, 5000);
  expect_error(kBase, "adaptivity.max_tets", ">= 1", {"adaptivity.max_tets=0"});
}

// What the mesh's 21-bit lattice keys hold is refused at the scene's key; the
// mesh used to refuse it as "mesh box: cube counts ... overflow".
TEST(SceneYamlErrors, BoxesTheLatticeCannotHoldNameTheKey) {
  expect_error("object: {cubes: [1, 2000000, 1], cube_size_m: 0.025}\n", "object.cubes[1]",
               "must be <= 524287 cubes along one axis");
  EXPECT_NO_THROW(parse_scene_with_overrides("object: {cubes: [524287, 1, 1], cube_size_m: 0.025}\n", "test.yaml", {}));
  const std::string deep = "object: {cubes: [10000, 1, 1], cube_size_m: 0.025}\nadaptivity: {enabled: true}\n";
  expect_error(deep, "adaptivity.max_depth", "must be <= 18 for 10000 cubes along an axis",
               {"adaptivity.max_depth=19"});
  EXPECT_EQ(parse_scene_with_overrides(deep, "test.yaml", {"adaptivity.max_depth=18"}).adaptivity.max_depth, 18);
  // With adaptivity off the mesh is built to min_depth only.
  EXPECT_NO_THROW(parse_scene_with_overrides("object: {cubes: [10000, 1, 1], cube_size_m: 0.025}\n", "test.yaml",
                                             {"adaptivity.enabled=false", "adaptivity.max_depth=30"}));
}

TEST(SceneYamlErrors, MissingObject) {
  expect_error("name: x\n", "object", "missing required");
  expect_error("object: {cubes: [4, 4, 4]}\n", "object.cube_size_m", "missing required");
}

TEST(SceneYamlErrors, MissingFile) {
  const std::string path = scene_path("does_not_exist.yaml");
  try {
    load_scene_file(path);
    FAIL() << "no error";
  } catch (const SceneFileUnreadable& e) {
    EXPECT_EQ(e.source(), path);
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("no such file"), std::string::npos) << e.what();
  }
  EXPECT_THROW(load_scene_file(std::string(TISSUE_SOURCE_DIR) + "/config/scenes"), SceneFileUnreadable);  // a directory
}

// A scene is a few kilobytes; a bigger file is refused unread (the daemon
// reads it on its control thread, which the systemd watchdog watches).
TEST(SceneYamlErrors, AFileLargerThanOneMebibyteIsRefusedUnread) {
  TempDir dir;
  const std::string path = dir / "big.yaml";
  write_text(path, kMinimal + "# " + std::string((1u << 20) - kMinimal.size() - 2, 'x'));  // exactly 1 MiB
  EXPECT_EQ(load_scene_file(path).object.cubes[0], 4);
  write_text(path, kMinimal + "# " + std::string((1u << 20) - kMinimal.size() - 1, 'x'));
  try {
    load_scene_file(path);
    FAIL() << "no error";
  } catch (const SceneFileUnreadable& e) {
    EXPECT_EQ(e.source(), path);
    EXPECT_EQ(e.reason(), "cannot read scene file: 1048577 bytes is too large (the limit is 1048576 bytes)");
  }
}

// Under the size limit a flow list of half a million zeros took seconds and
// gigabytes to build before its length was checked (3 MiB: 6.6 s, 750 MB; the
// control thread was blocked past the watchdog's 5 s). The node count refuses
// it from the parser's events, before a tree is built.
TEST(SceneYamlErrors, AHugeListIsRefusedByItsNodeCountNamingTheFileAndTheLimit) {
  TempDir dir;
  const std::string path = dir / "huge.yaml";
  std::string text = kMinimal + "gravity_m_per_s2: [0";
  while (text.size() < (1u << 20) - 4) text += ",0";
  write_text(path, text + "]\n");
  const auto start = std::chrono::steady_clock::now();
  try {
    load_scene_file(path);
    FAIL() << "no error";
  } catch (const SceneFileUnreadable& e) {
    FAIL() << "refused as unreadable, not by its node count: " << e.what();
  } catch (const SceneError& e) {
    EXPECT_EQ(e.source(), path) << e.what();
    EXPECT_EQ(e.key_path(), "") << e.what();
    EXPECT_EQ(std::string(e.what()).rfind(path + ": ", 0), 0u) << e.what();
    EXPECT_NE(e.reason().find("more than 100000 YAML nodes"), std::string::npos) << e.what();
  }
  // Printed, not asserted: a unit test does not time.
  std::cout << "refused in " << std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count()
            << " s\n";
}

// The node limit leaves room for every list at its own limit (1000 regions a
// list, 1000 probes), each item with every key written out: ~83,000 nodes.
TEST(SceneYaml, ASceneWithEveryListAtItsLimitIsWithinTheNodeLimit) {
  const std::string box = "{box: {min_m: [0.1, 0, 0], max_m: [0.1, 0.1, 0.1]}}";
  const std::string profile = "{start_s: 0, ramp_s: 0.5, release_s: 1.0}";
  std::string text = kMinimal + "fixed:\n";
  for (int i = 0; i < 1000; ++i) text += "  - region: {box: {min_m: [0, 0, 0], max_m: [0, 0.1, 0.1]}}\n";
  text += "prescribed:\n";
  for (int i = 0; i < 1000; ++i)
    text += "  - {name: p" + std::to_string(i) + ", region: " + box +
            ", displacement_m: [0, 0, -0.01], profile: " + profile + "}\n";
  text += "loads:\n";
  for (int i = 0; i < 1000; ++i)
    text += "  - {name: l" + std::to_string(i) + ", region: " + box +
            ", total_force_N: [0, 0, -1], profile: " + profile + "}\n";
  text += "probes:\n";
  for (int i = 0; i < 1000; ++i) text += "  - {name: q" + std::to_string(i) + ", rest_m: [0.1, 0.05, 0.05]}\n";
  ASSERT_LT(text.size(), 1u << 20);
  const Scene s = parse_scene(text, "limits.yaml");
  EXPECT_EQ(s.fixed.size() + s.prescribed.size() + s.loads.size() + s.probes.size(), 4000u);
}

// What is wrong inside a file that was read is the file's own error, not an
// unreadable file (the daemon blames its config's `scene` key only for the
// latter).
TEST(SceneYamlErrors, AnErrorInsideAReadFileIsNotAnUnreadableFile) {
  TempDir dir;
  for (const std::string& text :
       {std::string("object: [\n"), std::string("name: x\n"), std::string("cannot read: 1\n")}) {
    const std::string path = dir / "bad.yaml";
    write_text(path, text);
    try {
      load_scene_file(path);
      FAIL() << "no error for " << text;
    } catch (const SceneFileUnreadable& e) {
      ADD_FAILURE() << "an error inside the file counted as unreadable: " << e.what();
    } catch (const SceneError& e) {
      EXPECT_EQ(e.source(), path);
    }
  }
}

TEST(SceneYamlErrors, YamlSyntaxErrorGivesTheLine) {
  const std::string what =
      expect_error("object:\n  cubes: [4, 4, 4]\n  cube_size_m: [0.025\nmaterial: {}\n", "", "YAML syntax error");
  EXPECT_NE(what.find("line 4"), std::string::npos) << what;
  const std::string tab = expect_error("object:\n  cubes: [4, 4, 4]\n cube_size_m: 0.1\n", "", "YAML syntax error");
  EXPECT_NE(tab.find("line 3"), std::string::npos) << tab;
}

TEST(SceneYamlErrors, EmptyDocumentAndMultipleDocuments) {
  expect_error("", "", "empty document");
  expect_error("# nothing but a comment\n\n", "", "empty document");
  expect_error("---\n...\n", "", "empty document");
  const std::string two = expect_error(kMinimal + "---\n" + kMinimal, "", "second YAML document");
  EXPECT_NE(two.find("line 2"), std::string::npos) << two;
  // yaml-cpp 0.7's LoadAll loops forever on these (jbeder/yaml-cpp#1040).
  expect_error(",\n", "", "");
  expect_error("!x\n,\n", "", "line 2");
  expect_error(kMinimal + ",\n", "", "line 2");
  expect_error("object: " + std::string(100000, '['), "", "nesting too deep");
}

// A file that is not a scene at all is said to be so without quoting it:
// through the control socket the daemon reads it with its own rights.
TEST(SceneYamlErrors, ADocumentThatIsNotAMapIsNotQuoted) {
  const std::string what = expect_error("root:x:0:0:root:/root:/bin/bash\nsecret hunter2\n", "", "map of sections");
  EXPECT_EQ(what.find("root"), std::string::npos) << what;
  EXPECT_EQ(what.find("hunter2"), std::string::npos) << what;
  EXPECT_NE(what.find("line of text"), std::string::npos) << what;
  expect_error("- a\n- b\n", "", "got a list");
  // Lines that YAML reads as keys (/etc/shadow's end in ':') are not echoed.
  const std::string shadow =
      expect_error("alice:$6$SALTsalt$HASHhashHASH:20228:0:99999:7:::\nbob:*:20228:0:99999:7:::\n", "<key not shown>",
                   "not a plain name");
  EXPECT_EQ(shadow.find("alice"), std::string::npos) << shadow;
  EXPECT_EQ(shadow.find("SALT"), std::string::npos) << shadow;
  // Nor is a file that is not a map when an override reaches into it.
  try {
    parse_scene_with_overrides("root:x:0:0:root:/root:/bin/bash secret\n", "t.yaml", {"integrator.kind=explicit"});
    ADD_FAILURE() << "expected an error";
  } catch (const SceneError& e) {
    const std::string what = e.what();
    EXPECT_EQ(what.find("root"), std::string::npos) << what;
    EXPECT_EQ(what.find("secret"), std::string::npos) << what;
    EXPECT_NE(what.find("not shown"), std::string::npos) << what;
  }
}

TEST(SceneYamlErrors, ValidateSceneWorksOnProgrammaticScenes) {
  Scene s;
  s.source = "built-in";
  EXPECT_NO_THROW(validate_scene(s));
  s.loads.push_back(LoadSpec{"push", Region{}, Vec3{0, 0, -1}, TimeProfile{}});
  EXPECT_NO_THROW(validate_scene(s));  // a point region at the origin corner
  s.integrator.dt_s = -1;
  try {
    validate_scene(s);
    FAIL() << "no error";
  } catch (const SceneError& e) {
    EXPECT_STREQ(e.what(), "built-in: integrator.dt_s: must be > 0 (got -1)");
  }
  s.integrator.dt_s = 1e-3;
  s.material.stiffness = static_cast<StiffnessLaw>(7);
  EXPECT_THROW(validate_scene(s), SceneError);
}

// --------------------------------------------------------------- overrides

TEST(SceneYamlOverrides, ScalarOverrides) {
  const Scene s = parse_scene_with_overrides(kBase, "test.yaml",
                                             {"integrator.dt_s=0.002", "adaptivity.enabled=false", "name=renamed"});
  EXPECT_DOUBLE_EQ(s.integrator.dt_s, 0.002);
  EXPECT_FALSE(s.adaptivity.enabled);
  EXPECT_EQ(s.name, "renamed");
  // Later overrides win.
  const Scene t = parse_scene_with_overrides(kBase, "test.yaml", {"integrator.dt_s=0.002", "integrator.dt_s = 0.004"});
  EXPECT_DOUBLE_EQ(t.integrator.dt_s, 0.004);
}

TEST(SceneYamlOverrides, ListOverrides) {
  const Scene s = parse_scene_with_overrides(
      kBase, "test.yaml",
      {"gravity_m_per_s2=[0,0,-9.81]", "loads[0].total_force_N[2]=-2", "object.cubes=[8, 2, 2]",
       "probes=[{name: a, rest_m: [0, 0, 0]}, {name: b, rest_m: [0.1, 0.05, 0.05]}]"});
  EXPECT_EQ(s.gravity_m_per_s2, (Vec3{0, 0, -9.81}));
  EXPECT_EQ(s.loads[0].total_force_N, (Vec3{0, 0, -2}));
  EXPECT_EQ(s.object.cubes, (std::array<int, 3>{8, 2, 2}));
  ASSERT_EQ(s.probes.size(), 2u);
  EXPECT_EQ(s.probes[1].name, "b");
}

TEST(SceneYamlOverrides, MissingSectionsAreCreated) {
  const Scene s =
      parse_scene_with_overrides(kMinimal, "test.yaml", {"adaptivity.enabled=true", "adaptivity.max_depth=4"});
  EXPECT_TRUE(s.adaptivity.enabled);
  EXPECT_EQ(s.adaptivity.max_depth, 4);
}

TEST(SceneYamlOverrides, AnchorsElsewhereAreNotChanged) {
  const std::string text = kMinimal + "gravity_m_per_s2: &g [0.01, 0.02, 0.03]\nprobes: [{name: p, rest_m: *g}]\n";
  const Scene s = parse_scene_with_overrides(text, "test.yaml", {"gravity_m_per_s2[2]=-9.81"});
  EXPECT_EQ(s.gravity_m_per_s2, (Vec3{0.01, 0.02, -9.81}));
  EXPECT_EQ(s.probes[0].rest_m, (Vec3{0.01, 0.02, 0.03}));
}

TEST(SceneYamlOverrides, UnknownPathFailsNamingIt) {
  const std::string what = expect_error(kBase, "integrator.dtt_s", "unknown key", {"integrator.dtt_s=0.002"});
  EXPECT_NE(what.find("(set by the override 'integrator.dtt_s=0.002')"), std::string::npos) << what;
  expect_error(kBase, "probes[3]", "out of range", {"probes[3].name=x"});
  expect_error(kBase, "name", "not a map", {"name.first=x"});
  expect_error(kBase, "material", "not a list", {"material[0]=1"});
}

TEST(SceneYamlOverrides, ValueThatBreaksValidationFailsWithTheKeyPath) {
  const std::string what = expect_error(kBase, "integrator.dt_s", "must be > 0", {"integrator.dt_s=0"});
  EXPECT_NE(what.find("(set by the override"), std::string::npos) << what;
  expect_error(kBase, "adaptivity.enabled", "expected a boolean", {"adaptivity.enabled=maybe"});
  expect_error(kBase, "gravity_m_per_s2", "not valid YAML", {"gravity_m_per_s2=[0,0"});
  expect_error(kBase, "gravity_m_per_s2", "expected a list of 3 numbers", {"gravity_m_per_s2=0,0,-9.81"});
}

// A daemon key set on the scene (tissued --batch, or a misspelt one under
// --config, which routes unknown keys to the scene) was "unknown key
// 'haptic'; allowed keys: name, object, ..." with no word of the daemon.
TEST(SceneYamlOverrides, AKeyNearADaemonSettingSaysSo) {
  const std::string typo = expect_error(
      kMinimal, "haptic", "unknown key 'haptic' (did you mean the daemon setting 'haptics'?", {"haptic.rate_hz=500"});
  EXPECT_NE(typo.find("allowed keys: name, object"), std::string::npos) << typo;
  // The same text answers the control protocol's `set`, which refuses daemon
  // keys: it says how a running daemon takes one (not only --set, which a
  // `set` user cannot use).
  EXPECT_NE(typo.find("a running daemon: edit that file and reload it (SIGHUP)"), std::string::npos) << typo;
  expect_error(kMinimal, "scene", "unknown key 'scene' (did you mean the daemon setting 'scene'?",
               {"scene=cantilever.yaml"});
  expect_error(kMinimal + "status_interval_s: 1\n", "status_interval_s",
               "(did you mean the daemon setting 'status_interval_s'?");
  // A scene key's own suggestion comes first.
  const std::string scene_typo = expect_error(kMinimal + "materal: {}\n", "materal", "(did you mean 'material'?)");
  EXPECT_EQ(scene_typo.find("daemon"), std::string::npos) << scene_typo;
}

TEST(SceneYamlOverrides, MalformedOverrideFailsClearly) {
  const std::string what = expect_error(kBase, "", "expected key.path=value", {"integrator.dt_s"});
  EXPECT_NE(what.find("integrator.dt_s"), std::string::npos) << what;
  expect_error(kBase, "", "bad key path", {"=1"});
  expect_error(kBase, "", "bad key path", {"integrator..dt_s=1"});
  expect_error(kBase, "", "bad key path", {"loads[x].name=a"});
  expect_error(kBase, "", "bad key path", {"loads[0.name=a"});
}

TEST(SceneYamlOverrides, FileWithOverrides) {
  const Scene s = load_scene_file_with_overrides(scene_path("beam.yaml"), {"integrator.kind=explicit"});
  EXPECT_EQ(s.integrator.kind, IntegratorKind::kExplicit);
  EXPECT_EQ(s.object.cubes, (std::array<int, 3>{8, 2, 2}));
}

// ------------------------------------------------------------------- fuzz

TEST(SceneYamlFuzz, MutatedScenesEitherParseOrThrowSceneError) {
  const std::string original = read_text(scene_path("cantilever.yaml"));
  ASSERT_FALSE(original.empty());
  const std::string yamlish = "[]{}:,-&*!|>'\"#%@`?\n\t .0123456789e";
  std::mt19937 rng(20240611);
  const auto pick = [&](std::size_t n) { return std::uniform_int_distribution<std::size_t>(0, n - 1)(rng); };
  int parsed = 0, rejected = 0;
  for (int iteration = 0; iteration < 600; ++iteration) {
    std::string text = original;
    const int edits = 1 + static_cast<int>(pick(4));
    for (int e = 0; e < edits && !text.empty(); ++e) {
      switch (pick(5)) {
        case 0:  // flip a byte to any value
          text[pick(text.size())] = static_cast<char>(pick(256));
          break;
        case 1:  // truncate
          text.resize(pick(text.size()));
          break;
        case 2:  // insert YAML punctuation
          text.insert(pick(text.size() + 1), 1, yamlish[pick(yamlish.size())]);
          break;
        case 3: {  // delete a range
          const std::size_t at = pick(text.size());
          text.erase(at, pick(20) + 1);
          break;
        }
        default: {  // flip one bit
          text[pick(text.size())] ^= static_cast<char>(1 << pick(8));
          break;
        }
      }
    }
    try {
      const Scene s = parse_scene(text, "fuzz.yaml");
      EXPECT_NO_THROW(validate_scene(s));
      ++parsed;
    } catch (const SceneError& e) {
      EXPECT_EQ(e.source(), "fuzz.yaml");
      EXPECT_FALSE(e.reason().empty());
      ++rejected;
    } catch (const std::exception& e) {
      ADD_FAILURE() << "iteration " << iteration << ": non-SceneError exception: " << e.what() << "\n" << text;
    } catch (...) {
      ADD_FAILURE() << "iteration " << iteration << ": unknown exception\n" << text;
    }
  }
  // Both outcomes occur, so the mutations neither always break nor never touch the scene.
  EXPECT_GT(parsed, 10);
  EXPECT_GT(rejected, 100);
}

// The optional tool: absent means no tool at all; present, every field is
// read and validated like the rest.
TEST(SceneYaml, ToolSectionIsOptionalAndRead) {
  EXPECT_FALSE(parse_scene(kBase, "base.yaml").tool.has_value());
  const Scene s = parse_scene(kBase +
                                  "tool:\n  patch_radius_m: 0.03\n  engage_distance_m: 0.004\n"
                                  "  freeze_radius_m: 0\n  max_force_N: 7.5\n",
                              "tool.yaml");
  ASSERT_TRUE(s.tool.has_value());
  EXPECT_EQ(s.tool->patch_radius_m, 0.03);
  EXPECT_EQ(s.tool->engage_distance_m, 0.004);
  EXPECT_EQ(s.tool->freeze_radius_m, 0.0);
  EXPECT_EQ(s.tool->max_force_N, 7.5);
  const Scene defaults = parse_scene(kBase + "tool: {}\n", "tool.yaml");
  ASSERT_TRUE(defaults.tool.has_value());
  EXPECT_EQ(defaults.tool->max_force_N, ToolSpec{}.max_force_N);
}

TEST(SceneYamlErrors, ToolValuesAreChecked) {
  expect_error(kBase + "tool: {max_force_N: 0}\n", "tool.max_force_N", "must be");
  expect_error(kBase + "tool: {patch_radius_m: -1}\n", "tool.patch_radius_m", "must be");
  expect_error(kBase + "tool: {freeze_radius_m: .nan}\n", "tool.freeze_radius_m", "");
  expect_error(kBase + "tool: {radius: 1}\n", "tool.radius", "unknown key");
}

// Every numeric key lands in its own field. kBase leaves many at their
// struct defaults (a key read into the wrong field, or not at all, would
// pass EveryKeyOfTheBaseSceneIsRead there): each is set here to a value
// neither its default nor kBase's, and no other field may move.
TEST(SceneYaml, EachNumericKeyLandsInItsOwnField) {
  struct Case {
    const char* from;
    const char* to;
    double (*get)(const Scene&);
    double want;
  };
  const Case cases[] = {
      {"cube_size_m: 0.025", "cube_size_m: 0.03", [](const Scene& s) { return s.object.cube_size_m; }, 0.03},
      {"youngs_modulus_Pa: 5.0e4", "youngs_modulus_Pa: 7.0e4",
       [](const Scene& s) { return s.material.youngs_modulus_Pa; }, 7.0e4},
      {"density_kg_per_m3: 100", "density_kg_per_m3: 120", [](const Scene& s) { return s.material.density_kg_per_m3; },
       120.0},
      {"rayleigh_alpha_per_s: 0.0", "rayleigh_alpha_per_s: 2.5",
       [](const Scene& s) { return s.material.rayleigh_alpha_per_s; }, 2.5},
      {"rayleigh_beta_s: 0.003", "rayleigh_beta_s: 0.004", [](const Scene& s) { return s.material.rayleigh_beta_s; },
       0.004},
      {"gravity_m_per_s2: [0, 0, 0]", "gravity_m_per_s2: [0, 0, -9.5]",
       [](const Scene& s) { return s.gravity_m_per_s2[2]; }, -9.5},
      {"refine_threshold_Pa: 20", "refine_threshold_Pa: 21",
       [](const Scene& s) { return s.adaptivity.refine_threshold_Pa; }, 21.0},
      {"simplify_factor: 0.25", "simplify_factor: 0.3", [](const Scene& s) { return s.adaptivity.simplify_factor; },
       0.3},
      {"stretch_ratio: 1.05", "stretch_ratio: 1.07", [](const Scene& s) { return s.adaptivity.stretch_ratio; }, 1.07},
      {"min_depth: 0", "min_depth: 1", [](const Scene& s) { return double(s.adaptivity.min_depth); }, 1.0},
      {"max_depth: 3", "max_depth: 4", [](const Scene& s) { return double(s.adaptivity.max_depth); }, 4.0},
      {"every_steps: 5", "every_steps: 7", [](const Scene& s) { return double(s.adaptivity.every_steps); }, 7.0},
      {"max_ops_per_step: 64", "max_ops_per_step: 33",
       [](const Scene& s) { return double(s.adaptivity.max_ops_per_step); }, 33.0},
      {"min_age_steps: 20", "min_age_steps: 21", [](const Scene& s) { return double(s.adaptivity.min_age_steps); },
       21.0},
      {"midpoint_tolerance: 1.0e-3", "midpoint_tolerance: 2.0e-3",
       [](const Scene& s) { return s.adaptivity.midpoint_tolerance; }, 2.0e-3},
      {"dt_s: 0.001", "dt_s: 0.002", [](const Scene& s) { return s.integrator.dt_s; }, 0.002},
      {"max_substeps: 1000", "max_substeps: 999", [](const Scene& s) { return double(s.integrator.max_substeps); },
       999.0},
      {"substep_safety: 0.8", "substep_safety: 0.7", [](const Scene& s) { return s.integrator.substep_safety; }, 0.7},
      {"explicit_energy_slack: 1.0", "explicit_energy_slack: 0.25",
       [](const Scene& s) { return s.integrator.explicit_energy_slack; }, 0.25},
      {"cg_tolerance: 1.0e-6", "cg_tolerance: 3.0e-6", [](const Scene& s) { return s.integrator.cg_tolerance; },
       3.0e-6},
      {"cg_max_iterations: 100", "cg_max_iterations: 77",
       [](const Scene& s) { return double(s.integrator.cg_max_iterations); }, 77.0},
  };
  const Scene base = parse_scene(kBase, "test.yaml");
  const Scene defaults;
  for (const Case& c : cases) {
    SCOPED_TRACE(c.to);
    ASSERT_NE(c.want, c.get(base));
    ASSERT_NE(c.want, c.get(defaults));
    const Scene s = parse_scene(base_with(c.from, c.to), "test.yaml");
    EXPECT_EQ(c.get(s), c.want);
    for (const Case& other : cases)
      if (&other != &c) {
        EXPECT_EQ(other.get(s), other.get(base)) << "moved: " << other.from;
      }
  }
}

// Bounds of the numeric keys PhysicallyMeaninglessValues leaves out, each
// refused naming its key, and the closed bounds' edges accepted.
TEST(SceneYamlErrors, RemainingNumericBoundsAreChecked) {
  expect_error(base_with("rayleigh_alpha_per_s: 0.0", "rayleigh_alpha_per_s: -1"), "material.rayleigh_alpha_per_s",
               ">= 0");
  expect_error(base_with("refine_threshold_Pa: 20", "refine_threshold_Pa: 0"), "adaptivity.refine_threshold_Pa",
               "must be > 0");
  expect_error(base_with("max_ops_per_step: 64", "max_ops_per_step: 0"), "adaptivity.max_ops_per_step", ">= 1");
  expect_error(base_with("min_age_steps: 20", "min_age_steps: -1"), "adaptivity.min_age_steps", ">= 0");
  expect_error(base_with("midpoint_tolerance: 1.0e-3", "midpoint_tolerance: 0"), "adaptivity.midpoint_tolerance",
               "must be > 0");
  expect_error(base_with("max_substeps: 1000", "max_substeps: 0"), "integrator.max_substeps", ">= 1");
  expect_error(base_with("cg_max_iterations: 100", "cg_max_iterations: 0"), "integrator.cg_max_iterations", ">= 1");
  expect_error(kBase + "tool: {engage_distance_m: 0}\n", "tool.engage_distance_m", "must be > 0");
  expect_error(base_with("cubes: [4, 4, 4]", "cubes: [1000, 100, 101]"), "object.cubes", "too many cubes");
  // Refining is bounded by the same budget as the starting mesh: max_tets
  // 2147483647 with a tiny threshold reached 6.3M tets and 1.9 GB in 14 steps.
  expect_error(kBase, "adaptivity.max_tets", "must be <= 20000000 (about 4 GB of mesh; got 2147483647)",
               {"adaptivity.max_tets=2147483647"});
  EXPECT_NO_THROW(parse_scene_with_overrides(kBase, "ok.yaml", {"adaptivity.max_tets=20000000"}));
  // Masses and stiffnesses the simulation cannot hold: a density of 1e308
  // overflowed the lumped masses, the free nodes stood still and the batch
  // report's kinetic energy was NaN after a run that exited 0.
  expect_error(kBase, "material.density_kg_per_m3",
               "with object.cube_size_m 0.025, a cube's mass in kg would be 1.5625",
               {"material.density_kg_per_m3=1e308"});
  expect_error(kBase, "material.density_kg_per_m3", "beyond what the simulation holds in double precision (got 1e+200)",
               {"material.density_kg_per_m3=1e200", "object.cube_size_m=1e10"});
  expect_error(kBase, "material.density_kg_per_m3", "a cube's mass in kg would be 1.5625",
               {"material.density_kg_per_m3=1e-300"});
  expect_error(kBase, "material.youngs_modulus_Pa", "the cube's spring stiffness scale (E x cube size) in N/m",
               {"material.youngs_modulus_Pa=1e-300"});
  EXPECT_NO_THROW(parse_scene_with_overrides(kBase, "ok.yaml",
                                             {"material.youngs_modulus_Pa=1e12", "material.density_kg_per_m3=2e4"}));
  // Past any real material (a typo, or units not SI): representable, but a
  // load strains so stiff a body less than its coordinates resolve, and so
  // heavy a one moves by less than that a step; the projective rung then
  // turned rounding into energy (kinetic energy 1e5x the work done at
  // density 1.8e19, growing; found by tests/physics/scene_extremes_test.cpp).
  expect_error(kBase, "material.youngs_modulus_Pa", "must be <= 1e+13 Pa (ten times diamond's; got 1.8e+19)",
               {"material.youngs_modulus_Pa=1.8e19"});
  expect_error(kBase, "material.density_kg_per_m3", "must be <= 1e+05 kg/m³ (four times osmium's; got 1.8e+19)",
               {"material.density_kg_per_m3=1.8e19"});
  EXPECT_NO_THROW(parse_scene_with_overrides(kBase, "ok.yaml",
                                             {"material.youngs_modulus_Pa=1e13", "material.density_kg_per_m3=1e5"}));
  // The mass and stiffness scales were in range, but not the factors the
  // body multiplies on the way: density x six-volume overflowed (inf masses),
  // cube_size_m³ / 2^30 underflowed (every tet's volume and stiffness 0).
  // kMinimal: no region to be refused first for lying outside so small a box.
  expect_error(kMinimal, "object.cube_size_m", "a cube's volume in m³ would be 1e-240, outside [1e-100, 1e+100]",
               {"object.cube_size_m=1e-80", "material.density_kg_per_m3=1e308", "material.youngs_modulus_Pa=1e80"});
  expect_error(kMinimal, "object.cube_size_m", "beyond what the simulation holds in double precision (got 2e-108)",
               {"object.cube_size_m=2e-108", "material.density_kg_per_m3=1e300", "material.youngs_modulus_Pa=1e100"});
  // The other edge: a volume near double's largest (1.79e308 m³) made some
  // edges' summed volumes, and their stiffnesses, inf.
  expect_error(
      kMinimal, "object.cube_size_m", "double precision (got 5.64e+102)",
      {"object.cube_size_m=5.64e102", "material.density_kg_per_m3=1e-300", "material.youngs_modulus_Pa=1e-100"});

  // docs/scene-format.md: dt_s <= 1 s, substep_safety in (0, 1], min_age_steps
  // and rayleigh_alpha_per_s >= 0, at most 3333333 cubes (2e7 tets): the edges themselves are valid.
  // The load is released at 2 s: kBase's 1 s is the first 1 s step's end, so
  // it would act at no step (AProfileThatActsAtNoStepEndIsRefused).
  const Scene edges = parse_scene_with_overrides(
      kBase, "test.yaml",
      {"integrator.dt_s=1", "integrator.substep_safety=1", "adaptivity.min_age_steps=0", "object.cubes=[333, 100, 100]",
       "object.cube_size_m=0.001", "adaptivity.enabled=false", "loads[0].profile.release_s=2"});
  EXPECT_EQ(edges.integrator.dt_s, 1.0);
  EXPECT_EQ(edges.integrator.substep_safety, 1.0);
  EXPECT_EQ(edges.adaptivity.min_age_steps, 0);
  EXPECT_EQ(edges.object.cubes, (std::array<int, 3>{333, 100, 100}));
}

// Rayleigh damping the simulation cannot hold in double precision is
// refused, naming the key: kBase is the cantilever (E 5e4 Pa, density 100,
// cubes of 25 mm refined to depth 3, dt 1 ms), whose finest leaf's
// frequency scale is sqrt(E / density) / 3.125 mm = 7155 /s. Accepted, beta
// 1e300 s made the explicit rung's stable sub-step inf (its damping ratio
// squared overflowed: one sub-step, then "state became non-finite"; from
// beta 1e151 s), beta 1e160 s left the implicit rung's CG at 0 iterations
// with the body frozen (from 1e140 s its steps stopped short of the
// tolerance), and alpha 1e300 /s did the same to its steps.
TEST(SceneYamlErrors, RayleighDampingBeyondDoublePrecisionIsRefused) {
  const std::string said =
      expect_error(kBase, "material.rayleigh_beta_s", "(got 1e+300)", {"material.rayleigh_beta_s=1e300"});
  EXPECT_NE(said.find("beyond what the simulation holds in double precision"), std::string::npos) << said;
  EXPECT_NE(said.find("7.16e+03 /s"), std::string::npos) << said;  // the frequency scale it is measured against
  for (const char* beta : {"1e151", "1e140", "1e96", "1.7e308"})
    expect_error(kBase, "material.rayleigh_beta_s", "beyond what the simulation holds in double precision",
                 {std::string("material.rayleigh_beta_s=") + beta});
  // beta x omega² x dt_s = beta x 5.12e4 is the tighter bound here.
  expect_error(kBase, "material.rayleigh_beta_s", "x integrator.dt_s", {"material.rayleigh_beta_s=1e96"});
  expect_error(kBase, "material.rayleigh_alpha_per_s", "alpha x integrator.dt_s) would be 1e+297",
               {"material.rayleigh_alpha_per_s=1e300"});
  expect_error(kBase, "material.rayleigh_alpha_per_s", "beyond what the simulation holds in double precision",
               {"material.rayleigh_alpha_per_s=1e104"});
  // The edges, and beta where the dampers do not use it (damping: paper).
  EXPECT_NO_THROW(parse_scene_with_overrides(kBase, "ok.yaml", {"material.rayleigh_beta_s=1e95"}));
  EXPECT_NO_THROW(parse_scene_with_overrides(kBase, "ok.yaml", {"material.rayleigh_alpha_per_s=5e102"}));
  EXPECT_NO_THROW(
      parse_scene_with_overrides(kBase, "ok.yaml", {"material.damping=paper", "material.rayleigh_beta_s=1e300"}));
}

// What the damping bound promises: at the largest beta and alpha the check
// accepts, every rung either takes its steps with a finite state and energy
// or refuses a step it cannot take at integrator.max_substeps (the explicit
// rung: a damping ratio of 1e99 needs ever more sub-steps), saying so.
TEST(SceneYamlErrors, TheLargestDampingTheCheckAcceptsRunsOrIsRefusedByTheSubstepCap) {
  for (const char* kind : {"explicit", "implicit", "projective"})
    for (const std::vector<std::string>& damping :
         {std::vector<std::string>{"material.rayleigh_beta_s=1e95"},
          std::vector<std::string>{"material.rayleigh_alpha_per_s=5e102"},
          std::vector<std::string>{"material.rayleigh_beta_s=1e95", "material.rayleigh_alpha_per_s=5e102"}}) {
      std::vector<std::string> overrides = damping;
      overrides.push_back(std::string("integrator.kind=") + kind);
      const Scene s = parse_scene_with_overrides(kBase, "edge.yaml", overrides);
      physics::Simulation sim(s);
      const std::string at = std::string(kind) + " with " + damping.back();
      for (int i = 0; i < 5; ++i) {
        const physics::StepResult r = sim.step();
        if (!r.ok) {
          EXPECT_EQ(std::string(kind), "explicit") << at << ": " << r.error;
          EXPECT_NE(r.error.find("more than integrator.max_substeps"), std::string::npos) << at << ": " << r.error;
          break;
        }
        const double energy_J = sim.kinetic_energy_J() + sim.elastic_energy_J();
        ASSERT_TRUE(std::isfinite(energy_J)) << at << ", step " << i;
        const physics::Body& body = sim.body();
        bool finite = true;
        body.mesh().for_each_node([&](physics::NodeId n, const mesh::Node&) {
          finite = finite && body.x_m[n].allFinite() && body.v_m_per_s[n].allFinite();
        });
        ASSERT_TRUE(finite) << at << ", step " << i;
      }
    }
}

// What the scale checks promise (scene_yaml.cpp, kMinCubeScale): every
// scene they accept gets node masses, inverse masses and spring
// stiffnesses that are ordinary doubles, from the starting cubes down to
// the finest leaf the scene can reach (max_depth 30), and equal to the
// unit body's (cube, density and E of 1) scaled by density x cube_size³
// and E x cube_size. Swept over cube sizes 1e-120..1e120 m, densities and
// moduli 1e-300..1e300.
TEST(SceneYamlErrors, EveryScaleTheCheckAcceptsGivesOrdinaryMassesAndStiffnesses) {
  Scene unit = parse_scene("object: {cubes: [2, 1, 1], cube_size_m: 1}\n", "unit.yaml");
  unit.material.density_kg_per_m3 = 1.0;
  unit.material.youngs_modulus_Pa = 1.0;
  // Undamped: the sweep's stiffest-and-lightest scales (frequencies to 1e109
  // /s at depth 30) are beyond the damping bound with the default beta
  // (RayleighDampingBeyondDoublePrecisionIsRefused); this is about masses and
  // stiffnesses.
  unit.material.rayleigh_beta_s = 0.0;
  unit.adaptivity.enabled = true;
  unit.adaptivity.max_depth = 30;
  validate_scene(unit);
  const physics::Body unit_body(unit);
  const mesh::KuhnMesh& mesh = unit_body.mesh();
  const auto& first_tet = mesh.tet(0).v;  // depth 0, the shape of every depth 3N, 30 included
  ASSERT_EQ(mesh.tet(0).depth, 0);
  const double leaf_edge_lattice_units = 1.0;  // the finest cube at depth 30 is one lattice unit across

  // Decades, and the cube sizes that broke the body (scene_yaml.cpp, kMinCubeScale).
  std::vector<double> cube_sizes_m = {2e-108, 1e-80, 5.64e102};
  for (int cube_exp = -120; cube_exp <= 120; cube_exp += 10) cube_sizes_m.push_back(1.5 * std::pow(10.0, cube_exp));
  int accepted = 0;
  for (const double cube_size_m : cube_sizes_m)
    for (int density_exp = -300; density_exp <= 300; density_exp += 20)
      for (int modulus_exp = -300; modulus_exp <= 300; modulus_exp += 20) {
        Scene s = unit;
        s.object.cube_size_m = cube_size_m;
        s.material.density_kg_per_m3 = 1.5 * std::pow(10.0, density_exp);
        s.material.youngs_modulus_Pa = 1.5 * std::pow(10.0, modulus_exp);
        try {
          validate_scene(s);
        } catch (const SceneError&) {
          continue;
        }
        ++accepted;
        const physics::Body body(s);
        std::ostringstream where;
        where << "cube_size_m " << s.object.cube_size_m << ", density " << s.material.density_kg_per_m3 << ", E "
              << s.material.youngs_modulus_Pa;
        const std::string at = where.str();
        // The scales in long double (range to 1e4932): no over- or underflow.
        const long double cube = s.object.cube_size_m;
        const long double mass_scale = s.material.density_kg_per_m3 * cube * cube * cube;
        const long double stiffness_scale = s.material.youngs_modulus_Pa * cube;
        bool all_ok = true;
        body.mesh().for_each_node([&](physics::NodeId n, const mesh::Node&) {
          const double m = body.mass_kg[n];
          const long double expected = mass_scale * unit_body.mass_kg[n];
          if (!std::isnormal(m) || !std::isnormal(body.inv_mass_per_kg[n]) ||
              std::fabs(static_cast<long double>(m) - expected) > 1e-12L * expected) {
            ADD_FAILURE() << at << ": node " << n << " mass " << m << " kg, inverse " << body.inv_mass_per_kg[n]
                          << ", expected " << static_cast<double>(expected);
            all_ok = false;
          }
        });
        body.mesh().for_each_edge([&](physics::EdgeId e, const mesh::Edge&) {
          const double k = body.stiffness_N_per_m[e];
          const long double expected = stiffness_scale * unit_body.stiffness_N_per_m[e];
          if (!std::isnormal(k) || std::fabs(static_cast<long double>(k) - expected) > 1e-12L * expected) {
            ADD_FAILURE() << at << ": edge " << e << " stiffness " << k << " N/m, expected "
                          << static_cast<double>(expected);
            all_ok = false;
          }
        });
        // The finest leaf: a node holding one depth-30 tet's six-volume
        // (1), and a depth-30 tet's springs, the shortest one lattice unit.
        const double unit_m = body.mesh().lattice_unit_m();
        const double leaf_mass_kg = physics::node_mass_kg(s.material.density_kg_per_m3, 1, unit_m);
        const long double leaf_expected =
            s.material.density_kg_per_m3 * static_cast<long double>(unit_m) * unit_m * unit_m / 24;
        if (!std::isnormal(leaf_mass_kg) || !std::isnormal(1.0 / leaf_mass_kg) ||
            std::fabs(static_cast<long double>(leaf_mass_kg) - leaf_expected) > 1e-12L * leaf_expected) {
          ADD_FAILURE() << at << ": a leaf node's mass " << leaf_mass_kg << " kg, expected "
                        << static_cast<double>(leaf_expected);
          all_ok = false;
        }
        for (const double share_m3 : body.tet_edge_shares_m3(first_tet, 30)) {
          const double k = physics::spring_stiffness_N_per_m(s.material.youngs_modulus_Pa, share_m3,
                                                             leaf_edge_lattice_units * unit_m);
          if (!std::isnormal(share_m3) || !std::isnormal(k)) {
            ADD_FAILURE() << at << ": a leaf tet's share " << share_m3 << " m³, stiffness " << k << " N/m";
            all_ok = false;
          }
        }
        if (!all_ok) return;  // one scene's failures are enough to read
      }
  // The sweep reached the corners: cube sizes 1.5e-30..1.5e30 m, with the
  // densities and moduli in range, up to the material caps (1e5 kg/m³,
  // 1e13 Pa: 1.5e0 and 1.5e0 are the largest of the sweep's decades below
  // them) (the three cube sizes that broke the body: none). 700 before the
  // caps.
  EXPECT_EQ(accepted, 250);
}

}  // namespace
}  // namespace tissue::scene
