// The adaptive tetrahedral mesh of the seed paper (§2–3.4): a box of cubes cut
// into 6 Kuhn tetrahedra each, refined by Maubach (longest-edge) bisection in
// whole diamonds, so the mesh is conforming by construction.
//
// Ownership and cost model:
// - Nodes, edges and tets live in pools with stable ids (freed ids are reused).
//   Physics keeps per-id arrays; the change log says which ids appear/vanish.
// - Edges are keyed by their doubled midpoint. An edge that is the refinement
//   edge of leaf tets *is* their diamond: it heads an intrusive list of those
//   tets, so no separate diamond table exists.
// - split/merge touch only the diamond (and, for split, its unsplit ancestors);
//   their cost is proportional to what changes, not to the mesh size.
// - Incident volumes are kept as exact integers: 6·V in lattice units.
//
// Threading: none. The sim thread owns a mesh; others see snapshots.
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "mesh/lattice.hpp"
#include "mesh/mesh_change.hpp"
#include "util/key_index_map.hpp"

namespace tissue::mesh {

struct BoxSpec {
  int cubes_x = 1;
  int cubes_y = 1;
  int cubes_z = 1;
  double cube_size_m = 0.1;
  // Deepest bisection level a leaf may reach (0 = the 6-tet cubes only).
  int max_depth = 9;
};

// Most cubes along one axis the 21-bit lattice keys hold (at depth 0).
inline constexpr std::int64_t kMaxCubesPerAxis = kMaxLatticeCoord / 2;

// Deepest BoxSpec::max_depth the lattice keys hold for a box with
// `largest_cubes` cubes along its longest axis (at most 60); -1 when that
// count is outside [1, kMaxCubesPerAxis]. Scene checks use it to name their
// key before a KuhnMesh refuses the box.
int max_lattice_depth(std::int64_t largest_cubes);

struct Node {
  Vec3i lattice{};              // lattice coordinates
  std::int64_t six_volume = 0;  // Σ 6V of incident leaf tets (lattice units)
  NodeId edge_a = kInvalidId;   // endpoints of the edge this node split,
  NodeId edge_b = kInvalidId;   //   kInvalidId for coarse grid nodes
  std::uint8_t depth = 0;       // depth of the diamond that created it
  bool alive = false;
};

struct Edge {
  NodeId a = kInvalidId;
  NodeId b = kInvalidId;
  std::int64_t six_volume = 0;      // Σ 6V of incident leaf tets; 0 <=> edge gone
  TetId diamond_head = kInvalidId;  // first leaf tet whose refinement edge this is
};

struct Tet {
  // Maubach order: refinement edge is (v[0], v[k]) with k = 3 - depth % 3.
  std::array<NodeId, 4> v{};
  // Its six edges in kTetEdgeSlots order. Stored (24 bytes) because finding
  // them again by hash was most of the cost of a bisection.
  std::array<EdgeId, 6> e{};
  TetId next_in_diamond = kInvalidId;
  // Bit i = 1 when the ancestor at depth i+1 (or this tet, i = depth-1) was
  // the second child of its parent. Merge needs it to rebuild parents in the
  // order their own parents produced them.
  std::uint64_t child_path = 0;
  std::uint8_t depth = kDeadDepth;
  bool negative = false;  // Maubach order has negative orientation
  static constexpr std::uint8_t kDeadDepth = 0xff;
};

class KuhnMesh {
 public:
  // Throws std::invalid_argument naming the field for non-positive counts or
  // sizes, a max depth the lattice cannot hold, or a box that overflows keys.
  explicit KuhnMesh(const BoxSpec& spec);

  const BoxSpec& spec() const { return spec_; }
  const LatticeDomain& domain() const { return domain_; }
  // Edge of one lattice unit in metres.
  double lattice_unit_m() const { return lattice_unit_m_; }
  // 6V of a tet at `depth` in lattice units (exact).
  std::int64_t six_volume_at_depth(int depth) const { return coarse_six_volume_ >> depth; }
  // 6V of the whole box in lattice units (exact).
  std::int64_t total_six_volume() const { return total_six_volume_; }

  // --- Counts and pools (ids index the pools; check alive) -----------------
  std::size_t node_count() const { return node_count_; }
  std::size_t edge_count() const { return edge_count_; }
  std::size_t tet_count() const { return tet_count_; }
  std::size_t node_capacity() const { return nodes_.size(); }
  std::size_t edge_capacity() const { return edges_.size(); }
  std::size_t tet_capacity() const { return tets_.size(); }

  const Node& node(NodeId id) const { return nodes_[id]; }
  const Edge& edge(EdgeId id) const { return edges_[id]; }
  const Tet& tet(TetId id) const { return tets_[id]; }
  bool node_alive(NodeId id) const { return id < nodes_.size() && nodes_[id].alive; }
  bool edge_alive(EdgeId id) const { return id < edges_.size() && edges_[id].six_volume > 0; }
  bool tet_alive(TetId id) const { return id < tets_.size() && tets_[id].depth != Tet::kDeadDepth; }

  NodeId find_node(Key key) const { return node_index_.find(key); }
  EdgeId find_edge(Key key) const { return edge_index_.find(key); }
  EdgeId find_edge(NodeId a, NodeId b) const {
    return edge_index_.find(edge_key(nodes_[a].lattice, nodes_[b].lattice));
  }
  Key node_key(NodeId id) const { return vertex_key(nodes_[id].lattice); }
  std::array<double, 3> node_position_m(NodeId id) const;

  // Vertices in positive orientation (det(v1-v0, v2-v0, v3-v0) > 0).
  std::array<NodeId, 4> oriented_vertices(TetId id) const;
  // The key of the diamond (refinement edge) a leaf tet belongs to.
  Key diamond_of(TetId id) const;

  // --- Diamonds ------------------------------------------------------------
  // True when the diamond's node exists.
  bool is_split(Key diamond) const { return node_index_.contains(diamond); }
  // True when `diamond` is a diamond of this box whose tets lie above max depth
  // and it is not yet split (its ancestors may still be unsplit).
  bool can_split(Key diamond) const;
  // True when split and none of its child diamonds is split.
  bool can_merge(Key diamond) const;
  // Throws std::invalid_argument saying why when !can_merge(diamond): not a
  // diamond of this box, not split, or a child diamond split. Changes nothing.
  void require_can_merge(Key diamond) const;
  // Depth of a diamond's tets; throws std::invalid_argument if `diamond` is
  // not a diamond of this box.
  DiamondInfo diamond_info(Key diamond) const;

  // Splits `diamond` and, first, every unsplit ancestor (crack-free closure).
  // Returns the number of diamonds split (0 if already split). Throws
  // std::invalid_argument when the key is not a diamond of this box or its
  // tets are at max depth. Events are appended to `log` if non-null.
  int split(Key diamond, MeshChangeLog* log = nullptr);

  // The leaf tets split(diamond) would bisect, each once, into `tets`: the
  // diamond's own and those of every unsplit ancestor its closure splits
  // (tets the closure creates on the way lie inside these). Empty when it
  // cannot split. `pending` is scratch (reused: no allocation once grown).
  void closure_tets(Key diamond, std::vector<TetId>& tets, std::vector<Key>& pending) const;
  // The diamonds split(diamond) would split, itself and every unsplit
  // ancestor, each once, into `closure` (scratch, reused); returns their
  // count, which is what split(diamond) would return (0 when it cannot
  // split). Costs what the walk up costs, not the tets' lists: a pass asks
  // it of a candidate before deciding whether its closure fits the budget.
  int closure_diamonds(Key diamond, std::vector<Key>& closure) const;

  // The tets merge(diamond) would restore, each by its vertices in Maubach
  // order (as tet().v would hold them), into `parents`; returns their count,
  // 0 when !can_merge(diamond). Changes nothing: a pass measures the
  // restored tets before it merges.
  int merge_restores(Key diamond, std::array<std::array<NodeId, 4>, 8>& parents) const;

  // Merges a split diamond whose children are all unsplit. Throws
  // std::invalid_argument otherwise.
  void merge(Key diamond, MeshChangeLog* log = nullptr);

  // --- Iteration -----------------------------------------------------------
  template <class F>
  void for_each_tet(F&& f) const {
    for (TetId t = 0; t < tets_.size(); ++t)
      if (tets_[t].depth != Tet::kDeadDepth) f(t, tets_[t]);
  }
  template <class F>
  void for_each_node(F&& f) const {
    for (NodeId n = 0; n < nodes_.size(); ++n)
      if (nodes_[n].alive) f(n, nodes_[n]);
  }
  template <class F>
  void for_each_edge(F&& f) const {
    for (EdgeId e = 0; e < edges_.size(); ++e)
      if (edges_[e].six_volume > 0) f(e, edges_[e]);
  }

  // Calls f(e, edge) for every live edge at `node` (dead nodes have none).
  // Every edge of the hierarchy joins lattice points p and p + s δ with
  // s = 2^j ≤ H (the coarse cube) and δ ∈ {−1, 0, 1}³ \ {0} (Kuhn tets and
  // their Maubach children are scaled Kuhn tets), so this is 26 (K + 1) hash
  // lookups, not a walk over every edge.
  template <class F>
  void for_each_edge_at_node(NodeId node, F&& f) const {
    if (!node_alive(node)) return;
    const Vec3i& p = nodes_[node].lattice;
    for (std::int64_t s = 1; s <= domain_.coarse_cube(); s *= 2)
      for (int dx = -1; dx <= 1; ++dx)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dz = -1; dz <= 1; ++dz) {
            if (dx == 0 && dy == 0 && dz == 0) continue;
            const Vec3i q{p[0] + s * dx, p[1] + s * dy, p[2] + s * dz};
            if (!domain_.contains(q)) continue;
            const EdgeId e = edge_index_.find(edge_key(p, q));
            // A midpoint names at most one live edge, which need not end here.
            if (e == kInvalidId) continue;
            const Edge& edge = edges_[e];
            if (edge.six_volume > 0 && (edge.a == node || edge.b == node)) f(e, edge);
          }
  }

  // Changes whenever the set of leaf tets may have changed (split, merge),
  // and is unique across all meshes of the process: two equal versions mean
  // the same topology, so a surface or layout derived from it can be reused.
  std::uint64_t topology_version() const { return topology_version_; }

  // Bytes held by the mesh's pools and indices (capacity, not just size).
  std::size_t memory_bytes() const;
  // Pre-sizes pools and indices for about `tets` leaf tets.
  void reserve_tets(std::size_t tets);

 private:
  int split_recursive(Key diamond, const DiamondInfo& info, MeshChangeLog* log);
  void bisect(TetId t, NodeId z, MeshChangeLog* log);
  void unbisect(TetId first, TetId second, const std::array<NodeId, 4>& parent, NodeId z, MeshChangeLog* log);
  // Full-cost add/remove (six edge shares each): construction only.
  TetId add_tet(const std::array<NodeId, 4>& v, int depth, std::uint64_t child_path, MeshChangeLog* log);
  // Tet records without edge-share bookkeeping; `edges` in kTetEdgeSlots order.
  TetId link_tet(const std::array<NodeId, 4>& v, int depth, std::uint64_t child_path,
                 const std::array<EdgeId, 6>& edges, MeshChangeLog* log);
  void unlink_tet(TetId t, MeshChangeLog* log);
  void change_edge_share(EdgeId e, std::int64_t delta, MeshChangeLog* log);
  NodeId add_node(const Vec3i& p, NodeId edge_a, NodeId edge_b, int depth, MeshChangeLog* log);
  void remove_node(NodeId id, MeshChangeLog* log);
  EdgeId add_edge_share(NodeId a, NodeId b, std::int64_t six_volume, MeshChangeLog* log);
  bool orientation_negative(const std::array<NodeId, 4>& v) const;

  BoxSpec spec_;
  LatticeDomain domain_;
  double lattice_unit_m_ = 0.0;
  std::int64_t coarse_six_volume_ = 0;
  std::int64_t total_six_volume_ = 0;
  std::uint64_t topology_version_ = next_topology_version();
  static std::uint64_t next_topology_version();

  std::vector<Node> nodes_;
  std::vector<Edge> edges_;
  std::vector<Tet> tets_;
  std::vector<NodeId> free_nodes_;
  std::vector<EdgeId> free_edges_;
  std::vector<TetId> free_tets_;
  util::KeyIndexMap node_index_;
  util::KeyIndexMap edge_index_;
  std::size_t node_count_ = 0;
  std::size_t edge_count_ = 0;
  std::size_t tet_count_ = 0;
};

// Refinement tag of a tet at `depth`: the refinement edge is (v0, v_tag).
constexpr int maubach_tag(int depth) { return 3 - depth % 3; }

// A live tet by its corners, sorted, and its depth. TetIds are reused across
// split and merge and corners come in Maubach order, so this is what stays
// equal for the same tet: the set difference of two sorted lists taken before
// and after a mesh change is the tets it removed and added (analyses of what
// a change did, e.g. the energy a split makes).
using SortedTet = std::pair<std::array<NodeId, 4>, int>;
// Every live tet of `mesh` as a SortedTet, the list sorted.
std::vector<SortedTet> sorted_live_tets(const KuhnMesh& mesh);

}  // namespace tissue::mesh
