// Integrator implementations (internal to physics/; users go through
// make_integrator in integrator.hpp).
#pragma once

#include <Eigen/Core>
#include <Eigen/SparseCholesky>
#include <array>
#include <cmath>
#include <cstdint>
#include <optional>
#include <type_traits>
#include <vector>

#include "physics/forces.hpp"
#include "physics/frequency_estimate.hpp"
#include "physics/integrator.hpp"
#include "physics/integrator_simd.hpp"

namespace tissue::physics {

// Copy of the node state, restored when a step must be rejected.
class StateSave {
 public:
  void save(const Body& body) {
    x_ = body.x_m;
    v_ = body.v_m_per_s;
  }
  void restore(Body& body) const {
    std::copy(x_.begin(), x_.end(), body.x_m.begin());
    std::copy(v_.begin(), v_.end(), body.v_m_per_s.begin());
  }

 private:
  std::vector<Vec3> x_, v_;
};

// Four springs of the explicit stream, structure of arrays (32 B per spring):
// the AVX2 kernel takes lengths, square roots and divisions four at a time.
// a4/b4 are 4 × node id (first double of the node in a Pad3 array).
struct ExplicitSpringBatch {
  std::uint32_t a4[4], b4[4];
  double rest_m[4], k_N_per_m[4], c_N_s_per_m[4];
};

// f[a] += F, f[b] −= F for every spring of `batches`, F the spring and
// damper force on a; x, v, f are padded per-node arrays and rest_m the rest
// positions (for the rare spring collapsed below 1e-9 of its rest length).
// Both instruction sets give bit-identical results. v = nullptr: every
// spring's c is zero (no damper: velocities are not read); the result is
// that of c = 0.
void explicit_spring_forces(Simd simd, const ExplicitSpringBatch* batches, std::size_t count, const Pad3* x,
                            const Pad3* v, const Vec3* rest_m, Pad3* f);

// The single-precision explicit path (integrator_explicit_float.cpp).
// A node's displacement from rest, velocity or force: four floats (the
// fourth 0), one SSE register.
struct alignas(16) Pad3f {
  float v[4] = {0.0f, 0.0f, 0.0f, 0.0f};
};

// Eight springs, structure of arrays (32 B per spring): rest edge vector
// e = X_b − X_a, rest length L = |e|, stiffness, damping; a4/b4 are 4 × node
// id (first float of the node in a Pad3f array).
struct ExplicitSpringBatchF {
  std::uint32_t a4[8], b4[8];
  float ex[8], ey[8], ez[8];
  float rest_m[8], k_N_per_m[8], c_N_s_per_m[8];
};

// f[a] += F, f[b] −= F for every spring, F the spring and damper force on a
// at displacements u and velocities v (v = nullptr: no spring has a damper).
// Both instruction sets give bit-identical results.
void explicit_spring_forces_float(Simd simd, const ExplicitSpringBatchF* batches, std::size_t count, const Pad3f* u,
                                  const Pad3f* v, Pad3f* f);

// Mass damping v ← v / (1 + h α) for a state in float (both float layouts).
// Stiff bodies take short sub-steps: at h α below 6e-8, 1 + h α is 1 in
// float (α was dropped), near it a multiple of 1.2e-7 (α 0.01/s at 51
// sub-steps per ms: 18% too strong); and even an exact divisor cannot move
// a float velocity by less than half its last digit (h α 2e-7 at |v| just
// below 1: 3.3 last digits, rounded to 3). So the float sub-steps divide
// once every `every` of them, by (1 + h α)^every, which is at least
// 1 + kMinDecay: the divisor and the division then each round to within
// 2^-24 / kMinDecay = 2^-11 of the decay they apply (1e-3 together at
// most). The step's last `count % every` sub-steps' share (all of it when
// every > count) is applied in double by store(): leftover_divisor. α is
// then held to 0.1% however short h is, and the damping is late by at most
// `every` sub-steps (velocity off by less than 2 kMinDecay relative
// meanwhile). At h α >= kMinDecay: every sub-step, as before.
struct FloatMassDamping {
  static constexpr double kMinDecay = 0x1p-13;  // 1.2e-4
  double log_factor = 0.0;                      // ln(1 + h α)
  int every = 1;                                // sub-steps per division in float
  float divisor = 1.0f;                         // (1 + h α)^every, rounded to float
  FloatMassDamping(double h_s, double alpha_per_s);
  // (1 + h α)^(count % every): what store() divides by, in double.
  double leftover_divisor(int count) const { return std::exp((count % every) * log_factor); }
};

// Writes back one node stepped in float (both float layouts): a kinematic
// node moves in double by `count` sub-steps of h_s at its velocity; a free
// one takes its increments u − u0, v − v0 (u0, v0 its state as loaded, u the
// displacement from rest), exact in double, and the step's mass damping the
// float sub-steps left to it (velocity / leftover_divisor, in double).
// Inline: it runs once per node per step, from both layouts' store loops.
inline void store_float_stepped_node(Body& body, NodeId n, bool kinematic, const float (&u)[3], const float (&v)[3],
                                     const float (&u0)[3], const float (&v0)[3], double h_s, int count,
                                     double leftover_divisor) {
  if (kinematic) {
    // Moved in double with its (unchanged) velocity, sub-step by sub-step as
    // the double path does, so a prescribed displacement lands exactly where
    // it does there.
    for (int s = 0; s < count; ++s) body.x_m[n] = body.x_m[n] + h_s * body.v_m_per_s[n];
    return;
  }
  // Free: the step's increments, exact in double (a difference of two floats
  // is), added to the double state. Writing x = X + u instead would round the
  // whole state to float displacements every step: a mirrored or far-moved
  // body (|u| ~ 0.1 m) would gain ~1e-14 J of rounding energy out of nothing,
  // where the increments of a body at rest are exactly 0.
  for (int k = 0; k < 3; ++k) {
    body.x_m[n][k] += static_cast<double>(u[k]) - static_cast<double>(u0[k]);
    body.v_m_per_s[n][k] += static_cast<double>(v[k]) - static_cast<double>(v0[k]);
  }
  if (leftover_divisor != 1.0) body.v_m_per_s[n] /= leftover_divisor;
}

// The explicit integrator's state and spring stream in single precision.
class ExplicitFloatState {
 public:
  // Spring stream and padded arrays for the body's topology.
  void build(const Body& body);
  // Copies positions (as displacements), velocities and external forces in.
  void load(const Body& body, const std::vector<Vec3>& f_ext_N);
  // `count` sub-steps of h (mass damping α taken implicitly, as in double,
  // on FloatMassDamping's schedule).
  void substeps(Simd simd, double h_s, double alpha_per_s, int count);
  // Every live node's displacement and velocity finite and below 1e30.
  bool finite(const Body& body) const;
  // max |u_b − u_a| / L over the springs, at the state now (integrator.hpp,
  // deformed_frequency2_bound_per_s2).
  double end_displacement_ratio() const;
  // Adds the free nodes' increments (u and v now minus as loaded) to the
  // body's double state; kinematic nodes move in double by the last
  // substeps() call's h and count. Call before the body changes.
  void store(Body& body) const;
  const std::vector<ExplicitSpringBatchF>& stream() const { return batches_; }

 private:
  std::vector<ExplicitSpringBatchF> batches_;
  bool damped_ = true;
  // By node id, plus two pad nodes the filler springs join.
  std::vector<Pad3f> u_, v_, f_, f_ext_;
  std::vector<Pad3f> u0_, v0_;  // as loaded: store() adds the increments
  std::vector<float> inv_mass_;
  double h_s_ = 0.0;  // the last substeps() call's, for store()
  int count_ = 0;
  double leftover_divisor_ = 1.0;  // FloatMassDamping::leftover_divisor of that call
};

// The offset layout of the explicit sub-steps (integrator_explicit_offset.cpp):
// on a mesh of one depth, nodes numbered row by row along the lattice and kept as
// structure of arrays (component i of position p at [i * stride + p]), and
// springs taken W at a time as (a0 + j, b0 + j), j < W, a0 a multiple of W,
// b0 − a0 the offset they share — plain vector loads and stores at both ends.
struct OffsetBatchD {
  static constexpr int kLanes = 4;
  std::uint32_t a0, b0;
  double rest_m[4], k_N_per_m[4], c_N_s_per_m[4];  // k = 0: an empty lane
};
struct OffsetBatchF {
  static constexpr int kLanes = 8;
  std::uint32_t a0, b0;
  float ex[8], ey[8], ez[8];  // rest edge vector, position b0 + j minus a0 + j
  float rest_m[8], k_N_per_m[8], c_N_s_per_m[8];
};
// Batches [first, end) share a0 (the a-side forces are summed in registers).
struct OffsetGroup {
  std::uint32_t a0, first, end;
};

// Which node sits at which position and which spring in which lane.
struct OffsetPlan {
  std::vector<NodeId> node_at;  // live nodes by row (lattice z, y), each row split by parity or signature
  std::size_t stride = 0;       // per component: ≥ nodes + W, whole vectors
  struct Batch {
    std::uint32_t a0, b0;
    std::array<EdgeId, 8> edge;  // lane j joins positions a0 + j and b0 + j; mesh::kInvalidId: empty
  };
  std::vector<Batch> batches;  // by (a0, b0)
  std::vector<OffsetGroup> groups;
  double fill = 0.0;  // springs / (W × batches)
};
// The plan for `lanes` (4 or 8) lanes, for any mesh (its fill says whether
// it pays).
OffsetPlan plan_offset_layout(const Body& body, int lanes);
// Whether every live tet has one depth: the meshes whose nodes form a lattice.
bool mesh_has_one_depth(const Body& body);

// f[a] += F, f[b] −= F for every lane, F the spring and damper force on its
// lower end a (x: positions in double, displacements from rest in float;
// v = nullptr: no dampers).
// Both instruction sets give bit-identical results.
template <typename Real>
// worst_ratio2 non-null: also the largest (|Δu| / L)² over the springs
// (deformed_frequency2_bound_per_s2's r², Δu from x, less rest: the rest
// positions, 3 × stride, for double positions; null for float displacements)
// into it, the same on either instruction set.
void offset_spring_forces(Simd simd,
                          const std::conditional_t<std::is_same_v<Real, float>, OffsetBatchF, OffsetBatchD>* batches,
                          const OffsetGroup* groups, std::size_t group_count, std::size_t stride, const Real* x,
                          const Real* v, const Vec3* rest_by_position, Real* f, const Real* rest = nullptr,
                          Real* worst_ratio2 = nullptr);

// v += h w f (then / divisor) where w ≠ 0, x += h v, f = f_ext over the
// structure-of-arrays state (stride a multiple of the lanes). Both
// instruction sets give bit-identical results.
template <typename Real>
void offset_update(Simd simd, Real h, Real divisor, const Real* inv_mass, std::size_t stride, const Real* f_ext,
                   Real* x, Real* v, Real* f);

// The explicit state on the offset layout, in double or float (same duties
// as ExplicitFloatState).
template <typename Real>
class ExplicitOffsetState {
 public:
  using Batch = std::conditional_t<std::is_same_v<Real, float>, OffsetBatchF, OffsetBatchD>;
  // Below this share of filled lanes the gathered stream is cheaper
  // (physics_bench BM_ExplicitSubstep with either layout forced, beams of
  // one depth, 2026-11-25): at 0.6-0.76 filled the offset layout ran 1.1-1.4x
  // faster; at 0.45 (a depth-2 beam in row-parity order: 4.0 vs 2.7 ns per
  // spring; at depth 11, 1.6x10^6 springs: 11.4 vs 5.5) and 0.26 it ran
  // 1.5-3x slower. Adaptively refined meshes fill ~0.4 in lattice order
  // (measured while planning) and are not planned at all (not one depth).
  static constexpr double kMinOffsetFill = 0.6;
  // Builds the layout when the mesh has one depth and fills at least
  // kMinOffsetFill of the lanes, or always when `force` (returns true);
  // otherwise clears it.
  bool build(const Body& body, bool force = false);
  void load(const Body& body, const std::vector<Vec3>& f_ext_N);
  // end_displacement_ratio non-null: r at the last sub-step's forces (the
  // state after count − 1 updates), measured in that force pass.
  void substeps(Simd simd, double h_s, double alpha_per_s, int count, double* end_displacement_ratio = nullptr);
  bool finite() const;
  void store(Body& body) const;
  // As ExplicitFloatState::end_displacement_ratio (scalar and AVX2 give the
  // same value: lane by lane the same operations, then a maximum).
  double end_displacement_ratio(Simd simd) const;
  // The share of lanes holding a spring in the last plan (0 without one).
  double fill() const { return fill_; }
  const std::vector<Batch>& batches() const { return batches_; }
  // Bytes of the stream a sub-step reads per spring: batch headers, the
  // lanes' parameters it loads (no damping coefficient without dampers),
  // group records; empty lanes included. For the benchmark's bound.
  double stream_bytes_per_spring() const;

 private:
  std::vector<NodeId> node_at_;
  std::size_t stride_ = 0;
  std::vector<Batch> batches_;
  std::vector<OffsetGroup> groups_;
  bool damped_ = false;
  double fill_ = 0.0;
  std::vector<Vec3> rest_by_position_;   // for the collapsed-spring direction
  std::vector<Real> x_, v_, f_, f_ext_;  // 3 × stride
  std::vector<Real> x0_, v0_;            // float: as loaded (store() adds the increments); double: unused
  std::vector<Real> rest_;               // double: rest positions, 3 × stride (float keeps displacements)
  std::vector<Real> inv_mass_;           // stride
  double h_s_ = 0.0;                     // the last substeps() call's, for store()
  int count_ = 0;
  double leftover_divisor_ = 1.0;  // float: FloatMassDamping::leftover_divisor of that call
};
extern template class ExplicitOffsetState<double>;
extern template class ExplicitOffsetState<float>;

class ExplicitIntegrator final : public Integrator {
 public:
  ExplicitIntegrator(const scene::IntegratorSpec& spec, const scene::MaterialSpec& material,
                     Simd simd = detected_simd());
  StepOutcome step(Body& body, const std::vector<Vec3>& f_ext_N, double dt_s) override;
  void mesh_changed() override { layout_version_ = 0; }
  // r measured afresh at the next step (not the r, growth and rise bound of
  // a state the body no longer holds: they might ask for too few sub-steps).
  void state_restored() override {
    end_displacement_ratio_ = -1.0;
    growth_per_step_ = 0.0;
    r_rise_bound_ = 0.0;
  }
  const char* name() const override { return single_precision() ? "explicit float" : "explicit"; }

  // Which spring stream the sub-steps run on: kAuto takes the offset layout
  // where it pays (ExplicitOffsetState::build), else the gathered stream;
  // the others force one (kOffset on any mesh: for tests and the benchmark).
  enum class Layout { kAuto, kGathered, kOffset };
  void set_layout(Layout layout) {
    layout_choice_ = layout;
    layout_version_ = 0;
  }
  // Whether the current mesh runs on the offset layout, and its stream bytes
  // per spring (ExplicitOffsetState::stream_bytes_per_spring).
  bool offset_layout() const { return offset_; }
  double offset_stream_bytes_per_spring() const {
    return single_precision() ? offset_float_.stream_bytes_per_spring() : offset_double_.stream_bytes_per_spring();
  }

  // `count` sub-steps of h under f_ext_N, without the stability refusal, the
  // state save or the finiteness check of step(). For the benchmark.
  void run_substeps(Body& body, const std::vector<Vec3>& f_ext_N, double h_s, int count);
  // The spring stream as last built (empty before the first step). For the
  // benchmark's memory-access floor, which runs its own loop over it.
  const std::vector<ExplicitSpringBatch>& spring_stream() const { return batches_; }
  // integrator.explicit_precision: float.
  bool single_precision() const { return spec_.explicit_precision == scene::ExplicitPrecision::kFloat; }
  // The stable step in use, and whether the Lanczos bound has tightened it
  // (see below) for the current layout. For tests and the benchmark.
  const ExplicitStableStep& stable_step() const { return stable_; }
  bool tightened() const { return tightened_; }
  const FrequencyEstimate& estimate() const { return estimate_; }

  // A step takes fewer sub-steps than the margin above allows when the
  // deformation, measured, proves them stable (integrator.hpp,
  // deformed_frequency2_bound_per_s2): the largest relative displacement r
  // of a spring's ends, measured on the last state, gives a bound on the
  // deformed stiffness; if substep_safety × kVerifiedSafetyPerSafety (0.95 by
  // default, and at most kVerifiedSafetyMax) of the stable step under that bound needs fewer sub-steps, the
  // step runs with them and r is measured again near its end (on the offset
  // layout at the last sub-step's forces, inside that force pass; on the
  // gathered streams on the state reached, in a pass of its own); the step
  // is accepted if the bound there allows them too, else run again from the
  // body (untouched until a step is accepted) with the usual count or more,
  // and r measured again at the end of that run (as for a verified step).
  // So a shortened step is verified at its start and near its end (not at
  // every sub-step: the margin is for that). A pass of its own costs
  // 0.4-0.8 of a sub-step, so the count is shortened only where that saves
  // one; without shortening, r is measured every kRemeasureSteps steps to
  // see whether it would.
  static constexpr double kVerifiedSafetyPerSafety = 19.0 / 16.0;  // 0.8 -> 0.95
  static constexpr double kVerifiedSafetyMax = 0.95;               // never nearer the stable bound than this
  static constexpr int kRemeasureSteps = 64;                       // or sooner: r_rise_bound_
  // r of the last state measured; steps taken with fewer sub-steps, and
  // steps run again (steps the integrator accepted: a step the Simulation
  // then refuses at its energy bound is counted, one refused here is not).
  // For tests and the benchmark.
  double end_displacement_ratio() const { return end_displacement_ratio_; }
  // How far r may have risen since it was measured (see r_rise_bound_).
  double r_rise_bound() const { return r_rise_bound_; }
  std::int64_t verified_steps() const { return verified_steps_; }
  std::int64_t rerun_steps() const { return rerun_steps_; }
  // The stable step at relative end displacement r on the current mesh.
  ExplicitStableStep stable_step_at(double end_displacement_ratio) const;

  // The sub-step starts from the guaranteed bounds (explicit_stable_step).
  // Once the current mesh has run kLanczosWaitCostMultiple times the Lanczos
  // estimate's cost in sub-steps, the estimate starts, spread over the
  // following steps at kLanczosShare of their cost (no step pays for all of
  // it: 10 ms at 5x10^4 springs), and its bound (frequency_estimate.hpp:
  // above λmax except with probability 1e-9) is taken when lower. A mesh that
  // changes sooner pays nothing; one that changes just before the estimate
  // completes has paid at most 1/4 extra; one that stays gets the tight
  // sub-step after ~4x the estimate's cost (a few hundred sub-steps).
  // ε = 0.05 (was 0.1: 1.4x the iterations for a sub-step 0.975x the true
  // limit instead of 0.95x, which the verified count below needs to match a
  // stepper run at 0.90x of it: physics_bench ExplicitVsPlainStepper).
  static constexpr double kLanczosRelativeGap = 0.05, kLanczosFailureProbability = 1e-9;
  static constexpr std::int64_t kLanczosWaitCostMultiple = 2;
  static constexpr double kLanczosShare = 0.5;
  // One Lanczos iteration (scalar pass over the springs and nodes) in
  // explicit sub-steps: 1.0-1.8 from 10^3 to 4x10^5 springs (physics_bench
  // BM_FrequencyEstimate, iteration_vs_substep).
  static constexpr std::int64_t kLanczosIterationCost = 2;

 private:
  // Spring stream, stable bound and padded state sized for the topology.
  void build_layout(const Body& body);
  // Copies the body's state in; runs `count` sub-steps on the padded copy
  // (end_displacement_ratio non-null: and measures r, on the offset layout
  // in the last sub-step's force pass, on the gathered streams in a pass of
  // their own over the state reached; body: the double stream's rest
  // positions).
  void load(const Body& body, const std::vector<Vec3>& f_ext_N);
  void advance(double h_s, int count, double* end_displacement_ratio = nullptr, const Body* body = nullptr);
  // r of the padded copy (float and offset states: their own; the double
  // stream: positions minus the body's rest positions).
  double measure_end_displacement_ratio(const Body& body) const;
  // Sub-steps for dt_s at relative end displacement r with the verified
  // margin (max_substeps + 1 when more than that).
  int verified_substeps(double dt_s, double end_displacement_ratio) const;
  // The share of the stable bound a verified sub-step takes: capped, as with
  // substep_safety above 16/19 the ratio alone would take sub-steps longer
  // than the stable bound itself.
  double verified_fraction() const {
    return std::min(kVerifiedSafetyPerSafety * spec_.substep_safety, kVerifiedSafetyMax);
  }
  // Runs `count` sub-steps from the loaded state and stores the result in the
  // body, or rejects a non-finite one (the body untouched). measure_r (a
  // step run again): r is measured at the end, as on the verified path,
  // instead of r_rise_bound_ growing by the step's move.
  StepOutcome run_and_accept(Body& body, double dt_s, int count, StepOutcome out, bool measure_r = false);
  // r's rise over a last sub-step of h_s ending at the body's velocities:
  // 2 h max|v| / the shortest moving spring (the offset layout measures r
  // at that sub-step's start).
  double last_substep_rise(const Body& body, double h_s) const;
  // state_is_finite for the padded copy, over the body's live nodes.
  bool advanced_state_is_finite(const Body& body) const;
  // Copies the padded state back to the body: a step of `substeps`
  // sub-steps, told to before_store_ first.
  void store(Body& body, int substeps) const;
  // Counts a step's sub-steps on this layout and, past the wait, runs the
  // Lanczos iterations they pay for; takes its bound once it is done.
  void spend_on_estimate(const Body& body, int substeps);

  scene::IntegratorSpec spec_;
  double alpha_per_s_;
  bool paper_damping_;  // material.damping: paper (what a refusal advises)
  Simd simd_;
  std::uint64_t layout_version_ = 0;  // body.parameters_version() the layout was built for
  ExplicitBounds bounds_;
  double rest_bound_per_s2_ = 0.0;        // min(bounds_.rest_per_s2, the Lanczos bound once done)
  ExplicitStableStep stable_;             // stable_step_at(0)
  double end_displacement_ratio_ = -1.0;  // of the last state measured; < 0: not measured on this layout
  double growth_per_step_ = 0.0;          // r's rise over the last verified step (≥ 0)
  int steps_since_measured_ = 0;
  // An upper bound on r's rise since it was last measured: a step moving
  // every node by at most d moves a spring's ends relative to each other by
  // at most 2 d, so r rises by at most 2 d / (the shortest moving spring's
  // rest length). When r + this bound reaches 1/2, r is measured again
  // before the step (the collapse check needs it; the steps on the plain
  // margin path measured it only every kRemeasureSteps). A verified or
  // rerun step on the offset layout measures r at its last sub-step's
  // start, so the bound starts from that sub-step's move, not 0.
  double r_rise_bound_ = 0.0;
  double shortest_rest_m_ = 0.0;  // of a spring with a free end, on this layout
  std::vector<Vec3> x_start_m_;   // the body's positions before a stored step
  std::int64_t verified_steps_ = 0;
  const Vec3* rest_m_ = nullptr;  // the body's rest positions, for the double stream's collapsed springs
  std::int64_t rerun_steps_ = 0;
  bool tightened_ = false;
  std::int64_t layout_substeps_ = 0, lanczos_wait_substeps_ = 0;  // sub-steps run on this layout
  std::optional<RestFrequencyLanczos> lanczos_;                   // under way
  double lanczos_credit_ = 0.0;                                   // iterations paid for, not yet run
  FrequencyEstimate estimate_;
  std::vector<ExplicitSpringBatch> batches_;
  bool damped_ = true;  // some spring in the stream has a damper
  // By node id, plus two pad nodes the filler springs of the last batch join
  // (x = 0 and x = e_x, k = c = 0: an exactly zero force).
  std::vector<Pad3> x_, v_, f_, f_ext_;
  std::vector<double> inv_mass_;
  ExplicitFloatState float_;  // used instead of the above with explicit_precision: float
  Layout layout_choice_ = Layout::kAuto;
  bool offset_ = false;  // the offset layout below runs instead of the streams above
  ExplicitOffsetState<double> offset_double_;
  ExplicitOffsetState<float> offset_float_;
};

// One spring of the implicit system, streamed in edge order. Its block
//   B = h c d̂d̂ᵀ + h² k (d̂d̂ᵀ + t (I − d̂d̂ᵀ)) = along d̂d̂ᵀ + iso I
// (t = max(0, 1 − L/l), the clamped transverse term) is stored as
// e = √along d̂ and iso, B = S (eeᵀ + iso I), in single precision scaled by
// the step's power of two S (ImplicitIntegrator::step: no entry exceeds 1):
// 24 B instead of ids + a 72 B Matrix3d, and no multiply by `along` per
// product. The products run in double on the widened floats; the operator
// stays exactly symmetric positive definite, within ~1e-7 of the double
// blocks (below any CG tolerance). At 4x10^5 springs, where the CG's data
// outgrew L3, a cg20 step ran 25 % faster than with 40 B double records.
// e comes first so one 128-bit load and one widening give e and iso.
// a4 and b4 are 4 × the unknown index, i.e. the first double of the unknown
// in a Pad3 array seen as doubles (a scaled-index load, no shift); a
// kinematic end maps to the sink slot.
struct ImplicitSpring {
  float e[3];
  float iso;
  std::uint32_t a4, b4;
};

// ap[a] += B̃ (p[a] − p[b]), ap[b] −= B̃ (p[a] − p[b]) for every spring, in
// order, B̃ = eeᵀ + iso I as stored (the caller scales by S). Both instruction
// sets give bit-identical results.
void implicit_spring_matvec(Simd simd, const ImplicitSpring* springs, std::size_t count, const Pad3* p, Pad3* ap);

class ImplicitIntegrator final : public Integrator {
 public:
  // How the CG matrix-vector product is evaluated. Both apply the same
  // operator (a test checks they agree); kMatrixFree is the default because it
  // benchmarks faster at every size (figures in integrator_implicit.cpp).
  enum class Matvec { kMatrixFree, kAssembledBlockCsr };
  // CG preconditioner. kTwoLevel adds to Jacobi a coarse correction: free
  // nodes grouped into aggregates (cells of a coarse grid over the rest
  // shape, ~27 nodes each), the Galerkin coarse matrix Pᵀ A P of their rigid
  // translations assembled and band-Cholesky factored every step, applied
  // additively: M⁻¹ = D⁻¹ + P (Pᵀ A P)⁻¹ Pᵀ (SPD, so CG stays valid).
  // kAuto: kTwoLevel from kAutoTwoLevelUnknowns free nodes on, else kJacobi,
  // decided again at every mesh change.
  enum class Preconditioner { kJacobi, kTwoLevel, kAuto };
  // Where two-level starts paying (physics_bench BM_PreconditionerCrossover,
  // tolerance 1e-6, dt = 1 ms, thread CPU per step, two-level / Jacobi): the
  // compact cube 0.87-0.96 from 729 nodes (429: 1.01), the slender beam 0.96
  // from 2,089 nodes (1,225: 1.14), 0.70 at 8,281; Jacobi's iterations grow
  // with the mesh (27 -> 100, the cap) where two-level's stay at 26-45. At
  // dt = 10 ms on the beam two-level costs 1.1-1.3x, but Jacobi stops at the
  // cap there, short of the tolerance.
  static constexpr std::uint32_t kAutoTwoLevelUnknowns = 1000;

  ImplicitIntegrator(const scene::IntegratorSpec& spec, const scene::MaterialSpec& material,
                     Matvec matvec = Matvec::kMatrixFree, Simd simd = detected_simd(),
                     Preconditioner preconditioner = Preconditioner::kJacobi);
  StepOutcome step(Body& body, const std::vector<Vec3>& f_ext_N, double dt_s) override;
  void mesh_changed() override {}
  const char* name() const override { return "implicit"; }

  // y = A p with the system matrix of the last step, both indexed by node id
  // (entries of kinematic nodes in p are ignored, in y zero). For tests.
  void system_product(const std::vector<Vec3>& p_by_node, std::vector<Vec3>& y_by_node);
  // z = M⁻¹ r with the preconditioner of the last step, by node id (only its
  // coarse part P (Pᵀ A P)⁻¹ Pᵀ r when `coarse_only`; zero without one), and
  // the aggregate of a node (kNoAggregate: kinematic, or Jacobi). For tests.
  void precondition(const std::vector<Vec3>& r_by_node, std::vector<Vec3>& z_by_node, bool coarse_only = false);
  static constexpr std::uint32_t kNoAggregate = 0xffffffffu;
  std::uint32_t aggregate_of_node(NodeId n) const;
  bool coarse_active() const { return coarse_ok_; }
  // Whether the current layout uses the two-level preconditioner (kAuto's
  // choice, or the fixed one).
  bool two_level() const { return two_level_; }

 private:
  // ap = A p over the unknowns (after p = z + beta p when `update_p`);
  // returns pᵀAp.
  double apply(bool update_p, double beta);
  double apply_assembled();
  void assemble();
  // Unknown numbering and the spring visiting order, per mesh topology.
  void build_layout(const Body& body);
  void build_aggregates(const Body& body);
  // Assembles and factors Pᵀ A P; false when a pivot is not positive (the
  // step then runs with Jacobi alone).
  bool factor_coarse();
  // z += P (Pᵀ A P)⁻¹ Pᵀ r; returns rᵀz.
  double coarse_correct();

  scene::IntegratorSpec spec_;
  double alpha_per_s_;
  Matvec matvec_;
  Preconditioner preconditioner_;
  bool two_level_ = false;  // per layout: see kAuto
  bool coarse_ok_ = false;
  std::vector<std::uint32_t> aggregate_of_unknown_;  // kNoAggregate for the sink
  std::uint32_t coarse_dofs_ = 0, band_ = 0;         // 3 per aggregate; lower bandwidth
  std::vector<double> coarse_factor_;                // band Cholesky, (band_ + 1) per row
  std::vector<double> coarse_rhs_;
  std::vector<Pad3> coarse_pad_;  // Pᵀ r and the coarse solution, per aggregate
  // Springs joining two aggregates (or an aggregate and a kinematic node):
  // the only ones that reach Pᵀ A P; grouped by aggregate pair.
  struct CoarseSpring {
    std::uint32_t spring, pair;  // index into springs_ and coarse_pairs_
  };
  struct CoarsePair {
    std::uint32_t hi, lo;  // aggregates, hi > lo; hi = kNoAggregate: lo's kinematic neighbours
  };
  std::vector<CoarsePair> coarse_pairs_;
  std::vector<double> pair_blocks_;  // Σ B per pair, 6 symmetric entries
  std::vector<CoarseSpring> coarse_springs_;
  Simd simd_;
  double h_ = 0.0;
  std::uint32_t unknowns_ = 0;                  // free nodes; index unknowns_ is the sink
  std::vector<std::uint32_t> unknown_of_node_;  // sink for kinematic and dead nodes
  std::vector<NodeId> node_of_unknown_;
  std::uint64_t layout_version_ = 0;                // body.parameters_version() the layout was built for
  std::vector<EdgeId> live_edges_;                  // springs with a free end, in id order
  double stiffness_max_ = 0.0, damping_max_ = 0.0;  // over live_edges_: the records' scale
  std::vector<ImplicitSpring> springs_;
  double record_scale2_ = 1.0;  // S: the blocks are S times the records' (step)
  // Per unknown (+ sink): (1 + h alpha) m / S, the Jacobi inverse, CG vectors.
  std::vector<double> mass_;
  std::vector<Pad3> diag_inv_, rhs_, dv_, r_, z_, p_, ap_;
  std::vector<Vec3> dv_by_node_;  // warm start: last step's solution
  // Rest position of each node id at the last layout: a node whose id now
  // stands elsewhere (reused after a merge) drops its warm start.
  std::vector<Vec3> warm_start_rest_m_;
  // Assembled block-CSR (kAssembledBlockCsr): per unknown its diagonal block,
  // then its off-diagonal blocks −B with their column.
  std::vector<Eigen::Matrix3d> diag_block_, off_block_;
  std::vector<std::uint32_t> row_start_, col_;
  StateSave save_;
};

// The scene's choice (integrator.cg_preconditioner) as the integrator's.
ImplicitIntegrator::Preconditioner implicit_preconditioner(scene::CgPreconditioner choice);

class ProjectiveIntegrator final : public Integrator {
 public:
  ProjectiveIntegrator(const scene::IntegratorSpec& spec, const scene::MaterialSpec& material);
  StepOutcome step(Body& body, const std::vector<Vec3>& f_ext_N, double dt_s) override;
  void mesh_changed() override { factor_valid_ = false; }
  const char* name() const override { return "projective"; }

 private:
  void factor(const Body& body, double dt_s);

  scene::IntegratorSpec spec_;
  double alpha_per_s_;
  bool factor_valid_ = false;
  double factored_dt_s_ = 0.0;
  std::uint64_t factored_version_ = 0;  // body.parameters_version() the factor was built for
  std::vector<int> dof_of_node_;        // free nodes → row, else -1
  std::vector<NodeId> node_of_dof_;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver_;
  Eigen::MatrixXd rhs_, solution_;
  std::vector<Vec3> inertial_, d_, x_prev_;
  ImplicitDamperWork dampers_;
  StateSave save_;
};

}  // namespace tissue::physics
