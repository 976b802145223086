"""Agreement with ASE: pyraycut.neighbor_list and the drop-in pyraycut.ase.neighbor_list against
ase.neighborlist.neighbor_list, for open and periodic Atoms (triclinic, cells smaller than twice
the cutoff, mixed pbc, unwrapped positions). The order of pairs may differ: compared sorted."""
import numpy as np
import pytest
from conftest import AVAILABLE, SYSTEM_METHODS

import pyraycut
import pyraycut.ase

ase = pytest.importorskip("ase", reason="ase is not installed (python/requirements.txt has it)")
from ase import Atoms  # noqa: E402
from ase.neighborlist import neighbor_list as ase_neighbor_list  # noqa: E402

REL = 1e-5  # pairs this close (relative) to the cutoff may go either way in float32

CASES = [  # (N, box edge, cutoff)
    (0, 1.0, 1.0),
    (1, 1.0, 1.0),
    (2, 1.0, 2.0),
    (50, 5.0, 2.5),
    (300, 10.0, 3.0),
    (1000, 20.0, 4.5),
    (1000, 60.0, 2.0),  # sparse: most atoms alone
]


def open_atoms(n, edge, seed):
    """Random non-periodic Atoms whose float64 positions are float32 values (what raycut reads)."""
    x32 = (np.random.default_rng(seed).random((n, 3)) * edge).astype(np.float32)
    atoms = Atoms(symbols=["Ar"] * n, positions=x32.astype(np.float64), pbc=False)
    return atoms, x32


def by_pair(i, j, *rest):
    """The arrays sorted by (i, j)."""
    order = np.lexsort((np.asarray(j), np.asarray(i)))
    return tuple(np.asarray(a)[order] for a in (i, j) + rest)


def edge_mask(d, cutoff):
    return np.abs(np.asarray(d, np.float64) - cutoff) <= REL * cutoff


def compare(ours, theirs, cutoff):
    """Same pairs once the pairs at the cutoff are set aside; same d and D on the shared ones."""
    oi, oj, od, oD = by_pair(*ours)
    ai, aj, ad, aD = by_pair(*theirs)
    keep_o, keep_a = ~edge_mask(od, cutoff), ~edge_mask(ad, cutoff)
    oi, oj, od, oD = oi[keep_o], oj[keep_o], od[keep_o], oD[keep_o]
    ai, aj, ad, aD = ai[keep_a], aj[keep_a], ad[keep_a], aD[keep_a]
    assert len(oi) == len(ai)
    np.testing.assert_array_equal(oi, ai)
    np.testing.assert_array_equal(oj, aj)
    np.testing.assert_allclose(od, ad, rtol=1e-6, atol=1e-6 * cutoff)
    np.testing.assert_allclose(oD, aD, rtol=1e-6, atol=1e-6 * cutoff)


@pytest.mark.parametrize("method", AVAILABLE)
@pytest.mark.parametrize("n,edge,cutoff", CASES)
def test_raycut_matches_ase(method, n, edge, cutoff):
    atoms, x32 = open_atoms(n, edge, seed=n)
    ours = pyraycut.neighbor_list("ijdD", x32, cutoff, method=method)
    theirs = ase_neighbor_list("ijdD", atoms, cutoff)
    compare(ours, theirs, cutoff)


@pytest.mark.parametrize("n,edge,cutoff", CASES)
def test_drop_in_matches_ase(n, edge, cutoff):
    atoms, _ = open_atoms(n, edge, seed=n + 1)
    ours = pyraycut.ase.neighbor_list("ijdDS", atoms, cutoff)
    theirs = ase_neighbor_list("ijdDS", atoms, cutoff)
    for a, b in zip(ours, theirs):
        assert a.dtype == b.dtype and a.shape[1:] == b.shape[1:], (a.dtype, b.dtype)
    assert np.all(np.diff(ours[0]) >= 0), "i is sorted, as ASE's"
    assert not np.any(ours[4]) and not np.any(theirs[4])
    compare(ours[:4], theirs[:4], cutoff)


def test_drop_in_self_interaction_and_letters():
    atoms, _ = open_atoms(200, 8.0, seed=3)
    ours = pyraycut.ase.neighbor_list("ijdD", atoms, 2.0, self_interaction=True)
    theirs = ase_neighbor_list("ijdD", atoms, 2.0, self_interaction=True)
    compare(ours, theirs, 2.0)
    i, j = ours[:2]
    assert np.count_nonzero(i == j) == len(atoms)
    assert np.all(np.diff(i) >= 0)
    # One letter: the array alone; letters in the order asked.
    d = pyraycut.ase.neighbor_list("d", atoms, 2.0)
    assert isinstance(d, np.ndarray) and d.dtype == np.float64
    j2, i2 = pyraycut.ase.neighbor_list("ji", atoms, 2.0)
    assert np.array_equal(i2, ours[0][ours[0] != ours[1]])


def test_drop_in_bad_input():
    atoms, _ = open_atoms(10, 5.0, seed=4)
    atoms.set_cell([5.0, 5.0, 5.0])
    assert len(pyraycut.ase.neighbor_list("i", atoms, 1.0)) == len(ase_neighbor_list("i", atoms,
                                                                                   1.0))
    with pytest.raises(ValueError):
        pyraycut.ase.neighbor_list("ijx", atoms, 1.0)
    with pytest.raises(ValueError):
        pyraycut.ase.neighbor_list("ij", atoms, [1.0] * (len(atoms) + 1))  # one per atom
    with pytest.raises(ValueError):
        pyraycut.ase.neighbor_list("ij", atoms, -1.0)
    with pytest.raises(TypeError):
        pyraycut.ase.neighbor_list("ij", np.zeros((3, 3)), 1.0)
    # A singular cell: the library's message.
    atoms.set_cell([[5.0, 0, 0], [10.0, 0, 0], [0, 0, 5.0]])
    atoms.pbc = True
    with pytest.raises(ValueError, match="linearly dependent"):
        pyraycut.ase.neighbor_list("ij", atoms, 1.0)


def test_one_number_cutoffs_take_the_direct_route_with_the_general_routes_answers():
    """pyraycut.ase calls the engine directly for one plain number as the cutoff (an Atoms'
    arrays need no parsing): the same pairs and the same refusals as pyraycut.neighbor_list."""
    from ase import Atoms
    from ase.build import bulk, molecule

    def general(atoms, cutoff):
        periodic = bool(atoms.pbc.any())
        return pyraycut.neighbor_list("ijS", atoms.positions, cutoff,
                                      cell=atoms.cell.array if periodic else None,
                                      pbc=atoms.pbc if periodic else None)

    slab = bulk("Cu", "fcc", a=3.6, cubic=True).repeat((2, 2, 1))
    slab.pbc = (True, True, False)
    cases = [bulk("Cu", "fcc", a=3.6), slab, molecule("CH3CH2OH"), Atoms()]
    for atoms, cutoff in zip(cases, (5.0, 4, 2.0, 3.0)):
        atoms.rattle(0.05, seed=2)
        for want, got in zip(general(atoms, cutoff),
                             pyraycut.ase.neighbor_list("ijS", atoms, cutoff)):
            assert np.array_equal(np.asarray(want), got), atoms
    bad = bulk("Cu", "fcc", a=3.6).repeat(2)
    for cutoff in (1e-50, 1e39, float("nan")):
        with pytest.raises(ValueError) as want:
            general(bad, cutoff)
        with pytest.raises(ValueError) as got:
            pyraycut.ase.neighbor_list("ij", bad, cutoff)
        assert str(got.value) == str(want.value)
    bad.positions[3, 1] = np.inf
    with pytest.raises(ValueError, match="3") as got:
        pyraycut.ase.neighbor_list("ij", bad, 3.0)
    with pytest.raises(ValueError) as want:
        general(bad, 3.0)
    assert str(got.value) == str(want.value)


# ---- periodic ----------------------------------------------------------------------------------


def random_cell(rng, edge, skew):
    return edge * (np.eye(3) + skew * rng.uniform(-1, 1, (3, 3)))


def periodic_atoms(n, cell, pbc, seed, unwrap=0, spread=1.0):
    """Random Atoms in the cell (fractional coordinates in [0, 1), [0, spread) on open axes),
    moved by up to `unwrap` whole cells along the periodic axes."""
    rng = np.random.default_rng(seed)
    frac = rng.random((n, 3))
    pbc = np.broadcast_to(np.asarray(pbc, bool), (3,))
    frac[:, ~pbc] *= spread
    frac += rng.integers(-unwrap, unwrap + 1, (n, 3)) * pbc
    return Atoms(symbols=["Ar"] * n, positions=frac @ np.asarray(cell), cell=cell, pbc=pbc)


def by_triple(i, j, d, D, S):
    order = np.lexsort((S[:, 2], S[:, 1], S[:, 0], j, i))
    return tuple(np.asarray(a)[order] for a in (i, j, d, D, S))


def compare_periodic(ours, theirs, cutoff, atol):
    """Same (i, j, S) once the pairs at the cutoff are set aside; same d and D on them."""
    ours = by_triple(*(np.asarray(a) for a in ours))
    theirs = by_triple(*(np.asarray(a) for a in theirs))
    keep_o, keep_a = ~edge_mask(ours[2], cutoff), ~edge_mask(theirs[2], cutoff)
    ours = [a[keep_o] for a in ours]
    theirs = [a[keep_a] for a in theirs]
    assert len(ours[0]) == len(theirs[0])
    for k in (0, 1, 4):
        np.testing.assert_array_equal(ours[k], theirs[k])
    np.testing.assert_allclose(ours[2], theirs[2], rtol=0, atol=atol)
    np.testing.assert_allclose(ours[3], theirs[3], rtol=0, atol=atol)


PERIODIC = {  # name: (N, edge, skew, pbc, cutoff, unwrap)
    "cubic": (60, 8.0, 0.0, True, 3.0, 0),
    "triclinic": (60, 8.0, 0.3, True, 3.0, 0),
    "small": (6, 3.0, 0.2, True, 4.5, 0),  # cutoff > edge: many images and self-images
    "tiny": (2, 1.5, 0.1, True, 3.2, 0),
    "slab": (40, 6.0, 0.2, (True, True, False), 2.5, 0),
    "wire": (30, 4.0, 0.0, (False, False, True), 3.0, 0),
    "mixed": (40, 5.0, 0.3, (True, False, True), 2.8, 0),
    "unwrapped": (50, 6.0, 0.25, True, 3.0, 4),
    "far": (30, 5.0, 0.2, (True, True, False), 2.5, 1000),
    "one-atom": (1, 2.5, 0.0, True, 6.0, 0),
}


@pytest.mark.parametrize("name", sorted(PERIODIC))
@pytest.mark.parametrize("seed", [0, 1])
def test_drop_in_matches_ase_periodic(name, seed):
    n, edge, skew, pbc, cutoff, unwrap = PERIODIC[name]
    rng = np.random.default_rng(100 + seed)
    atoms = periodic_atoms(n, random_cell(rng, edge, skew), pbc, seed, unwrap, spread=2.0)
    ours = pyraycut.ase.neighbor_list("ijdDS", atoms, cutoff)
    theirs = ase_neighbor_list("ijdDS", atoms, cutoff)
    for a, b in zip(ours, theirs):
        assert a.dtype == b.dtype and a.shape[1:] == b.shape[1:], (a.dtype, b.dtype)
    assert np.all(np.diff(ours[0]) >= 0), "i is sorted, as ASE's"
    # d and D come from the Atoms' float64 positions and the integer S: ASE's values.
    compare_periodic(ours, theirs, cutoff, atol=1e-9 * max(edge * (unwrap + 1), cutoff))
    if name in ("small", "tiny", "one-atom"):
        assert np.any(ours[0] == ours[1]), "self-images"


@pytest.mark.parametrize("cell,pbc", [
    ([[5.0, 0, 0], [1.0, 5.0, 0], [0, 0, 0]], (True, True, False)),  # a slab, c = 0
    ([[0, 0, 0], [0, 0, 0], [0, 0, 4.0]], (False, False, True)),  # a wire, a = b = 0
    ([[2.0, 0, 0], [0, 0, 0], [0, 0, 0]], (True, False, False)),  # thinner than the cutoff
])
def test_drop_in_zero_rows_on_open_axes(cell, pbc):
    rng = np.random.default_rng(5)
    x = rng.random((30, 3)) * 6 + rng.integers(-3, 4, (30, 3)) * np.diag(cell)
    atoms = Atoms(symbols=["Ar"] * 30, positions=x, cell=cell, pbc=pbc)
    ours = pyraycut.ase.neighbor_list("ijdDS", atoms, 3.0)
    theirs = ase_neighbor_list("ijdDS", atoms, 3.0)
    compare_periodic(ours, theirs, 3.0, atol=1e-9)


@pytest.mark.parametrize("method", SYSTEM_METHODS)
@pytest.mark.parametrize("name", ["triclinic", "small", "mixed", "unwrapped"])
def test_raycut_matches_ase_periodic(method, name):
    n, edge, skew, pbc, cutoff, unwrap = PERIODIC[name]
    rng = np.random.default_rng(7)
    atoms = periodic_atoms(n, random_cell(rng, edge, skew), pbc, 3, unwrap)
    x32 = atoms.positions.astype(np.float32)
    atoms.positions = x32.astype(np.float64)  # what raycut reads
    ours = pyraycut.neighbor_list("ijdDS", x32, cutoff, cell=atoms.cell[:], pbc=atoms.pbc,
                                method=method)
    theirs = ase_neighbor_list("ijdDS", atoms, cutoff)
    compare_periodic([np.asarray(a, np.float64) if k in (2, 3) else np.asarray(a, np.int64)
                      for k, a in enumerate(ours)], theirs, cutoff,
                     atol=2e-6 * edge * (unwrap + 1))


def test_drop_in_periodic_self_interaction_and_bulk():
    bulk = pytest.importorskip("ase.build").bulk
    for atoms, cutoff in ((bulk("Cu", "fcc", a=3.6), 5.0),  # one atom, primitive cell
                          (bulk("Si", "diamond", a=5.43, cubic=True), 4.0),
                          (bulk("Fe", "bcc", a=2.87).repeat((1, 2, 3)), 3.0)):
        for self_interaction in (False, True):
            ours = pyraycut.ase.neighbor_list("ijdDS", atoms, cutoff,
                                            self_interaction=self_interaction)
            theirs = ase_neighbor_list("ijdDS", atoms, cutoff, self_interaction=self_interaction)
            compare_periodic(ours, theirs, cutoff, atol=1e-9)
            own = (ours[0] == ours[1]) & ~ours[4].any(axis=1)
            assert np.count_nonzero(own) == (len(atoms) if self_interaction else 0)
    # Letters in the order asked, one letter alone, on periodic Atoms too.
    atoms = bulk("Cu", "fcc", a=3.6)
    S = pyraycut.ase.neighbor_list("S", atoms, 5.0)
    assert isinstance(S, np.ndarray) and S.dtype == np.int64 and S.shape[1] == 3
    S2, i2 = pyraycut.ase.neighbor_list("Si", atoms, 5.0)
    assert np.array_equal(S2, S) and len(i2) == len(S)


def test_drop_in_far_along_an_open_axis():
    # 1e6 away: float32 rounds to multiples of 0.0625, and a pair 1.0624 apart came out within
    # 1.01 (found by adversarial tests). The positions are centred in float64 first.
    for pbc in (False, (False, True, True)):
        atoms = Atoms("H3", positions=[[1e6 + 0.0313, 0, 0], [1e6 + 1.0937, 0, 0],
                                       [1e6 + 2.0, 0.5, 0]], cell=[10.0, 10.0, 10.0], pbc=pbc)
        for cutoff in (1.01, 1.07):
            got = pyraycut.ase.neighbor_list("ijS", atoms, cutoff)
            want = ase_neighbor_list("ijS", atoms, cutoff)
            assert sorted(zip(*[a.tolist() if a.ndim == 1 else map(tuple, a) for a in got])) == \
                sorted(zip(*[a.tolist() if a.ndim == 1 else map(tuple, a) for a in want]))
