#include "mesh/kuhn_mesh.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace tissue::mesh {

namespace {

// A free slot of a pool: the most recently freed one (warm in cache), else a new one.
template <class T>
std::uint32_t take_slot(std::vector<T>& pool, std::vector<std::uint32_t>& free_slots) {
  if (!free_slots.empty()) {
    const std::uint32_t id = free_slots.back();
    free_slots.pop_back();
    return id;
  }
  pool.emplace_back();
  return static_cast<std::uint32_t>(pool.size() - 1);
}

std::string describe_key(Key key) {
  const Vec3i d = unpack_doubled(key);
  std::ostringstream os;
  os << "diamond at doubled lattice point (" << d[0] << ", " << d[1] << ", " << d[2] << ")";
  return os.str();
}

// Smallest coarse exponent K such that every split up to max_depth lands on
// the integer lattice: a tet at depth d lives in cubes of H / 2^(d/3) units and
// its refinement-edge midpoint needs that size to be even.
int coarse_log2_for_depth(int max_depth) { return max_depth <= 0 ? 1 : (max_depth - 1) / 3 + 1; }

}  // namespace

int max_lattice_depth(std::int64_t largest_cubes) {
  if (largest_cubes < 1 || largest_cubes > kMaxCubesPerAxis) return -1;
  // Depths 3K-2 .. 3K need a coarse cube of 2^K lattice units.
  int k = 1;
  while ((largest_cubes << (k + 1)) <= kMaxLatticeCoord) ++k;
  return std::min(60, 3 * k);
}

std::uint64_t KuhnMesh::next_topology_version() {
  // Atomic only so meshes built on different threads (daemon, tests) never
  // share a number; no other state is shared.
  static std::atomic<std::uint64_t> next{1};
  return next.fetch_add(1, std::memory_order_relaxed);
}

KuhnMesh::KuhnMesh(const BoxSpec& spec) : spec_(spec) {
  auto reject = [](const std::string& field, const std::string& why) {
    throw std::invalid_argument("mesh box: " + field + " " + why);
  };
  if (spec.cubes_x <= 0) reject("cubes_x = " + std::to_string(spec.cubes_x), "must be a positive cube count");
  if (spec.cubes_y <= 0) reject("cubes_y = " + std::to_string(spec.cubes_y), "must be a positive cube count");
  if (spec.cubes_z <= 0) reject("cubes_z = " + std::to_string(spec.cubes_z), "must be a positive cube count");
  if (!(spec.cube_size_m > 0.0) || !std::isfinite(spec.cube_size_m))
    reject("cube_size_m = " + std::to_string(spec.cube_size_m), "must be a finite length > 0 m");
  if (spec.max_depth < 0) reject("max_depth = " + std::to_string(spec.max_depth), "must be >= 0");

  const std::int64_t largest = std::max({spec.cubes_x, spec.cubes_y, spec.cubes_z});
  const int depth_limit = max_lattice_depth(largest);
  if (depth_limit < 0)
    reject("cube counts (largest " + std::to_string(largest) + ")",
           "overflow the 21-bit lattice keys; at most " + std::to_string(kMaxCubesPerAxis) + " cubes per axis");
  if (spec.max_depth > depth_limit)
    reject("max_depth = " + std::to_string(spec.max_depth),
           "exceeds what the lattice can hold for " + std::to_string(largest) + " cubes along an axis (at most " +
               std::to_string(depth_limit) + ")");
  const int k = coarse_log2_for_depth(spec.max_depth);

  domain_.cubes = {spec.cubes_x, spec.cubes_y, spec.cubes_z};
  domain_.coarse_log2 = k;
  const std::int64_t h = domain_.coarse_cube();
  lattice_unit_m_ = spec.cube_size_m / static_cast<double>(h);
  coarse_six_volume_ = h * h * h;
  const __int128 total = static_cast<__int128>(6) * coarse_six_volume_ * spec.cubes_x * spec.cubes_y * spec.cubes_z;
  if (total > std::numeric_limits<std::int64_t>::max())
    reject("cube counts", "make the total volume overflow 64-bit lattice units");
  total_six_volume_ = static_cast<std::int64_t>(total);

  // Coarse nodes: ids in x-fastest order over the (n+1)^3 grid.
  const std::int64_t nx = spec.cubes_x + 1, ny = spec.cubes_y + 1, nz = spec.cubes_z + 1;
  const std::size_t coarse_cubes = static_cast<std::size_t>(spec.cubes_x) * spec.cubes_y * spec.cubes_z;
  reserve_tets(6 * coarse_cubes);
  nodes_.reserve(static_cast<std::size_t>(nx * ny * nz));
  for (std::int64_t z = 0; z < nz; ++z)
    for (std::int64_t y = 0; y < ny; ++y)
      for (std::int64_t x = 0; x < nx; ++x) add_node({x * h, y * h, z * h}, kInvalidId, kInvalidId, 0, nullptr);
  auto coarse_id = [&](std::int64_t x, std::int64_t y, std::int64_t z) {
    return static_cast<NodeId>(x + nx * (y + ny * z));
  };

  // Six Kuhn tets per cube on the reflected grid: per axis, an even cube
  // index starts at its far side and walks backwards, an odd one starts at
  // its near side. Neighbouring cubes are mirror images, so the grid is
  // conforming and cubic-symmetric already at level 0.
  constexpr std::array<std::array<int, 3>, 6> kPermutations{
      {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}}};
  for (std::int64_t cz = 0; cz < spec.cubes_z; ++cz)
    for (std::int64_t cy = 0; cy < spec.cubes_y; ++cy)
      for (std::int64_t cx = 0; cx < spec.cubes_x; ++cx) {
        const std::array<std::int64_t, 3> cube{cx, cy, cz};
        std::array<std::int64_t, 3> start{}, step{};
        for (int a = 0; a < 3; ++a) {
          const bool even = cube[a] % 2 == 0;
          start[a] = even ? cube[a] + 1 : cube[a];
          step[a] = even ? -1 : 1;
        }
        for (const auto& perm : kPermutations) {
          std::array<std::int64_t, 3> p = start;
          std::array<NodeId, 4> v{};
          v[0] = coarse_id(p[0], p[1], p[2]);
          for (int i = 0; i < 3; ++i) {
            p[perm[i]] += step[perm[i]];
            v[i + 1] = coarse_id(p[0], p[1], p[2]);
          }
          add_tet(v, 0, 0, nullptr);
        }
      }
}

std::array<double, 3> KuhnMesh::node_position_m(NodeId id) const {
  const Vec3i& p = nodes_[id].lattice;
  return {p[0] * lattice_unit_m_, p[1] * lattice_unit_m_, p[2] * lattice_unit_m_};
}

std::array<NodeId, 4> KuhnMesh::oriented_vertices(TetId id) const {
  std::array<NodeId, 4> v = tets_[id].v;
  if (tets_[id].negative) std::swap(v[0], v[1]);
  return v;
}

Key KuhnMesh::diamond_of(TetId id) const {
  const Tet& t = tets_[id];
  return edge_key(nodes_[t.v[0]].lattice, nodes_[t.v[maubach_tag(t.depth)]].lattice);
}

DiamondInfo KuhnMesh::diamond_info(Key diamond) const {
  DiamondInfo info;
  std::string why;
  if (!classify_diamond(domain_, diamond, &info, &why))
    throw std::invalid_argument(describe_key(diamond) + " is not a diamond of this box: " + why);
  return info;
}

bool KuhnMesh::can_split(Key diamond) const {
  DiamondInfo info;
  if (!classify_diamond(domain_, diamond, &info, nullptr)) return false;
  return info.depth < spec_.max_depth && !is_split(diamond);
}

bool KuhnMesh::can_merge(Key diamond) const {
  if (!is_split(diamond)) return false;
  DiamondInfo info;
  if (!classify_diamond(domain_, diamond, &info, nullptr)) return false;
  std::array<Key, 8> children{};
  const int n = diamond_children(domain_, info, &children);
  for (int i = 0; i < n; ++i)
    if (is_split(children[i])) return false;
  return true;
}

int KuhnMesh::split(Key diamond, MeshChangeLog* log) {
  const DiamondInfo info = diamond_info(diamond);  // validates before anything else
  if (is_split(diamond)) return 0;
  if (info.depth >= spec_.max_depth)
    throw std::invalid_argument(describe_key(diamond) + " has tets at depth " + std::to_string(info.depth) +
                                ", and max_depth is " + std::to_string(spec_.max_depth) + ": cannot split further");
  topology_version_ = next_topology_version();
  return split_recursive(diamond, info, log);
}

int KuhnMesh::closure_diamonds(Key diamond, std::vector<Key>& closure) const {
  closure.clear();
  if (!can_split(diamond)) return 0;
  // Breadth-first over the unsplit ancestors; `closure` is also the visited
  // list (a diamond is reached through up to four children). split_recursive
  // splits exactly these: every unsplit parent, recursively.
  closure.push_back(diamond);
  for (std::size_t i = 0; i < closure.size(); ++i) {
    DiamondInfo info;
    classify_diamond(domain_, closure[i], &info, nullptr);
    std::array<Key, 4> parents{};
    const int parent_count = diamond_parents(domain_, info, &parents);
    for (int j = 0; j < parent_count; ++j)
      if (!is_split(parents[j]) && std::find(closure.begin(), closure.end(), parents[j]) == closure.end())
        closure.push_back(parents[j]);
  }
  return static_cast<int>(closure.size());
}

void KuhnMesh::closure_tets(Key diamond, std::vector<TetId>& tets, std::vector<Key>& pending) const {
  tets.clear();
  closure_diamonds(diamond, pending);
  for (const Key key : pending) {
    // A diamond's tets exist once the parent each comes from is split: some
    // may exist while another parent is unsplit, hence every diamond's list.
    const EdgeId e = edge_index_.find(key);
    if (e != util::KeyIndexMap::kNotFound)
      for (TetId t = edges_[e].diamond_head; t != kInvalidId; t = tets_[t].next_in_diamond) tets.push_back(t);
  }
}

int KuhnMesh::merge_restores(Key diamond, std::array<std::array<NodeId, 4>, 8>& parents) const {
  if (!can_merge(diamond)) return 0;
  const NodeId z = node_index_.find(diamond);
  DiamondInfo info;
  classify_diamond(domain_, diamond, &info, nullptr);
  std::array<Key, 8> children{};
  const int child_count = diamond_children(domain_, info, &children);
  const int k = maubach_tag(info.depth);
  int count = 0;
  // As merge(): the tets around z sit in the child diamonds' lists; each
  // parent is its first child with z replaced by the far end of z's edge.
  for (int i = 0; i < child_count; ++i) {
    const EdgeId e = edge_index_.find(children[i]);
    if (e == util::KeyIndexMap::kNotFound) continue;
    for (TetId t = edges_[e].diamond_head; t != kInvalidId; t = tets_[t].next_in_diamond) {
      const Tet& child = tets_[t];
      if (child.v[k] != z || ((child.child_path >> info.depth) & 1)) continue;  // not a first child of z
      if (count == 8) throw std::logic_error(describe_key(diamond) + ": more than 8 parent tets");
      parents[count] = child.v;
      parents[count][k] = child.v[0] == nodes_[z].edge_a ? nodes_[z].edge_b : nodes_[z].edge_a;
      ++count;
    }
  }
  return count;
}

int KuhnMesh::split_recursive(Key diamond, const DiamondInfo& info, MeshChangeLog* log) {
  int splits = 0;
  // Closure: a diamond's tets exist only once all its parents are split.
  std::array<Key, 4> parents{};
  const int parent_count = diamond_parents(domain_, info, &parents);
  for (int i = 0; i < parent_count; ++i) {
    if (is_split(parents[i])) continue;
    DiamondInfo parent_info;
    classify_diamond(domain_, parents[i], &parent_info, nullptr);
    splits += split_recursive(parents[i], parent_info, log);
  }

  const EdgeId e = edge_index_.find(diamond);
  if (e == util::KeyIndexMap::kNotFound)
    throw std::logic_error(describe_key(diamond) + ": refinement edge missing after parent closure");
  std::array<TetId, 8> members{};
  int count = 0;
  for (TetId t = edges_[e].diamond_head; t != kInvalidId; t = tets_[t].next_in_diamond) {
    if (count == 8) throw std::logic_error(describe_key(diamond) + ": more than 8 tets");
    members[count++] = t;
  }
  const int expected = diamond_tet_count(domain_, info);
  if (count != expected)
    throw std::logic_error(describe_key(diamond) + ": has " + std::to_string(count) + " tets, expected " +
                           std::to_string(expected));

  const NodeId z = add_node(info.centre, edges_[e].a, edges_[e].b, info.depth, log);
  for (int i = 0; i < count; ++i) bisect(members[i], z, log);
  if (log) ++log->diamonds_split;
  return splits + 1;
}

// Bisection touches only what changes. Of the parent's edges, the
// refinement edge (x0, xk) loses the whole share, the four edges at x0 or xk
// lose half (each survives in one child), and the opposite edge keeps its
// share (it lies in both children). The four new edges at z gain theirs.
// That is 10 edge lookups per bisection instead of 18 for remove + 2 adds.
void KuhnMesh::bisect(TetId t, NodeId z, MeshChangeLog* log) {
  const Tet parent = tets_[t];
  const int k = maubach_tag(parent.depth);
  const std::int64_t six = six_volume_at_depth(parent.depth), half = six / 2;
  const std::array<EdgeId, 6>& parent_edges = parent.e;
  unlink_tet(t, log);
  const NodeId x0 = parent.v[0], xk = parent.v[k];
  for (int i = 0; i < 6; ++i) {
    const int p = kTetEdgeSlots[i][0], q = kTetEdgeSlots[i][1];
    const bool at_x0 = p == 0, at_xk = p == k || q == k;
    if (at_x0 && at_xk)
      change_edge_share(parent_edges[i], -six, log);
    else if (at_x0 || at_xk)
      change_edge_share(parent_edges[i], -half, log);
  }
  nodes_[x0].six_volume -= half;
  nodes_[xk].six_volume -= half;
  nodes_[z].six_volume += six;
  // New edges at z: half a share from each child that has them.
  struct Known {
    NodeId a, b;
    EdgeId id;
  };
  std::array<Known, 10> known{};
  int n_known = 0;
  for (int i = 0; i < 6; ++i) {
    const int p = kTetEdgeSlots[i][0], q = kTetEdgeSlots[i][1];
    if (p == 0 && q == k) continue;  // the refinement edge is in neither child
    known[n_known++] = {parent.v[p], parent.v[q], parent_edges[i]};
  }
  for (int i = 0; i < 4; ++i) {
    const NodeId other = parent.v[i];
    const std::int64_t share = (i == 0 || i == k) ? half : six;
    known[n_known++] = {other, z, add_edge_share(other, z, share, log)};
  }
  auto edges_of = [&](const std::array<NodeId, 4>& v) {
    std::array<EdgeId, 6> ids{};
    for (int i = 0; i < 6; ++i) {
      const NodeId a = v[kTetEdgeSlots[i][0]], b = v[kTetEdgeSlots[i][1]];
      for (int j = 0; j < n_known; ++j)
        if ((known[j].a == a && known[j].b == b) || (known[j].a == b && known[j].b == a)) ids[i] = known[j].id;
    }
    return ids;
  };
  // Maubach: child0 = (x0..x_{k-1}, z, x_{k+1}..x3), child1 = (x1..x_k, z, x_{k+1}..x3).
  std::array<NodeId, 4> c0 = parent.v, c1 = parent.v;
  c0[k] = z;
  for (int i = 0; i < k; ++i) c1[i] = parent.v[i + 1];
  c1[k] = z;
  link_tet(c0, parent.depth + 1, parent.child_path, edges_of(c0), log);
  link_tet(c1, parent.depth + 1, parent.child_path | (std::uint64_t{1} << parent.depth), edges_of(c1), log);
}

// The inverse of bisect for one pair of sibling leaves. Every edge it needs
// but the parent's refinement edge is stored in the two children.
void KuhnMesh::unbisect(TetId first, TetId second, const std::array<NodeId, 4>& parent, NodeId z, MeshChangeLog* log) {
  const int depth = tets_[first].depth - 1;
  const int k = maubach_tag(depth);
  const std::int64_t six = six_volume_at_depth(depth), half = six / 2;
  const std::uint64_t path = tets_[first].child_path;
  struct Known {
    NodeId a, b;
    EdgeId id;
  };
  std::array<Known, 12> known{};
  int n_known = 0;
  for (TetId child : {first, second})
    for (int i = 0; i < 6; ++i)
      known[n_known++] = {tets_[child].v[kTetEdgeSlots[i][0]], tets_[child].v[kTetEdgeSlots[i][1]], tets_[child].e[i]};
  auto edge_between = [&](NodeId a, NodeId b) {
    for (const Known& kn : known)
      if ((kn.a == a && kn.b == b) || (kn.a == b && kn.b == a)) return kn.id;
    throw std::logic_error("mesh: sibling tets lack an edge of their parent");
  };
  std::array<EdgeId, 4> z_edges{};
  for (int i = 0; i < 4; ++i) z_edges[i] = edge_between(parent[i], z);
  std::array<EdgeId, 6> parent_edges{};
  for (int i = 0; i < 6; ++i) {
    const int p = kTetEdgeSlots[i][0], q = kTetEdgeSlots[i][1];
    if (!(p == 0 && q == k)) parent_edges[i] = edge_between(parent[p], parent[q]);
  }
  unlink_tet(first, log);
  unlink_tet(second, log);
  // Edges at z lose what bisect gave them (and die with the last pair).
  for (int i = 0; i < 4; ++i) change_edge_share(z_edges[i], (i == 0 || i == k) ? -half : -six, log);
  nodes_[parent[0]].six_volume += half;
  nodes_[parent[k]].six_volume += half;
  nodes_[z].six_volume -= six;
  for (int i = 0; i < 6; ++i) {
    const int p = kTetEdgeSlots[i][0], q = kTetEdgeSlots[i][1];
    const bool at_x0 = p == 0, at_xk = p == k || q == k;
    if (at_x0 && at_xk)
      parent_edges[i] = add_edge_share(parent[p], parent[q], six, log);
    else if (at_x0 || at_xk)
      change_edge_share(parent_edges[i], half, log);
  }
  link_tet(parent, depth, path, parent_edges, log);
}

TetId KuhnMesh::link_tet(const std::array<NodeId, 4>& v, int depth, std::uint64_t child_path,
                         const std::array<EdgeId, 6>& edges, MeshChangeLog* log) {
  const TetId id = take_slot(tets_, free_tets_);
  Tet& t = tets_[id];
  t.v = v;
  t.e = edges;
  t.depth = static_cast<std::uint8_t>(depth);
  t.child_path = child_path;
  t.negative = orientation_negative(v);
  // The refinement edge (v0, v_k) is slot pair k - 1 in kTetEdgeSlots order.
  Edge& refinement = edges_[edges[maubach_tag(depth) - 1]];
  t.next_in_diamond = refinement.diamond_head;
  refinement.diamond_head = id;
  ++tet_count_;
  if (log) log->events.push_back({MeshEvent::Kind::kTetAdded, static_cast<std::uint8_t>(depth), id, v, edges});
  return id;
}

void KuhnMesh::unlink_tet(TetId id, MeshChangeLog* log) {
  const Tet t = tets_[id];
  Edge& refinement = edges_[t.e[maubach_tag(t.depth) - 1]];
  if (refinement.diamond_head == id) {
    refinement.diamond_head = t.next_in_diamond;
  } else {
    TetId prev = refinement.diamond_head;
    while (tets_[prev].next_in_diamond != id) prev = tets_[prev].next_in_diamond;
    tets_[prev].next_in_diamond = t.next_in_diamond;
  }
  tets_[id].depth = Tet::kDeadDepth;
  tets_[id].next_in_diamond = kInvalidId;
  free_tets_.push_back(id);
  --tet_count_;
  // Logged before any of its edges may die, so a replay sees them alive.
  if (log) log->events.push_back({MeshEvent::Kind::kTetRemoved, t.depth, id, t.v, t.e});
}

void KuhnMesh::require_can_merge(Key diamond) const {
  // The key first: a coarse grid vertex is "split" (its node exists) but no
  // diamond, and has no edge to merge into.
  const DiamondInfo info = diamond_info(diamond);
  if (!is_split(diamond)) throw std::invalid_argument(describe_key(diamond) + " cannot merge: it is not split");
  std::array<Key, 8> children{};
  const int child_count = diamond_children(domain_, info, &children);
  for (int i = 0; i < child_count; ++i)
    if (is_split(children[i]))
      throw std::invalid_argument(describe_key(diamond) + " cannot merge: its child " + describe_key(children[i]) +
                                  " is split (merge finer diamonds first)");
}

void KuhnMesh::merge(Key diamond, MeshChangeLog* log) {
  require_can_merge(diamond);
  const NodeId z = node_index_.find(diamond);
  const DiamondInfo info = diamond_info(diamond);
  std::array<Key, 8> children{};
  const int child_count = diamond_children(domain_, info, &children);
  topology_version_ = next_topology_version();

  // The tets around z are exactly the children of the diamond's tets; they
  // sit in the child diamonds' lists (z is never on their refinement edges).
  std::array<TetId, 16> halves{};
  int half_count = 0;
  for (int i = 0; i < child_count; ++i) {
    const EdgeId e = edge_index_.find(children[i]);
    if (e == util::KeyIndexMap::kNotFound) continue;
    for (TetId t = edges_[e].diamond_head; t != kInvalidId; t = tets_[t].next_in_diamond) {
      const auto& v = tets_[t].v;
      if (v[0] != z && v[1] != z && v[2] != z && v[3] != z) continue;
      if (half_count == 16) throw std::logic_error(describe_key(diamond) + ": more than 16 child tets");
      halves[half_count++] = t;
    }
  }
  const int expected = 2 * diamond_tet_count(domain_, info);
  if (half_count != expected)
    throw std::logic_error(describe_key(diamond) + ": found " + std::to_string(half_count) +
                           " child tets around its node, expected " + std::to_string(expected));

  // Rebuild each parent from its first child: parent = child0 with z replaced
  // by the far end of the refinement edge (the end of z's edge that is not
  // child0's first vertex); its sibling is child1 = (x1..x_k, z, ...).
  const int parent_depth = info.depth;
  const int k = maubach_tag(parent_depth);
  struct Pair {
    TetId first, second;
    std::array<NodeId, 4> parent;
  };
  std::array<Pair, 8> pairs{};
  int pair_count = 0;
  // Pair everything before changing anything: unbisect frees ids that the
  // rebuilt parents may reuse.
  for (int i = 0; i < half_count; ++i) {
    const Tet& child = tets_[halves[i]];
    if ((child.child_path >> parent_depth) & 1) continue;  // second child: found via its sibling
    std::array<NodeId, 4> parent = child.v;
    parent[k] = child.v[0] == nodes_[z].edge_a ? nodes_[z].edge_b : nodes_[z].edge_a;
    std::array<NodeId, 4> sibling = parent;
    for (int j = 0; j < k; ++j) sibling[j] = parent[j + 1];
    sibling[k] = z;
    int match = -1;
    for (int j = 0; j < half_count; ++j)
      if (tets_[halves[j]].v == sibling) match = j;
    if (match < 0 || pair_count == 8) throw std::logic_error(describe_key(diamond) + ": child tets do not pair up");
    pairs[pair_count++] = {halves[i], halves[match], parent};
  }
  if (pair_count * 2 != half_count) throw std::logic_error(describe_key(diamond) + ": child tets do not pair up");
  for (int i = 0; i < pair_count; ++i) unbisect(pairs[i].first, pairs[i].second, pairs[i].parent, z, log);
  remove_node(z, log);
  if (log) ++log->diamonds_merged;
}

TetId KuhnMesh::add_tet(const std::array<NodeId, 4>& v, int depth, std::uint64_t child_path, MeshChangeLog* log) {
  const std::int64_t six = six_volume_at_depth(depth);
  std::array<EdgeId, 6> edge_ids{};
  for (int i = 0; i < 6; ++i) edge_ids[i] = add_edge_share(v[kTetEdgeSlots[i][0]], v[kTetEdgeSlots[i][1]], six, log);
  for (NodeId n : v) nodes_[n].six_volume += six;
  return link_tet(v, depth, child_path, edge_ids, log);
}

NodeId KuhnMesh::add_node(const Vec3i& p, NodeId edge_a, NodeId edge_b, int depth, MeshChangeLog* log) {
  const NodeId id = take_slot(nodes_, free_nodes_);
  nodes_[id] = Node{p, 0, edge_a, edge_b, static_cast<std::uint8_t>(depth), true};
  node_index_.insert(vertex_key(p), id);
  ++node_count_;
  if (log)
    log->events.push_back(
        {MeshEvent::Kind::kNodeAdded, static_cast<std::uint8_t>(depth), id, {edge_a, edge_b, kInvalidId, kInvalidId}});
  return id;
}

void KuhnMesh::remove_node(NodeId id, MeshChangeLog* log) {
  Node& n = nodes_[id];
  if (n.six_volume != 0) throw std::logic_error("mesh: removing a node that still has incident tets");
  node_index_.erase(vertex_key(n.lattice));
  n.alive = false;
  free_nodes_.push_back(id);
  --node_count_;
  if (log)
    log->events.push_back({MeshEvent::Kind::kNodeRemoved, n.depth, id, {n.edge_a, n.edge_b, kInvalidId, kInvalidId}});
}

EdgeId KuhnMesh::add_edge_share(NodeId a, NodeId b, std::int64_t six_volume, MeshChangeLog* log) {
  const Key key = edge_key(nodes_[a].lattice, nodes_[b].lattice);
  EdgeId id = edge_index_.find(key);
  if (id == util::KeyIndexMap::kNotFound) {
    id = take_slot(edges_, free_edges_);
    edges_[id] = Edge{std::min(a, b), std::max(a, b), 0, kInvalidId};
    edge_index_.insert(key, id);
    ++edge_count_;
    if (log)
      log->events.push_back({MeshEvent::Kind::kEdgeAdded, 0, id, {edges_[id].a, edges_[id].b, kInvalidId, kInvalidId}});
  } else if (!((edges_[id].a == a && edges_[id].b == b) || (edges_[id].a == b && edges_[id].b == a))) {
    // Two distinct edges with one midpoint would break the diamond encoding.
    throw std::logic_error("mesh: two edges share a midpoint key");
  }
  edges_[id].six_volume += six_volume;
  return id;
}

void KuhnMesh::change_edge_share(EdgeId id, std::int64_t delta, MeshChangeLog* log) {
  if (id == util::KeyIndexMap::kNotFound) throw std::logic_error("mesh: changing the share of a missing edge");
  Edge& e = edges_[id];
  e.six_volume += delta;
  if (e.six_volume > 0) return;
  if (e.six_volume < 0 || e.diamond_head != kInvalidId)
    throw std::logic_error("mesh: edge volume bookkeeping out of balance");
  edge_index_.erase(edge_key(nodes_[e.a].lattice, nodes_[e.b].lattice));
  free_edges_.push_back(id);
  --edge_count_;
  if (log) log->events.push_back({MeshEvent::Kind::kEdgeRemoved, 0, id, {e.a, e.b, kInvalidId, kInvalidId}});
}

bool KuhnMesh::orientation_negative(const std::array<NodeId, 4>& v) const {
  const Vec3i& p0 = nodes_[v[0]].lattice;
  __int128 d[3][3];
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) d[r][c] = nodes_[v[r + 1]].lattice[c] - p0[c];
  const __int128 det = d[0][0] * (d[1][1] * d[2][2] - d[1][2] * d[2][1]) -
                       d[0][1] * (d[1][0] * d[2][2] - d[1][2] * d[2][0]) +
                       d[0][2] * (d[1][0] * d[2][1] - d[1][1] * d[2][0]);
  if (det == 0) throw std::logic_error("mesh: degenerate tetrahedron");
  return det < 0;
}

std::size_t KuhnMesh::memory_bytes() const {
  return nodes_.capacity() * sizeof(Node) + edges_.capacity() * sizeof(Edge) + tets_.capacity() * sizeof(Tet) +
         (free_nodes_.capacity() + free_edges_.capacity() + free_tets_.capacity()) * sizeof(std::uint32_t) +
         node_index_.memory_bytes() + edge_index_.memory_bytes();
}

void KuhnMesh::reserve_tets(std::size_t tets) {
  // Kuhn meshes have about 1.2 edges and 0.18 nodes per tet.
  tets_.reserve(tets);
  edges_.reserve(tets + tets / 4);
  nodes_.reserve(tets / 5 + 8);
  edge_index_.reserve(tets + tets / 4);
  node_index_.reserve(tets / 5 + 8);
}

std::vector<SortedTet> sorted_live_tets(const KuhnMesh& mesh) {
  std::vector<SortedTet> tets;
  tets.reserve(mesh.tet_count());
  mesh.for_each_tet([&](TetId, const Tet& t) {
    std::array<NodeId, 4> v = t.v;
    std::sort(v.begin(), v.end());
    tets.push_back({v, t.depth});
  });
  std::sort(tets.begin(), tets.end());
  return tets;
}

}  // namespace tissue::mesh
