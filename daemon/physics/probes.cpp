#include "physics/probes.hpp"

#include <Eigen/Dense>
#include <stdexcept>

namespace tissue::physics {

std::array<double, 4> barycentric(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) {
  Eigen::Matrix3d m;
  m << b - a, c - a, d - a;
  const Vec3 l = m.partialPivLu().solve(p - a);
  return {1.0 - l.sum(), l[0], l[1], l[2]};
}

bool Probe::cache_valid(const Body& body) {
  const mesh::KuhnMesh& mesh = body.mesh();
  if (tet_ == mesh::kInvalidId) return false;
  // Leaf tets change only with the topology version: the per-step read costs
  // one comparison.
  if (mesh.topology_version() == topology_version_) return true;
  // Tet and node ids are both reused, so a live tet of the same id with the
  // same vertex ids can be another tet (a merge frees a node and its tets, a
  // later split hands the ids out again with the node elsewhere). A tet is
  // its four lattice points: if they are the same, so is the tet and so are
  // the weights. Checking them, rather than locating again after every
  // change, keeps a pass that changed the mesh elsewhere from costing a walk
  // over every tet per probe.
  if (!mesh.tet_alive(tet_) || mesh.tet(tet_).v != nodes_) return false;
  for (int i = 0; i < 4; ++i)
    if (!mesh.node_alive(nodes_[i]) || mesh.node(nodes_[i]).lattice != corners_[i]) return false;
  topology_version_ = mesh.topology_version();
  return true;
}

void Probe::locate(const Body& body) {
  double best = -INFINITY;
  body.mesh().for_each_tet([&](TetId t, const mesh::Tet& tet) {
    if (best >= -1e-12) return;  // already inside one: keep the first (lowest id)
    const auto& v = tet.v;
    const auto l = barycentric(rest_m_, body.rest_m[v[0]], body.rest_m[v[1]], body.rest_m[v[2]], body.rest_m[v[3]]);
    const double worst = std::min({l[0], l[1], l[2], l[3]});
    if (worst > best) {
      best = worst;
      tet_ = t;
      nodes_ = v;
      bary_ = l;
    }
  });
  // The object fills its box, and the Simulation puts a probe the scene's
  // checks let lie outside it (kProbeOutsideBoxTolerance) onto the box: such
  // a point lies in or on a tet up to rounding, which relative to a small tet
  // can exceed any fixed tolerance (0.09 nm outside a 25 mm tet is -3.6e-9).
  // The nearest tet is taken; only a point clearly outside (callers that
  // skip the scene's checks) is refused.
  if (best < -1e-6) {
    tet_ = mesh::kInvalidId;
    throw std::invalid_argument("probe '" + name_ + "' lies outside the object");
  }
  for (int i = 0; i < 4; ++i) corners_[i] = body.mesh().node(nodes_[i]).lattice;
  topology_version_ = body.mesh().topology_version();
}

Vec3 Probe::displacement_m(const Body& body) {
  if (!cache_valid(body)) locate(body);
  Vec3 u = Vec3::Zero();
  for (int i = 0; i < 4; ++i) u += bary_[i] * (body.x_m[nodes_[i]] - body.rest_m[nodes_[i]]);
  return u;
}

}  // namespace tissue::physics
