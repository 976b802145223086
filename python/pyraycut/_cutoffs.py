"""Per-atom and per-pair cutoffs, as ASE's ``neighbor_list`` takes them: the search runs at the
largest pair cutoff, and the list pass itself keeps the pairs within their own cutoff (decided in
double, on the device for device positions: ``raycut::PairCutoffs``).

- a sequence of N radii (ASE's ``natural_cutoffs``): pair (i, j) within ``r_i + r_j``;
- ``{(Z1, Z2): rc}``: pair cutoffs by species (symmetric; a pair of species not listed has no
  neighbours, as in ASE); keys are atomic numbers or, with ASE installed, symbols;
- ``{Z: r}``: a radius per species, pair (i, j) within ``r_Zi + r_Zj``.
"""
from __future__ import annotations

import numbers as _numbers
from typing import Any, Optional

import numpy as np


def is_varying(cutoff: Any) -> bool:
    """Whether ``cutoff`` is per atom or per pair (anything but one number)."""
    if type(cutoff) in (float, int) or isinstance(cutoff, _numbers.Real):
        return False  # first: torch.compile traces a float as a SymFloat
    return isinstance(cutoff, dict) or (not isinstance(cutoff, (str, bytes)) and
                                        hasattr(cutoff, "__len__") and np.ndim(cutoff) > 0)


def _species(key: Any) -> int:
    if isinstance(key, (_numbers.Integral, np.integer)) and not isinstance(key, bool):
        return int(key)
    if isinstance(key, str):
        try:
            from ase.data import atomic_numbers
        except ImportError:
            raise ValueError(f"cutoff: the species {key!r} is a symbol; pass atomic numbers, or "
                             "install ase to use symbols") from None
        if key not in atomic_numbers:
            raise ValueError(f"cutoff: unknown chemical symbol {key!r}")
        return int(atomic_numbers[key])
    raise ValueError(f"cutoff: a species must be an atomic number or a symbol, got {key!r}")


def _value(value: Any, what: str) -> float:
    if not isinstance(value, _numbers.Real) or not np.isfinite(value) or value < 0:
        raise ValueError(f"cutoff: {what} must be a finite number >= 0, got {value!r}")
    return float(value)


class PairCutoffs:
    """The cutoff of every pair of an N-particle system: ``search`` (the largest, where the
    neighbour search runs), ``of(i, j)`` (float64 per pair) and the arrays the list pass reads."""

    def __init__(self, cutoff: Any, n: int, numbers: Optional[Any]) -> None:
        self._radius = None  # (N,) radii: pair cutoff r_i + r_j
        self._table = None   # (U, U) pair cutoffs over the species present
        self._kind = None    # (N,) the species index of each particle, into _table
        if isinstance(cutoff, dict):
            if numbers is None:
                raise ValueError("cutoff: a dict of per-species cutoffs needs the atomic numbers "
                                 "of the particles (numbers=, or an Atoms' numbers)")
            z = np.asarray(numbers).reshape(-1)
            if len(z) != n:
                raise ValueError(f"numbers: {len(z)} atomic numbers for {n} particles")
            if not cutoff:
                raise ValueError("cutoff: an empty dict (no species pair has a cutoff)")
            pairs = [isinstance(k, tuple) for k in cutoff]
            if all(pairs):
                present, self._kind = np.unique(z, return_inverse=True)
                self._kind = self._kind.reshape(-1)
                self._table = np.zeros((len(present), len(present)))
                for key, value in cutoff.items():
                    if len(key) != 2:
                        raise ValueError(f"cutoff: a species pair has two species, got {key!r}")
                    a, b = _species(key[0]), _species(key[1])
                    c = _value(value, f"the cutoff of {key!r}")
                    ia, ib = np.searchsorted(present, [a, b])
                    if ia < len(present) and ib < len(present) and present[ia] == a and \
                            present[ib] == b:
                        self._table[ia, ib] = self._table[ib, ia] = c
                # The largest cutoff among the species present (others cannot pair here).
                self.search = float(self._table.max()) if self._table.size else 0.0
            elif not any(pairs):
                radii = {_species(k): _value(v, f"the radius of species {k!r}")
                         for k, v in cutoff.items()}
                present = np.unique(z)
                missing = [int(s) for s in present if int(s) not in radii]
                if missing:
                    raise ValueError(f"cutoff: no radius for species {missing} (the dict gives "
                                     f"{sorted(radii)})")
                lookup = np.zeros(int(present.max()) + 1 if len(present) else 1)
                for s in present:
                    lookup[int(s)] = radii[int(s)]
                self._radius = lookup[z.astype(np.int64)] if n else np.zeros(0)
                self.search = 2.0 * max(radii[int(s)] for s in present) if n else 0.0
            else:
                raise ValueError("cutoff: a dict keyed either by species pairs (Z1, Z2) or by "
                                 "species Z, not both")
        else:
            radius = np.asarray(cutoff, dtype=np.float64).reshape(-1)
            if len(radius) != n:
                raise ValueError(f"cutoff: {len(radius)} per-atom cutoffs for {n} particles")
            if not np.all(np.isfinite(radius)) or np.any(radius < 0):
                bad = int(np.flatnonzero(~(np.isfinite(radius) & (radius >= 0)))[0])
                raise ValueError(f"cutoff: per-atom cutoffs must be finite and >= 0, got "
                                 f"{radius[bad]} at index {bad}")
            self._radius = radius
            self.search = 2.0 * float(radius.max()) if n else 0.0

    def of(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """The cutoff of each pair (i, j), float64."""
        if self._radius is not None:
            return self._radius[i] + self._radius[j]
        return self._table[self._kind[i], self._kind[j]]

    def search_cutoff(self) -> float:
        """Where the engine searches: the largest pair cutoff rounded up to a float32, so that the
        search offers every pair the list pass may keep (1 when every cutoff is 0: any positive
        value gives arrays of the right types and shapes)."""
        if self.search <= 0:
            return 1.0
        c = np.float32(self.search)
        return float(c if float(c) >= self.search else np.nextafter(c, np.float32(np.inf)))

    def arrays(self) -> dict:
        """The keyword arguments of the extension's list call: ``radii`` (N,) float64, or
        ``species`` (N,) uint32 with the flattened ``table`` of the species present."""
        if self._radius is not None:
            if len(self._radius) == 0:
                return {}  # no particles: no pairs to keep
            return {"radii": np.ascontiguousarray(self._radius, dtype=np.float64)}
        if self._table.size == 0:
            return {}
        return {"species": np.ascontiguousarray(self._kind, dtype=np.uint32),
                "table": np.ascontiguousarray(self._table, dtype=np.float64).reshape(-1)}
