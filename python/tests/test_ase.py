"""Agreement with ASE on open systems: raycut.neighbor_list and the drop-in
raycut.ase.neighbor_list against ase.neighborlist.neighbor_list, for non-periodic Atoms."""
import numpy as np
import pytest
from conftest import AVAILABLE

import raycut
import raycut.ase

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
    ours = raycut.neighbor_list("ijdD", x32, cutoff, method=method)
    theirs = ase_neighbor_list("ijdD", atoms, cutoff)
    compare(ours, theirs, cutoff)


@pytest.mark.parametrize("n,edge,cutoff", CASES)
def test_drop_in_matches_ase(n, edge, cutoff):
    atoms, _ = open_atoms(n, edge, seed=n + 1)
    ours = raycut.ase.neighbor_list("ijdDS", atoms, cutoff)
    theirs = ase_neighbor_list("ijdDS", atoms, cutoff)
    for a, b in zip(ours, theirs):
        assert a.dtype == b.dtype and a.shape[1:] == b.shape[1:], (a.dtype, b.dtype)
    assert np.all(np.diff(ours[0]) >= 0), "i is sorted, as ASE's"
    assert not np.any(ours[4]) and not np.any(theirs[4])
    compare(ours[:4], theirs[:4], cutoff)


def test_drop_in_self_interaction_and_letters():
    atoms, _ = open_atoms(200, 8.0, seed=3)
    ours = raycut.ase.neighbor_list("ijdD", atoms, 2.0, self_interaction=True)
    theirs = ase_neighbor_list("ijdD", atoms, 2.0, self_interaction=True)
    compare(ours, theirs, 2.0)
    i, j = ours[:2]
    assert np.count_nonzero(i == j) == len(atoms)
    assert np.all(np.diff(i) >= 0)
    # One letter: the array alone; letters in the order asked.
    d = raycut.ase.neighbor_list("d", atoms, 2.0)
    assert isinstance(d, np.ndarray) and d.dtype == np.float64
    j2, i2 = raycut.ase.neighbor_list("ji", atoms, 2.0)
    assert np.array_equal(i2, ours[0][ours[0] != ours[1]])


def test_drop_in_refuses_periodic_and_bad_input():
    atoms, _ = open_atoms(10, 5.0, seed=4)
    atoms.set_cell([5.0, 5.0, 5.0])
    raycut.ase.neighbor_list("ij", atoms, 1.0)  # a cell without pbc is an open system
    for pbc in (True, [True, False, False], [False, False, True]):
        atoms.pbc = pbc
        with pytest.raises(ValueError, match="periodic boxes are not supported yet"):
            raycut.ase.neighbor_list("ij", atoms, 1.0)
    atoms.pbc = False
    with pytest.raises(ValueError):
        raycut.ase.neighbor_list("ijx", atoms, 1.0)
    with pytest.raises(ValueError):
        raycut.ase.neighbor_list("ij", atoms, [1.0] * len(atoms))  # per-atom cutoffs
    with pytest.raises(ValueError):
        raycut.ase.neighbor_list("ij", atoms, -1.0)
    with pytest.raises(TypeError):
        raycut.ase.neighbor_list("ij", np.zeros((3, 3)), 1.0)
