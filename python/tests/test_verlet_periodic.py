"""pyraycut.VerletList in periodic boxes and batches (cell, pbc, batch; shifts S in its lists): over
trajectories of moving, unwrapped particles it rebuilds exactly when some particle has moved more
than skin / 2 since the last rebuild, and its list, filtered by the cutoff at the current
positions (r_ij = x[j] - x[i] + S @ cell), equals a fresh pyraycut.neighbor_list("ijS") at the
cutoff at every step. Host (NumPy) on every method with boxes; CUDA (PyTorch) skipped without it."""
import numpy as np
import pytest
from conftest import AVAILABLE, SYSTEM_METHODS, torch_cuda

import pyraycut

CUTOFF, SKIN = 2.5, 0.4
DENSITY = 0.8442  # the LJ liquid of the benchmarks (docs/benchmarks.md)
REL = 1e-5  # pairs this close (relative) to the cutoff may go either way in float32
TRICLINIC = np.array([[1.0, 0.0, 0.0], [0.3, 0.95, 0.0], [0.2, -0.15, 0.9]])


def liquid(n, cell, seed):
    """n uniform random points in the cell (fractional coordinates in [0, 1)), float32."""
    frac = np.random.default_rng(seed).random((n, 3))
    return (frac @ np.asarray(cell, np.float64)).astype(np.float32)


def cube(n):
    return (n / DENSITY) ** (1 / 3) * np.eye(3)


def csr_rows(offsets):
    offsets = np.asarray(offsets)
    return np.repeat(np.arange(len(offsets) - 1), np.diff(offsets))


def per_pair_cells(cells, offsets, i):
    """The cell of each pair's system (the system of its row i), (P, 3, 3)."""
    cells = np.asarray(cells, np.float64)
    if cells.ndim == 2:
        return np.broadcast_to(cells, (len(i), 3, 3))
    system = np.searchsorted(np.asarray(offsets), i, side="right") - 1
    return cells[system]


def vectors(x, i, j, S, cells, offsets=None):
    x = np.asarray(x, np.float64)
    c = per_pair_cells(cells, offsets, i)
    return x[j] - x[i] + np.einsum("pk,pkl->pl", np.asarray(S, np.float64), c)


def split(i, j, S, x, cells, offsets=None):
    """{(i, j, S)} of the pairs strictly within the cutoff (float64, at x), and those of the
    cutoff band, which float32 may put on either side."""
    i, j, S = np.asarray(i), np.asarray(j), np.asarray(S)
    d = np.linalg.norm(vectors(x, i, j, S, cells, offsets), axis=1)
    band = np.abs(d - CUTOFF) <= REL * CUTOFF
    key = lambda m: {(a, b) + tuple(s) for a, b, s in zip(i[m].tolist(), j[m].tolist(),
                                                          S[m].tolist())}
    return key((d < CUTOFF) & ~band), key(band)


def walk(x, steps, size, seed):
    """Positions of a random walk (never wrapped back into the box), float32."""
    rng = np.random.default_rng(seed)
    out, y = [], x.astype(np.float64)
    for _ in range(steps):
        y = y + rng.uniform(-1, 1, y.shape) * size
        out.append(y.astype(np.float32))
    return out


def follow(verlet, trajectory, fresh, cells, offsets=None, half=False):
    """Runs the list over the trajectory: rebuilds exactly past skin / 2, and at every step its
    pairs within the cutoff are those of a fresh list (`fresh(x)` -> (i, j, S))."""
    start = trajectory[0]
    assert verlet.update(start) is True
    rebuilds = 1
    for x in trajectory[1:]:
        far = np.sqrt(((x.astype(np.float64) - start) ** 2).sum(1)).max()
        rebuilt = verlet.update(x)
        if abs(far - SKIN / 2) > 1e-4 * SKIN:  # clear of the threshold's rounding
            assert rebuilt == (far > SKIN / 2)
        if rebuilt:
            rebuilds, start = rebuilds + 1, x
        assert verlet.rebuilds == rebuilds
        out = verlet.neighbours()
        offsets_, indices, S = out[0], out[1], out[-1]  # shifts come last
        assert S.dtype == np.int32 and S.shape == (len(indices), 3)
        i = csr_rows(offsets_)
        if half:
            assert np.all((i < indices) | ((i == indices) & (S[:, 0] * 9 + S[:, 1] * 3 + S[:, 2]
                                                              > 0))), "half orientation"
        got, got_band = split(i, indices, S, x, cells, offsets)
        want, want_band = split(*fresh(x), x, cells, offsets)
        band = got_band | want_band
        assert len(got) + len(got_band) <= len(indices)
        assert got - band == want - band
        assert len(want) > 0
    return rebuilds


@pytest.mark.parametrize("half", [False, True])
@pytest.mark.parametrize("shape", ["cube", "triclinic", "small-cube", "slab"])
def test_periodic_trajectory(system_method, shape, half):
    n = {"cube": 300, "triclinic": 300, "small-cube": 40, "slab": 200}[shape]
    cell = {"cube": cube(n), "small-cube": cube(n),  # small: 3.6 < 2 (cutoff + skin): images
            "triclinic": TRICLINIC * (n / DENSITY / np.linalg.det(TRICLINIC)) ** (1 / 3),
            "slab": np.diag([7.0, 7.0, 0.0])}[shape]
    pbc = (True, True, shape != "slab")
    if shape == "slab":
        cell_full = np.diag([7.0, 7.0, n / DENSITY / 49.0])
        x0 = liquid(n, cell_full, 1)
    else:
        x0 = liquid(n, cell, 1)
    trajectory = [x0] + walk(x0, 12, 0.04, seed=2)
    verlet = pyraycut.VerletList(CUTOFF, SKIN, method=system_method, half=half, shifts=True,
                               cell=cell, pbc=pbc)

    def fresh(x):
        return pyraycut.neighbor_list("ijS", x, CUTOFF, cell=cell, pbc=pbc, half=half,
                                    method=system_method)

    rebuilds = follow(verlet, trajectory, fresh, cell, half=half)
    assert 1 < rebuilds < len(trajectory)  # it kept the list for some steps, rebuilt for others
    # Particles left the box (unwrapped): the shifts refer to the positions as given.
    assert (trajectory[-1] < trajectory[0].min(0) - 0.01).any() or shape == "small-cube"


def test_batch_trajectory(system_method):
    sizes = [60, 0, 45, 80, 1]  # an empty system and a lone particle too
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    batch = np.repeat(np.arange(len(sizes)), sizes)
    cells = np.stack([cube(max(s, 40)) * (1 + 0.1 * k) for k, s in enumerate(sizes)])
    pbc = np.array([[True, True, True], [True, True, True], [True, False, True],
                    [True, True, True], [False, False, False]])
    x0 = np.concatenate([liquid(s, cells[k], 10 + k) for k, s in enumerate(sizes)])
    trajectory = [x0] + walk(x0, 10, 0.05, seed=3)
    verlet = pyraycut.VerletList(CUTOFF, SKIN, method=system_method, shifts=True, distances=True,
                               cell=cells, pbc=pbc, batch=batch)

    def fresh(x):
        return pyraycut.neighbor_list("ijS", x, CUTOFF, cell=cells, pbc=pbc, batch=batch,
                                    method=system_method)

    rebuilds = follow(verlet, trajectory, fresh, cells * pbc[:, :, None], offsets)
    assert 1 < rebuilds < len(trajectory)
    # Pairs never cross systems.
    o, idx, d, S = verlet.neighbours()
    system = np.searchsorted(offsets, np.arange(len(x0)), side="right") - 1
    assert np.array_equal(system[csr_rows(o)], system[idx])
    # The distances are those of the last rebuild's positions, at cutoff + skin.
    assert d.max() < CUTOFF + SKIN


def test_shifts_zero_without_a_cell_and_flags():
    x = liquid(200, cube(200), 4)
    verlet = pyraycut.VerletList(CUTOFF, SKIN, shifts=True, vectors=True)
    assert verlet.shifts and verlet.vectors and not verlet.distances and not verlet.half
    verlet.update(x)
    offsets, indices, D, S = verlet.neighbours()
    assert S.dtype == np.int32 and S.shape == (len(indices), 3) and not S.any()
    i = csr_rows(offsets)
    np.testing.assert_allclose(D, x[indices].astype(np.float64) - x[i], atol=1e-5)
    plain = pyraycut.VerletList(CUTOFF, SKIN, cell=cube(200), pbc=True)
    assert not plain.shifts
    plain.update(x)
    assert len(plain.neighbours()) == 2  # (offsets, indices): shifts only when asked


def test_vectors_and_distances_with_shifts(system_method):
    n = 12
    cell = cube(n)  # side 2.4 < cutoff + skin: pairs once per image, and self-images
    x = liquid(n, cell, 5)
    verlet = pyraycut.VerletList(CUTOFF, SKIN, method=system_method, distances=True, vectors=True,
                               shifts=True, cell=cell, pbc=True)
    verlet.update(x)
    offsets, indices, d, D, S = verlet.neighbours()
    i = csr_rows(offsets)
    r = vectors(x, i, indices, S, cell)
    np.testing.assert_allclose(D, r, atol=2e-5)
    np.testing.assert_allclose(d, np.linalg.norm(r, axis=1), atol=2e-5)
    assert (i == indices).any(), "self-images in a box smaller than the list's range"
    ri, rj, rS = pyraycut.neighbor_list("ijS", x, np.float32(CUTOFF) + np.float32(SKIN), cell=cell,
                                      method=system_method)
    assert ({(a, b) + tuple(s) for a, b, s in zip(i.tolist(), indices.tolist(), S.tolist())} ==
            {(a, b) + tuple(s) for a, b, s in zip(ri.tolist(), rj.tolist(), rS.tolist())})


def test_errors():
    cells = np.stack([cube(50)] * 2)
    with pytest.raises(ValueError, match="batch"):
        pyraycut.VerletList(CUTOFF, SKIN, cell=cells)  # two boxes, no batch
    with pytest.raises(ValueError, match="sorted"):
        pyraycut.VerletList(CUTOFF, SKIN, cell=cube(50), batch=[0, 1, 0])
    with pytest.raises(ValueError, match="singular|cell"):
        pyraycut.VerletList(CUTOFF, SKIN, cell=np.zeros((3, 3)), pbc=True).update(
            liquid(10, cube(10), 0))
    verlet = pyraycut.VerletList(CUTOFF, SKIN, cell=cube(50), batch=np.repeat([0, 1], 25))
    with pytest.raises(ValueError):
        verlet.update(liquid(40, cube(50), 0))  # the batch says 50 particles
    assert verlet.rebuilds == 0
    assert verlet.update(liquid(50, cube(50), 0)) and verlet.rebuilds == 1


@pytest.mark.parametrize("method", [m for m in AVAILABLE if m not in SYSTEM_METHODS])
def test_methods_without_boxes_say_so(method):
    verlet = pyraycut.VerletList(CUTOFF, SKIN, method=method, cell=cube(50))
    with pytest.raises(NotImplementedError):
        verlet.update(liquid(50, cube(50), 0))


# ---- CUDA ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("method", [m for m in SYSTEM_METHODS if m not in ("brute-force",)])
def test_torch_periodic_batch_trajectory(method):
    torch = torch_cuda()
    sizes = [120, 90, 1]
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    cells = np.stack([cube(120), cube(90) * 1.1, cube(40)])
    x0 = np.concatenate([liquid(s, cells[k], 20 + k) for k, s in enumerate(sizes)])
    batch = torch.repeat_interleave(torch.arange(3), torch.tensor(sizes)).cuda()
    verlet = pyraycut.VerletList(CUTOFF, SKIN, method=method, shifts=True, cell=cells, pbc=True,
                               batch=batch)
    trajectory = [x0] + walk(x0, 8, 0.05, seed=6)
    start = trajectory[0]
    assert verlet.update(torch.from_numpy(start).cuda())
    for x in trajectory[1:]:
        far = np.sqrt(((x.astype(np.float64) - start) ** 2).sum(1)).max()
        rebuilt = verlet.update(torch.from_numpy(x).cuda())
        if abs(far - SKIN / 2) > 1e-4 * SKIN:
            assert rebuilt == (far > SKIN / 2)
        if rebuilt:
            start = x
        o, idx, S = verlet.neighbours()
        for t in (o, idx, S):
            assert isinstance(t, torch.Tensor) and t.device.type == "cuda"
        assert S.dtype == torch.int32
        got, gb = split(csr_rows(o.cpu().numpy()), idx.cpu().numpy(), S.cpu().numpy(), x,
                        cells, offsets)
        fi, fj, fS = pyraycut.neighbor_list("ijS", torch.from_numpy(x).cuda(), CUTOFF, cell=cells,
                                          batch=batch, method=method)
        want, wb = split(fi.cpu().numpy(), fj.cpu().numpy(), fS.cpu().numpy(), x, cells, offsets)
        assert got - (gb | wb) == want - (gb | wb)
    assert 1 < verlet.rebuilds < len(trajectory)
