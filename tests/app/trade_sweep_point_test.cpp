// A sweep point's errors (app/trade_sweep_point.hpp): against its reference
// run (tip and node field) and, for its tip path, against the truth run.
#include "app/trade_sweep_point.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

namespace tissue::app {
namespace {

namespace ph = tissue::physics;
using ph::Vec3;

// One tet, nodes 0..2 fixed at rest, node 3 free and displaced by `u3`.
ph::DisplacementField one_tet_field(const Vec3& u3) {
  ph::DisplacementField f;
  f.rest_m = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1)};
  f.u_m = {Vec3::Zero(), Vec3::Zero(), Vec3::Zero(), u3};
  f.free = {0, 0, 0, 1};
  f.tets = {{0, 1, 2, 3}};
  return f;
}

SweepPoint captured_point(const Vec3& tip, const Vec3& u3) {
  SweepPoint p;
  p.tip = tip;
  p.field = one_tet_field(u3);
  p.captured = true;
  return p;
}

TEST(TradeSweepPoint, ErrorsAreRelativeToTheReference) {
  const SweepPoint ref = captured_point(Vec3(0, 0, -0.010), Vec3(0, 0, -0.02));
  SweepPoint p = captured_point(Vec3(0, 0, -0.011), Vec3(0, 0, -0.01));
  fill_errors(p, ref);
  ASSERT_TRUE(p.has_error);
  EXPECT_NEAR(p.tip_err, 0.1, 1e-12);  // 1 mm off a 10 mm tip
  // The one free node is 10 mm off the reference's largest displacement, 20 mm.
  EXPECT_NEAR(p.rms_err, 0.5, 1e-12);
  EXPECT_NEAR(p.max_err, 0.5, 1e-12);
  EXPECT_EQ(p.unlocated, 0u);
  EXPECT_EQ(metric_of(p, "tip"), p.tip_err);
  EXPECT_EQ(metric_of(p, "rms"), p.rms_err);
}

TEST(TradeSweepPoint, NoErrorUnlessBothRunsFinished) {
  SweepPoint ref = captured_point(Vec3(0, 0, -0.01), Vec3(0, 0, -0.02));
  ref.captured = false;  // the reference was capped or failed
  SweepPoint p = captured_point(Vec3(0, 0, -0.011), Vec3(0, 0, -0.01));
  fill_errors(p, ref);
  EXPECT_FALSE(p.has_error);
  EXPECT_TRUE(std::isnan(p.tip_err));
  EXPECT_TRUE(std::isnan(p.rms_err));
}

TEST(TradeSweepPoint, StatusSaysWhyARunStopped) {
  SweepPoint p;
  EXPECT_EQ(p.status(), "ok");
  p.st.capped = true;
  EXPECT_EQ(p.status(), "capped");
  p.st.ok = false;
  EXPECT_EQ(p.status(), "failed");
  p.st.interrupted_by = 2;
  EXPECT_EQ(p.status(), "interrupted");
  const SweepPoint skipped = not_run_point(scene::IntegratorKind::kExplicit, 5e-3, "not run: why");
  EXPECT_EQ(skipped.status(), "skipped");
  EXPECT_EQ(skipped.integrator, "explicit");
  EXPECT_EQ(skipped.st.error, "not run: why");
}

// A uniform reference run at max depth 2 with a tip path u_z(t).
SweepPoint reference_run(const char* integrator, double dt_s, const std::vector<double>& uz) {
  SweepPoint p;
  p.integrator = integrator;
  p.dt_s = dt_s;
  p.level = p.max_depth = 2;
  for (std::size_t k = 0; k < uz.size(); ++k) {
    p.tip_t_s.push_back(1e-3 * static_cast<double>(k + 1));
    p.tip_path_m.push_back(Vec3(0, 0, uz[k]));
  }
  return p;
}

// The truth is explicit before implicit, then the smallest dt; every
// finished run's path is measured against it.
TEST(TradeSweepPoint, TheTruthIsExplicitAtTheSmallestStep) {
  std::vector<SweepPoint> points = {
      reference_run("implicit", 1e-3, {-1.5e-3, -2.5e-3}),
      reference_run("explicit", 5e-3, {-1.0e-3, -2.0e-3}),
      reference_run("explicit", 1e-3, {-1.0e-3, -2.0e-3}),
  };
  SweepPoint capped = reference_run("projective", 1e-3, {-1.5e-3, -2.5e-3});
  capped.st.capped = true;
  points.push_back(capped);
  const auto truth = set_path_errors(points);
  ASSERT_EQ(truth.size(), 1u);
  EXPECT_EQ(truth.at(2), "explicit at dt 1 ms, uniform L2");
  EXPECT_EQ(points[2].path_err, 0.0);  // the truth against itself
  // 0.5 mm off at both samples, over the truth's largest 2 mm.
  EXPECT_NEAR(points[0].path_err, 0.25, 1e-12);
  EXPECT_NEAR(metric_of(points[0], "path"), 0.25, 1e-12);
  EXPECT_TRUE(std::isnan(points[3].path_err)) << "a capped run has no path error";
}

// The tip path's samples are bounded whatever the step count (1e8 steps,
// the most the setup allows, kept 1e8 samples: 3.2 GB a run): every step up
// to kMaxPathSamples, then a uniform grid ending at the last step.
TEST(TradeSweepPoint, TheTipPathKeepsABoundedUniformSampleOfTheSteps) {
  for (const long steps : {1L, 500L, kMaxPathSamples, kMaxPathSamples + 1, 123457L, 100000000L}) {
    SCOPED_TRACE(steps);
    long samples = 0, last = 0, gap = 0;
    bool uniform = true;
    for (long step = 1; step <= steps; ++step) {
      if (!is_path_sample(step, steps)) continue;
      if (step != steps && gap != 0 && step - last != gap) uniform = false;  // the last may come early
      if (step != steps) gap = step - last;
      last = step;
      ++samples;
    }
    EXPECT_LE(samples, kMaxPathSamples + 1);
    EXPECT_EQ(last, steps) << "the end state is always a sample";
    EXPECT_TRUE(uniform);
    if (steps <= kMaxPathSamples) {
      EXPECT_EQ(samples, steps) << "every step, as before";
    } else {
      EXPECT_GE(samples, kMaxPathSamples / 2) << "no coarser than it needs to be";
    }
  }
}

}  // namespace
}  // namespace tissue::app
