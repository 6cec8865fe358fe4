#include "physics/frequency_estimate.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "physics/physics_test_support.hpp"

namespace tissue::physics {
namespace {

using testing::beam_scene;
using testing::dense_rest_frequency2_per_s2;

// k is the smallest iteration count for which Kuczyński & Woźniakowski's
// failure probability 1.648 √n e^(−√ε (2k − 1)) is at most δ; it grows
// with ln n and ln(1/δ), so even a million nodes need few iterations.
TEST(FrequencyEstimate, IterationCountIsTheSmallestThatMeetsTheFailureProbability) {
  const auto failure = [](double n, double gap, int k) {
    return 1.648 * std::sqrt(n) * std::exp(-std::sqrt(gap) * (2 * k - 1));
  };
  for (const double n : {3.0, 300.0, 3e4, 3e6}) {
    for (const double delta : {1e-3, 1e-9}) {
      const int k = lanczos_iterations(static_cast<std::size_t>(n), 0.1, delta);
      EXPECT_LE(failure(n, 0.1, k), delta) << n << " " << delta;
      if (k > 1) {
        EXPECT_GT(failure(n, 0.1, k - 1), delta) << n << " " << delta;
      }
    }
  }
  EXPECT_LT(lanczos_iterations(300, 0.1, 1e-9), lanczos_iterations(3000000, 0.1, 1e-9));
  EXPECT_LT(lanczos_iterations(3000, 0.1, 1e-3), lanczos_iterations(3000, 0.1, 1e-9));
  EXPECT_LT(lanczos_iterations(3000, 0.2, 1e-9), lanczos_iterations(3000, 0.1, 1e-9));
  EXPECT_LE(lanczos_iterations(3000000, 0.1, 1e-9), 50);
}

// Against the dense eigensolver on the beam, uniformly refined and
// adaptively refined (mixed depths): the Ritz value never exceeds λmax, the
// bound never falls below it, and the estimate is deterministic.
void check(const Body& body, const std::string& what) {
  const double lambda = dense_rest_frequency2_per_s2(body);
  const FrequencyEstimate e = rest_frequency2_estimate(body);
  EXPECT_LE(e.ritz_per_s2, lambda * (1.0 + 1e-12)) << what;
  EXPECT_GE(e.bound_per_s2, lambda) << what;
  EXPECT_DOUBLE_EQ(e.bound_per_s2, e.ritz_per_s2 / 0.9) << what;
  // In practice it converges far inside the guaranteed 10 %: 0.999-1.000
  // of λmax on these meshes after ~40 iterations.
  EXPECT_GE(e.ritz_per_s2, 0.99 * lambda) << what;
  EXPECT_EQ(e.iterations, lanczos_iterations(3 * free_node_count(body), 0.1, 1e-9)) << what;
  EXPECT_EQ(rest_frequency2_estimate(body).ritz_per_s2, e.ritz_per_s2) << what << ": not deterministic";
}

TEST(FrequencyEstimate, RitzValueIsBelowTheTrueMaximumAndTheBoundAbove) {
  for (int depth : {0, 1, 2, 3}) {
    scene::Scene s = beam_scene();
    s.adaptivity.min_depth = depth;
    Body body(s);
    check(body, "depth " + std::to_string(depth));
  }
  const Body body = testing::randomly_refined_beam(11);
  check(body, "mixed depths 0..5");
}

// Run a few iterations at a time (as the explicit rung spreads it over
// steps), from a copy of a body that is gone by then: the same estimate.
TEST(FrequencyEstimate, IterationsInInstalmentsGiveTheSameEstimate) {
  scene::Scene s = beam_scene();
  s.adaptivity.min_depth = 2;
  auto body = std::make_unique<Body>(s);
  const FrequencyEstimate whole = rest_frequency2_estimate(*body);
  RestFrequencyLanczos lanczos(*body, 0.1, 1e-9);
  body.reset();
  int instalments = 0;
  while (!lanczos.iterate(3)) ++instalments;
  EXPECT_GT(instalments, 5);
  EXPECT_TRUE(lanczos.done());
  EXPECT_TRUE(lanczos.iterate(1));  // once done, further calls run nothing
  EXPECT_EQ(lanczos.iterations_run(), whole.iterations);
  EXPECT_EQ(lanczos.estimate().iterations, whole.iterations);
  EXPECT_EQ(lanczos.estimate().ritz_per_s2, whole.ritz_per_s2);
  EXPECT_EQ(lanczos.estimate().bound_per_s2, whole.bound_per_s2);
}

// Nothing free (every node fixed): no frequency, no iterations.
TEST(FrequencyEstimate, NothingFreeGivesZero) {
  scene::Scene s = beam_scene();
  s.fixed.push_back({testing::box({0, 0, 0}, {0.4, 0.1, 0.1})});
  s.loads.clear();  // the tip load would act on no free node (refused)
  Body body(s);
  const FrequencyEstimate e = rest_frequency2_estimate(body);
  EXPECT_EQ(e.ritz_per_s2, 0.0);
  EXPECT_EQ(e.bound_per_s2, 0.0);
  EXPECT_EQ(e.iterations, 0);
}

}  // namespace
}  // namespace tissue::physics
