"""A drop-in for ``ase.neighborlist.neighbor_list``, for any Atoms: open, periodic, triclinic,
cells smaller than twice the cutoff, mixed pbc.

>>> from raycut.ase import neighbor_list
>>> i, j, d, D, S = neighbor_list("ijdDS", atoms, 3.0)   # as ase.neighborlist.neighbor_list

ASE's conventions: every (i, j, S) with ``D = positions[j] - positions[i] + S @ cell`` shorter
than the cutoff, (i, i, 0) left out (``self_interaction=False``: a particle's own periodic
images are kept, as ASE keeps them), S referring to the Atoms' positions as they are (wrapped
or not). ASE's types: ``i``, ``j`` intp sorted by ``i``; ``d`` (P,) and ``D`` (P, 3) float64,
computed in float64 from the Atoms' own positions and cell (as ASE computes them); ``S`` (P, 3)
int (int64). The order of pairs within a row may differ from ASE's.

The pairs are found by ``raycut.neighbor_list`` in float32 (the one float32 predicate): on
positions wrapped into the cell in float64 first (so that far-unwrapped positions lose no float32
precision) and translated in float64 so that their bounding box is centred on the origin (so
that Atoms far from the origin along an open axis lose none either), the shifts then translated
back to the positions given. Pairs within a few float32 ulps of the cutoff may differ from ASE's
float64 answer; a float32 ulp here is that of half the system's extent (of the cell along
periodic axes), so a system spanning 1e6 decides pairs to ~0.03. ASE itself is not imported: anything
with ``positions``, ``cell`` and ``pbc`` works (``cell`` may be absent for open systems).

Per-atom or per-pair cutoffs (ASE's list and dict cutoffs) are not supported (``ValueError``).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from . import _letters
from . import neighbor_list as _neighbor_list

__all__ = ["neighbor_list"]


def _effective_cell(cell: np.ndarray, pbc: np.ndarray) -> np.ndarray:
    """The cell with its non-periodic rows replaced by unit vectors orthogonal to the periodic
    ones (those rows may be zero or parallel to a periodic row): a basis for fractional
    coordinates along the periodic axes."""
    periodic = np.flatnonzero(pbc)
    if len(periodic) == 3:
        return cell
    eff = cell.copy()
    others = np.flatnonzero(~pbc)
    if len(periodic) == 0:
        eff[others] = np.eye(3)
        return eff
    q, _ = np.linalg.qr(cell[periodic].T, mode="complete")  # last columns: the complement
    for k, axis in enumerate(others):
        eff[axis] = q[:, len(periodic) + k]
    return eff


def _wrap(positions: np.ndarray, cell: np.ndarray, pbc: np.ndarray) -> tuple:
    """(wrapped, n) with positions = wrapped + n @ cell, n integer (0 on open axes). Where the
    cell is unusable (singular, non-finite) nothing is wrapped: the library then refuses the
    box with its own message."""
    n = np.zeros(positions.shape, np.int64)
    if not pbc.any() or not len(positions):
        return positions, n
    with np.errstate(all="ignore"):
        try:
            frac = np.linalg.solve(_effective_cell(cell, pbc).T, positions.T).T
        except np.linalg.LinAlgError:
            return positions, n
        if not np.all(np.isfinite(frac)) or np.abs(frac).max() > 2.0**30:
            return positions, n
    n[:, pbc] = np.floor(frac[:, pbc]).astype(np.int64)
    return positions - n.astype(np.float64) @ cell, n


def _centred_float32(positions: np.ndarray) -> np.ndarray:
    """float32 positions translated (in float64) so that their bounding box is centred on the
    origin: the same vectors D and shifts S, with the float32 rounding of the extent's half
    instead of the absolute coordinates' (Atoms 1e6 away along an open axis gave a pair at 1.062
    for a cutoff of 1.01: float32 rounds 1e6 to multiples of 0.0625)."""
    if len(positions) == 0:
        return positions.astype(np.float32)
    centre = 0.5 * (positions.min(axis=0) + positions.max(axis=0))
    return (positions - centre).astype(np.float32)


def neighbor_list(quantities: str, atoms: Any, cutoff: float, self_interaction: bool = False,
                  method: str = "auto") -> Any:
    """``ase.neighborlist.neighbor_list(quantities, atoms, cutoff, self_interaction)``, computed
    by raycut (``method``: a name from ``raycut.methods()`` or ``"auto"``).

    ``quantities``: letters of ``"ijdDS"``, returned in that order (one letter: the array
    alone). ``self_interaction``: also the pairs (i, i, 0), at distance 0, as ASE adds them.
    Raises ValueError for a singular cell or a periodic axis with a zero cell row (the library's
    message), and for per-atom cutoffs.
    """
    _letters(quantities)
    try:
        pbc = np.broadcast_to(np.asarray(atoms.pbc, dtype=bool), (3,)).copy()
        positions = np.asarray(atoms.positions, dtype=np.float64).reshape(-1, 3)
    except AttributeError:
        raise TypeError(f"atoms must be an ase.Atoms (or have positions and pbc), got "
                        f"{type(atoms).__name__}") from None
    cell = getattr(atoms, "cell", None)
    cell = np.zeros((3, 3)) if cell is None else np.asarray(cell, dtype=np.float64).reshape(3, 3)

    if pbc.any():
        wrapped, n = _wrap(positions, cell, pbc)
        i, j, S = _neighbor_list("ijS", _centred_float32(wrapped), cutoff, cell=cell, pbc=pbc,
                                 method=method)
        i = np.asarray(i, dtype=np.intp)
        j = np.asarray(j, dtype=np.intp)
        # wrapped = positions - n @ cell, so S for the positions as given is S_w + n_i - n_j.
        S = np.asarray(S, dtype=np.int64) + n[i] - n[j]
    else:
        i, j = _neighbor_list("ij", _centred_float32(positions), cutoff, method=method)
        i = np.asarray(i, dtype=np.intp)
        j = np.asarray(j, dtype=np.intp)
        S = np.zeros((len(i), 3), dtype=np.int64)
    if self_interaction and len(positions):
        own = np.arange(len(positions), dtype=np.intp)
        i = np.concatenate([i, own])
        j = np.concatenate([j, own])
        S = np.concatenate([S, np.zeros((len(own), 3), np.int64)])
        order = np.argsort(i, kind="stable")  # sorted by i, as ASE returns them
        i, j, S = i[order], j[order], S[order]

    out = []
    vectors = None
    for letter in quantities:
        if letter == "i":
            out.append(i)
        elif letter == "j":
            out.append(j)
        elif letter in "dD":
            if vectors is None:  # float64, as ASE
                vectors = positions[j] - positions[i] + S.astype(np.float64) @ cell
            out.append(vectors if letter == "D" else np.sqrt(np.sum(vectors * vectors, axis=1)))
        else:
            out.append(S)
    return out[0] if len(out) == 1 else tuple(out)
