#!/usr/bin/python3
"""Can per-type spring weights make every diamond split energy-neutral?

The isotropic weights (daemon/physics/spring_law.cpp, NUMERICS.md §2) make each
uniform level of the Kuhn lattice isotropic. A single split of one diamond
replaces the diamond's tets by their children, and for an affine deformation
the stored energy then changes unless the children's quadratic energy form
equals the parents'. This script builds, for every complete interior diamond
at depths 0 (cube diagonal), 1 (face diagonal) and 2 (axis) of a 4x4x4-cube
reflected grid, the change Σ children − Σ parents of that form as a linear
function of the 10 weights (3 edge classes of type I, 3 of type II, 4 of type
III), and reports:
  - the largest change for the tabulated weights, per depth, relative to the
    diamond's share of the energy, for uniaxial and shear strain;
  - the rank of the stacked system: rank 10 means the only weights that make
    every split neutral are all zero, i.e. no per-type, per-edge-class
    weights can.
Needs numpy (Debian: python3-numpy, pulled in by python3-h5py in
scripts/install-deps.sh). Takes ~1 s (0.96 s with Debian's python3 and numpy).
Run: bench/analysis/split_energy_weights.py
"""
import itertools

import numpy as np

H = 8  # coarse cube size in lattice units (two bisection cycles stay integral)
NAMES = ["I axis", "I face", "I body", "II half-body", "II axis", "II face",
         "III half-axis", "III half-face", "III half-body", "III axis"]
# 24 (l / l_max)^2 -> weight index, per depth % 3 (as isotropic_edge_weight)
CLASSES = {0: {8: 0, 16: 1, 24: 2}, 1: {9: 3, 12: 4, 24: 5}, 2: {6: 6, 12: 7, 18: 8, 24: 9}}
TABULATED = np.array([0.5525, 1.4847, 1.3729, 0.9507, 1.0754, 0.9971, 0.9481, 1.0074, 1.0444, 0.9481])


def coarse_tets(n):
    """Six Kuhn tets per cube on the reflected grid (NUMERICS.md §1)."""
    tets = []
    for c in itertools.product(range(n), repeat=3):
        start = [(c[a] + 1) * H if c[a] % 2 == 0 else c[a] * H for a in range(3)]
        step = [-H if c[a] % 2 == 0 else H for a in range(3)]
        for perm in itertools.permutations(range(3)):
            p = list(start)
            vs = [tuple(p)]
            for ax in perm:
                p[ax] += step[ax]
                vs.append(tuple(p))
            tets.append((vs, 0))
    return tets


def bisect(tet):
    v, d = tet
    k = 3 - d % 3
    z = tuple((v[0][i] + v[k][i]) // 2 for i in range(3))
    return [(v[:k] + [z] + v[k + 1:], d + 1), (v[1:k + 1] + [z] + v[k + 1:], d + 1)]


def volume(v):
    a = np.array(v, float)
    return abs(np.linalg.det(a[1:] - a[0])) / 6


def voigt(e):
    e = np.array(e, float) / np.linalg.norm(e)
    return np.array([e[0] ** 2, e[1] ** 2, e[2] ** 2, 2 * e[1] * e[2], 2 * e[0] * e[2], 2 * e[0] * e[1]])


def energy_forms(tet):
    """Per weight class, the tet's linearised energy form: E/2 · εᵀ (Σ_c w_c Q_c) ε."""
    v, d = tet
    forms = np.zeros((10, 6, 6))
    pairs = list(itertools.combinations(range(4), 2))
    l2 = [sum((v[i][a] - v[j][a]) ** 2 for a in range(3)) for i, j in pairs]
    for (i, j), length2 in zip(pairs, l2):
        a = voigt(np.subtract(v[i], v[j]))
        forms[CLASSES[d % 3][24 * length2 // max(l2)]] += volume(v) * np.outer(a, a)
    return forms


def main():
    full = {0: 6, 1: 4, 2: 8}  # tets of a complete interior diamond per phase
    strains = {"uniaxial xx": np.array([1, 0, 0, 0, 0, 0.0]), "shear xy": np.array([0, 0, 0, 0, 0, 1.0])}
    tets = coarse_tets(4)
    # Energy density of the (isotropic) level-0 lattice for each strain: the
    # scale the changes are measured on, as in the C++ test
    # Body.CubeDiagonalSplitsKeepTheEnergyOfEachStrainComponentAlone.
    lattice = np.tensordot(TABULATED, sum(energy_forms(t) for t in tets), 1) / sum(volume(t[0]) for t in tets)
    density = {name: eps @ lattice @ eps for name, eps in strains.items()}
    rows = []
    for depth in range(3):
        diamonds = {}
        for t in tets:
            v, d = t
            k = 3 - d % 3
            diamonds.setdefault(tuple(sorted([v[0], v[k]])), []).append(t)
        worst = {name: 0.0 for name in strains}
        count = 0
        for members in diamonds.values():
            if len(members) != full[depth]:
                continue
            count += 1
            parents = sum(energy_forms(t) for t in members)
            children = sum(energy_forms(c) for t in members for c in bisect(t))
            change = children - parents
            rows.append(change.reshape(10, 36).T)
            share = sum(volume(t[0]) for t in members)
            for name, eps in strains.items():
                change_of_energy = eps @ np.tensordot(TABULATED, change, 1) @ eps
                worst[name] = max(worst[name], abs(change_of_energy) / (density[name] * share))
        print(f"depth {depth}: {count} interior diamonds; largest |energy change| / diamond's share, tabulated weights: "
              + ", ".join(f"{n} {w:.2f}" for n, w in worst.items()))
        tets = [c for t in tets for c in bisect(t)]
    system = np.vstack(rows)
    singular = np.linalg.svd(system, compute_uv=False)
    rank = int(np.sum(singular > 1e-9 * singular[0]))
    print(f"neutrality system: {system.shape[0]} equations in 10 weights, rank {rank}; "
          f"smallest/largest singular value {singular[-1] / singular[0]:.3f}")
    print("no nonzero weights make every split neutral" if rank == 10 else "a neutral weight set exists")


if __name__ == "__main__":
    main()
