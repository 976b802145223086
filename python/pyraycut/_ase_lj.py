"""pyraycut.ase.LennardJones: ASE's Lennard-Jones calculator on raycut's pair pass."""
from __future__ import annotations

from typing import Any

import numpy as np
from ase.calculators.calculator import Calculator, all_changes

from .ase import _engine_on
from .ase import neighbor_list as _ase_neighbor_list

# Voigt order xx yy zz yz xz xy (ASE) from pyraycut's virial components xx yy zz xy xz yz.
_TO_VOIGT = [0, 1, 2, 5, 4, 3]


class LennardJones(Calculator):
    """``ase.calculators.lj.LennardJones``, computed by raycut: the same parameters, results and
    conventions.

    >>> atoms.calc = pyraycut.ase.LennardJones(sigma=3.4, epsilon=0.0104, rc=8.5)
    >>> atoms.get_potential_energy(), atoms.get_forces(), atoms.get_stress()

    Parameters (ASE's): ``sigma`` (1.0), ``epsilon`` (1.0), ``rc`` (cutoff; None: 3 sigma),
    ``ro`` (onset of the smooth cutoff; None: 0.66 rc), ``smooth`` (False: the pair energy
    shifted to 0 at rc, forces jumping to 0 there; True: the pair energy multiplied by ASE's C^1
    polynomial cutoff function between ro and rc). ``method``: a name from
    ``pyraycut.methods()`` or ``"auto"``.

    Results: ``energy`` = ``free_energy`` (eV), ``energies`` (per atom, each pair's energy half
    on each atom: they sum to ``energy``), ``forces``, and for a full-rank cell ``stress`` and
    ``stresses`` (Voigt xx yy zz yz xz xy, per atom summing to ``stress``: -virial / volume).

    Precision: with ``smooth=False`` the fused ``lj_forces`` pass runs in float32 (on the GPU
    where there is one), on positions wrapped and centred in float64, and the per-atom results
    are summed in float64: each per-atom value carries a relative error of a few float32 ulps
    of the sum of its terms' magnitudes (~1e-6). ``smooth=True`` runs on the pairs of
    ``pyraycut.ase.neighbor_list`` in float64, as ASE does (the cutoff function is not in the
    fused pass yet).
    """

    implemented_properties = ["energy", "energies", "forces", "free_energy", "stress",
                              "stresses"]
    default_parameters = {"epsilon": 1.0, "sigma": 1.0, "rc": None, "ro": None,
                          "smooth": False, "method": "auto"}
    nolabel = True

    def __init__(self, **kwargs: Any) -> None:
        Calculator.__init__(self, **kwargs)
        if self.parameters.rc is None:
            self.parameters.rc = 3 * self.parameters.sigma
        if self.parameters.ro is None:
            self.parameters.ro = 0.66 * self.parameters.rc
        p = self.parameters
        for name in ("sigma", "epsilon", "rc", "ro"):
            value = p[name]
            if not np.isfinite(value) or (name != "epsilon" and value < 0):
                raise ValueError(f"LennardJones: {name} must be a finite number"
                                 f"{'' if name == 'epsilon' else ' >= 0'}, got {value!r}")
        if not p.rc > 0:
            raise ValueError(f"LennardJones: rc must be > 0, got {p.rc!r}")
        if p.smooth and not p.ro < p.rc:
            raise ValueError(f"LennardJones: ro must be < rc with smooth=True, got ro={p.ro!r}, "
                             f"rc={p.rc!r}")

    def calculate(self, atoms: Any = None, properties: Any = None,
                  system_changes: Any = all_changes) -> None:
        if properties is None:
            properties = self.implemented_properties
        Calculator.calculate(self, atoms, properties, system_changes)
        p = self.parameters
        if p.smooth:
            energies, forces, virials = self._smooth()
        else:
            energies, forces, virials = self._fused()
        energy = float(energies.sum())
        self.results["energy"] = energy
        self.results["free_energy"] = energy
        self.results["energies"] = energies
        self.results["forces"] = forces
        if self.atoms.cell.rank == 3:
            stresses = -virials[:, _TO_VOIGT] / self.atoms.get_volume()
            self.results["stresses"] = stresses
            self.results["stress"] = stresses.sum(axis=0)

    def _fused(self) -> tuple:
        """lj_forces, shifted at rc: per-atom energy, force and virial (xx yy zz xy xz yz)."""
        p = self.parameters
        engine = _engine_on(self.atoms, p.rc, p.method)
        out = engine.compute("lj_forces", lj_epsilon=p.epsilon, lj_sigma=p.sigma, lj_shift=True)
        return (np.asarray(out["energy"], np.float64), np.asarray(out["force"], np.float64),
                np.asarray(out["virial"], np.float64))

    def _smooth(self) -> tuple:
        """ASE's smooth cutoff, in float64 over the pairs of the full list."""
        p = self.parameters
        n = len(self.atoms)
        i, d, D = _ase_neighbor_list("idD", self.atoms, p.rc, method=p.method)
        r2 = d * d
        c6 = (p.sigma ** 2 / r2) ** 3
        c12 = c6 * c6
        pair_energy = 4 * p.epsilon * (c12 - c6)
        pair_force = -24 * p.epsilon * (2 * c12 - c6) / r2  # times D: the force on i from j
        rc2, ro2 = p.rc ** 2, p.ro ** 2
        outer = r2 >= ro2
        cutoff = np.where(outer, (rc2 - r2) ** 2 * (rc2 + 2 * r2 - 3 * ro2) / (rc2 - ro2) ** 3, 1)
        d_cutoff = np.where(outer, 6 * (rc2 - r2) * (ro2 - r2) / (rc2 - ro2) ** 3, 0)
        pair_force = cutoff * pair_force + 2 * d_cutoff * pair_energy
        pair_energy = pair_energy * cutoff
        f = pair_force[:, None] * D
        energies = 0.5 * np.bincount(i, pair_energy, minlength=n)
        forces = np.stack([np.bincount(i, f[:, k], minlength=n) for k in range(3)], axis=1)
        a, b = [0, 1, 2, 0, 0, 1], [0, 1, 2, 1, 2, 2]
        virials = np.stack([np.bincount(i, -0.5 * f[:, a[k]] * D[:, b[k]], minlength=n)
                            for k in range(6)], axis=1)
        return energies, forces, virials
