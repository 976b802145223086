#!/usr/bin/env python3
"""Reference pairs for tests/test_periodic_oracle.cpp, from ASE's neighbour list.

Writes tests/data/periodic_ase_<name>.txt: the cutoff, pbc, the cell (rows a, b, c), the
positions (float32 values, written as the shortest decimal of the double they convert to, so
reading them as double and casting to float is exact) and every pair (i, j, S) that
ase.neighborlist.neighbor_list("ijS", atoms, cutoff) returns (self_interaction=False: all but
(i, i, 0); r_ij = x_j - x_i + S . cell for the positions as given, unwrapped ones included).

    python3 tests/data/make_periodic_ase.py      # needs numpy and ase (made with ASE 3.29.0)
"""
import os

import ase
import numpy as np
from ase import Atoms
from ase.neighborlist import neighbor_list

HERE = os.path.dirname(os.path.abspath(__file__))


def case(name, cell, pbc, n, cutoff, seed, unwrap=0, z_extent=None):
    rng = np.random.default_rng(seed)
    cell = np.array(cell, dtype=np.float64)
    frac = rng.random((n, 3))
    if unwrap:
        frac[:, :] += rng.integers(-unwrap, unwrap + 1, size=(n, 3)) * np.array(pbc)
    positions = frac @ cell
    if z_extent is not None:  # a slab: z free along the non-periodic axis (c is zero)
        positions[:, 2] = rng.random(n) * z_extent
    positions = positions.astype(np.float32).astype(np.float64)  # exactly float32 values
    atoms = Atoms("X%d" % n, positions=positions, cell=cell, pbc=pbc)
    i, j, S = neighbor_list("ijS", atoms, cutoff)
    order = np.lexsort((S[:, 2], S[:, 1], S[:, 0], j, i))
    i, j, S = i[order], j[order], S[order]
    path = os.path.join(HERE, "periodic_ase_%s.txt" % name)
    with open(path, "w") as out:
        out.write("# made by tests/data/make_periodic_ase.py with ASE %s: "
                  "neighbor_list(\"ijS\", atoms, cutoff)\n" % ase.__version__)
        out.write("cutoff %r\n" % float(cutoff))
        out.write("pbc %s\n" % " ".join("1" if p else "0" for p in pbc))
        out.write("cell %s\n" % " ".join(repr(float(v)) for v in cell.reshape(-1)))
        out.write("positions %d\n" % n)
        for p in positions:
            out.write("%r %r %r\n" % tuple(float(v) for v in p))
        out.write("pairs %d\n" % len(i))
        for a, b, s in zip(i, j, S):
            out.write("%d %d %d %d %d\n" % (a, b, s[0], s[1], s[2]))
    print(path, n, "atoms", len(i), "pairs")


# A cube smaller than 2C (C > L): many images of every pair, self-images too.
case("cubic_small", [[2.0, 0, 0], [0, 2.0, 0], [0, 0, 2.0]], [True, True, True], 6, 2.9, 1)
# Triclinic, positions unwrapped up to 3 cells away along each axis.
case("triclinic_unwrapped", [[3.0, 0, 0], [1.2, 2.8, 0], [-0.7, 0.9, 2.6]], [True, True, True],
     12, 2.2, 2, unwrap=3)
# A slab (pbc T T F), left-handed in-plane rows, zero c; z spread over 4 (> 2C).
case("slab_left", [[2.5, 0, 0], [0.8, -2.3, 0], [0, 0, 0]], [True, True, False], 10, 2.0, 3,
     unwrap=2, z_extent=4.0)
