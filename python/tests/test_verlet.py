"""pyraycut.VerletList: the list at cutoff + skin, kept while no particle has moved more than skin / 2
(and still holding every pair within the cutoff then), rebuilt beyond that; arrays that outlive
rebuilds. Host (NumPy) for every method here; CUDA (PyTorch, CuPy) skipped without them."""
import numpy as np
import pytest
from conftest import CUTOFF, DEVICE_METHODS, brute_force, cupy_cuda, pair_set, torch_cuda, uniform

import pyraycut

SKIN = 0.03


def csr_pairs(offsets, indices):
    offsets = np.asarray(offsets)
    rows = np.repeat(np.arange(len(offsets) - 1), np.diff(offsets))
    return rows, np.asarray(indices)


def small_move(x, skin, seed=3):
    """Every particle moved by less than skin / 2 (and most of them by something)."""
    step = np.random.default_rng(seed).uniform(-1, 1, x.shape) * (0.45 * skin / np.sqrt(3))
    return (x + step).astype(np.float32)


def large_move(x, skin, seed=4):
    """Every particle moved by more than skin / 2."""
    step = np.random.default_rng(seed).choice([-1.0, 1.0], x.shape) * skin
    return (x + step).astype(np.float32)


def assert_holds_cutoff_pairs(offsets, indices, x, cutoff, half=False):
    """Every pair within `cutoff` of `x` is in the list (the list may hold more)."""
    listed = pair_set(*csr_pairs(offsets, indices))
    assert len(listed) == len(np.asarray(indices)), "a pair appears twice"
    inside, edge = brute_force(x, cutoff)
    if half:
        inside = {(a, b) for a, b in inside if a < b}
    assert not (inside - edge) - listed


def test_small_move_keeps_the_list(method):
    x = uniform(500)
    verlet = pyraycut.VerletList(CUTOFF, SKIN, method=method)
    assert verlet.rebuilds == 0 and verlet.cutoff == pytest.approx(CUTOFF)
    assert verlet.skin == pytest.approx(SKIN) and verlet.method == method
    assert verlet.update(x) is True
    assert verlet.rebuilds == 1 and verlet.size == len(x)
    offsets, indices = verlet.neighbours()
    assert offsets.dtype == np.int64 and indices.dtype == np.int32
    assert offsets.shape == (len(x) + 1,) and indices.shape == (offsets[-1],)
    before = pair_set(*csr_pairs(offsets, indices))

    moved = small_move(x, SKIN)
    assert np.abs(moved - x).max() > 0.1 * SKIN  # they did move
    assert verlet.update(moved) is False
    assert verlet.rebuilds == 1
    offsets2, indices2 = verlet.neighbours()
    assert pair_set(*csr_pairs(offsets2, indices2)) == before
    assert_holds_cutoff_pairs(offsets2, indices2, moved, CUTOFF)
    # The list is at cutoff + skin: it holds pairs beyond the cutoff too.
    inside, _ = brute_force(x, CUTOFF)
    assert len(before) > len(inside)


def test_large_move_rebuilds_at_cutoff_plus_skin(method):
    x = uniform(500)
    verlet = pyraycut.VerletList(CUTOFF, SKIN, method=method, distances=True, vectors=True)
    assert verlet.update(x)
    moved = large_move(x, SKIN)
    assert verlet.update(moved) is True
    assert verlet.rebuilds == 2
    offsets, indices, d, v = verlet.neighbours()
    assert d.dtype == np.float32 and d.shape == indices.shape
    assert v.dtype == np.float32 and v.shape == (len(indices), 3)
    i, j = csr_pairs(offsets, indices)
    ri, rj, rd, rv = pyraycut.neighbor_list("ijdD", moved, np.float32(CUTOFF) + np.float32(SKIN),
                                          method=method)
    order, ref = np.lexsort((j, i)), np.lexsort((rj, ri))
    np.testing.assert_array_equal(i[order], ri[ref])
    np.testing.assert_array_equal(j[order], rj[ref])
    np.testing.assert_allclose(d[order], rd[ref], rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(v[order], rv[ref], rtol=1e-6, atol=1e-7)
    assert_holds_cutoff_pairs(offsets, indices, moved, CUTOFF)


def test_half_list(method):
    x = uniform(400)
    verlet = pyraycut.VerletList(CUTOFF, SKIN, method=method, half=True)
    verlet.update(x)
    verlet.update(small_move(x, SKIN))
    offsets, indices = verlet.neighbours()
    i, j = csr_pairs(offsets, indices)
    assert (i < j).all()
    ri, rj = pyraycut.neighbor_list("ij", x, np.float32(CUTOFF) + np.float32(SKIN), half=True,
                                  method=method)
    assert pair_set(i, j) == pair_set(ri, rj)
    assert_holds_cutoff_pairs(offsets, indices, small_move(x, SKIN), CUTOFF, half=True)


def test_rebuild_counter_over_a_trajectory():
    rng = np.random.default_rng(5)
    x = uniform(300)
    verlet = pyraycut.VerletList(CUTOFF, SKIN)
    assert verlet.update(x) and verlet.rebuilds == 1
    start, rebuilt = x.copy(), 1
    for _ in range(20):
        x = (x + rng.uniform(-1, 1, x.shape) * 0.004).astype(np.float32)
        far = np.sqrt(((x.astype(np.float64) - start) ** 2).sum(1)).max()
        got = verlet.update(x)
        if abs(far - SKIN / 2) > 1e-4 * SKIN:  # clear of the threshold's rounding
            assert got == (far > SKIN / 2)
        if got:
            rebuilt, start = rebuilt + 1, x.copy()
        assert verlet.rebuilds == rebuilt
        offsets, indices = verlet.neighbours()
        assert_holds_cutoff_pairs(offsets, indices, x, CUTOFF)
    assert verlet.rebuilds > 2  # the trajectory did cross the skin a few times


def test_arrays_outlive_a_rebuild():
    x = uniform(400)
    verlet = pyraycut.VerletList(CUTOFF, SKIN, distances=True)
    verlet.update(x)
    old = verlet.neighbours()
    kept = [a.copy() for a in old]
    assert verlet.update(large_move(x, SKIN))
    new = verlet.neighbours()
    for a, b in zip(old, kept):  # unchanged by the rebuild
        np.testing.assert_array_equal(a, b)
    assert pair_set(*csr_pairs(*new[:2])) != pair_set(*csr_pairs(*old[:2]))


def test_float64_and_lists_are_converted():
    x = uniform(100).astype(np.float64)
    verlet = pyraycut.VerletList(CUTOFF, SKIN)
    assert verlet.update(x)
    assert not verlet.update(x.tolist())
    assert isinstance(verlet.neighbours()[0], np.ndarray)


def test_errors():
    x = uniform(100)
    verlet = pyraycut.VerletList(CUTOFF, SKIN)
    with pytest.raises(ValueError, match="update"):
        verlet.neighbours()
    verlet.update(x)
    with pytest.raises(ValueError, match="100"):
        verlet.update(x[:50])
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        verlet.update(x.reshape(-1))
    bad = x.copy()
    bad[7, 1] = np.nan
    with pytest.raises(ValueError, match="7"):
        verlet.update(bad)
    assert verlet.rebuilds == 1
    with pytest.raises(ValueError):
        pyraycut.VerletList(CUTOFF, -0.1)
    with pytest.raises(ValueError):
        pyraycut.VerletList(0.0, SKIN)
    with pytest.raises(ValueError):
        pyraycut.VerletList(CUTOFF, float("inf"))
    with pytest.raises(ValueError):
        pyraycut.VerletList(CUTOFF, SKIN, method="no-such-method")


def test_empty_and_single():
    for x in (np.zeros((0, 3), np.float32), np.array([[0.5, 0.5, 0.5]], np.float32)):
        verlet = pyraycut.VerletList(CUTOFF, SKIN, distances=True, vectors=True)
        assert verlet.update(x)
        assert not verlet.update(x)
        offsets, indices, d, v = verlet.neighbours()
        assert offsets.tolist() == [0] * (len(x) + 1)
        assert len(indices) == len(d) == len(v) == 0


# ---- CUDA ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("method", DEVICE_METHODS + ["cell-list"])
def test_torch_verlet(method):
    torch = torch_cuda()
    x = uniform(800)
    verlet = pyraycut.VerletList(CUTOFF, SKIN, method=method, distances=True)
    assert verlet.update(torch.from_numpy(x).cuda())
    offsets, indices, d = verlet.neighbours()
    for t, dtype in zip((offsets, indices, d), (torch.int64, torch.int32, torch.float32)):
        assert isinstance(t, torch.Tensor) and t.device.type == "cuda" and t.dtype == dtype
    first = pair_set(*csr_pairs(offsets.cpu().numpy(), indices.cpu().numpy()))
    kept = [t.clone() for t in (offsets, indices, d)]

    moved = small_move(x, SKIN)
    assert verlet.update(torch.from_numpy(moved).cuda()) is False
    o2, i2, _ = verlet.neighbours()
    assert pair_set(*csr_pairs(o2.cpu().numpy(), i2.cpu().numpy())) == first
    assert_holds_cutoff_pairs(o2.cpu().numpy(), i2.cpu().numpy(), moved, CUTOFF)

    far = large_move(x, SKIN)
    assert verlet.update(torch.from_numpy(far).cuda()) is True and verlet.rebuilds == 2
    o3, i3, d3 = verlet.neighbours()
    ri, rj = pyraycut.neighbor_list("ij", far, np.float32(CUTOFF) + np.float32(SKIN))
    assert pair_set(*csr_pairs(o3.cpu().numpy(), i3.cpu().numpy())) == pair_set(ri, rj)
    for t, k in zip((offsets, indices, d), kept):  # the first list's arrays are still intact
        assert torch.equal(t, k)
    with pytest.raises(ValueError):
        verlet.update(torch.from_numpy(far[:10]).cuda())


def test_cupy_verlet():
    cupy = cupy_cuda()
    x = uniform(600)
    verlet = pyraycut.VerletList(CUTOFF, SKIN, vectors=True)
    assert verlet.update(cupy.asarray(x))
    offsets, indices, v = verlet.neighbours()
    for a in (offsets, indices, v):
        assert isinstance(a, cupy.ndarray)
    assert offsets.dtype == cupy.int64 and indices.dtype == cupy.int32 and v.shape[1] == 3
    assert verlet.update(cupy.asarray(small_move(x, SKIN))) is False
    far = large_move(x, SKIN)
    assert verlet.update(cupy.asarray(far)) is True
    o, i, _ = verlet.neighbours()
    ri, rj = pyraycut.neighbor_list("ij", far, np.float32(CUTOFF) + np.float32(SKIN))
    assert pair_set(*csr_pairs(o.get(), i.get())) == pair_set(ri, rj)
