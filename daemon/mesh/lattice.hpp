// Integer lattice of the Kuhn/Maubach hierarchy: keys and diamond rules.
//
// Every vertex the hierarchy can ever create lies on an integer lattice whose
// unit is the finest allowed node spacing, so points, edges and diamonds have
// exact integer keys and nothing is matched in floating point.
//
// Keys pack *doubled* coordinates, 21 bits per axis: a vertex p has key
// pack(2p) and an edge (a, b) has key pack(a + b), i.e. its doubled midpoint.
// Hence a diamond's key (the key of its refinement edge) equals the key of the
// node its split creates: "diamond d is split" <=> "node with key d exists".
//
// Diamond classification needs no geometric search (Gregorski et al. 2002;
// Weiss & De Floriani 2011): for a diamond centre c (lattice coordinates) let
// s be the minimum number of trailing zeros over the axes and n the number of
// axes attaining it. Then the diamond's cube size is h = 2^(s+1) and its phase
// is 3 - n: 0 = cube diagonal (6 tets), 1 = face diagonal (4, or 2 on a domain
// face), 2 = axis edge (8, 4 on a face, 2 on a domain edge).
#pragma once

#include <array>
#include <cstdint>
#include <string>

namespace tissue::mesh {

using Key = std::uint64_t;
using Vec3i = std::array<std::int64_t, 3>;

inline constexpr int kKeyBitsPerAxis = 21;
// Largest lattice coordinate: doubled coordinates must fit in 21 bits.
inline constexpr std::int64_t kMaxLatticeCoord = (std::int64_t{1} << (kKeyBitsPerAxis - 1)) - 1;

// Packs doubled coordinates (each in [0, 2^21)) into a key.
constexpr Key pack_doubled(const Vec3i& d) {
  return (static_cast<Key>(d[0]) << (2 * kKeyBitsPerAxis)) | (static_cast<Key>(d[1]) << kKeyBitsPerAxis) |
         static_cast<Key>(d[2]);
}

constexpr Vec3i unpack_doubled(Key k) {
  constexpr Key mask = (Key{1} << kKeyBitsPerAxis) - 1;
  return {static_cast<std::int64_t>((k >> (2 * kKeyBitsPerAxis)) & mask),
          static_cast<std::int64_t>((k >> kKeyBitsPerAxis) & mask), static_cast<std::int64_t>(k & mask)};
}

constexpr Key vertex_key(const Vec3i& p) { return pack_doubled({2 * p[0], 2 * p[1], 2 * p[2]}); }

constexpr Key edge_key(const Vec3i& a, const Vec3i& b) { return pack_doubled({a[0] + b[0], a[1] + b[1], a[2] + b[2]}); }

// The diamond classification of a lattice point (see file comment).
struct DiamondInfo {
  Vec3i centre{};         // lattice coordinates of the node a split creates
  int phase = 0;          // 0 cube diagonal, 1 face diagonal, 2 axis edge
  std::int64_t cube = 0;  // h: edge length of the cube the diamond lives in
  int depth = 0;          // bisection depth of the diamond's tetrahedra
  int normal_axis = -1;   // phase 1: the face normal
  int edge_axis = -1;     // phase 2: the axis the refinement edge runs along
};

// The box of cubes in lattice units plus the coarse cube size H = 2^k_coarse.
struct LatticeDomain {
  std::array<std::int64_t, 3> cubes{};  // nx, ny, nz
  int coarse_log2 = 0;                  // K: coarse cube edge H = 2^K lattice units

  std::int64_t coarse_cube() const { return std::int64_t{1} << coarse_log2; }
  std::int64_t extent(int axis) const { return cubes[axis] * coarse_cube(); }
  bool contains(const Vec3i& p) const {
    for (int a = 0; a < 3; ++a)
      if (p[a] < 0 || p[a] > extent(a)) return false;
    return true;
  }
  // True when p lies on the domain boundary plane of `axis`.
  bool on_boundary(const Vec3i& p, int axis) const { return p[axis] == 0 || p[axis] == extent(axis); }
};

// Classifies the doubled-coordinate key of a would-be diamond. Returns false
// (with `why` filled) when the key is not a diamond of this domain's
// hierarchy: not a packed key (bits above the 63 of the coordinates), off
// the lattice, outside the box, or a coarse grid vertex.
bool classify_diamond(const LatticeDomain& domain, Key key, DiamondInfo* info, std::string* why);

// Parent diamonds (keys) inside the domain; they must be split before this
// one can be. Returns how many were written (0..4).
int diamond_parents(const LatticeDomain& domain, const DiamondInfo& d, std::array<Key, 4>* parents);

// Child diamonds (keys) inside the domain: the diamonds whose refinement
// edges the split of `d` exposes. Returns how many were written (0..8).
int diamond_children(const LatticeDomain& domain, const DiamondInfo& d, std::array<Key, 8>* children);

// Number of tetrahedra of a complete diamond in this domain (boundary-reduced).
int diamond_tet_count(const LatticeDomain& domain, const DiamondInfo& d);

}  // namespace tissue::mesh
