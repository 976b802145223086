"""pyraycut.ase.CoulombDSF and Engine.compute("coulomb_dsf") against a brute-force NumPy float64
damped shifted-force sum over explicit periodic images (written here from Fennell & Gezelter's
formulas), on a periodic NaCl-like crystal, a triclinic cell and a molecule without a cell;
forces against finite differences of the energy."""
import numpy as np
import pytest
from conftest import SYSTEM_METHODS

import pyraycut
import pyraycut.ase

ase = pytest.importorskip("ase", reason="ase is not installed (python/requirements.txt has it)")
from ase import Atoms  # noqa: E402
from scipy.special import erfc  # noqa: E402

K_EV = ase.units.Hartree * ase.units.Bohr  # 14.399645 eV A / e^2
CPU_METHODS = [m for m in SYSTEM_METHODS if m in ("brute-force", "cell-list")]


def phi(r, alpha, rc):
    slope = erfc(alpha * rc) / rc**2 + 2 * alpha / np.sqrt(np.pi) * np.exp(-(alpha * rc)**2) / rc
    value = erfc(alpha * r) / r - erfc(alpha * rc) / rc + slope * (r - rc)
    derivative = (-erfc(alpha * r) / r**2
                  - 2 * alpha / np.sqrt(np.pi) * np.exp(-(alpha * r)**2) / r + slope)
    return value, derivative


def reference(positions, charges, cell, pbc, alpha, rc, k):
    """(energies, forces, virials xx yy zz xy xz yz, scale) per atom in float64, over every
    image within rc; scale: the sum of the magnitudes of each atom's energy terms."""
    positions = np.asarray(positions, np.float64)
    n = len(positions)
    cell = np.asarray(cell, np.float64)
    reach = [0, 0, 0]
    if np.any(pbc):
        volume = abs(np.linalg.det(cell))
        for a in range(3):
            if pbc[a]:
                width = volume / np.linalg.norm(np.cross(cell[(a + 1) % 3], cell[(a + 2) % 3]))
                reach[a] = int(np.ceil(rc / width)) + 1
    energies = -(erfc(alpha * rc) / (2 * rc) + alpha / np.sqrt(np.pi)) * k * charges**2
    scale = np.abs(energies).copy()
    forces = np.zeros((n, 3))
    virials = np.zeros((n, 6))
    qq = k * charges[:, None] * charges[None, :]
    a_idx, b_idx = [0, 1, 2, 0, 0, 1], [0, 1, 2, 1, 2, 2]
    for sa in range(-reach[0], reach[0] + 1):
        for sb in range(-reach[1], reach[1] + 1):
            for sc in range(-reach[2], reach[2] + 1):
                shift = np.array([sa, sb, sc], np.float64) @ cell
                d = positions[None, :, :] - positions[:, None, :] + shift  # d[i, j] = x_j - x_i
                r = np.linalg.norm(d, axis=2)
                keep = r < rc
                if sa == sb == sc == 0:
                    np.fill_diagonal(keep, False)
                rr = np.where(keep, r, 1.0)
                value, derivative = phi(rr, alpha, rc)
                pair = np.where(keep, qq * value, 0.0)
                energies += 0.5 * pair.sum(axis=1)
                scale += np.where(keep, np.abs(qq) / rr, 0.0).sum(axis=1)
                g = np.where(keep, qq * derivative / rr, 0.0)
                f = g[:, :, None] * d
                forces += f.sum(axis=1)
                for c in range(6):
                    virials[:, c] += (-0.5 * d[:, :, a_idx[c]] * f[:, :, b_idx[c]]).sum(axis=1)
    return energies, forces, virials, scale


def nacl(repeat=2, a=5.64, jitter=0.15, seed=0):
    """A rocksalt crystal (charges +1 / -1) with its atoms moved a little (forces not zero)."""
    base = np.array([[0, 0, 0], [0, .5, .5], [.5, 0, .5], [.5, .5, 0]])
    frac, charges = [], []
    for i in range(repeat):
        for j in range(repeat):
            for k in range(repeat):
                for b in base:
                    frac.append((b + [i, j, k]) / repeat)
                    charges.append(1.0)
                    frac.append((b + [.5, 0, 0] + [i, j, k]) / repeat)
                    charges.append(-1.0)
    cell = np.eye(3) * a * repeat
    rng = np.random.default_rng(seed)
    positions = np.array(frac) @ cell + rng.normal(0, jitter, (len(frac), 3))
    atoms = Atoms(["Na", "Cl"] * (len(frac) // 2), positions=positions, cell=cell, pbc=True)
    atoms.set_initial_charges(charges)
    return atoms


def triclinic(n=40, seed=1):
    """Random atoms in a triclinic cell thinner than twice the cutoff, neutral random charges."""
    rng = np.random.default_rng(seed)
    cell = np.array([[7.0, 0, 0], [2.1, 6.4, 0], [-1.3, 1.7, 5.5]])
    atoms = Atoms(["X"] * n, scaled_positions=rng.random((n, 3)), cell=cell, pbc=True)
    q = rng.uniform(-1, 1, n)
    atoms.set_initial_charges(q - q.mean())
    return atoms


def molecule(n=12, seed=2):
    """Atoms without a cell, well apart (> 1 A), charges summing to 0."""
    rng = np.random.default_rng(seed)
    positions = []
    while len(positions) < n:
        x = rng.random(3) * 6.0
        if all(np.linalg.norm(x - p) > 1.0 for p in positions):
            positions.append(x)
    atoms = Atoms(["X"] * n, positions=positions)
    q = rng.uniform(-0.8, 0.8, n)
    atoms.set_initial_charges(q - q.mean())
    return atoms


SYSTEMS = {"nacl": (nacl, 0.2, 7.0), "triclinic": (triclinic, 0.25, 6.5),
           "molecule": (molecule, 0.3, 4.0)}


@pytest.mark.parametrize("method", CPU_METHODS)
@pytest.mark.parametrize("name", sorted(SYSTEMS))
def test_calculator_matches_float64_images(name, method):
    make, alpha, rc = SYSTEMS[name]
    atoms = make()
    atoms.calc = pyraycut.ase.CoulombDSF(alpha=alpha, rc=rc, method=method)
    periodic = atoms.pbc.any()
    energies, forces, virials, scale = reference(
        atoms.positions, atoms.get_initial_charges(), atoms.cell[:], atoms.pbc, alpha, rc, K_EV)
    tolerance = 2e-6 * scale.sum()
    assert abs(atoms.get_potential_energy() - energies.sum()) < tolerance
    assert atoms.calc.results["free_energy"] == atoms.get_potential_energy()
    got = atoms.get_potential_energies()
    np.testing.assert_allclose(got, energies, rtol=0, atol=2e-6 * scale.max())
    assert abs(got.sum() - atoms.get_potential_energy()) < 1e-9 * scale.sum()
    np.testing.assert_allclose(atoms.get_forces(), forces, rtol=0,
                               atol=1e-5 * np.abs(forces).max() + 1e-6)
    if periodic:
        volume = atoms.get_volume()
        voigt = [0, 1, 2, 5, 4, 3]
        want = -virials[:, voigt] / volume
        np.testing.assert_allclose(atoms.get_stresses(), want, rtol=0,
                                   atol=2e-5 * np.abs(want).max())
        np.testing.assert_allclose(atoms.get_stress(), want.sum(axis=0), rtol=0,
                                   atol=2e-5 * np.abs(want).sum())
    else:
        with pytest.raises(Exception):  # ASE: no stress without a cell
            atoms.get_stress()


@pytest.mark.parametrize("name", sorted(SYSTEMS))
def test_forces_are_minus_the_energy_gradient(name):
    """Finite differences of the calculator's own energy (float32 pass, so a step of 1e-2 A)
    and of the float64 reference (the convention itself)."""
    make, alpha, rc = SYSTEMS[name]
    atoms = make()
    atoms.calc = pyraycut.ase.CoulombDSF(alpha=alpha, rc=rc)
    forces = atoms.get_forces()
    ref_forces = reference(atoms.positions, atoms.get_initial_charges(), atoms.cell[:],
                           atoms.pbc, alpha, rc, K_EV)[1]
    rng = np.random.default_rng(3)
    h = 1e-2
    for atom in rng.choice(len(atoms), 3, replace=False):
        for axis in range(3):
            moved = [atoms.copy(), atoms.copy()]
            for sign, a in zip((1, -1), moved):
                a.positions[atom, axis] += sign * h
                a.calc = pyraycut.ase.CoulombDSF(alpha=alpha, rc=rc)
            slope = (moved[0].get_potential_energy() - moved[1].get_potential_energy()) / (2 * h)
            assert forces[atom, axis] == pytest.approx(-slope, abs=2e-3 + 1e-3 * abs(slope))
            # The float64 reference, with a step its precision affords.
            h64 = 1e-5
            e64 = []
            for sign in (1, -1):
                x = atoms.positions.copy()
                x[atom, axis] += sign * h64
                e64.append(reference(x, atoms.get_initial_charges(), atoms.cell[:], atoms.pbc,
                                     alpha, rc, K_EV)[0].sum())
            assert ref_forces[atom, axis] == pytest.approx(-(e64[0] - e64[1]) / (2 * h64),
                                                           rel=1e-6, abs=1e-7)


def test_engine_compute_with_query_points_and_refusals():
    rng = np.random.default_rng(4)
    sources = (rng.random((80, 3)) * 6).astype(np.float32)
    queries = (rng.random((9, 3)) * 6).astype(np.float32)
    q = rng.uniform(-1, 1, 80).astype(np.float32)
    qq = rng.uniform(-1, 1, 9).astype(np.float32)
    engine = pyraycut.Engine("cell-list")
    engine.build(sources, 2.5, queries=queries)
    out = engine.compute("coulomb_dsf", charge=q, query_charge=qq, alpha=0.4,
                         coulomb_constant=2.0)
    assert set(out) == {"energy", "force", "virial"}
    # The queries as extra atoms of an open system with their own charges: the query rows are
    # the pairs (query, source) only.
    alpha, rc, k = 0.4, 2.5, 2.0
    d = sources[None, :, :].astype(np.float64) - queries[:, None, :]
    r = np.linalg.norm(d, axis=2)
    keep = r < rc
    value, derivative = phi(np.where(keep, r, 1.0), alpha, rc)
    pair = np.where(keep, k * qq[:, None] * q[None, :] * value, 0)
    self_energy = -(erfc(alpha * rc) / (2 * rc) + alpha / np.sqrt(np.pi)) * k * qq.astype(float)**2
    np.testing.assert_allclose(out["energy"], 0.5 * pair.sum(1) + self_energy, rtol=0, atol=1e-5)
    g = np.where(keep, k * qq[:, None] * q[None, :] * derivative / np.where(keep, r, 1.0), 0)
    np.testing.assert_allclose(out["force"], (g[:, :, None] * d).sum(1), rtol=0, atol=1e-4)

    with pytest.raises(ValueError, match="query_charge is missing"):
        engine.compute("coulomb_dsf", charge=q)
    with pytest.raises(ValueError, match=r"charge must have shape \(80,\)"):
        engine.compute("coulomb_dsf", charge=q[:9], query_charge=qq)
    with pytest.raises(ValueError, match=r"charge\[2\] = nan: must be finite"):
        engine.compute("coulomb_dsf", charge=np.where(np.arange(80) == 2, np.nan, q)
                       .astype(np.float32), query_charge=qq)
    with pytest.raises(ValueError, match="parameter alpha = -1 is not accepted"):
        engine.compute("coulomb_dsf", charge=q, query_charge=qq, alpha=-1.0)
    with pytest.raises(ValueError, match="kernel lj reads no input 'charge'"):
        engine.compute("lj", charge=q)
    with pytest.raises(ValueError, match="unknown option 'charges'"):
        engine.compute("coulomb_dsf", charges=q)


def test_catalogue_is_the_library_s():
    cat = pyraycut.KERNEL_CATALOGUE["coulomb_dsf"]
    assert [o for o, _ in cat["outputs"]] == ["energy", "force", "virial"]
    assert [i["name"] for i in cat["inputs"]] == ["charge", "query_charge"]
    assert {p["name"]: p["default"] for p in cat["parameters"]} == {"alpha": 0.0,
                                                                    "coulomb_constant": 1.0}
    assert pyraycut.KERNELS["sph_force"] == ("force",)
    assert [i["name"] for i in pyraycut.KERNEL_CATALOGUE["sph_force"]["inputs"]] == [
        "velocity", "density", "pressure"]
    # The stubs name every built-in kernel, in the catalogue's order.
    import ast
    import pathlib
    import re
    stubs = ast.parse((pathlib.Path(pyraycut.__file__).parent / "_raycut.pyi").read_text())
    listing = next(ast.get_docstring(f) for f in ast.walk(stubs)
                   if isinstance(f, ast.FunctionDef) and f.name == "kernel_catalogue")
    assert re.findall(r'"(\w+)"', listing) == list(pyraycut.KERNEL_CATALOGUE)


def test_calculator_bad_parameters():
    with pytest.raises(ValueError, match="alpha must be a finite number >= 0"):
        pyraycut.ase.CoulombDSF(alpha=-0.1)
    with pytest.raises(ValueError, match="rc must be > 0"):
        pyraycut.ase.CoulombDSF(rc=0.0)
    with pytest.raises(ValueError, match="k must be a finite number"):
        pyraycut.ase.CoulombDSF(k=float("inf"))
    assert pyraycut.ase.CoulombDSF().parameters.k == pytest.approx(14.399645, rel=1e-6)
