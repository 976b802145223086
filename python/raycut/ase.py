"""A drop-in for ``ase.neighborlist.neighbor_list`` on open (non-periodic) systems.

>>> from raycut.ase import neighbor_list
>>> i, j, d, D = neighbor_list("ijdD", atoms, 3.0)   # as ase.neighborlist.neighbor_list

The pairs are found by ``raycut.neighbor_list`` on the positions as float32 (the one float32
predicate ``|x_j - x_i|^2 < cutoff^2``; pairs within a few float32 ulps of the cutoff may differ
from ASE's float64 answer), and returned with ASE's types: ``i``, ``j`` intp sorted by ``i``;
``d`` (P,) and ``D`` (P, 3) float64, computed in float64 from the Atoms' own positions (as ASE
computes them); ``S`` (P, 3) int64 shifts, all zero here. ASE itself is not imported: anything
with ``positions`` and ``pbc`` works.

Periodic boxes are not supported yet: Atoms with any ``pbc`` raise ``ValueError``. Per-atom or
per-pair cutoffs (ASE's list and dict cutoffs) are not supported either (``ValueError``).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from . import neighbor_list as _neighbor_list

__all__ = ["neighbor_list"]

_QUANTITIES = "ijdDS"


def neighbor_list(quantities: str, atoms: Any, cutoff: float, self_interaction: bool = False,
                  method: str = "auto") -> Any:
    """``ase.neighborlist.neighbor_list(quantities, atoms, cutoff, self_interaction)`` for Atoms
    without periodic boundaries, computed by raycut (``method``: a name from
    ``raycut.methods()`` or ``"auto"``).

    ``quantities``: letters of ``"ijdDS"``, returned in that order (one letter: the array
    alone). ``self_interaction``: also the pairs (i, i), at distance 0, as ASE adds them.
    """
    if not isinstance(quantities, str) or not quantities:
        raise ValueError("quantities must be a non-empty string of the letters i, j, d, D, S")
    for letter in quantities:
        if letter not in _QUANTITIES:
            raise ValueError(f"unknown quantity {letter!r} in {quantities!r} (known: i, j, d, "
                             "D, S)")
    try:
        pbc = np.asarray(atoms.pbc, dtype=bool)
        positions = np.asarray(atoms.positions, dtype=np.float64)
    except AttributeError:
        raise TypeError(f"atoms must be an ase.Atoms (or have positions and pbc), got "
                        f"{type(atoms).__name__}") from None
    if pbc.any():
        raise ValueError("periodic boxes are not supported yet")
    positions = positions.reshape(-1, 3)

    i, j = _neighbor_list("ij", positions.astype(np.float32), cutoff, method=method)
    i = np.asarray(i, dtype=np.intp)
    j = np.asarray(j, dtype=np.intp)
    if self_interaction and len(positions):
        own = np.arange(len(positions), dtype=np.intp)
        i = np.concatenate([i, own])
        j = np.concatenate([j, own])
        order = np.argsort(i, kind="stable")  # sorted by i, as ASE returns them
        i, j = i[order], j[order]

    out = []
    vectors = None
    for letter in quantities:
        if letter == "i":
            out.append(i)
        elif letter == "j":
            out.append(j)
        elif letter in "dD":
            if vectors is None:
                vectors = positions[j] - positions[i]  # float64, as ASE
            out.append(vectors if letter == "D" else np.sqrt(np.sum(vectors * vectors, axis=1)))
        else:  # "S": no periodic images in an open system
            out.append(np.zeros((len(i), 3), dtype=np.int64))
    return out[0] if len(out) == 1 else tuple(out)
