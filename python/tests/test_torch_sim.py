"""pyraycut.torch_sim.neighbor_list, torch-sim's neighbour-list function, against a float64 NumPy
brute force that enumerates each system's images explicitly: batches mixing cubic, triclinic,
partially periodic and open systems, boxes smaller than the cutoff, every cell and pbc layout
torch-sim passes, self pairs, float32 and float64; then a torch-sim style pair energy built on
it."""
import itertools
import math

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="PyTorch is not installed")
from pyraycut.torch_sim import neighbor_list  # noqa: E402

TRICLINIC = np.array([[3.0, 0.0, 0.0], [0.9, 2.6, 0.0], [-0.7, 0.5, 2.8]])
# (cell, pbc) of each system; the open one has a zero cell, as torch-sim gives molecules.
SYSTEMS = [
    (np.diag([2.5, 2.5, 2.5]), [True, True, True]),
    (TRICLINIC, [True, False, True]),
    (np.zeros((3, 3)), [False, False, False]),
    (np.diag([1.2, 4.0, 3.0]), [True, True, True]),  # thinner than the cutoff along a
]
SIZES = [30, 25, 20, 12]
CUTOFF = 1.6
BAND = 1e-5  # pairs this close (relative) to the cutoff may go either way in float32


def system_positions(cell, pbc, n, seed):
    rng = np.random.default_rng(seed)
    if not any(pbc):
        return rng.uniform(-2.0, 2.0, (n, 3))
    return rng.uniform(0.0, 1.0, (n, 3)) @ cell


def oracle(x, cell, pbc, cutoff):
    """{(i, j, S)} with |x_j - x_i + S @ cell| < cutoff, (i, i, 0) left out, and the set of
    those within the band of the cutoff; x inside the cell on its periodic axes."""
    x, cell = np.asarray(x, np.float64), np.asarray(cell, np.float64)
    ranges = []
    for axis in range(3):
        if pbc[axis]:
            # |S_a| <= reach covers every image within the cutoff of a point inside the cell.
            spacing = 1.0 / np.linalg.norm(np.linalg.inv(cell)[:, axis])
            reach = math.ceil(cutoff / spacing) + 1
            ranges.append(range(-reach, reach + 1))
        else:
            ranges.append(range(1))
    inside, band = set(), set()
    for shift in itertools.product(*ranges):
        offset = np.array(shift, np.float64) @ cell
        r = np.linalg.norm(x[None, :, :] + offset - x[:, None, :], axis=-1)
        if not any(shift):
            np.fill_diagonal(r, np.inf)
        inside |= {(int(a), int(b), shift) for a, b in zip(*np.nonzero(r < cutoff))}
        band |= {(int(a), int(b), shift)
                 for a, b in zip(*np.nonzero(np.abs(r - cutoff) <= BAND * cutoff))}
    return inside, band


def batch(dtype=torch.float64, systems=SYSTEMS, sizes=SIZES):
    xs = [system_positions(c, p, n, seed) for seed, ((c, p), n) in enumerate(zip(systems, sizes))]
    positions = torch.tensor(np.concatenate(xs), dtype=dtype)
    cell = torch.tensor(np.stack([c for c, _ in systems]), dtype=dtype)
    pbc = torch.tensor([p for _, p in systems])
    system_idx = torch.repeat_interleave(torch.arange(len(sizes)), torch.tensor(sizes))
    return xs, positions, cell, pbc, system_idx


def expected(xs, systems=SYSTEMS, cutoff=CUTOFF):
    """The oracle's pairs of every system, in global indices, with the band."""
    inside, band, start = set(), set(), 0
    for x, (cell, pbc) in zip(xs, systems):
        a, b = oracle(x, cell, pbc, cutoff)
        inside |= {(i + start, j + start, s) for i, j, s in a}
        band |= {(i + start, j + start, s) for i, j, s in b}
        start += len(x)
    return inside, band


def triples(mapping, shifts):
    return [(int(i), int(j), tuple(int(round(c)) for c in s))
            for (i, j), s in zip(mapping.T.tolist(), shifts.tolist())]


def assert_pairs(got, inside, band):
    found = set(got)
    assert len(found) == len(got), "a pair is listed twice"
    assert not (inside - found) - band, f"missing {sorted((inside - found) - band)[:5]}"
    assert not (found - inside) - band, f"extra {sorted((found - inside) - band)[:5]}"


CUDA = pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda", marks=CUDA)])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_batch_equals_the_brute_force_of_each_system(dtype, device):
    xs, positions, cell, pbc, system_idx = (t.to(device) if isinstance(t, torch.Tensor) else t
                                            for t in batch(dtype))
    mapping, system_mapping, shifts = neighbor_list(positions, cell, pbc, torch.tensor(CUTOFF),
                                                    system_idx)
    assert mapping.dtype == torch.int64 and mapping.shape[0] == 2
    assert system_mapping.dtype == torch.int64 and shifts.dtype == dtype
    assert shifts.shape == (mapping.shape[1], 3)
    assert mapping.device == system_mapping.device == shifts.device == positions.device
    assert torch.equal(system_mapping, system_idx[mapping[0]])
    assert torch.equal(system_idx[mapping[0]], system_idx[mapping[1]]), "a pair crosses systems"
    assert bool((mapping[0][1:] >= mapping[0][:-1]).all()), "not sorted by the centre atom"
    got = triples(mapping, shifts)
    assert_pairs(got, *expected(xs))
    # Both ways: (i, j, S) and (j, i, -S).
    found = set(got)
    assert all((j, i, tuple(-c for c in s)) in found for i, j, s in got)
    # torch-sim's own reconstruction of the vectors (compute_cell_shifts: shifts @ cell).
    vectors = (positions[mapping[1]] - positions[mapping[0]]
               + torch.einsum("pa,pab->pb", shifts, cell[system_mapping]))
    assert bool((vectors.norm(dim=1) < CUTOFF * (1 + BAND)).all())


def test_cell_and_pbc_layouts_give_the_same_list():
    _, positions, cell, pbc, system_idx = batch()
    reference = neighbor_list(positions, cell, pbc, CUTOFF, system_idx)
    stacked = neighbor_list(positions, cell.reshape(-1, 3), pbc, CUTOFF, system_idx)
    for a, b in zip(reference, stacked):
        assert torch.equal(a, b)


def test_one_cell_and_pbc_for_every_system():
    systems = [(TRICLINIC, [True, True, False])] * 3
    sizes = [15, 0, 18]  # an empty system too
    xs, positions, _, _, system_idx = batch(systems=systems, sizes=sizes)
    cell = torch.tensor(TRICLINIC)
    for pbc in (torch.tensor([True, True, False]),
                torch.tensor([[True, True, False]] * 3)):
        mapping, system_mapping, shifts = neighbor_list(positions, cell, pbc, CUTOFF, system_idx)
        assert_pairs(triples(mapping, shifts), *expected(xs, systems))
        assert torch.equal(system_mapping, system_idx[mapping[0]])


def test_bool_pbc_and_open_systems():
    systems = [(np.zeros((3, 3)), [False] * 3)] * 2
    xs, positions, cell, _, system_idx = batch(systems=systems, sizes=[20, 22])
    mapping, _, shifts = neighbor_list(positions, cell, False, CUTOFF, system_idx)
    assert not shifts.any()
    assert_pairs(triples(mapping, shifts), *expected(xs, systems))


def test_self_interaction_appends_each_atom_once():
    xs, positions, cell, pbc, system_idx = batch()
    plain = neighbor_list(positions, cell, pbc, CUTOFF, system_idx)
    mapping, system_mapping, shifts = neighbor_list(positions, cell, pbc, CUTOFF, system_idx,
                                                    self_interaction=True)
    pairs = plain[0].shape[1]
    assert torch.equal(mapping[:, :pairs], plain[0])
    atoms = torch.arange(len(positions))
    assert torch.equal(mapping[:, pairs:], torch.stack((atoms, atoms)))
    assert torch.equal(system_mapping[pairs:], system_idx)
    assert not shifts[pairs:].any()


def test_a_pair_energy_built_on_it_matches_the_oracle():
    """A torch-sim PairPotentialModel's energy: half of the pair energies of a full list summed
    per system, with forces from autograd through the positions."""
    xs, positions, cell, pbc, system_idx = batch()
    positions.requires_grad_(True)
    mapping, system_mapping, shifts = neighbor_list(positions, cell, pbc, CUTOFF, system_idx)
    vectors = (positions[mapping[1]] - positions[mapping[0]]
               + torch.einsum("pa,pab->pb", shifts, cell[system_mapping]))
    r = vectors.norm(dim=1)
    pair = 4 * ((0.8 / r) ** 12 - (0.8 / r) ** 6)
    energy = torch.zeros(len(SIZES), dtype=torch.float64).index_add(0, system_mapping, 0.5 * pair)
    forces = -torch.autograd.grad(energy.sum(), positions)[0]
    energy = energy.detach()
    start = 0
    for s, (x, (c, p)) in enumerate(zip(xs, SYSTEMS)):
        inside, _ = oracle(x, c, p, CUTOFF)
        rij = [np.linalg.norm(x[j] - x[i] + np.array(S) @ c) for i, j, S in inside]
        reference = sum(0.5 * 4 * ((0.8 / d) ** 12 - (0.8 / d) ** 6) for d in rij)
        assert energy[s].item() == pytest.approx(reference, rel=1e-10, abs=1e-10)
        mine = forces[start:start + len(x)]
        # Newton's third law: the forces of a system sum to zero, up to their rounding.
        assert float(mine.sum(0).abs().max()) <= 1e-12 * float(mine.abs().sum())
        start += len(x)


@pytest.mark.parametrize("call, message", [
    (lambda x, c, p, b: neighbor_list(x, c, p, CUTOFF, b[:-1]), "system_idx must be a tensor"),
    (lambda x, c, p, b: neighbor_list(x, c[:, :2], p, CUTOFF, b), "cell must have shape"),
    (lambda x, c, p, b: neighbor_list(x, None, p, CUTOFF, b), "cell must be a tensor"),
])
def test_bad_arguments_are_refused_by_name(call, message):
    _, positions, cell, pbc, system_idx = batch()
    with pytest.raises(ValueError, match=message):
        call(positions, cell, pbc, system_idx)
