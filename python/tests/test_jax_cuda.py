"""pyraycut.jax on a CUDA GPU (the stream-ordered small-system pass, python/src/jax_ffi_cuda.cu)
against the CPU custom call on the same inputs, under jax.jit: the same (i, j, S) triples and the
same counts for a periodic cube, a small triclinic cell (several images per pair), float64 cells,
jax.vmap, a ragged batch, half lists and lists cut by one; and the negative count codes for bad
device data. Skipped (with the reason) without a GPU that JAX sees, or where the library was
built without CUDA."""
import numpy as np
import pytest
from test_periodic import TRICLINIC, inside_cell, reference, triples

jax = pytest.importorskip("jax", reason="JAX is not installed")
try:
    import pyraycut.jax as rjax
except ImportError as e:
    pytest.skip(f"pyraycut.jax's custom call is not built ({e})", allow_module_level=True)
import jax.numpy as jnp  # noqa: E402


def _gpus():
    try:
        return jax.devices("gpu")
    except RuntimeError:  # no GPU backend
        return []


if not _gpus():
    pytest.skip("JAX sees no GPU", allow_module_level=True)
if not rjax.HAS_CUDA:
    pytest.skip("pyraycut.jax was built without CUDA (no CUDA handlers)", allow_module_level=True)
GPU = _gpus()[0]
CPU = jax.devices("cpu")[0]


def on(device, function, *args):
    """jax.jit(function) on `device` (its inputs placed there), the outputs as NumPy arrays."""
    placed = [jax.device_put(a, device) for a in args]
    out = jax.jit(function)(*placed)
    assert all(o.devices() == {device} for o in out)
    return [np.asarray(o) for o in out]


def both(function, *args):
    return on(CPU, function, *args), on(GPU, function, *args)


def pairs(i, j, S, count):
    n = min(int(count), len(i))
    return triples(i[:n], j[:n], S[:n])


def assert_same_list(cpu, gpu, pad, reference_pairs=None):
    """One list (i, j, S, count) from each device: equal counts and triples, padding after."""
    i, j, S, count = gpu
    assert count.dtype == np.int32 and i.dtype == np.int32 and S.dtype == np.int32
    assert int(count) == int(cpu[3]) >= 0
    n = min(int(count), len(i))
    found = pairs(*gpu)
    assert len(found) == n, "a triple appears twice"
    assert np.all(np.diff(i[:n]) >= 0), "sorted by i"
    if int(count) <= len(i):
        assert found == pairs(*cpu)
        if reference_pairs is not None:
            assert found == reference_pairs
    else:  # cut: the first K of the list, all of them real pairs
        assert len(found) == len(i) and found <= (reference_pairs or found)
    assert np.all(i[n:] == pad) and np.all(j[n:] == pad) and not S[n:].any()
    return found


def exact_reference(x, cutoff, cell, pbc=(True,) * 3):
    """The float64 pairs, with no triple so close to the cutoff that float32 could decide either
    way (the inputs are chosen so), so that both devices must find exactly these."""
    inside, edge = reference(x, x, cutoff, cell, pbc)
    assert not edge, "test data with a pair at the cutoff: pick another seed"
    return inside


# A periodic cube: N = 128, L = 5.3, cutoff 2.5 (just under L / 2: pairs across every face,
# edge and corner, S in {-1, 0, 1}^3).
CUBE_N, CUBE_L, CUBE_CUTOFF = 128, 5.3, 2.5
CUBE = CUBE_L * np.eye(3)


def test_periodic_cube_full_half_and_cut():
    x = inside_cell(CUBE_N, CUBE, seed=1)
    want = exact_reference(x, CUBE_CUTOFF, CUBE)
    assert {v for t in want for v in t[2:]} == {-1, 0, 1}
    cell = CUBE.astype(np.float32)
    k = len(want) + 50

    def listed(x, c):
        return rjax.neighbor_list(x, CUBE_CUTOFF, cell=c, max_pairs=k)

    cpu, gpu = both(listed, x, cell)
    found = assert_same_list(cpu, gpu, CUBE_N, want)
    assert int(gpu[3]) == len(want) > CUBE_N
    # Half: each pair once, every one in the full list.
    cpu, gpu = both(lambda x, c: rjax.neighbor_list(x, CUBE_CUTOFF, cell=c, max_pairs=k,
                                                    half=True), x, cell)
    half = assert_same_list(cpu, gpu, CUBE_N)
    assert 2 * len(half) == len(want) and half <= found
    # One short: count says the list was cut, on both devices alike.
    cpu, gpu = both(lambda x, c: rjax.neighbor_list(x, CUBE_CUTOFF, cell=c,
                                                    max_pairs=len(want) - 1), x, cell)
    assert int(gpu[3]) == int(cpu[3]) == len(want)
    assert_same_list(cpu, gpu, CUBE_N, want)


# A triclinic cell thinner than twice the cutoff: several images of each pair, self-images.
SMALL_CELL = 0.4 * TRICLINIC
SMALL_CUTOFF = 0.45


@pytest.mark.parametrize("cell_dtype", [np.float32, np.float64])
@pytest.mark.parametrize("pbc", [(True,) * 3, (True, True, False)])
def test_triclinic_several_images(cell_dtype, pbc):
    x = inside_cell(20, SMALL_CELL, pbc, seed=5)
    want = exact_reference(x, SMALL_CUTOFF, SMALL_CELL, pbc)
    images = {}
    for a, b, *_ in want:
        images[a, b] = images.get((a, b), 0) + 1
    assert max(images.values()) > 1 and any(a == b for a, b in images)
    with jax.enable_x64(cell_dtype == np.float64):
        cell = jnp.asarray(SMALL_CELL, cell_dtype)
        assert cell.dtype == cell_dtype
        for half in (False, True):
            cpu, gpu = both(lambda x, c: rjax.neighbor_list(
                x, SMALL_CUTOFF, cell=c, pbc=pbc, max_pairs=len(want) + 7, half=half), x, cell)
            found = assert_same_list(cpu, gpu, 20, None if half else want)
            assert len(found) == (len(want) // 2 if half else len(want))


def test_open_system():
    x = inside_cell(40, SMALL_CELL, (False,) * 3, spread=1.0, seed=6)
    want = exact_reference(x, SMALL_CUTOFF, None, (False,) * 3)
    cpu, gpu = both(lambda x: rjax.neighbor_list(x, SMALL_CUTOFF, max_pairs=len(want) + 3), x)
    assert_same_list(cpu, gpu, 40, want)


VMAP_CELLS = np.stack([0.9 * TRICLINIC, TRICLINIC, 0.8 * TRICLINIC]).astype(np.float32)
VMAP_CUTOFF = 0.45


def test_vmap_over_three_systems_with_exact_counts_when_cut():
    xs = np.stack([inside_cell(24, VMAP_CELLS[b], seed=20 + b) for b in range(3)])
    wants = [exact_reference(xs[b], VMAP_CUTOFF, VMAP_CELLS[b]) for b in range(3)]
    counts = [len(w) for w in wants]
    assert len(set(counts)) == 3  # different counts, so that K can cut some and not others
    for k in (max(counts) + 5, max(counts) - 1, sorted(counts)[1]):
        def batched(xs, cells, k=k):
            return jax.vmap(lambda x, c: rjax.neighbor_list(x, VMAP_CUTOFF, cell=c,
                                                            max_pairs=k))(xs, cells)

        cpu, gpu = both(batched, xs, VMAP_CELLS)
        assert gpu[0].shape == (3, k) and gpu[2].shape == (3, k, 3) and gpu[3].shape == (3,)
        assert [int(c) for c in gpu[3]] == [int(c) for c in cpu[3]] == counts
        for b in range(3):
            assert_same_list([a[b] for a in cpu], [a[b] for a in gpu], 24, wants[b])
    # Half lists and one cell shared by every system (not mapped).
    cpu, gpu = both(lambda xs: jax.vmap(lambda x: rjax.neighbor_list(
        x, VMAP_CUTOFF, cell=VMAP_CELLS[1], max_pairs=max(counts), half=True))(xs), xs)
    for b in range(3):
        assert_same_list([a[b] for a in cpu], [a[b] for a in gpu], 24)


# A ragged batch: 4 systems of 30, 0, 1 and 45 particles, each with its own cell (the third
# small and a slab: the single particle meets its own images).
RAGGED_SIZES = (30, 0, 1, 45)
RAGGED_CELLS = np.stack([0.9 * TRICLINIC, TRICLINIC, 0.35 * TRICLINIC,
                         1.2 * np.eye(3)]).astype(np.float32)
RAGGED_PBC = np.array([[True] * 3, [True] * 3, [True, True, False], [True, False, True]])
RAGGED_CUTOFF = 0.45


def ragged_system():
    xs = [inside_cell(n, RAGGED_CELLS[b], RAGGED_PBC[b], seed=50 + b)
          for b, n in enumerate(RAGGED_SIZES)]
    batch = np.repeat(np.arange(len(RAGGED_SIZES), dtype=np.int32), RAGGED_SIZES)
    offsets = np.concatenate([[0], np.cumsum(RAGGED_SIZES)])
    want = set()
    for b, part in enumerate(xs):
        if len(part):
            want |= {(i + offsets[b], j + offsets[b]) + tuple(S) for i, j, *S in exact_reference(
                part, RAGGED_CUTOFF, RAGGED_CELLS[b], tuple(RAGGED_PBC[b]))}
    return np.concatenate(xs).astype(np.float32), batch, want


def test_ragged_batch_of_four_systems():
    x, batch, want = ragged_system()
    n_points = len(x)
    k = len(want) + 11

    def listed(x, b, c, half=False, k=k):
        return rjax.neighbor_list(x, RAGGED_CUTOFF, cell=c, pbc=RAGGED_PBC, batch=b,
                                  max_pairs=k, half=half)

    cpu, gpu = both(listed, x, batch, RAGGED_CELLS)
    found = assert_same_list(cpu, gpu, n_points, want)
    assert all(batch[a] == batch[b] for a, b, *_ in found)
    assert any(a == b == 30 for a, b, *_ in found)  # the single particle's images
    cpu, gpu = both(lambda x, b, c: listed(x, b, c, half=True), x, batch, RAGGED_CELLS)
    half = assert_same_list(cpu, gpu, n_points)
    assert 2 * len(half) == len(want) and half <= found
    cpu, gpu = both(lambda x, b, c: listed(x, b, c, k=len(want) - 1), x, batch, RAGGED_CELLS)
    assert int(gpu[3]) == int(cpu[3]) == len(want)
    assert_same_list(cpu, gpu, n_points, want)
    # Open systems (no cell), B from num_systems; and no particles at all.
    cpu, gpu = both(lambda x, b: rjax.neighbor_list(x, RAGGED_CUTOFF, batch=b, num_systems=4,
                                                    max_pairs=k), x, batch)
    assert_same_list(cpu, gpu, n_points)
    cpu, gpu = both(lambda x, b: rjax.neighbor_list(x, RAGGED_CUTOFF, cell=RAGGED_CELLS, batch=b,
                                                    max_pairs=4),
                    np.zeros((0, 3), np.float32), np.zeros(0, np.int32))
    assert_same_list(cpu, gpu, 0)
    assert int(gpu[3]) == 0


def test_bad_device_data_gives_negative_counts():
    """What the CPU reports as an error of the call comes back as a count code on the GPU."""
    x, batch, _ = ragged_system()

    def count(x, b, cells=RAGGED_CELLS):
        i, j, S, c = on(GPU, lambda x, b, cells: rjax.neighbor_list(
            x, RAGGED_CUTOFF, cell=cells, pbc=RAGGED_PBC, batch=b, max_pairs=64), x, b, cells)
        if int(c) < 0:
            assert np.all(i == len(x)) and np.all(j == len(x)) and not S.any()  # all padding
        return int(c)

    assert count(x, batch) > 64  # the good input, cut
    bad = x.copy()
    bad[7, 1] = np.nan
    assert count(bad, batch) == -1
    assert count(x, batch[::-1].copy()) == -2
    assert count(x, np.where(batch == 3, 4, batch).astype(np.int32)) == -4
    flat = RAGGED_CELLS.copy()
    flat[0, 2] = flat[0, 0]  # two equal rows: no volume
    assert count(x, batch, flat) == -3
