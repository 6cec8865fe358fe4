// The shipped scenes at the extremes the scene loader accepts: every number
// of cantilever.yaml, contact.yaml and beam.yaml replaced, one at a time, by
// an extreme, each run on every integrator (the largest and smallest doubles, 0, a negative, 1e9, past 64
// bits). The loader refuses it naming the file and the key, or the scene is
// built and stepped: either the build is refused with a reason (mesh limits,
// a probe outside the object), or each step is taken with a finite state
// within the energy budget (tests/physics/diagnostics.hpp), or refused with a
// reason and the state kept.
// Never a crash, a NaN, or an exception of another kind.
#include <gtest/gtest.h>

#include <fstream>
#include <iterator>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "physics/diagnostics.hpp"
#include "physics/simulation.hpp"
#include "scene/scene_names.hpp"
#include "scene/scene_yaml.hpp"
#include "support/yaml_numbers.hpp"

namespace tissue::physics {
namespace {

std::string read_text(const std::string& path) {
  std::ifstream in(path);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

TEST(SceneExtremes, EveryNumberOfTheShippedScenesAtAnExtremeIsRefusedOrStepsFinite) {
  const std::vector<std::string> extremes = {"1e308", "1.8e19", "1e9", "1e-9", "5e-324", "0", "-1"};
  // The implicit rung's energy guard holds every step to its budget; the
  // explicit rung may exceed it by its O(h ω) oscillation (stability_test).
  constexpr double kSlack = 1e-6, kExplicitSlack = 0.05;
  int parsed = 0, refused = 0, built = 0, stepped = 0;
  for (const char* name : {"cantilever.yaml", "contact.yaml", "beam.yaml"}) {
    const std::string path = std::string(TISSUE_SOURCE_DIR) + "/config/scenes/" + name;
    const std::string original = read_text(path);
    ASSERT_FALSE(original.empty()) << path;
    const std::vector<tissue::testing::YamlNumber> numbers = tissue::testing::yaml_numbers(original);
    ASSERT_GT(numbers.size(), 10u);
    for (const tissue::testing::YamlNumber& number : numbers) {
      const std::size_t at = number.offset, length = number.length;
      const std::string& key = number.key;
      for (const std::string& extreme : extremes) {
        std::string text = original;
        text.replace(at, length, extreme);
        const std::string what = std::string(name) + ": " + key + ": " + number.text + " -> " + extreme;
        scene::Scene s;
        try {
          s = scene::parse_scene(text, path);
          scene::validate_scene(s);
          ++parsed;
        } catch (const scene::SceneError& e) {
          // The key or the rule it broke (a region outside the object the
          // new cube size makes, the object's size): named with the file.
          EXPECT_EQ(e.source(), path) << what;
          EXPECT_FALSE(e.reason().empty()) << what;
          ++refused;
          continue;
        } catch (const std::exception& e) {
          ADD_FAILURE() << what << ": not a SceneError: " << e.what();
          continue;
        }
        for (const scene::IntegratorKind kind :
             {scene::IntegratorKind::kImplicit, scene::IntegratorKind::kExplicit, scene::IntegratorKind::kProjective}) {
          scene::Scene on_kind = s;
          on_kind.integrator.kind = kind;
          const bool explicit_rung = kind == scene::IntegratorKind::kExplicit;
          const std::string run = what + " (" + std::string(scene::name_of(scene::kIntegratorNames, kind)) + ")";
          std::unique_ptr<Simulation> sim;
          try {
            sim = std::make_unique<Simulation>(on_kind);  // refused: mesh limits, a region that selects only held nodes
          } catch (const std::invalid_argument& e) {
            EXPECT_FALSE(std::string(e.what()).empty()) << run;
            continue;
          } catch (const std::exception& e) {
            ADD_FAILURE() << run << ": not an invalid_argument: " << e.what();
            continue;
          }
          ++built;
          const EnergyAudit audit = audit_steps(*sim, 10);
          EXPECT_FALSE(audit.nonfinite) << run;
          EXPECT_TRUE(state_is_finite(sim->body())) << run;
          if (audit.refused) {
            // Forces beyond range (gravity or a load of 1e308), or the
            // explicit rung above its sub-step cap: the step is rejected with
            // its reason and the state kept (the service's trial step refuses
            // such a scene before serving it).
            EXPECT_FALSE(audit.error.empty()) << run;
            continue;
          }
          ++stepped;
          // The explicit rung may exceed the budget by its O(h ω)
          // oscillation (as in stability_test); the others by nothing.
          const double slack = explicit_rung ? kExplicitSlack : kSlack;
          EXPECT_TRUE(audit.within_energy_bound(slack)) << run << ": worst excess " << audit.worst_excess;
        }
      }
    }
  }
  EXPECT_GT(parsed, 50);
  EXPECT_GT(refused, 50);
  EXPECT_GT(stepped, 20);
  EXPECT_GE(built, stepped);
}

}  // namespace
}  // namespace tissue::physics
