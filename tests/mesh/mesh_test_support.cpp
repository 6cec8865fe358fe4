#include "mesh/mesh_test_support.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace tissue::mesh::testing {

long long signed_six_volume(const KuhnMesh& mesh, const std::array<NodeId, 4>& v) {
  const Vec3i& p0 = mesh.node(v[0]).lattice;
  long long d[3][3];
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) d[r][c] = mesh.node(v[r + 1]).lattice[c] - p0[c];
  return d[0][0] * (d[1][1] * d[2][2] - d[1][2] * d[2][1]) - d[0][1] * (d[1][0] * d[2][2] - d[1][2] * d[2][0]) +
         d[0][2] * (d[1][0] * d[2][1] - d[1][1] * d[2][0]);
}

ConformityReport check_conformity(const KuhnMesh& mesh) {
  ConformityReport r;
  std::map<std::array<Key, 3>, int> faces;
  long long volume = 0;
  mesh.for_each_tet([&](TetId t, const Tet& tet) {
    const long long six = signed_six_volume(mesh, mesh.oriented_vertices(t));
    if (six <= 0) r.problems.push_back("tet " + std::to_string(t) + " not positively oriented");
    if (six != mesh.six_volume_at_depth(tet.depth))
      r.problems.push_back("tet " + std::to_string(t) + " volume does not match its depth");
    volume += six;
    for (int skip = 0; skip < 4; ++skip) {
      std::array<Key, 3> f{};
      int j = 0;
      for (int i = 0; i < 4; ++i)
        if (i != skip) f[j++] = mesh.node_key(tet.v[i]);
      std::sort(f.begin(), f.end());
      ++faces[f];
    }
  });
  if (volume != mesh.total_six_volume())
    r.problems.push_back("total 6V " + std::to_string(volume) + " != box " + std::to_string(mesh.total_six_volume()));
  const LatticeDomain& dom = mesh.domain();
  for (const auto& [f, count] : faces) {
    if (count > 2) {
      r.problems.push_back("face shared by " + std::to_string(count) + " tets");
      continue;
    }
    if (count == 2) {
      ++r.interior_faces;
      continue;
    }
    bool on_box = false;
    for (int a = 0; a < 3 && !on_box; ++a) {
      const Vec3i p0 = unpack_doubled(f[0]), p1 = unpack_doubled(f[1]), p2 = unpack_doubled(f[2]);
      on_box = p0[a] == p1[a] && p0[a] == p2[a] && (p0[a] == 0 || p0[a] == 2 * dom.extent(a));
    }
    if (!on_box) r.problems.push_back("unshared face inside the box (a crack or hanging node)");
    ++r.boundary_faces;
  }
  return r;
}

std::vector<std::string> check_bookkeeping(const KuhnMesh& mesh) {
  std::vector<std::string> problems;
  std::map<NodeId, long long> node_six;
  std::map<Key, long long> edge_six;
  std::map<Key, int> diamond_members;
  mesh.for_each_tet([&](TetId t, const Tet& tet) {
    const long long six = mesh.six_volume_at_depth(tet.depth);
    for (int i = 0; i < 4; ++i) {
      node_six[tet.v[i]] += six;
      for (int j = i + 1; j < 4; ++j)
        edge_six[edge_key(mesh.node(tet.v[i]).lattice, mesh.node(tet.v[j]).lattice)] += six;
    }
    ++diamond_members[mesh.diamond_of(t)];
  });
  std::size_t nodes = 0;
  mesh.for_each_node([&](NodeId n, const Node& node) {
    ++nodes;
    auto it = node_six.find(n);
    if (it == node_six.end()) {
      problems.push_back("node " + std::to_string(n) + " alive but in no tet");
      return;
    }
    if (it->second != node.six_volume)
      problems.push_back("node " + std::to_string(n) + " 6V " + std::to_string(node.six_volume) + " != recomputed " +
                         std::to_string(it->second));
    if (mesh.find_node(mesh.node_key(n)) != n) problems.push_back("node index disagrees");
  });
  if (nodes != node_six.size() || nodes != mesh.node_count()) problems.push_back("node count mismatch");
  std::size_t edges = 0;
  mesh.for_each_edge([&](EdgeId e, const Edge& edge) {
    ++edges;
    const Key k = edge_key(mesh.node(edge.a).lattice, mesh.node(edge.b).lattice);
    auto it = edge_six.find(k);
    if (it == edge_six.end() || it->second != edge.six_volume)
      problems.push_back("edge " + std::to_string(e) + " 6V mismatch");
    if (mesh.find_edge(k) != e) problems.push_back("edge index disagrees");
    int listed = 0;
    for (TetId t = edge.diamond_head; t != kInvalidId; t = mesh.tet(t).next_in_diamond) ++listed;
    auto dm = diamond_members.find(k);
    if (listed != (dm == diamond_members.end() ? 0 : dm->second))
      problems.push_back("diamond list of edge " + std::to_string(e) + " has wrong length");
  });
  if (edges != edge_six.size() || edges != mesh.edge_count()) problems.push_back("edge count mismatch");
  return problems;
}

MeshSets mesh_sets(const KuhnMesh& mesh) {
  MeshSets s;
  mesh.for_each_node([&](NodeId n, const Node&) { s.nodes.insert(mesh.node_key(n)); });
  mesh.for_each_edge(
      [&](EdgeId, const Edge& e) { s.edges.insert(edge_key(mesh.node(e.a).lattice, mesh.node(e.b).lattice)); });
  mesh.for_each_tet([&](TetId, const Tet& t) {
    std::array<Key, 4> q{};
    for (int i = 0; i < 4; ++i) q[i] = mesh.node_key(t.v[i]);
    std::sort(q.begin(), q.end());
    s.tets.insert(q);
  });
  return s;
}

std::array<double, 6> sorted_edge_lengths(const KuhnMesh& mesh, TetId t) {
  const auto& v = mesh.tet(t).v;
  std::array<double, 6> len{};
  int k = 0;
  for (int i = 0; i < 4; ++i)
    for (int j = i + 1; j < 4; ++j) {
      double s = 0;
      for (int a = 0; a < 3; ++a) {
        const double d = static_cast<double>(mesh.node(v[i]).lattice[a] - mesh.node(v[j]).lattice[a]);
        s += d * d;
      }
      len[k++] = std::sqrt(s);
    }
  std::sort(len.begin(), len.end());
  return len;
}

}  // namespace tissue::mesh::testing
