"""pyraycut.ase's ASE tools against ASE's own: per-atom and per-species cutoffs
(pyraycut.ase.neighbor_list, pyraycut.neighbor_list), NeighborList, and the LennardJones calculator
(energy, per-atom energies, forces, stress, per-atom stresses) on periodic, triclinic, slab and
molecular systems."""
import numpy as np
import pytest

import pyraycut
import pyraycut.ase

ase = pytest.importorskip("ase", reason="ase is not installed (python/requirements.txt has it)")
from ase import Atoms  # noqa: E402
from ase.build import bulk, molecule  # noqa: E402
from ase.calculators.lj import LennardJones as AseLennardJones  # noqa: E402
from ase.neighborlist import NeighborList as AseNeighborList  # noqa: E402
from ase.neighborlist import natural_cutoffs  # noqa: E402
from ase.neighborlist import neighbor_list as ase_neighbor_list  # noqa: E402


def triples(i, j, S):
    """The sorted (i, j, Sx, Sy, Sz) rows of a list."""
    rows = np.column_stack([np.asarray(i), np.asarray(j), np.asarray(S)]).astype(np.int64)
    return rows[np.lexsort(rows.T[::-1])] if len(rows) else rows.reshape(0, 5)


def random_atoms(n, cell, pbc, seed, species=(18,), unwrap=0):
    """Random Atoms in the cell (random species), moved by up to `unwrap` cells, far enough
    apart (> 0.8) that the Lennard-Jones energies stay of order one."""
    rng = np.random.default_rng(seed)
    cell = np.asarray(cell, np.float64)
    kept = []
    while len(kept) < n:
        p = rng.random(3) @ cell
        if all(np.linalg.norm(p - q) > 0.8 for q in kept):
            kept.append(p)
    positions = np.array(kept).reshape(-1, 3)
    pbc = np.broadcast_to(np.asarray(pbc, bool), (3,))
    positions += (rng.integers(-unwrap, unwrap + 1, (n, 3)) * pbc) @ cell
    return Atoms(numbers=rng.choice(species, n), positions=positions, cell=cell, pbc=pbc)


SYSTEMS = {
    "fcc-periodic": lambda: bulk("Ar", "fcc", a=5.26, cubic=True).repeat((3, 3, 3)),
    "triclinic": lambda: random_atoms(50, [[6.0, 0, 0], [1.5, 5.5, 0], [0.8, -1.0, 6.2]], True,
                                      seed=3, unwrap=2),
    "slab": lambda: random_atoms(40, [[6.0, 0, 0], [1.0, 6.0, 0], [0, 0, 20.0]],
                                 (True, True, False), seed=4),
    "molecule": lambda: molecule("C6H6"),
    "cluster": lambda: random_atoms(30, np.eye(3) * 5.0, False, seed=5),
    "small-cell": lambda: random_atoms(4, np.eye(3) * 3.2, True, seed=6),  # rc > the cell
}


# ---- per-atom and per-species cutoffs ----------------------------------------------------------


def cutoff_forms(atoms):
    z = sorted(set(atoms.numbers.tolist()))
    radii = {int(s): 0.6 + 0.2 * k for k, s in enumerate(z)}
    pairs = {(z[0], z[0]): 1.3}
    if len(z) > 1:
        pairs[(z[0], z[1])] = 1.9  # (z[1], z[1]) not listed: no such pairs, as in ASE
    return {"natural": natural_cutoffs(atoms, mult=1.1),
            "radii-list": [radii[int(s)] for s in atoms.numbers],
            "species-radii": radii, "pairs": pairs}


MIXED = {
    "molecule": lambda: molecule("CH3CH2OH"),
    "periodic": lambda: random_atoms(40, [[5.0, 0, 0], [1.0, 5.0, 0], [0.5, 0.5, 5.5]], True,
                                     seed=7, species=(1, 6, 8), unwrap=1),
    "slab": lambda: random_atoms(30, [[5.0, 0, 0], [0, 5.0, 0], [0, 0, 15.0]], (True, True, False),
                                 seed=8, species=(6, 8)),
}


@pytest.mark.parametrize("system", sorted(MIXED))
@pytest.mark.parametrize("form", ["natural", "radii-list", "species-radii", "pairs"])
@pytest.mark.parametrize("self_interaction", [False, True])
def test_varying_cutoffs_match_ase(system, form, self_interaction):
    atoms = MIXED[system]()
    cutoff = cutoff_forms(atoms)[form]
    ours = pyraycut.ase.neighbor_list("ijdS", atoms, cutoff, self_interaction=self_interaction)
    theirs = ase_neighbor_list("ijdS", atoms, cutoff if form != "species-radii" else
                               [cutoff[int(z)] for z in atoms.numbers],
                               self_interaction=self_interaction)
    assert len(ours[0]) > len(atoms) // 2  # not empty
    assert np.all(np.diff(ours[0]) >= 0), "sorted by i, as ASE"
    np.testing.assert_array_equal(triples(ours[0], ours[1], ours[3]),
                                  triples(theirs[0], theirs[1], theirs[3]))
    assert np.sort(ours[2]) == pytest.approx(np.sort(theirs[2]), abs=1e-12)


@pytest.mark.parametrize("form", ["radii-list", "species-radii", "pairs"])
def test_raycut_neighbor_list_takes_varying_cutoffs(form):
    atoms = MIXED["periodic"]()
    cutoff = cutoff_forms(atoms)[form]
    for half in (False, True):
        i, j, d, S = pyraycut.neighbor_list("ijdS", atoms.positions, cutoff, cell=atoms.cell[:],
                                          pbc=True, numbers=atoms.numbers, half=half)
        assert d.dtype == np.float64 and i.dtype == np.int64  # float64 positions: float64 d
        full = pyraycut.neighbor_list("ijdS", atoms.positions, 4.0, cell=atoms.cell[:], pbc=True,
                                    half=half)
        pair_cutoff = pyraycut._cutoffs.PairCutoffs(cutoff, len(atoms), atoms.numbers)
        keep = full[2] < pair_cutoff.of(full[0], full[1])
        np.testing.assert_array_equal(triples(i, j, S),
                                      triples(full[0][keep], full[1][keep], full[3][keep]))
        assert 0 < len(i) < len(full[0])


def test_varying_cutoffs_bad_input():
    atoms = MIXED["molecule"]()
    x = atoms.positions
    with pytest.raises(ValueError, match="per-atom cutoffs for"):
        pyraycut.neighbor_list("ij", x, [1.0] * (len(x) - 1))
    with pytest.raises(ValueError, match="needs the atomic numbers"):
        pyraycut.neighbor_list("ij", x, {(1, 6): 1.2})
    with pytest.raises(ValueError, match="no radius for species"):
        pyraycut.ase.neighbor_list("ij", atoms, {6: 0.8})
    with pytest.raises(ValueError, match="not both"):
        pyraycut.ase.neighbor_list("ij", atoms, {6: 0.8, (1, 1): 1.0})
    with pytest.raises(ValueError, match="finite and >= 0"):
        pyraycut.ase.neighbor_list("ij", atoms, [-1.0] * len(atoms))
    with pytest.raises(ValueError, match="unknown chemical symbol"):
        pyraycut.ase.neighbor_list("ij", atoms, {("C", "Xx"): 1.0})
    # Symbols as ASE takes them.
    by_symbol = pyraycut.ase.neighbor_list("ij", atoms, {("C", "H"): 1.2})
    by_number = pyraycut.ase.neighbor_list("ij", atoms, {(6, 1): 1.2})
    np.testing.assert_array_equal(by_symbol[0], by_number[0])
    np.testing.assert_array_equal(by_symbol[1], by_number[1])


# ---- NeighborList ------------------------------------------------------------------------------


def neighbour_rows(nl, n):
    rows = []
    for a in range(n):
        idx, off = nl.get_neighbors(a)
        assert idx.shape == (len(off),) and off.shape == (len(idx), 3)
        rows.extend((a, int(b), *map(int, s)) for b, s in zip(idx, off))
    return rows


def unordered(rows):
    """Each pair as an unordered one: (a, b, S) and (b, a, -S) are the same pair."""
    out = set()
    for a, b, *s in rows:
        out.add(min((a, b, *s), (b, a, *(-v for v in s))))
    return out


@pytest.mark.parametrize("system", ["molecule", "periodic", "slab"])
@pytest.mark.parametrize("bothways", [False, True])
@pytest.mark.parametrize("self_interaction", [False, True])
def test_neighborlist_drop_in(system, bothways, self_interaction):
    atoms = MIXED[system]()
    cutoffs = natural_cutoffs(atoms)
    kw = dict(skin=0.2, self_interaction=self_interaction, bothways=bothways)
    ours, theirs = pyraycut.ase.NeighborList(cutoffs, **kw), AseNeighborList(cutoffs, **kw)
    assert ours.update(atoms) and theirs.update(atoms)
    mine, ref = neighbour_rows(ours, len(atoms)), neighbour_rows(theirs, len(atoms))
    assert len(mine) == len(ref) > 0
    if bothways:
        assert sorted(mine) == sorted(ref)
    else:
        assert unordered(mine) == unordered(ref)
    # Positions of the neighbours, as ASE's documentation computes them.
    idx, off = ours.get_neighbors(0)
    pos = atoms.positions[idx] + off @ atoms.cell
    assert np.all(np.linalg.norm(pos - atoms.positions[0], axis=1) <
                  cutoffs[0] + np.asarray(cutoffs)[idx] + 2 * 0.2)
    # Small moves (< skin) keep the list; a larger one rebuilds it.
    moved = atoms.copy()
    moved.positions[3] += [0.15, 0, 0]
    assert not ours.update(moved) and not theirs.update(moved)
    moved.positions[3] += [0.15, 0, 0]
    assert ours.update(moved) and theirs.update(moved)
    assert ours.nupdates == theirs.nupdates == 2
    mine, ref = neighbour_rows(ours, len(atoms)), neighbour_rows(theirs, len(atoms))
    assert (sorted(mine) == sorted(ref)) if bothways else (unordered(mine) == unordered(ref))
    matrix = ours.get_connectivity_matrix(sparse=False)
    ref = theirs.get_connectivity_matrix(sparse=False)
    if bothways:
        np.testing.assert_array_equal(matrix, ref)
    else:  # the same pairs, maybe in the other row
        np.testing.assert_array_equal(matrix + matrix.T, ref + ref.T)
    assert matrix.sum() == len(mine)
    np.testing.assert_array_equal(ours.get_connectivity_matrix().toarray(), matrix)


def test_neighborlist_sorted_and_errors():
    atoms = MIXED["periodic"]()
    cutoffs = natural_cutoffs(atoms)
    ours = pyraycut.ase.NeighborList(cutoffs, sorted=True, bothways=True, self_interaction=False)
    theirs = AseNeighborList(cutoffs, sorted=True, bothways=True, self_interaction=False)
    with pytest.raises(RuntimeError, match="update"):
        ours.get_neighbors(0)
    ours.update(atoms)
    theirs.update(atoms)
    for a in range(len(atoms)):  # the same order as ASE's sorted rows
        for x, y in zip(ours.get_neighbors(a), theirs.get_neighbors(a)):
            np.testing.assert_array_equal(x, y)
    with pytest.raises(ValueError, match="Wrong number of cutoff radii"):
        pyraycut.ase.NeighborList(cutoffs[:-1]).update(atoms)
    with pytest.raises(ValueError, match="skin"):
        pyraycut.ase.NeighborList(cutoffs, skin=-1.0)


# ---- LennardJones ------------------------------------------------------------------------------

# Tolerances: the fused pass runs in float32. Each per-atom value is a float32 sum over ~50-100
# neighbours of terms up to ~24 eps / sigma (forces near the minimum): scale = 24 eps x 12.
# float32 rounding (2^-24 ~ 6e-8 relative per operation, growing with the number of terms) and
# float32 positions (rounded to ~6e-8 of the system's extent) give errors of a few 1e-7 of that
# scale: 2e-6 x scale (measured: at most 9e-5 on forces of fcc argon, 3e-7 of the scale: a
# margin of ~6). The smooth path runs in float64, as ASE's: 1e-10.
PARAMS = [dict(sigma=1.0, epsilon=1.0, rc=2.5), dict(sigma=1.1, epsilon=0.7),
          dict(sigma=1.0, epsilon=1.0, rc=2.5, smooth=True),
          dict(sigma=1.05, epsilon=1.3, rc=3.0, ro=2.0, smooth=True)]


def scaled(system, sigma):
    """The system with its nearest distances near the LJ minimum of this sigma."""
    atoms = SYSTEMS[system]()
    if len(atoms) > 1:
        from ase.geometry import get_distances

        _, d = get_distances(atoms.positions, cell=atoms.cell, pbc=atoms.pbc)
        d = d[d > 0].min()
        f = 1.12 * sigma / d
        atoms.set_cell(atoms.cell[:] * f, scale_atoms=True) if atoms.cell.rank == 3 else \
            atoms.set_positions(atoms.positions * f)
    return atoms


@pytest.mark.parametrize("system", sorted(SYSTEMS))
@pytest.mark.parametrize("k", range(len(PARAMS)))
def test_lennard_jones_matches_ase(system, k):
    params = PARAMS[k]
    atoms = scaled(system, params["sigma"])
    atoms.rattle(0.02, seed=k)
    ours_atoms = atoms.copy()
    atoms.calc = AseLennardJones(**params)
    ours_atoms.calc = pyraycut.ase.LennardJones(**params)
    rel = 1e-10 if params.get("smooth") else 2e-6
    scale = 24 * params["epsilon"] * 12  # ~ the sum of term magnitudes per atom (12 neighbours)
    e, e_ours = atoms.get_potential_energy(), ours_atoms.get_potential_energy()
    assert e_ours == pytest.approx(e, abs=rel * scale * len(atoms))
    assert ours_atoms.get_potential_energy(force_consistent=True) == pytest.approx(e_ours)
    energies = ours_atoms.get_potential_energies()
    np.testing.assert_allclose(energies, atoms.get_potential_energies(), atol=rel * scale)
    assert energies.sum() == pytest.approx(e_ours, rel=1e-12, abs=1e-12)  # each pair half-half
    np.testing.assert_allclose(ours_atoms.get_forces(), atoms.get_forces(), atol=rel * scale)
    if atoms.cell.rank == 3:
        v = atoms.get_volume()
        stress = ours_atoms.get_stress()
        np.testing.assert_allclose(stress, atoms.get_stress(), atol=rel * scale * len(atoms) / v)
        stresses = ours_atoms.get_stresses()
        np.testing.assert_allclose(stresses, atoms.get_stresses(), atol=rel * scale / v)
        np.testing.assert_allclose(stresses.sum(0), stress, rtol=1e-12, atol=1e-14)
    else:
        with pytest.raises(Exception):
            ours_atoms.get_stress()
    assert abs(e) > 0.02 * len(atoms)  # a configuration with real energy, not a trivial 0


def test_lennard_jones_defaults_and_bad_parameters():
    calc = pyraycut.ase.LennardJones(sigma=2.0)
    assert calc.parameters.rc == 6.0 and calc.parameters.ro == pytest.approx(0.66 * 6.0)
    with pytest.raises(ValueError, match="rc"):
        pyraycut.ase.LennardJones(rc=0.0)
    with pytest.raises(ValueError, match="ro"):
        pyraycut.ase.LennardJones(rc=2.0, ro=2.5, smooth=True)
    with pytest.raises(ValueError, match="sigma"):
        pyraycut.ase.LennardJones(sigma=float("nan"))


# ---- per-atom sums of the fused pass (lj_forces) ------------------------------------------------


def test_lj_forces_per_atom_sums_against_float64_brute_force():
    """Per-atom energies and virials of lj_forces sum to the system's (each pair half and half),
    with and without the shift at the cutoff, against an O(N^2) float64 sum."""
    rng = np.random.default_rng(11)
    rc, eps, sigma = 2.0, 0.8, 0.9
    grid = np.stack(np.meshgrid(*[np.arange(7.0)] * 3, indexing="ij"), -1).reshape(-1, 3)
    x = (grid + rng.uniform(-0.1, 0.1, grid.shape)).astype(np.float32)  # a jittered lattice
    n = len(x)
    x64 = x.astype(np.float64)
    D = x64[None, :, :] - x64[:, None, :]  # D[i, j] = x_j - x_i
    r2 = (D ** 2).sum(-1)
    inside = (r2 < rc * rc) & ~np.eye(n, dtype=bool)
    upper = np.triu(inside, 1)
    u = np.where(inside, (sigma ** 2 / np.where(inside, r2, 1.0)) ** 3, 0.0)
    uc = (sigma ** 2 / rc ** 2) ** 3
    energy = (4 * eps * u * (u - 1))[upper].sum()
    shift = 4 * eps * uc * (uc - 1) * upper.sum()
    g = np.where(inside, -24 * eps * u * (2 * u - 1) / np.where(inside, r2, 1.0), 0.0)
    f = g[:, :, None] * D  # force on i from j
    pa, pb = [0, 1, 2, 0, 0, 1], [0, 1, 2, 1, 2, 2]
    virial = np.array([(-D[:, :, pa[k]] * f[:, :, pb[k]])[upper].sum() for k in range(6)])
    magnitude = (4 * eps * u * (u + 1))[upper].sum()
    engine = pyraycut.Engine("cell-list")
    engine.build(x, rc)
    for shifted in (False, True):
        out = engine.compute("lj_forces", lj_epsilon=eps, lj_sigma=sigma, lj_shift=shifted)
        want = energy - (shift if shifted else 0.0)
        assert out["energy"].astype(np.float64).sum() == pytest.approx(want, abs=1e-5 * magnitude)
        got_virial = out["virial"].astype(np.float64).sum(0)
        np.testing.assert_allclose(got_virial, virial, atol=1e-5 * np.abs(virial).sum())
    # lj (the paper's kernel) counts each pair fully on both atoms: twice the system's.
    lj = engine.compute("lj", lj_epsilon=eps, lj_sigma=sigma)["energy"].astype(np.float64).sum()
    assert lj == pytest.approx(2 * energy, abs=2e-5 * magnitude)
    with pytest.raises(ValueError, match="lj_shift"):
        engine.compute("lj", lj_shift=True)


def test_pair_cutoffs_of_absent_species_do_not_widen_the_search():
    """A cutoff for species not in the system (U-U at 50 here) leaves the search at the largest
    cutoff among the species present: the same pairs, found at 1.3, not at 50."""
    atoms = MIXED["molecule"]()
    cutoffs = pyraycut._cutoffs.PairCutoffs({(6, 6): 1.6, (1, 6): 1.2, (92, 92): 50.0}, len(atoms),
                                          atoms.numbers)
    assert cutoffs.search == 1.6
    ours = pyraycut.ase.neighbor_list("ij", atoms, {(6, 6): 1.6, (1, 6): 1.2, (92, 92): 50.0})
    theirs = ase_neighbor_list("ij", atoms, {(6, 6): 1.6, (1, 6): 1.2, (92, 92): 50.0})
    assert sorted(zip(*ours)) == sorted(zip(*(a.tolist() for a in theirs))) != []


def test_varying_cutoffs_in_the_pass_take_every_framework_and_huge_boxes():
    """Per-pair cutoffs run in the list pass: PyTorch tensors are taken as NumPy arrays are, and a
    box 10^4 cutoffs wide with pairs placed within 1e-6 of their own cutoff gives ASE's pairs
    (decided in double from the float64 positions)."""
    rng = np.random.default_rng(11)
    length = 2.0e4
    base = rng.random((40, 3)) * length
    radii_of = {1: 0.35, 6: 0.8, 8: 0.7}
    z = rng.choice([1, 6, 8], 40)
    partner_z = rng.choice([1, 6, 8], 40)
    own = np.array([radii_of[a] + radii_of[b] for a, b in zip(z, partner_z)])
    direction = rng.normal(size=(40, 3))
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    offset = rng.choice([-1, 1], 40) * 10.0 ** rng.uniform(-7, -5, 40)
    partner = base + (own * (1 + offset))[:, None] * direction
    atoms = Atoms(numbers=np.concatenate([z, partner_z]),
                  positions=np.concatenate([base, partner]), cell=np.eye(3) * length, pbc=True)
    cutoff = {k: v for k, v in radii_of.items()}
    ours = pyraycut.ase.neighbor_list("ijS", atoms, cutoff)
    theirs = ase_neighbor_list("ijS", atoms, [radii_of[int(a)] for a in atoms.numbers])
    np.testing.assert_array_equal(triples(*ours), triples(*theirs))
    assert 0 < len(ours[0]) < 80  # about half the partners are in

    torch = pytest.importorskip("torch")
    x = torch.tensor(atoms.positions)
    i, j, S = pyraycut.neighbor_list("ijS", x, cutoff, cell=atoms.cell[:], pbc=True,
                                     numbers=atoms.numbers)
    assert isinstance(i, torch.Tensor)
    np.testing.assert_array_equal(triples(i.numpy(), j.numpy(), S.numpy()), triples(*theirs))
    with pytest.raises(ValueError, match="not with max_pairs"):
        pyraycut.neighbor_list("ij", x, cutoff, numbers=atoms.numbers, max_pairs=100)

    @torch.compile(fullgraph=True)
    def compiled(y):
        return pyraycut.neighbor_list("ij", y, cutoff, numbers=atoms.numbers)

    with pytest.raises(Exception, match="nor inside torch.compile"):
        compiled(x)
