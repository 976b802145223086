"""pyraycut.ase.CoulombDSF: the damped shifted-force Coulomb sum as an ASE calculator."""
from __future__ import annotations

from typing import Any

import numpy as np
from ase import units
from ase.calculators.calculator import Calculator, all_changes

from ._ase_lj import _TO_VOIGT
from .ase import _engine_on


class CoulombDSF(Calculator):
    """Damped shifted-force (DSF) Coulomb, Fennell & Gezelter, J. Chem. Phys. 124, 234104
    (2006), the formula documented for LAMMPS's ``pair_style coul/dsf``, computed by raycut's
    fused ``coulomb_dsf`` pass.

    >>> atoms.set_initial_charges(q)
    >>> atoms.calc = pyraycut.ase.CoulombDSF(alpha=0.2, rc=10.0)
    >>> atoms.get_potential_energy(), atoms.get_forces(), atoms.get_stress()

    With ``a = alpha`` and ``C = rc``, each pair within C adds
    ``k q_i q_j [erfc(a r)/r - erfc(a C)/C + (erfc(a C)/C^2 + 2a/sqrt(pi) exp(-a^2 C^2)/C)(r - C)]``
    (energy and force go to 0 at C), and each atom its self energy
    ``-(erfc(a C)/(2C) + a/sqrt(pi)) k q_i^2``.

    Parameters: ``alpha`` (damping, 1/A, >= 0; 0.2), ``rc`` (cutoff, A; 10.0), ``k`` (Coulomb
    constant; None: 14.399645 eV A / e^2, ASE's units), ``method``: a name from
    ``pyraycut.methods()`` or ``"auto"``. Charges: ``atoms.get_initial_charges()``.

    Results: ``energy`` = ``free_energy`` (eV), ``energies`` (per atom: half of each pair's
    energy on each atom plus the atom's self energy; they sum to ``energy``), ``forces``, and
    for a full-rank cell ``stress`` and ``stresses`` (Voigt xx yy zz yz xz xy, -virial /
    volume, per atom summing to ``stress``).

    Precision: the pass runs in float32 (on the GPU where there is one) on positions wrapped
    and centred in float64 and float32 charges; the per-atom results are summed in float64.
    """

    implemented_properties = ["energy", "energies", "forces", "free_energy", "stress",
                              "stresses"]
    default_parameters = {"alpha": 0.2, "rc": 10.0, "k": None, "method": "auto"}
    nolabel = True

    def __init__(self, **kwargs: Any) -> None:
        Calculator.__init__(self, **kwargs)
        p = self.parameters
        if p.k is None:
            p.k = units.Hartree * units.Bohr
        for name, lowest in (("alpha", 0.0), ("rc", None), ("k", None)):
            value = p[name]
            ok = isinstance(value, (int, float, np.floating, np.integer)) and np.isfinite(value)
            if not ok or (lowest is not None and value < lowest):
                raise ValueError(f"CoulombDSF: {name} must be a finite number"
                                 f"{'' if lowest is None else ' >= 0'}, got {value!r}")
        if not p.rc > 0:
            raise ValueError(f"CoulombDSF: rc must be > 0, got {p.rc!r}")

    def calculate(self, atoms: Any = None, properties: Any = None,
                  system_changes: Any = all_changes) -> None:
        if properties is None:
            properties = self.implemented_properties
        Calculator.calculate(self, atoms, properties, system_changes)
        p = self.parameters
        charges = np.asarray(self.atoms.get_initial_charges(), np.float64)
        if not np.isfinite(charges).all():
            bad = int(np.flatnonzero(~np.isfinite(charges))[0])
            raise ValueError(f"CoulombDSF: charge of atom {bad} is {charges[bad]!r}: charges "
                             f"must be finite")
        engine = _engine_on(self.atoms, p.rc, p.method)
        out = engine.compute("coulomb_dsf", charge=charges.astype(np.float32),
                             alpha=p.alpha, coulomb_constant=p.k)
        energies = np.asarray(out["energy"], np.float64)
        virials = np.asarray(out["virial"], np.float64)
        energy = float(energies.sum())
        self.results["energy"] = energy
        self.results["free_energy"] = energy
        self.results["energies"] = energies
        self.results["forces"] = np.asarray(out["force"], np.float64)
        if self.atoms.cell.rank == 3:
            stresses = -virials[:, _TO_VOIGT] / self.atoms.get_volume()
            self.results["stresses"] = stresses
            self.results["stress"] = stresses.sum(axis=0)
