"""The host (NumPy) path on every available method: against brute force, the list options, the
Engine, padded lists and errors."""
import numpy as np
import pytest
from conftest import AVAILABLE, CUTOFF, INPUTS, assert_same_pairs, brute_force, pair_set, uniform

import pyraycut


def test_methods():
    rows = pyraycut.methods()
    assert [set(r) for r in rows] == [{"name", "summary", "available", "why"}] * len(rows)
    names = [r["name"] for r in rows]
    assert "brute-force" in names and "cell-list" in names
    for r in rows:
        assert r["available"] == (r["why"] == ""), r
    assert pyraycut.auto_method() in AVAILABLE


@pytest.mark.parametrize("family", sorted(INPUTS))
def test_neighbor_list_vs_brute_force(method, family):
    x = INPUTS[family]()
    i, j = pyraycut.neighbor_list("ij", x, CUTOFF, method=method)
    assert isinstance(i, np.ndarray) and i.dtype == np.int64 and j.dtype == np.int64
    assert np.all(np.diff(i) >= 0), "i is sorted"
    assert_same_pairs(i, j, x, CUTOFF)


@pytest.mark.parametrize("family", ["uniform", "coincident", "empty", "single"])
def test_half_is_full_halved(method, family):
    x = INPUTS[family]()
    full = pair_set(*pyraycut.neighbor_list("ij", x, CUTOFF, method=method))
    i, j = pyraycut.neighbor_list("ij", x, CUTOFF, half=True, method=method)
    assert np.all(i < j)
    assert pair_set(i, j) == {(a, b) for a, b in full if a < b}
    assert 2 * len(i) == len(full)
    assert_same_pairs(i, j, x, CUTOFF, half=True)


@pytest.mark.parametrize("family", ["uniform", "coincident"])
def test_half_any_row_holds_each_pair_once(method, family):
    x = INPUTS[family]()
    engine = pyraycut.Engine(method)
    engine.build(x, CUTOFF)
    offsets, indices, vectors = engine.neighbours(half=True, vectors=True, any_row=True)
    rows = np.repeat(np.arange(len(offsets) - 1), np.diff(offsets))
    pairs = {(min(a, b), max(a, b)) for a, b in zip(rows.tolist(), indices.tolist())}
    full = pair_set(*pyraycut.neighbor_list("ij", x, CUTOFF, method=method))
    assert len(pairs) == len(indices) and pairs == {(a, b) for a, b in full if a < b}
    np.testing.assert_array_equal(vectors, x[indices] - x[rows])


def test_quantities_order_and_single_letter(method):
    x = uniform(300)
    i, j, d, D = pyraycut.neighbor_list("ijdD", x, CUTOFF, method=method)
    D2, j2, i2, d2 = pyraycut.neighbor_list("Djid", x, CUTOFF, method=method)
    # Row order within a row is unspecified: compare as sorted (i, j) records.
    a = np.lexsort((j, i))
    b = np.lexsort((j2, i2))
    np.testing.assert_array_equal(i[a], i2[b])
    np.testing.assert_array_equal(j[a], j2[b])
    np.testing.assert_array_equal(d[a], d2[b])
    np.testing.assert_array_equal(D[a], D2[b])
    only = pyraycut.neighbor_list("d", x, CUTOFF, method=method)
    assert isinstance(only, np.ndarray) and only.shape == d.shape


@pytest.mark.parametrize("half", [False, True])
def test_distances_and_vectors_match_positions(method, half):
    x = INPUTS["clustered"]()
    i, j, d, D = pyraycut.neighbor_list("ijdD", x, CUTOFF, half=half, method=method)
    assert d.dtype == np.float32 and D.dtype == np.float32 and D.shape == (len(i), 3)
    np.testing.assert_allclose(D, x[j] - x[i], rtol=0, atol=1e-6)
    np.testing.assert_allclose(d, np.linalg.norm(D.astype(np.float64), axis=1), rtol=1e-5,
                               atol=1e-7)
    assert np.all(d < CUTOFF * (1 + 1e-6))


def test_float64_and_lists_are_converted(method):
    x = uniform(200)
    ref = pair_set(*pyraycut.neighbor_list("ij", x, CUTOFF, method=method))
    assert pair_set(*pyraycut.neighbor_list("ij", x.astype(np.float64), CUTOFF, method=method)) == ref
    assert pair_set(*pyraycut.neighbor_list("ij", x.tolist(), CUTOFF, method=method)) == ref
    fortran = np.asfortranarray(x)
    assert pair_set(*pyraycut.neighbor_list("ij", fortran, CUTOFF, method=method)) == ref


def test_engine_count_matches_list_rows(method):
    x = INPUTS["clustered"]()
    engine = pyraycut.Engine(method)
    engine.build(x, CUTOFF)
    assert engine.method == method and engine.size == len(x)
    count = engine.compute("count")["count"]
    assert count.dtype == np.int32 and count.shape == (len(x),)
    offsets, indices = engine.neighbours()
    assert offsets.dtype == np.int64 and indices.dtype == np.int32
    assert offsets[0] == 0 and offsets[-1] == len(indices)
    np.testing.assert_array_equal(np.diff(offsets), count)
    inside, edge = brute_force(x, CUTOFF)
    rows = np.repeat(np.arange(len(x)), np.diff(offsets))
    assert pair_set(rows, indices) - edge == inside - edge


def test_engine_neighbours_options(method):
    x = uniform(300)
    engine = pyraycut.Engine(method)
    engine.build(x, CUTOFF)
    offsets, indices, d, D = engine.neighbours(half=True, distances=True, vectors=True)
    rows = np.repeat(np.arange(len(x)), np.diff(offsets))
    assert np.all(rows < indices)
    np.testing.assert_allclose(D, x[indices] - x[rows], atol=1e-6, rtol=0)
    np.testing.assert_allclose(d, np.linalg.norm(D, axis=1), rtol=1e-5)
    # Earlier outputs own their buffer: a new call does not change them.
    kept = indices.copy()
    engine.update(uniform(300, seed=9))
    engine.neighbours()
    np.testing.assert_array_equal(indices, kept)


def test_engine_kernels(method):
    x = uniform(400)
    engine = pyraycut.Engine(method)
    engine.build(x, 0.15)
    out = engine.compute("smooth")
    assert set(out) == {"energy", "force"}
    offsets, indices = engine.neighbours()
    rows = np.repeat(np.arange(len(x)), np.diff(offsets))
    r = (x[indices] - x[rows]).astype(np.float64)
    w = 0.15**2 - (r**2).sum(1)
    energy = np.bincount(rows, w**2, minlength=len(x))
    force = np.stack([np.bincount(rows, w * r[:, k], minlength=len(x)) for k in range(3)], 1)
    np.testing.assert_allclose(out["energy"], energy, rtol=1e-3, atol=1e-9)
    np.testing.assert_allclose(out["force"], force, rtol=1e-3, atol=1e-7)
    lj = engine.compute("lj_forces", lj_epsilon=0.5, lj_sigma=0.01)
    assert lj["force"].shape == (len(x), 3) and lj["virial"].shape == (len(x), 6)
    assert engine.compute("sph_density", sph_mass=1.0)["density"].shape == (len(x),)
    n = len(x)
    f = engine.compute("sph_force", sph_mass=1.0, sph_viscosity=0.1,
                       velocity=np.zeros((n, 3)), density=np.ones(n), pressure=np.ones(n))
    assert f["force"].shape == (n, 3) and np.all(np.isfinite(f["force"]))


def test_engine_empty_and_single(method):
    for x in (INPUTS["empty"](), INPUTS["single"]()):
        engine = pyraycut.Engine(method)
        engine.build(x, CUTOFF)
        n = len(x)
        out = engine.compute("lj_forces")
        assert out["energy"].shape == (n,) and out["virial"].shape == (n, 6)
        assert engine.compute("count")["count"].tolist() == [0] * n
        offsets, indices = engine.neighbours()
        assert offsets.tolist() == [0] * (n + 1) and indices.shape == (0,)
        idx, counts, report = engine.padded_neighbours(4)
        assert idx.shape == (n, 4) and counts.shape == (n,) and not report["overflowed"]


def test_padded_half_matches_half_list(method):
    x = INPUTS["clustered"]()
    engine = pyraycut.Engine(method)
    engine.build(x, CUTOFF)
    offsets, indices = engine.neighbours(half=True)
    k = max(1, int(np.diff(offsets).max()))
    idx, counts, report = engine.padded_neighbours(k, half=True)
    assert not report["overflowed"]
    np.testing.assert_array_equal(counts, np.diff(offsets))
    for i in range(len(x)):
        assert sorted(idx[i, :counts[i]]) == sorted(indices[offsets[i]:offsets[i + 1]])
        assert all(j > i for j in idx[i, :counts[i]])


@pytest.mark.parametrize("family", ["uniform", "clustered"])
def test_padded_nearest_is_each_rows_k_nearest(method, family):
    """nearest=True: each row's K nearest, nearest first (ties by index), from a float64 brute
    force; with query points too. GPU methods refuse it by name."""
    x = INPUTS[family]()
    q = uniform(50, seed=9)
    engine = pyraycut.Engine(method)
    for queries in (None, q):
        try:
            engine.build(x, CUTOFF, queries=queries)
        except NotImplementedError:  # a method without query sets
            continue
        if engine.space != "host":
            with pytest.raises(NotImplementedError, match="nearest"):
                engine.padded_neighbours(4, nearest=True)
            return
        targets = x if queries is None else q
        k = 5
        idx, counts, report = engine.padded_neighbours(k, nearest=True)
        d = np.linalg.norm(targets[:, None, :].astype(np.float64) - x[None, :, :], axis=2)
        for i in range(len(targets)):
            within = [j for j in np.argsort(d[i], kind="stable") if d[i, j] < CUTOFF
                      and (queries is not None or j != i)]
            assert counts[i] == len(within)
            want = sorted(within, key=lambda j: (d[i, j], j))[:k]
            assert list(idx[i, :len(want)]) == want, i
            assert all(idx[i, len(want):] == len(x))


def test_padded_overflow_report(method):
    x = INPUTS["clustered"]()
    engine = pyraycut.Engine(method)
    engine.build(x, CUTOFF)
    count = engine.compute("count")["count"]
    k = max(1, int(np.median(count)))
    idx, counts, report = engine.padded_neighbours(k)
    assert idx.shape == (len(x), k) and idx.dtype == np.int32
    np.testing.assert_array_equal(counts, count)
    assert report["overflowed"] and report["overflowed_rows"] == int(np.sum(count > k))
    assert report["largest_count"] == int(count.max())
    with pytest.raises(pyraycut.CapacityError, match="grow K"):
        engine.padded_neighbours(k, raise_on_overflow=True)
    assert issubclass(pyraycut.CapacityError, RuntimeError)
    # Grown to the largest count: every row whole, padded with N.
    idx, counts, report = engine.padded_neighbours(report["largest_count"], True)
    assert not report["overflowed"]
    offsets, indices = engine.neighbours()
    for row in range(0, len(x), 37):
        got = idx[row, : counts[row]]
        assert sorted(got) == sorted(indices[offsets[row] : offsets[row + 1]])
        assert np.all(idx[row, counts[row] :] == len(x))


def test_errors():
    x = uniform(10)
    bad = x.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="index 3"):
        pyraycut.neighbor_list("ij", bad, CUTOFF)
    bad[3, 1] = np.inf
    with pytest.raises(ValueError, match="index 3"):
        pyraycut.Engine("cell-list").build(bad, CUTOFF)
    for cutoff in (0.0, -1.0, float("nan"), float("inf"), 1e40):
        with pytest.raises(ValueError, match="cutoff"):
            pyraycut.neighbor_list("ij", x, cutoff)
    with pytest.raises(ValueError, match=f"9 per-atom cutoffs for {len(x)} particles"):
        pyraycut.neighbor_list("ij", x, [0.1] * (len(x) - 1))
    with pytest.raises(ValueError, match="one number here"):
        pyraycut.Engine("cell-list").build(x, [0.1] * len(x))
    with pytest.raises(ValueError, match="pbc without a cell"):
        pyraycut.neighbor_list("ij", x, CUTOFF, pbc=True)
    i, S = pyraycut.neighbor_list("iS", x, CUTOFF, pbc=[False, False, False])  # open: zero shifts
    assert i.dtype == np.int64 and S.dtype == np.int32 and S.shape == (len(i), 3)
    assert not S.any()
    with pytest.raises(ValueError, match="unknown quantity"):
        pyraycut.neighbor_list("ijx", x, CUTOFF)
    with pytest.raises(ValueError, match="shape"):
        pyraycut.neighbor_list("ij", np.zeros((4, 2), np.float32), CUTOFF)
    with pytest.raises(ValueError, match="unknown method"):
        pyraycut.Engine("no-such-method")
    engine = pyraycut.Engine("cell-list")
    with pytest.raises(ValueError, match="before build"):
        engine.neighbours()
    engine.build(x, CUTOFF)
    with pytest.raises(ValueError):
        engine.compute("no-such-kernel")
    with pytest.raises(ValueError, match="same N|particles|10"):
        engine.update(uniform(11))
    unavailable = [m["name"] for m in pyraycut.methods() if not m["available"]]
    if unavailable:
        with pytest.raises(NotImplementedError, match="not available"):
            pyraycut.Engine(unavailable[0])


def test_other_framework_host_dlpack():
    x = uniform(300)

    class Foreign:  # an unknown framework's host array, known only through DLPack
        def __init__(self, a):
            self.a = a

        def __dlpack__(self, **kwargs):
            return self.a.__dlpack__(**kwargs)

        def __dlpack_device__(self):
            return self.a.__dlpack_device__()

    i, j = pyraycut.neighbor_list("ij", Foreign(x), CUTOFF)
    assert isinstance(i, np.ndarray)
    assert pair_set(i, j) == pair_set(*pyraycut.neighbor_list("ij", x, CUTOFF))
    with pytest.raises(ValueError, match="float32"):
        pyraycut.neighbor_list("ij", Foreign(x.astype(np.float64)), CUTOFF)
    with pytest.raises(TypeError, match="__dlpack__"):
        pyraycut.Engine().build(object(), CUTOFF)


def test_sparse_batch_indices_cost_nothing():
    # [0, 10**9] with one box for all asked for gigabytes (a frame and offsets per empty system).
    x = np.array([[0, 0, 0], [0.5, 0, 0], [0.6, 0, 0]], np.float32)
    i, j = pyraycut.neighbor_list("ij", x, 0.7, batch=[0, 10**9, 10**9])
    assert sorted(zip(i.tolist(), j.tolist())) == [(1, 2), (2, 1)]


def test_query_points_refuse_update_and_sph_force_and_pad_with_the_source_count():
    rng = np.random.default_rng(0)
    x = rng.random((50, 3)).astype(np.float32)
    q = x[:7] + 0.01
    e = pyraycut.Engine("cell-list")
    e.build(x, 0.3, queries=q)
    with pytest.raises(NotImplementedError, match="query points"):
        e.update(x + 0.1)
    indices, counts, _ = e.padded_neighbours(40)
    for row, c in zip(np.asarray(indices), np.asarray(counts)):
        assert (row[:c] < 50).all() and (row[c:] == 50).all()
    with pytest.raises(NotImplementedError, match="query points"):
        e.compute("sph_force", sph_mass=1.0, velocity=np.zeros((7, 3), np.float32),
                  density=np.ones(7, np.float32), pressure=np.ones(7, np.float32))
