#include "mesh/lattice.hpp"

#include <bit>

namespace tissue::mesh {

namespace {

// Trailing zeros of a lattice coordinate; 0 counts as "infinitely even".
int trailing_zeros(std::int64_t v) { return v == 0 ? 63 : std::countr_zero(static_cast<std::uint64_t>(v)); }

Vec3i offset(const Vec3i& c, int axis, std::int64_t delta) {
  Vec3i p = c;
  p[axis] += delta;
  return p;
}

}  // namespace

bool classify_diamond(const LatticeDomain& domain, Key key, DiamondInfo* info, std::string* why) {
  // unpack_doubled reads the low 63 bits only: a key with bit 63 set would
  // name the diamond of its low bits, which the mesh stores under the other key.
  if (key >> (3 * kKeyBitsPerAxis) != 0) {
    if (why) *why = "key has bits set above the 63 bits of packed coordinates";
    return false;
  }
  const Vec3i doubled = unpack_doubled(key);
  Vec3i c{};
  for (int a = 0; a < 3; ++a) {
    if (doubled[a] % 2 != 0) {
      if (why) *why = "midpoint is off the lattice (the finest lattice level is reached)";
      return false;
    }
    c[a] = doubled[a] / 2;
  }
  if (!domain.contains(c)) {
    if (why) *why = "centre lies outside the box";
    return false;
  }
  int tz[3];
  int s = 63;
  for (int a = 0; a < 3; ++a) {
    tz[a] = trailing_zeros(c[a]);
    if (tz[a] < s) s = tz[a];
  }
  int n = 0;
  for (int a = 0; a < 3; ++a) n += (tz[a] == s) ? 1 : 0;
  // A point even at the coarse spacing is a coarse grid vertex, not a diamond.
  if (s >= domain.coarse_log2) {
    if (why) *why = "point is a coarse grid vertex, not the centre of a diamond";
    return false;
  }
  DiamondInfo d;
  d.centre = c;
  d.phase = 3 - n;
  d.cube = std::int64_t{1} << (s + 1);
  const int level = domain.coarse_log2 - (s + 1);  // number of cube halvings
  d.depth = 3 * level + d.phase;
  for (int a = 0; a < 3; ++a) {
    if (d.phase == 1 && tz[a] > s) d.normal_axis = a;
    if (d.phase == 2 && tz[a] == s) d.edge_axis = a;
  }
  if (info) *info = d;
  return true;
}

int diamond_parents(const LatticeDomain& domain, const DiamondInfo& d, std::array<Key, 4>* parents) {
  int count = 0;
  const std::int64_t half = d.cube / 2;
  auto add = [&](const Vec3i& p) {
    if (domain.contains(p)) (*parents)[count++] = vertex_key(p);
  };
  switch (d.phase) {
    case 0: {
      if (d.depth == 0) return 0;  // coarse cubes are roots
      // The cube's corners that are axis-edge centres of the 2h grid.
      for (int corner = 0; corner < 8; ++corner) {
        Vec3i p = d.centre;
        for (int a = 0; a < 3; ++a) p[a] += ((corner >> a) & 1) ? half : -half;
        int zeros_at_2h = 0;  // axes where p is a multiple of 2h
        for (int a = 0; a < 3; ++a)
          zeros_at_2h += (trailing_zeros(p[a]) > std::countr_zero(static_cast<std::uint64_t>(d.cube))) ? 1 : 0;
        // Axis-edge centre of size 2h: exactly two axes on the 2h grid, one at h.
        if (zeros_at_2h == 2) add(p);
      }
      break;
    }
    case 1:
      add(offset(d.centre, d.normal_axis, -half));
      add(offset(d.centre, d.normal_axis, +half));
      break;
    case 2:
      for (int a = 0; a < 3; ++a) {
        if (a == d.edge_axis) continue;
        add(offset(d.centre, a, -half));
        add(offset(d.centre, a, +half));
      }
      break;
    default:
      break;
  }
  return count;
}

int diamond_children(const LatticeDomain& domain, const DiamondInfo& d, std::array<Key, 8>* children) {
  // Work in doubled coordinates: children of the finest splittable diamonds
  // have half-integer centres (their tets are at max depth and never split,
  // but merge still finds them by their refinement-edge keys).
  int count = 0;
  const Vec3i c2{2 * d.centre[0], 2 * d.centre[1], 2 * d.centre[2]};
  const std::int64_t half2 = d.cube;  // (h/2) doubled
  auto add = [&](const Vec3i& p2) {
    for (int a = 0; a < 3; ++a)
      if (p2[a] < 0 || p2[a] > 2 * domain.extent(a)) return;
    (*children)[count++] = pack_doubled(p2);
  };
  switch (d.phase) {
    case 0:
      for (int a = 0; a < 3; ++a) {
        add(offset(c2, a, -half2));
        add(offset(c2, a, +half2));
      }
      break;
    case 1:
      for (int a = 0; a < 3; ++a) {
        if (a == d.normal_axis) continue;
        add(offset(c2, a, -half2));
        add(offset(c2, a, +half2));
      }
      break;
    case 2: {
      const std::int64_t quarter2 = d.cube / 2;  // (h/4) doubled
      for (int corner = 0; corner < 8; ++corner) {
        Vec3i p = c2;
        for (int a = 0; a < 3; ++a) p[a] += ((corner >> a) & 1) ? quarter2 : -quarter2;
        add(p);
      }
      break;
    }
    default:
      break;
  }
  return count;
}

int diamond_tet_count(const LatticeDomain& domain, const DiamondInfo& d) {
  const std::int64_t half = d.cube / 2;
  switch (d.phase) {
    case 0:
      return 6;  // a cube diagonal is always inside its cube
    case 1: {
      // Two tets in each of the (one or two) cubes sharing the face.
      int cubes = 0;
      for (std::int64_t s : {-half, half}) cubes += domain.contains(offset(d.centre, d.normal_axis, s)) ? 1 : 0;
      return 2 * cubes;
    }
    case 2: {
      // Two tets in each of the (one, two or four) cubes around the edge.
      const int b1 = (d.edge_axis + 1) % 3, b2 = (d.edge_axis + 2) % 3;
      int cubes = 0;
      for (std::int64_t s1 : {-half, half})
        for (std::int64_t s2 : {-half, half})
          cubes += domain.contains(offset(offset(d.centre, b1, s1), b2, s2)) ? 1 : 0;
      return 2 * cubes;
    }
    default:
      return 0;
  }
}

}  // namespace tissue::mesh
