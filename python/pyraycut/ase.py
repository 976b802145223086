"""A drop-in for ``ase.neighborlist.neighbor_list``, for any Atoms: open, periodic, triclinic,
cells smaller than twice the cutoff, mixed pbc.

>>> from pyraycut.ase import neighbor_list
>>> i, j, d, D, S = neighbor_list("ijdDS", atoms, 3.0)   # as ase.neighborlist.neighbor_list

ASE's conventions: every (i, j, S) with ``D = positions[j] - positions[i] + S @ cell`` shorter
than the cutoff, (i, i, 0) left out (``self_interaction=False``: a particle's own periodic
images are kept, as ASE keeps them), S referring to the Atoms' positions as they are (wrapped
or not). ASE's types: ``i``, ``j`` intp sorted by ``i``; ``d`` (P,) and ``D`` (P, 3) float64,
computed in float64 from the Atoms' own positions and cell (as ASE computes them); ``S`` (P, 3)
int (int64). The order of pairs within a row may differ from ASE's.

The pairs are found by ``pyraycut.neighbor_list`` in float32 (the one float32 predicate): on
positions wrapped into the cell in float64 first (so that far-unwrapped positions lose no float32
precision) and translated in float64 so that their bounding box is centred on the origin (so
that Atoms far from the origin along an open axis lose none either), the shifts then translated
back to the positions given. Pairs within a few float32 ulps of the cutoff may differ from ASE's
float64 answer; a float32 ulp here is that of half the system's extent (of the cell along
periodic axes), so a system spanning 1e6 decides pairs to ~0.03. ASE itself is not imported: anything
with ``positions``, ``cell`` and ``pbc`` works (``cell`` may be absent for open systems).

Per-atom and per-pair cutoffs are taken as ASE takes them: a list of radii (``natural_cutoffs``:
pair (i, j) within ``r_i + r_j``), ``{(Z1, Z2): rc}`` (species pairs not listed have no
neighbours) or ``{Z: r}`` (a radius per species), Z from ``atoms.numbers``. The search runs at
the largest pair cutoff, and the list pass keeps each pair within its own cutoff, decided in
double from the float64 positions as given.

Also here: ``NeighborList``, a drop-in for ``ase.neighborlist.NeighborList``, and
``LennardJones``, an ASE calculator equal to ``ase.calculators.lj.LennardJones``, and
``CoulombDSF``, the damped shifted-force Coulomb sum (Fennell & Gezelter 2006) as an ASE
calculator (both imported on first use: only they need ASE).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from . import _arrays, _cutoffs, _letters, _put_back, _raycut, _take_engine
from . import neighbor_list as _neighbor_list

__all__ = ["CoulombDSF", "LennardJones", "NeighborList", "neighbor_list"]


def __getattr__(name: str) -> Any:
    if name == "LennardJones":  # an ase Calculator: imports ASE, so only when asked for
        from ._ase_lj import LennardJones

        return LennardJones
    if name == "CoulombDSF":
        from ._ase_coulomb import CoulombDSF

        return CoulombDSF
    raise AttributeError(f"module 'pyraycut.ase' has no attribute {name!r}")


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


def _system(atoms: Any) -> tuple:
    """(positions (N, 3) float64, cell (3, 3) float64, pbc (3,) bool) of an Atoms."""
    try:
        pbc = np.asarray(atoms.pbc, dtype=bool)
        # ASE's own pbc is (3,) already; broadcast_to costs more than the rest of this here.
        pbc = pbc.copy() if pbc.shape == (3,) else np.broadcast_to(pbc, (3,)).copy()
        positions = np.asarray(atoms.positions, dtype=np.float64).reshape(-1, 3)
    except AttributeError:
        raise TypeError(f"atoms must be an ase.Atoms (or have positions and pbc), got "
                        f"{type(atoms).__name__}") from None
    cell = getattr(atoms, "cell", None)
    cell = np.zeros((3, 3)) if cell is None else np.asarray(cell, dtype=np.float64).reshape(3, 3)
    return positions, cell, pbc


def _engine_on(atoms: Any, cutoff: float, method: str) -> Any:
    """A pyraycut Engine built over an Atoms at ``cutoff``: its positions wrapped into the cell
    along periodic axes and centred, in float64, then rounded to float32 (the calculators'
    fused passes)."""
    from . import Engine

    positions, cell, pbc = _system(atoms)
    engine = Engine(method)
    if pbc.any():
        wrapped, _ = _wrap(positions, cell, pbc)
        engine.build(_centred_float32(wrapped), cutoff, cell=cell, pbc=pbc)
    else:
        engine.build(_centred_float32(positions), cutoff)
    return engine


def _pairs(positions: np.ndarray, cutoff: Any, cell: np.ndarray, pbc: np.ndarray,
           periodic: bool, method: str, numbers: Any) -> tuple:
    """(i, j, S) of ``pyraycut.neighbor_list("ijS", ...)`` over an Atoms' arrays. For one plain
    number as the cutoff the engine's build and pairs are called directly: an Atoms' arrays are
    already in the shapes the extension takes ((N, 3) float64, a (3, 3) cell, 3 flags), and the
    general route's parsing of every other input form was half of a 1-atom cell's call. The
    library checks the same things either way (finite positions, the cutoff, the cell)."""
    if type(cutoff) not in (float, int):  # per-atom or per-pair cutoffs, numpy scalars
        return _neighbor_list("ijS", positions, cutoff, cell=cell if periodic else None,
                              pbc=pbc if periodic else None, method=method, numbers=numbers)
    engine, key = _take_engine(method, _arrays.HOST)
    pairs = engine._host_system_pairs(
        np.ascontiguousarray(positions, dtype=np.float64), float(cutoff),
        np.ascontiguousarray(cell).reshape(1, 3, 3) if periodic else None,
        pbc.reshape(1, 3) if periodic else None)
    _put_back(key, engine)
    return pairs


def neighbor_list(quantities: str, atoms: Any, cutoff: Any, self_interaction: bool = False,
                  method: str = "auto") -> Any:
    """``ase.neighborlist.neighbor_list(quantities, atoms, cutoff, self_interaction)``, computed
    by raycut (``method``: a name from ``pyraycut.methods()`` or ``"auto"``).

    ``quantities``: letters of ``"ijdDS"``, returned in that order (one letter: the array
    alone). ``cutoff``: one number, a list of per-atom radii, ``{(Z1, Z2): rc}`` or
    ``{Z: r}`` (see the module's doc). ``self_interaction``: also the pairs (i, i, 0), at
    distance 0, as ASE adds them (kept where 0 < the pair's cutoff, as ASE does). Raises
    ValueError for a singular cell or a periodic axis with a zero cell row (the library's
    message), and for bad cutoffs (naming them).
    """
    _letters(quantities)
    positions, cell, pbc = _system(atoms)
    varying = _cutoffs.is_varying(cutoff)
    numbers = getattr(atoms, "numbers", None)
    periodic = True in pbc.tolist()  # pbc.any() took 1.2 us, 7 % of a 1-atom cell's call
    # Decided by the list pass in double from the float64 positions as given (S then refers to
    # them, as ASE's does), per-atom and per-pair cutoffs too.
    i, j, S = _pairs(positions, cutoff, cell, pbc, periodic, method, numbers)
    i = np.asarray(i, dtype=np.intp)
    j = np.asarray(j, dtype=np.intp)
    S = np.asarray(S, dtype=np.int64)
    if self_interaction and len(positions):
        own = np.arange(len(positions), dtype=np.intp)
        if varying:  # (i, i, 0) at distance 0: kept where 0 < its cutoff, as ASE does
            own = own[_cutoffs.PairCutoffs(cutoff, len(positions), numbers).of(own, own) > 0]
        i = np.concatenate([i, own])
        j = np.concatenate([j, own])
        S = np.concatenate([S, np.zeros((len(own), 3), np.int64)])
        order = np.argsort(i, kind="stable")  # sorted by i, as ASE returns them
        i, j, S = i[order], j[order], S[order]

    out = []
    vectors = lengths = None
    for letter in quantities:
        if letter == "i":
            out.append(i)
        elif letter == "j":
            out.append(j)
        elif letter in "dD":
            if vectors is None:  # float64, rounded as ASE's
                x = np.ascontiguousarray(positions)
                vectors, lengths = _raycut.pair_vectors(
                    x, x, np.ascontiguousarray(i, np.int64), np.ascontiguousarray(j, np.int64),
                    S if periodic else None, np.ascontiguousarray(cell[None]) if periodic else None,
                    None)
            out.append(vectors if letter == "D" else lengths)
        else:
            out.append(S)
    return out[0] if len(out) == 1 else tuple(out)


class _Atoms:
    """What ``neighbor_list`` reads of an Atoms (positions, cell, pbc), for NeighborList."""

    def __init__(self, positions: np.ndarray, cell: np.ndarray, pbc: np.ndarray) -> None:
        self.positions, self.cell, self.pbc = positions, cell, pbc


class NeighborList:
    """A drop-in for ``ase.neighborlist.NeighborList``, built by raycut.

    >>> nl = NeighborList(natural_cutoffs(atoms), self_interaction=False, bothways=True)
    >>> nl.update(atoms)                     # True: built
    >>> indices, offsets = nl.get_neighbors(0)
    >>> atoms.positions[indices] + offsets @ atoms.cell   # the neighbours' positions

    ``cutoffs``: one radius per atom; atoms a and b are neighbours when their spheres, grown by
    ``skin``, overlap: ``d < r_a + r_b + 2 skin`` (ASE's rule). ``update(atoms)`` rebuilds the
    list (and returns True) on the first call, when pbc or the cell changed, or when an atom
    moved more than ``skin`` since the last build; otherwise the list stays and extra neighbours
    beyond the cutoffs may be returned, as in ASE. ``self_interaction``: atom a is its own
    neighbour (a, offset 0) (ASE's default: True). ``bothways``: every pair from both ends;
    otherwise each pair once, in the row of the lower index (a pair of an atom with its own
    image: in the row, with the offset lexicographically positive). ASE's half list may store
    an image pair in the other row: the set of pairs is the same. ``sorted``: each row sorted by
    neighbour index, then offset (x, y, z) as ASE sorts it; otherwise the order within a row is
    unspecified. ``primitive`` is accepted and ignored (ASE's choice of implementation).
    ``method``: a name from ``pyraycut.methods()`` or ``"auto"``.

    Offsets (int64) and indices (intp) refer to the positions as given (wrapped or not).
    """

    def __init__(self, cutoffs: Any, skin: float = 0.3, sorted: bool = False,
                 self_interaction: bool = True, bothways: bool = False, primitive: Any = None,
                 method: str = "auto") -> None:
        radii = np.asarray(cutoffs, dtype=np.float64).reshape(-1)
        if not np.all(np.isfinite(radii)) or np.any(radii < 0):
            raise ValueError("cutoffs: per-atom radii must be finite and >= 0")
        if not np.isfinite(skin) or skin < 0:
            raise ValueError(f"skin must be a finite number >= 0, got {skin!r}")
        self.cutoffs = radii
        self.skin = float(skin)
        self.sorted = bool(sorted)
        self.self_interaction = bool(self_interaction)
        self.bothways = bool(bothways)
        self.method = method
        self.nupdates = 0
        self._built = None  # (positions, cell, pbc) of the last build

    def update(self, atoms: Any) -> bool:
        """Rebuilds the list if needed (see the class); returns True when it did."""
        positions, cell, pbc = _system(atoms)
        if len(positions) != len(self.cutoffs):
            raise ValueError(f"Wrong number of cutoff radii: {len(self.cutoffs)} != "
                             f"{len(positions)}")
        if self._built is not None:
            old_positions, old_cell, old_pbc = self._built
            moved = ((positions - old_positions) ** 2).sum(1).max() if len(positions) else 0.0
            if (old_pbc == pbc).all() and (old_cell == cell).all() and moved <= self.skin ** 2:
                return False
        self.build(_Atoms(positions, cell, pbc))
        return True

    def build(self, atoms: Any) -> None:
        """Builds the list for these atoms, whatever they moved."""
        positions, cell, pbc = _system(atoms)
        i, j, S = neighbor_list("ijS", _Atoms(positions, cell, pbc), self.cutoffs + self.skin,
                                self.self_interaction, self.method)
        if not self.bothways:
            positive = (S[:, 0] > 0) | ((S[:, 0] == 0) & ((S[:, 1] > 0) | ((S[:, 1] == 0) &
                                                                          (S[:, 2] >= 0))))
            keep = (i < j) | ((i == j) & positive)
            i, j, S = i[keep], j[keep], S[keep]
        order = (np.lexsort((S[:, 2], S[:, 1], S[:, 0], j, i)) if self.sorted else
                 np.argsort(i, kind="stable"))
        self._j, self._S = j[order], S[order]
        self._first = np.searchsorted(i[order], np.arange(len(positions) + 1))
        self._built = (positions.copy(), cell.copy(), pbc.copy())
        self.nupdates += 1

    def get_neighbors(self, a: int) -> tuple:
        """``(indices, offsets)`` of atom a's neighbours: their positions are
        ``positions[indices] + offsets @ cell``."""
        if self.nupdates <= 0:
            raise RuntimeError("Must call update(atoms) on your neighborlist first!")
        lo, hi = self._first[a], self._first[a + 1]
        return self._j[lo:hi], self._S[lo:hi]

    def get_connectivity_matrix(self, sparse: bool = True) -> Any:
        """The (N, N) count of neighbour entries of each pair of atoms, as ASE's: a SciPy
        ``dok_matrix`` (``sparse``) or a NumPy array."""
        if self.nupdates <= 0:
            raise RuntimeError("Must call update(atoms) on your neighborlist first!")
        n = len(self._first) - 1
        rows = np.repeat(np.arange(n), np.diff(self._first))
        if not sparse:
            dense = np.zeros((n, n), dtype=np.int64)
            np.add.at(dense, (rows, self._j), 1)
            return dense
        from scipy import sparse as sp

        ones = np.ones(len(rows), dtype=np.int64)
        return sp.coo_matrix((ones, (rows, self._j)), shape=(n, n)).todok()
