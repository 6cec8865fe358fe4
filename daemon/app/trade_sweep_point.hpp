// One point of the sweep: a run's setting, what it measured and its errors.
//
// Error of a run vs a reference run: tip = |u_tip - u_tip,ref| / |u_tip,ref|;
// node RMS / max = |u(p_i) - u_ref,i| over the reference's free nodes p_i,
// u(p_i) interpolated barycentrically inside the run's leaf tet that contains
// p_i at rest, divided by max_i |u_ref,i| (physics/field_error.hpp).
#pragma once

#include <cmath>
#include <cstddef>
#include <map>
#include <string>
#include <vector>

#include "app/trade_run.hpp"
#include "physics/field_error.hpp"
#include "scene/scene.hpp"

namespace tissue::app {

struct SweepPoint {
  // Setting
  std::string integrator;
  double dt_s = 0.0;
  int max_depth = 0;
  bool adaptive = false;
  int level = 0;       // uniform level
  double th_Pa = NAN;  // adaptive threshold
  // Outcome
  RunStats st;
  std::size_t nodes = 0, tets = 0, springs = 0, peak_nodes = 0, peak_tets = 0;
  long splits = 0, merges = 0;
  int deepest = 0;                  // deepest leaf tet at the end
  std::size_t tets_at_deepest = 0;  // and how many leaves sit there
  physics::Vec3 tip = physics::Vec3::Zero();
  std::vector<double> tip_t_s;  // the tip after the steps is_path_sample keeps (a scene with probes)
  std::vector<physics::Vec3> tip_path_m;
  physics::DisplacementField field;  // dropped once errors are filled
  bool captured = false;
  // Errors vs the reference (filled when both ran)
  double tip_err = NAN, rms_err = NAN, max_err = NAN;
  std::size_t unlocated = 0;
  // The tip's path against the truth of its max depth (set_path_errors).
  double path_err = NAN;
  bool has_error = false;
  bool skipped = false;  // not run (reason in st.error)
  // "skipped", "interrupted", "failed", "capped" or "ok".
  std::string status() const;
};

// The tip path is kept at the run's steps number 1..steps (1-based) for which
// is_path_sample holds: every step up to kMaxPathSamples steps, beyond that
// every path_stride(steps)-th step and the last (a uniform time grid, as the
// steps are), so at most kMaxPathSamples + 1 samples a run. The path error
// stays the RMS over the run's time; --dts 1e-8 (5e7 steps, which the setup
// allows) kept 1.6 GB a run.
constexpr long kMaxPathSamples = 10000;
long path_stride(long steps);
bool is_path_sample(long step, long steps);

// A point that was not run (skipped), `reason` as its error; the caller sets
// the mesh fields (level, or adaptive, max_depth and th_Pa).
SweepPoint not_run_point(scene::IntegratorKind kind, double dt_s, const std::string& reason);

// `p`'s tip and node errors against `ref`, when both captured their end state.
void fill_errors(SweepPoint& p, const SweepPoint& ref);

// The dynamics' truth at each max depth: the uniform run at that depth with
// the smallest time error, explicit (symplectic, sub-stepped far below dt)
// at the smallest dt if the sweep ran it, else implicit, else projective.
// Every run's tip path is measured against it: the same-integrator
// reference above measures the mesh; this measures integrator and dt too
// (implicit Euler's damping at large dt ends in the same static state).
// Returns, per max depth, what the truth was ("" where none finished).
std::map<int, std::string> set_path_errors(std::vector<SweepPoint>& points);

// The error --metric names (rms, max, tip or path).
double metric_of(const SweepPoint& p, const std::string& metric);

}  // namespace tissue::app
