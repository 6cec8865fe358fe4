#include "physics/body.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include "mesh/refine_ops.hpp"
#include "mesh/surface.hpp"
#include "physics/boundary.hpp"
#include "physics/spring_law.hpp"

namespace tissue::physics {

namespace {

mesh::BoxSpec box_of(const scene::Scene& s) {
  const auto& a = s.adaptivity;
  // Without adaptivity the mesh never goes deeper than its starting depth.
  const int max_depth = a.enabled ? a.max_depth : a.min_depth;
  return {s.object.cubes[0], s.object.cubes[1], s.object.cubes[2], s.object.cube_size_m, max_depth};
}

std::int64_t lattice_length2(const mesh::KuhnMesh& m, NodeId a, NodeId b) {
  const mesh::Vec3i& p = m.node(a).lattice;
  const mesh::Vec3i& q = m.node(b).lattice;
  std::int64_t s = 0;
  for (int i = 0; i < 3; ++i) s += (p[i] - q[i]) * (p[i] - q[i]);
  return s;
}

// Process-wide, so two bodies never share a version unless one is a copy.
std::uint64_t next_parameters_version() {
  static std::atomic<std::uint64_t> next{1};
  return next.fetch_add(1, std::memory_order_relaxed);
}

}  // namespace

Body::Body(const scene::Scene& scene) : scene_(scene), mesh_(box_of(scene)) {
  if (scene.adaptivity.min_depth > 0) mesh::refine_uniform(mesh_, scene.adaptivity.min_depth);
  resize_to_mesh();
  mesh_.for_each_node([&](NodeId n, const mesh::Node&) {
    const auto p = mesh_.node_position_m(n);
    rest_m[n] = Vec3(p[0], p[1], p[2]);
    x_m[n] = rest_m[n];
    v_m_per_s[n].setZero();
    classify_node(n);
  });
  require_every_region_selects_a_node();
  rebuild_parameters();
}

void Body::require_every_region_selects_a_node() const {
  // The scene's checks see only the object's box; whether a region holds a
  // node shows on the mesh. A region between nodes would fix, move or load
  // nothing and the run would go on as if it did (a load "applied" with no
  // work, a beam "clamped" floating free). Refinement adds nodes only where
  // the body deforms, so an empty region stays empty: refuse it here.
  const double tol = 1e-6 * mesh_.lattice_unit_m();
  const auto check = [&](const scene::Region& region, const std::string& key) {
    bool any = false;
    mesh_.for_each_node([&](NodeId n, const mesh::Node&) {
      any = any || region.contains({rest_m[n][0], rest_m[n][1], rest_m[n][2]}, tol);
    });
    if (!any) {
      const double spacing_mm = 1e3 * scene_.object.cube_size_m / std::exp2(scene_.adaptivity.min_depth / 3.0);
      char spacing[32];
      std::snprintf(spacing, sizeof spacing, "%.3g", spacing_mm);
      throw scene::SceneModelError(key, std::string("selects no node of the mesh (its nodes are about ") + spacing +
                                            " mm apart: a region between them holds none); enlarge it or move it "
                                            "onto nodes");
    }
  };
  for (std::size_t i = 0; i < scene_.fixed.size(); ++i)
    check(scene_.fixed[i].region, "fixed[" + std::to_string(i) + "].region");
  for (std::size_t i = 0; i < scene_.prescribed.size(); ++i)
    check(scene_.prescribed[i].region, "prescribed[" + std::to_string(i) + "].region");
  for (std::size_t i = 0; i < scene_.loads.size(); ++i)
    check(scene_.loads[i].region, "loads[" + std::to_string(i) + "].region");

  // A node is held by the first region that claims it: fixed ones, then
  // prescribed ones in order (classify_node). A prescribed region whose every
  // node another holds moves nothing, and a load on fixed and prescribed nodes
  // only does no work (a tip load moved onto the clamped face: external work
  // 0, the tip still); both ran as if they acted. Refuse them, naming what
  // holds their nodes.
  struct Holders {
    bool free_node = false;                      // the region holds a free node
    std::vector<std::size_t> fixed, prescribed;  // what holds the others: indices, ascending, each once
  };
  // Over the nodes `for_each_selected` visits.
  const auto holders = [&](const auto& for_each_selected) {
    Holders h;
    auto& [acts, fixed, prescribed] = h;
    for_each_selected([&](NodeId n) {
      if (acts) return;
      if (kind[n] == NodeKind::kFree) {
        acts = true;
        return;
      }
      if (kind[n] == NodeKind::kPrescribed) {
        prescribed.push_back(static_cast<std::size_t>(prescribed_index[n]));
        return;
      }
      const scene::Vec3 p{rest_m[n][0], rest_m[n][1], rest_m[n][2]};
      for (std::size_t i = 0; i < scene_.fixed.size(); ++i)
        if (scene_.fixed[i].region.contains(p, tol)) fixed.push_back(i);
    });
    for (auto* v : {&fixed, &prescribed}) {
      std::sort(v->begin(), v->end());
      v->erase(std::unique(v->begin(), v->end()), v->end());
    }
    return h;
  };
  // "fixed by fixed[0] or fixed[2], or prescribed by prescribed[1]"
  const auto held_by = [](const std::vector<std::size_t>& fixed, const std::vector<std::size_t>& prescribed) {
    const auto keys = [](const char* list, const std::vector<std::size_t>& at) {
      std::string out;
      for (std::size_t j = 0; j < at.size(); ++j)
        out += (j == 0 ? "" : " or ") + std::string(list) + "[" + std::to_string(at[j]) + "]";
      return out;
    };
    std::string out;
    if (!fixed.empty()) out = "fixed by " + keys("fixed", fixed);
    if (!prescribed.empty())
      out += (out.empty() ? "" : ", or ") + std::string("prescribed by ") + keys("prescribed", prescribed);
    return out;
  };
  for (std::size_t i = 0; i < scene_.prescribed.size(); ++i) {
    bool own = false;
    mesh_.for_each_node(
        [&](NodeId n, const mesh::Node&) { own = own || prescribed_index[n] == static_cast<std::int32_t>(i); });
    if (own) continue;
    // Not one of its nodes is its own: each is fixed or an earlier region's.
    const scene::Region& region = scene_.prescribed[i].region;
    const Holders h = holders([&](const auto& visit) {
      mesh_.for_each_node([&](NodeId n, const mesh::Node&) {
        if (region.contains({rest_m[n][0], rest_m[n][1], rest_m[n][2]}, tol)) visit(n);
      });
    });
    throw scene::SceneModelError(
        "prescribed[" + std::to_string(i) + "].region",
        "every node it selects is " + held_by(h.fixed, h.prescribed) +
            " (a node is held by the first region that selects it: fixed ones, then prescribed ones in order), so "
            "it moves none; move it onto other nodes");
  }
  // A load acts on the nodes LoadDistribution gives it: the boundary
  // triangles wholly in its region, else the nodes in it. A region holding
  // the clamped face's triangles and a free node inside the body loads the
  // face only.
  mesh::SurfaceMesh surface;
  if (!scene_.loads.empty()) mesh::extract_surface(mesh_, &surface);
  for (std::size_t i = 0; i < scene_.loads.size(); ++i) {
    const std::map<NodeId, double> acted_on = load_node_weights(*this, surface, scene_.loads[i].region);
    const Holders h = holders([&](const auto& visit) {
      for (const auto& [n, weight] : acted_on) visit(n);
    });
    if (!h.free_node)
      throw scene::SceneModelError("loads[" + std::to_string(i) + "].region",
                                   "every node it selects is " + held_by(h.fixed, h.prescribed) +
                                       ", and a force on a fixed or prescribed node does nothing; move it onto free "
                                       "nodes");
  }
}

void Body::resize_to_mesh() {
  const std::size_t nodes = mesh_.node_capacity();
  if (x_m.size() < nodes) {
    x_m.resize(nodes, Vec3::Zero());
    v_m_per_s.resize(nodes, Vec3::Zero());
    rest_m.resize(nodes, Vec3::Zero());
    mass_kg.resize(nodes, 0.0);
    inv_mass_per_kg.resize(nodes, 0.0);
    kind.resize(nodes, NodeKind::kDead);
    prescribed_index.resize(nodes, -1);
    changed_step.resize(nodes, 0);
    node_touched_.resize(nodes, 0);
  }
  const std::size_t edges = mesh_.edge_capacity();
  if (edge_a.size() < edges) {
    edge_a.resize(edges, 0);
    edge_b.resize(edges, 0);
    rest_length_m.resize(edges, 1.0);  // never 0: a dead edge must not divide by zero
    weighted_volume_m3.resize(edges, 0.0);
    weighted_six_volume_e4_.resize(edges, 0);
    stiffness_N_per_m.resize(edges, 0.0);
    damping_N_s_per_m.resize(edges, 0.0);
    edge_touched_.resize(edges, 0);
  }
}

void Body::classify_node(NodeId n) {
  // Regions are in metres; lattice positions are exact multiples of the unit,
  // so a tolerance far below one lattice unit decides boundary cases.
  const double tol = 1e-6 * mesh_.lattice_unit_m();
  const scene::Vec3 p{rest_m[n][0], rest_m[n][1], rest_m[n][2]};
  kind[n] = NodeKind::kFree;
  prescribed_index[n] = -1;
  for (const auto& f : scene_.fixed)
    if (f.region.contains(p, tol)) kind[n] = NodeKind::kFixed;
  if (kind[n] == NodeKind::kFree) {
    for (std::size_t i = 0; i < scene_.prescribed.size(); ++i)
      if (scene_.prescribed[i].region.contains(p, tol)) {
        kind[n] = NodeKind::kPrescribed;
        prescribed_index[n] = static_cast<std::int32_t>(i);
        break;
      }
  }
}

namespace {

// The fraction of its displacement a prescribed region's drivers hold it at
// at time t_s: its profile from the first step on; before any step (t_s <= 0)
// the body is where it started, at rest.
double driven_fraction(const scene::TimeProfile& profile, double t_s) { return t_s > 0.0 ? profile.at(t_s) : 0.0; }

}  // namespace

void Body::place_kinematic_node(NodeId n) {
  // The edge's midpoint is off the target wherever the region is not a plane
  // (a box or sphere around a deformed region): the next step's driver
  // velocity (target − x) / dt snapped the node back, a spring jump and
  // kinetic energy booked to nobody.
  if (kind[n] == NodeKind::kFixed) {
    x_m[n] = rest_m[n];
    v_m_per_s[n].setZero();
  } else if (kind[n] == NodeKind::kPrescribed) {
    const scene::PrescribedSpec& p = scene_.prescribed[static_cast<std::size_t>(prescribed_index[n])];
    const Vec3 d(p.displacement_m[0], p.displacement_m[1], p.displacement_m[2]);
    const double dt_s = scene_.integrator.dt_s;
    const double now_s = time_s();
    const double now = driven_fraction(p.profile, now_s), before = driven_fraction(p.profile, now_s - dt_s);
    x_m[n] = rest_m[n] + now * d;
    // The velocity the drivers gave the region's nodes over the last step.
    v_m_per_s[n] = (now - before) / dt_s * d;
  }
}

std::array<std::int64_t, 6> Body::tet_edge_weights_e4(const std::array<NodeId, 4>& v, int depth) const {
  // Lattice coordinates of a node stay readable after it dies (merge removes
  // its node last, and no mesh operation re-adds a node it removed), so this
  // also serves removed tets replayed from a change log.
  std::array<std::int64_t, 6> len2{};
  std::int64_t longest2 = 0;
  for (int i = 0; i < 6; ++i) {
    len2[i] = lattice_length2(mesh_, v[mesh::kTetEdgeSlots[i][0]], v[mesh::kTetEdgeSlots[i][1]]);
    longest2 = std::max(longest2, len2[i]);
  }
  std::array<std::int64_t, 6> weights{};
  for (int i = 0; i < 6; ++i) weights[i] = edge_weight_e4(scene_.material.stiffness, depth, len2[i], longest2);
  return weights;
}

std::array<double, 6> Body::tet_edge_shares_m3(const std::array<NodeId, 4>& v, int depth) const {
  const double unit = mesh_.lattice_unit_m();
  const double volume_m3 = static_cast<double>(mesh_.six_volume_at_depth(depth)) * unit * unit * unit / 6.0;
  const std::array<std::int64_t, 6> weights = tet_edge_weights_e4(v, depth);
  std::array<double, 6> shares{};
  for (int i = 0; i < 6; ++i)
    shares[i] = static_cast<double>(weights[i]) / static_cast<double>(kEdgeWeightScale) * volume_m3;
  return shares;
}

void Body::add_tet_shares(const std::array<NodeId, 4>& v, int depth, const std::array<EdgeId, 6>& edges, int sign) {
  const std::array<std::int64_t, 6> weights = tet_edge_weights_e4(v, depth);
  const WeightedSixVolume six_volume = mesh_.six_volume_at_depth(depth);
  for (int i = 0; i < 6; ++i) weighted_six_volume_e4_[edges[i]] += sign * weights[i] * six_volume;
}

void Body::refresh_edge(EdgeId e) {
  ++edges_refreshed_;
  const NodeId a = edge_a[e], b = edge_b[e];
  // One rounding, of the exact sum: the spring is a function of its
  // incident tets, whatever order they came in.
  const double unit = mesh_.lattice_unit_m();
  weighted_volume_m3[e] = static_cast<double>(weighted_six_volume_e4_[e]) * unit * unit * unit /
                          (6.0 * static_cast<double>(kEdgeWeightScale));
  stiffness_N_per_m[e] =
      spring_stiffness_N_per_m(scene_.material.youngs_modulus_Pa, weighted_volume_m3[e], rest_length_m[e]);
  damping_N_s_per_m[e] =
      spring_damping_N_s_per_m(scene_.material, stiffness_N_per_m[e], mass_kg[a], mass_kg[b], rest_length_m[e]);
}

void Body::rebuild_parameters() {
  parameters_version_ = next_parameters_version();
  resize_to_mesh();
  std::fill(weighted_volume_m3.begin(), weighted_volume_m3.end(), 0.0);
  std::fill(weighted_six_volume_e4_.begin(), weighted_six_volume_e4_.end(), 0);
  std::fill(stiffness_N_per_m.begin(), stiffness_N_per_m.end(), 0.0);
  std::fill(damping_N_s_per_m.begin(), damping_N_s_per_m.end(), 0.0);
  const double unit = mesh_.lattice_unit_m();
  mesh_.for_each_edge([&](EdgeId e, const mesh::Edge& edge) {
    edge_a[e] = edge.a;
    edge_b[e] = edge.b;
    rest_length_m[e] = std::sqrt(static_cast<double>(lattice_length2(mesh_, edge.a, edge.b))) * unit;
  });
  mesh_.for_each_tet([&](TetId, const mesh::Tet& t) { add_tet_shares(t.v, t.depth, t.e, +1); });
  const double rho = scene_.material.density_kg_per_m3;
  mesh_.for_each_node([&](NodeId n, const mesh::Node& node) {
    mass_kg[n] = node_mass_kg(rho, node.six_volume, unit);
    inv_mass_per_kg[n] = kind[n] == NodeKind::kFree ? 1.0 / mass_kg[n] : 0.0;
  });
  mesh_.for_each_edge([&](EdgeId e, const mesh::Edge&) { refresh_edge(e); });
}

int Body::split(mesh::Key diamond) {
  log_.clear();
  int n = 0;
  try {
    n = mesh_.split(diamond, &log_);
  } catch (...) {
    // A bad key throws before the mesh changes (empty log); should the mesh
    // fail part way, the arrays still follow what it did.
    if (!log_.events.empty()) apply_log(log_);
    throw;
  }
  apply_log(log_);
  return n;
}

void Body::merge(mesh::Key diamond) {
  // Validated before any velocity changes: a coarse grid vertex's node has no
  // edge ends (kInvalidId indexed the arrays), and momentum handed to the ends
  // of a diamond the mesh then refused was momentum made from nothing.
  mesh_.require_can_merge(diamond);
  const NodeId z = mesh_.find_node(diamond);
  // The mesh gives half of z's mass to each end of its edge (each pair of
  // tets that joins into one hands z's quarter shares of both to the ends,
  // half each); that mass keeps the velocity it had at z, whatever z's kind:
  // a fixed node is held by the world at rest, a prescribed one moves with
  // its driver. A free end joins it to its own mass, an inelastic collision:
  // momentum kept, kinetic energy can only drop. A free end that kept its own
  // velocity instead made momentum and kinetic energy from nothing (a fixed z
  // next to a moving end: +1.6% of the free nodes' kinetic energy). A fixed
  // or prescribed end moves as its driver says, with the mass it gains.
  const NodeId ends[2] = {mesh_.node(z).edge_a, mesh_.node(z).edge_b};
  const Vec3 v_z = kind[z] == NodeKind::kFixed ? Vec3::Zero() : v_m_per_s[z];
  const Vec3 half_momentum = 0.5 * mass_kg[z] * v_z;
  for (NodeId e : ends) {
    if (kind[e] != NodeKind::kFree) continue;
    const double m = mass_kg[e] + 0.5 * mass_kg[z];
    v_m_per_s[e] = (mass_kg[e] * v_m_per_s[e] + half_momentum) / m;
  }
  log_.clear();
  mesh_.merge(diamond, &log_);
  apply_log(log_);
}

void Body::apply_log(const mesh::MeshChangeLog& log) {
  parameters_version_ = next_parameters_version();
  resize_to_mesh();
  const double unit = mesh_.lattice_unit_m();
  auto touch_edge = [&](EdgeId e) {
    if (!edge_touched_[e]) {
      edge_touched_[e] = 1;
      touched_edges_.push_back(e);
    }
  };
  auto touch_node = [&](NodeId n) {
    if (!node_touched_[n]) {
      node_touched_[n] = 1;
      touched_nodes_.push_back(n);
    }
  };
  for (const mesh::MeshEvent& ev : log.events) {
    switch (ev.kind) {
      case mesh::MeshEvent::Kind::kNodeAdded: {
        const NodeId z = ev.id, a = ev.nodes[0], b = ev.nodes[1];
        const auto p = mesh_.node_position_m(z);
        rest_m[z] = Vec3(p[0], p[1], p[2]);
        x_m[z] = 0.5 * (x_m[a] + x_m[b]);
        v_m_per_s[z] = 0.5 * (v_m_per_s[a] + v_m_per_s[b]);
        mass_kg[z] = 0.0;
        classify_node(z);
        place_kinematic_node(z);
        changed_step[z] = step_index;
        touch_node(z);
        break;
      }
      case mesh::MeshEvent::Kind::kNodeRemoved:
        kind[ev.id] = NodeKind::kDead;
        mass_kg[ev.id] = 0.0;
        inv_mass_per_kg[ev.id] = 0.0;
        v_m_per_s[ev.id].setZero();
        break;
      case mesh::MeshEvent::Kind::kEdgeAdded: {
        const EdgeId e = ev.id;
        edge_a[e] = ev.nodes[0];
        edge_b[e] = ev.nodes[1];
        rest_length_m[e] = std::sqrt(static_cast<double>(lattice_length2(mesh_, ev.nodes[0], ev.nodes[1]))) * unit;
        weighted_volume_m3[e] = 0.0;
        weighted_six_volume_e4_[e] = 0;
        touch_edge(e);
        break;
      }
      case mesh::MeshEvent::Kind::kEdgeRemoved: {
        const EdgeId e = ev.id;
        edge_a[e] = edge_b[e] = 0;
        rest_length_m[e] = 1.0;
        weighted_volume_m3[e] = stiffness_N_per_m[e] = damping_N_s_per_m[e] = 0.0;
        weighted_six_volume_e4_[e] = 0;
        break;
      }
      case mesh::MeshEvent::Kind::kTetAdded:
      case mesh::MeshEvent::Kind::kTetRemoved: {
        add_tet_shares(ev.nodes, ev.depth, ev.edges, ev.kind == mesh::MeshEvent::Kind::kTetAdded ? +1 : -1);
        for (EdgeId e : ev.edges) touch_edge(e);
        for (NodeId n : ev.nodes) touch_node(n);
        break;
      }
    }
  }
  const double rho = scene_.material.density_kg_per_m3;
  // The paper's damper depends on both end masses. A node's mass changes
  // only with the tets around it, so the touched nodes are all whose mass
  // changed, and the springs at them, named by no event when the tet at
  // their other end stayed, are the rest that need a refresh. Refreshing
  // every spring instead cost O(springs) per split or merge.
  const bool damper_needs_masses = scene_.material.damping == scene::DampingLaw::kPaper;
  for (NodeId n : touched_nodes_) {
    node_touched_[n] = 0;
    if (!mesh_.node_alive(n)) continue;
    mass_kg[n] = node_mass_kg(rho, mesh_.node(n).six_volume, unit);
    inv_mass_per_kg[n] = kind[n] == NodeKind::kFree ? 1.0 / mass_kg[n] : 0.0;
    if (damper_needs_masses) mesh_.for_each_edge_at_node(n, [&](EdgeId e, const mesh::Edge&) { touch_edge(e); });
  }
  touched_nodes_.clear();
  for (EdgeId e : touched_edges_) {
    edge_touched_[e] = 0;
    if (mesh_.edge_alive(e)) refresh_edge(e);
  }
  touched_edges_.clear();
}

double Body::total_mass_kg() const {
  double m = 0.0;
  mesh_.for_each_node([&](NodeId n, const mesh::Node&) { m += mass_kg[n]; });
  return m;
}

std::size_t free_node_count(const Body& body) {
  std::size_t n = 0;
  for (const double w : body.inv_mass_per_kg) n += w > 0.0;
  return n;
}

std::vector<EdgeId> moving_springs(const Body& body) {
  std::vector<EdgeId> out;
  for (EdgeId e = 0; e < body.stiffness_N_per_m.size(); ++e) {
    if (body.stiffness_N_per_m[e] == 0.0) continue;  // dead edge slot
    if (body.inv_mass_per_kg[body.edge_a[e]] == 0.0 && body.inv_mass_per_kg[body.edge_b[e]] == 0.0) continue;
    out.push_back(e);
  }
  return out;
}

Vec3 Body::momentum_kg_m_per_s() const {
  Vec3 p = Vec3::Zero();
  mesh_.for_each_node([&](NodeId n, const mesh::Node&) { p += mass_kg[n] * v_m_per_s[n]; });
  return p;
}

}  // namespace tissue::physics
