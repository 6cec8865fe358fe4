// Adaptation of the mesh to the deformation (seed paper §3.1, 3.2, 3.4, with
// the corrections of NUMERICS.md §2):
// - refine: split the diamond of every tet whose strain-energy density
//   exceeds Th (or whose worst edge length ratio, max(l/L, L/l), exceeds
//   stretch_ratio);
// - simplify, with hysteresis: merge a split diamond when it can merge, every
//   tet around its node is below Th · simplify_factor and so is every tet the
//   merge would restore (those can be ~2x as dense as their children: judged
//   on the children alone, a static body merged and re-split a diamond
//   forever once simplify_factor passed ~0.5), its node sits within
//   midpoint_tolerance · L of its edge's midpoint (merging then moves nothing
//   visibly), and it was split at least min_age_steps ago;
// - a budget of max_ops_per_step diamond splits + merges per pass keeps a
//   pass's cost bounded: a split counts its whole closure (the unsplit
//   ancestors it splits first), and one whose closure exceeds what is left
//   of the budget waits for a later pass, except as the pass's first split
//   (so a pass always progresses; that one pass does the closure whole);
//   after kMaxSplitWaitsPerPass such waits the pass stops looking for a
//   closure that fits (each look walks a closure up).
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "physics/body.hpp"

namespace tissue::physics {

struct AdaptStats {
  int splits = 0;  // diamonds split, closure included
  int merges = 0;
  // Σ ½ k (l − L)² before the pass changed anything, bit-identical to
  // elastic_energy_J (same sum in the same order), from the lengths the
  // pass measures anyway: the energy booking needs it for free.
  double elastic_energy_before_J = 0.0;
  // The pass stopped splitting at adaptivity.max_tets.
  bool ceiling_reached = false;
  // Nodes whose edges the pass walked (KuhnMesh::for_each_edge_at_node,
  // 26 (K + 1) hash lookups each) to find the merges that reach into the
  // frozen sphere: the cost a tool contact adds to a pass.
  int frozen_edge_walks = 0;
  // Split candidates whose closure the pass walked up (closure_diamonds, or
  // closure_tets when a sphere is frozen: a BFS plus a linear visited check,
  // O(L²) for a closure of L diamonds, L up to ~130 at depth 30).
  int closure_walks = 0;
  // Split candidates (distinct diamonds) whose closure waited for a later
  // pass because it exceeded what was left of the budget.
  int split_waits = 0;
};

class Adaptivity {
 public:
  // Split candidates whose closure does not fit what is left of the budget
  // (distinct diamonds) after which a pass stops looking for one that does;
  // see adapt().
  static constexpr int kMaxSplitWaitsPerPass = 32;

  explicit Adaptivity(const scene::AdaptivitySpec& spec) : spec_(spec) {}
  // One adaptation pass over the body.
  AdaptStats adapt(Body& body);
  // The density measure the criterion uses for a tet: Pa for strain energy,
  // dimensionless strain for stretch.
  double measure(const Body& body, TetId t) const;
  double refine_threshold() const;
  double simplify_threshold() const { return refine_threshold() * spec_.simplify_factor; }

  // While a tool presses the object the mesh under it must not change (the
  // haptic loop renders against that patch): tets with a vertex, and nodes,
  // currently within radius_m of centre_m are neither refined nor merged. A
  // split whose closure would bisect such a tet, and a merge that would
  // replace one, are skipped.
  void freeze_sphere(const Vec3& centre_m, double radius_m) {
    frozen_ = true;
    frozen_centre_m_ = centre_m;
    frozen_radius_m_ = radius_m;
  }
  void unfreeze() { frozen_ = false; }

 private:
  // Per-tet measure from per-edge strains (each edge's sqrt once, not once
  // per incident tet: ~5x fewer).
  double measure_from_edges(const mesh::Tet& tet) const;

  // True when a tet split(diamond) would bisect, closure included, has a
  // frozen vertex.
  bool closure_touches_frozen(const Body& body, mesh::Key diamond);
  // near_frozen_[n] = 1 for every node in the frozen sphere and every node
  // joined to one by an edge: a merge of such a node would replace a tet
  // with a frozen vertex. Counts the nodes whose edges it walks.
  void mark_near_frozen(const Body& body, AdaptStats& stats);
  // Largest measure of the tets merging `diamond` would restore, from the
  // current positions (0 when it cannot merge).
  double restored_measure(const Body& body, mesh::Key diamond);

  // Marks, and tells, a split candidate this pass passed over (see
  // passed_over_).
  void pass_over(const mesh::KuhnMesh& mesh, mesh::Key diamond);
  bool passed_over(const mesh::KuhnMesh& mesh, mesh::Key diamond) const;

  bool is_frozen(const Vec3& x_m) const {
    return frozen_ && (x_m - frozen_centre_m_).squaredNorm() <= frozen_radius_m_ * frozen_radius_m_;
  }

  scene::AdaptivitySpec spec_;
  bool frozen_ = false;
  Vec3 frozen_centre_m_ = Vec3::Zero();
  double frozen_radius_m_ = 0.0;
  double youngs_modulus_Pa_ = 0.0;
  std::vector<double> edge_strain_;  // per edge: l / L − 1
  // Per node slot: max measure of its incident tets at the start of the
  // pass, or kUnmeasured (below every measure, which is >= 0) for a slot
  // that held no live node then.
  static constexpr double kUnmeasured = -1.0;
  std::vector<double> node_max_;
  std::vector<std::pair<double, mesh::Key>> refine_;       // (−measure, diamond)
  std::vector<std::tuple<int, double, mesh::Key>> merge_;  // (−depth, measure, diamond)
  std::vector<TetId> closure_tets_;                        // scratch of closure_touches_frozen
  std::vector<mesh::Key> closure_keys_;                    // a split candidate's closure
  // Split candidates this pass passed over (their closure waited for the
  // budget or reached the frozen sphere), by their edge: a diamond comes
  // once per strained tet (up to 8), and a repeat would be decided the same
  // way (see adapt()), so it is skipped without walking its closure again.
  // Flags per edge slot, and the slots set, to clear them: no allocation
  // once grown.
  std::vector<std::uint8_t> passed_over_;
  std::vector<EdgeId> passed_over_edges_;
  std::vector<std::uint8_t> near_frozen_;            // per node slot, see mark_near_frozen
  std::array<std::array<NodeId, 4>, 8> restored_{};  // scratch of restored_measure
};

}  // namespace tissue::physics
