#include "physics/adaptivity.hpp"

#include <algorithm>
#include <cmath>
#include <tuple>

#include "physics/forces.hpp"

namespace tissue::physics {

double Adaptivity::measure(const Body& body, TetId t) const {
  return spec_.criterion == scene::RefineCriterion::kStretch ? max_edge_stretch(body, t)
                                                             : strain_energy_density_Pa(body, t);
}

double Adaptivity::refine_threshold() const {
  return spec_.criterion == scene::RefineCriterion::kStretch ? spec_.stretch_ratio - 1.0 : spec_.refine_threshold_Pa;
}

double Adaptivity::measure_from_edges(const mesh::Tet& tet) const {
  double sum = 0.0, worst = 0.0;
  for (EdgeId e : tet.e) {
    const double strain = edge_strain_[e];
    sum += strain * strain;
    worst = std::max(worst, stretch_from_strain(strain));
  }
  return spec_.criterion == scene::RefineCriterion::kStretch ? worst : 0.5 * youngs_modulus_Pa_ * sum;
}

bool Adaptivity::closure_touches_frozen(const Body& body, mesh::Key diamond) {
  // Not the wanted tet alone: the split bisects every tet of the diamond and
  // its closure every tet of each unsplit ancestor, coarser tets that can
  // reach into the sphere from outside it.
  body.mesh().closure_tets(diamond, closure_tets_, closure_keys_);
  for (const TetId t : closure_tets_)
    for (const NodeId n : body.mesh().tet(t).v)
      if (is_frozen(body.x_m[n])) return true;
  return false;
}

void Adaptivity::pass_over(const mesh::KuhnMesh& mesh, mesh::Key diamond) {
  // A candidate is the refinement edge of a live tet, and a passed-over one
  // is not split later in the pass (see adapt()), so its edge keeps its id.
  const EdgeId e = mesh.find_edge(diamond);
  if (e == util::KeyIndexMap::kNotFound) return;
  if (e >= passed_over_.size()) passed_over_.resize(mesh.edge_capacity(), 0);
  if (passed_over_[e]) return;
  passed_over_[e] = 1;
  passed_over_edges_.push_back(e);
}

bool Adaptivity::passed_over(const mesh::KuhnMesh& mesh, mesh::Key diamond) const {
  if (passed_over_edges_.empty()) return false;  // no lookup while nothing waits
  const EdgeId e = mesh.find_edge(diamond);
  return e < passed_over_.size() && passed_over_[e];
}

void Adaptivity::mark_near_frozen(const Body& body, AdaptStats& stats) {
  // A merge replaces every tet around its node z, and their vertices are
  // exactly z and the nodes joined to it by an edge: a node just outside the
  // sphere can have tets reaching into it. So mark each node in the sphere
  // and its neighbours, walking the edges of the few nodes under the tool
  // once, not those of every merge candidate (26 (K + 1) hash lookups each:
  // a contact made a pass on a big relaxed mesh ~19x slower).
  const mesh::KuhnMesh& mesh = body.mesh();
  near_frozen_.assign(mesh.node_capacity(), 0);
  mesh.for_each_node([&](NodeId n, const mesh::Node&) {
    if (!is_frozen(body.x_m[n])) return;
    near_frozen_[n] = 1;
    ++stats.frozen_edge_walks;
    mesh.for_each_edge_at_node(
        n, [&](EdgeId, const mesh::Edge& edge) { near_frozen_[edge.a] = near_frozen_[edge.b] = 1; });
  });
}

double Adaptivity::restored_measure(const Body& body, mesh::Key diamond) {
  // The tets a merge restores can be up to ~2x as dense as their children
  // (the children's edges lack some of the parents' directions), so a merge
  // judged on the children alone could restore tets above Th, which the
  // next pass split again: a static body cycled forever (simplify_factor
  // above ~0.5). Measured as measure_from_edges will measure them once
  // restored: merging moves no node, and a rest length is the lattice
  // length's root times the unit, as Body gives it.
  const mesh::KuhnMesh& mesh = body.mesh();
  const int count = mesh.merge_restores(diamond, restored_);
  const double unit_m = mesh.lattice_unit_m();
  double worst = 0.0;
  for (int i = 0; i < count; ++i) {
    const std::array<NodeId, 4>& v = restored_[i];
    double sum = 0.0, stretch = 0.0;
    for (const auto& slot : mesh::kTetEdgeSlots) {
      const NodeId a = v[slot[0]], b = v[slot[1]];
      const mesh::Vec3i& p = mesh.node(a).lattice;
      const mesh::Vec3i& q = mesh.node(b).lattice;
      std::int64_t length2 = 0;
      for (int c = 0; c < 3; ++c) length2 += (p[c] - q[c]) * (p[c] - q[c]);
      const double rest_m = std::sqrt(static_cast<double>(length2)) * unit_m;
      const double strain = (body.x_m[b] - body.x_m[a]).norm() / rest_m - 1.0;
      sum += strain * strain;
      stretch = std::max(stretch, stretch_from_strain(strain));
    }
    worst =
        std::max(worst, spec_.criterion == scene::RefineCriterion::kStretch ? stretch : 0.5 * youngs_modulus_Pa_ * sum);
  }
  return worst;
}

AdaptStats Adaptivity::adapt(Body& body) {
  AdaptStats stats;
  const mesh::KuhnMesh& mesh = body.mesh();
  const double refine_above = refine_threshold();
  const double merge_below = simplify_threshold();
  youngs_modulus_Pa_ = body.scene().material.youngs_modulus_Pa;
  edge_strain_.resize(body.rest_length_m.size());
  double energy_J = 0.0;
  mesh.for_each_edge([&](EdgeId e, const mesh::Edge&) {
    const double length_m = (body.x_m[body.edge_b[e]] - body.x_m[body.edge_a[e]]).norm();
    edge_strain_[e] = length_m / body.rest_length_m[e] - 1.0;
    const double stretch_m = length_m - body.rest_length_m[e];
    energy_J += 0.5 * body.stiffness_N_per_m[e] * stretch_m * stretch_m;
  });
  stats.elastic_energy_before_J = energy_J;
  // kUnmeasured stays on the slots no tet touches now (free slots): a split
  // below may reuse one, and its node must not look relaxed to the merges.
  node_max_.assign(body.x_m.size(), kUnmeasured);
  refine_.clear();
  mesh.for_each_tet([&](TetId t, const mesh::Tet& tet) {
    const double m = measure_from_edges(tet);
    for (NodeId n : tet.v) node_max_[n] = std::max(node_max_[n], m);
    if (m > refine_above && tet.depth < spec_.max_depth) {
      if (frozen_ && std::any_of(tet.v.begin(), tet.v.end(), [&](NodeId n) { return is_frozen(body.x_m[n]); })) return;
      refine_.emplace_back(-m, mesh.diamond_of(t));
    }
  });

  // Most strained first; each diamond once (a diamond comes once per
  // strained tet: a repeat finds it split, or passed over, below).
  std::sort(refine_.begin(), refine_.end());
  for (const EdgeId e : passed_over_edges_) passed_over_[e] = 0;
  passed_over_edges_.clear();
  int budget = spec_.max_ops_per_step;
  for (std::size_t i = 0; i < refine_.size() && budget > 0; ++i) {
    // The ceiling (adaptivity.max_tets): a threshold far below every tet's
    // density with a deep max_depth doubled the mesh each pass until the
    // process ran out of memory. Merges below still run.
    if (mesh.tet_count() >= static_cast<std::size_t>(spec_.max_tets)) {
      stats.ceiling_reached = true;
      break;
    }
    const mesh::Key d = refine_[i].second;
    if (!mesh.can_split(d)) continue;  // split already (closure of an earlier one) or at max depth
    // Decided already this pass: a repeat would be decided the same way. A
    // closure that waited stays longer than the budget (a later split that
    // splits k of its diamonds spends at least k), and one that reached the
    // frozen sphere still does (the frozen tet's diamond is not split: a
    // split's closure passed the same test, and tets only appear until
    // their diamond splits). So no walk up again, up to 8 times.
    if (passed_over(mesh, d)) continue;
    ++stats.closure_walks;
    int closure = 0;
    if (frozen_) {
      if (closure_touches_frozen(body, d)) {
        pass_over(mesh, d);
        continue;
      }
      closure = static_cast<int>(closure_keys_.size());
    } else {
      closure = mesh.closure_diamonds(d, closure_keys_);
    }
    // A closure longer than what is left waits for a later pass (splitting
    // it anyway overshot the budget by up to a whole closure: 52-134
    // diamonds at max_depth 30), unless nothing has been spent yet, so that
    // a pass always progresses: only a pass's first split may exceed it.
    if (closure > budget && budget < spec_.max_ops_per_step) {
      pass_over(mesh, d);
      // Looking further for a closure that fits what is left walked up every
      // remaining candidate (tens of thousands on a big strained body, each
      // O(L²)) when all of theirs were longer. The pass is for spending the
      // budget on the most strained first: once kMaxSplitWaitsPerPass of
      // them have waited (what is left is shorter than each of their
      // closures), the rest, less strained, waits for the next pass, which
      // starts from the top again, its first split exempt. So a pass walks
      // at most one closure per split plus 32 (well under a millisecond
      // even at L ~130), and a short closure (a refined front's diamond)
      // a few waits down the list still fills what is left. Only a binding
      // budget waits: where it does not, the same splits happen.
      if (++stats.split_waits >= kMaxSplitWaitsPerPass) break;
      continue;
    }
    const int n = body.split(d);
    stats.splits += n;
    budget -= n;
  }

  // Simplify the relaxed regions, finest diamonds first. Only nodes measured
  // above merge: a node this pass created (in a new slot, or in a freed one
  // whose entry is kUnmeasured) is never merged, whatever min_age_steps, so
  // refine and merge never fight. (With min_age_steps 0 a split landing in a
  // freed slot was merged in the same pass, every pass.)
  merge_.clear();
  const double tol = spec_.midpoint_tolerance;
  bool near_frozen_marked = false;
  mesh.for_each_node([&](NodeId z, const mesh::Node& node) {
    if (node.edge_a == mesh::kInvalidId || node.depth < spec_.min_depth) return;
    if (body.step_index - body.changed_step[z] < spec_.min_age_steps) return;
    if (z >= node_max_.size() || node_max_[z] == kUnmeasured || node_max_[z] >= merge_below) return;
    const Vec3 mid = 0.5 * (body.x_m[node.edge_a] + body.x_m[node.edge_b]);
    const double length = (body.rest_m[node.edge_b] - body.rest_m[node.edge_a]).norm();
    if ((body.x_m[z] - mid).norm() >= tol * length) return;
    if (frozen_) {
      // Marked after the splits above: a node one of them put in the sphere
      // blocks the merges around it too.
      if (!near_frozen_marked) {
        mark_near_frozen(body, stats);
        near_frozen_marked = true;
      }
      if (near_frozen_[z]) return;
    }
    merge_.emplace_back(-static_cast<int>(node.depth), node_max_[z], mesh.node_key(z));
  });
  std::sort(merge_.begin(), merge_.end());
  for (std::size_t i = 0; i < merge_.size() && budget > 0; ++i) {
    const mesh::Key d = std::get<2>(merge_[i]);
    if (!mesh.can_merge(d)) continue;
    // Hysteresis across the merge: the restored tets must be relaxed too,
    // else the next pass splits them again (see restored_measure). After
    // can_merge: a coarser diamond becomes mergeable only once this pass
    // merged its children, and merging moves no node, so it is measured now.
    if (restored_measure(body, d) >= merge_below) continue;
    body.merge(d);
    ++stats.merges;
    --budget;
  }
  return stats;
}

}  // namespace tissue::physics
