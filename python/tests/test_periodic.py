"""Periodic boxes, batches and query sets (docs/periodic.md, "Semantics") through pyraycut.neighbor_list,
pyraycut.radius and Engine, on every method that has them, against a NumPy brute force over
explicit images written here (independent of raycut): cubic, triclinic, cells thinner than twice
the cutoff (self-images), slabs and wires, unwrapped positions, batches with empty systems, query
sets; and the errors."""
import itertools

import numpy as np
import pytest
from conftest import AVAILABLE, SYSTEM_METHODS

import pyraycut

REL = 1e-5  # pairs this close (relative) to the cutoff may go either way in float32


# ---- the reference -----------------------------------------------------------------------------


def completed_cell(cell, pbc):
    """The periodic rows completed by orthonormal vectors orthogonal to them (Gram-Schmidt)."""
    cell = np.asarray(cell, np.float64)
    basis = [cell[k] for k in range(3) if pbc[k]]
    ortho = []
    for v in basis:
        w = v - sum(np.dot(v, u) * u for u in ortho)
        ortho.append(w / np.linalg.norm(w))
    out = cell.copy()
    for k in range(3):
        if pbc[k]:
            continue
        for e in np.eye(3):
            w = e - sum(np.dot(e, u) * u for u in ortho)
            if np.linalg.norm(w) > 0.5:
                break
        w /= np.linalg.norm(w)
        ortho.append(w)
        out[k] = w
    return out


def reference(targets, sources, cutoff, cell=None, pbc=(False,) * 3, exclude_self=True):
    """{(i, j, S)} with |sources[j] - targets[i] + S @ cell| < cutoff in float64, every image S,
    (i, i, 0) left out when exclude_self; and the ambiguous triples within REL of the cutoff.

    The fractional coordinate of r_ij along a periodic axis k is f_j - f_i + S_k, and at most
    cutoff / width_k in magnitude: so S_k lies within m_k = ceil(cutoff / width_k) + 1 of
    -floor(f_j - f_i), and every S there is tried."""
    t = np.asarray(targets, np.float64).reshape(-1, 3)
    s = np.asarray(sources, np.float64).reshape(-1, 3)
    pbc = np.broadcast_to(np.asarray(pbc, bool), (3,))
    cell = np.zeros((3, 3)) if cell is None else np.asarray(cell, np.float64)
    full = completed_cell(cell, pbc)
    inverse = np.linalg.inv(full)
    volume = abs(np.linalg.det(full))
    ranges = []
    for k in range(3):
        if not pbc[k]:
            ranges.append([0])
            continue
        width = volume / np.linalg.norm(np.cross(full[(k + 1) % 3], full[(k + 2) % 3]))
        m = int(np.ceil(cutoff / width)) + 1
        ranges.append(range(-m, m + 1))
    local = np.array(list(itertools.product(*ranges)), np.int64)  # (K, 3)
    ft, fs = t @ inverse, s @ inverse
    inside, edge = set(), set()
    for i in range(len(t)):
        base = -np.floor(fs - ft[i]).astype(np.int64) * pbc  # (N, 3)
        shifts = base[:, None, :] + local[None, :, :]  # (N, K, 3)
        r = s[:, None, :] - t[i] + shifts.astype(np.float64) @ cell
        dist = np.sqrt((r * r).sum(-1))
        if exclude_self and i < len(s):
            dist[i][~shifts[i].any(axis=1)] = np.inf
        for j, k in zip(*np.nonzero(dist < cutoff)):
            inside.add((i, int(j)) + tuple(int(v) for v in shifts[j, k]))
        for j, k in zip(*np.nonzero(np.abs(dist - cutoff) <= REL * cutoff)):
            edge.add((i, int(j)) + tuple(int(v) for v in shifts[j, k]))
    return inside, edge


def triples(i, j, S):
    i, j, S = np.asarray(i), np.asarray(j), np.asarray(S)
    return {(a, b) + tuple(c) for a, b, c in zip(i.tolist(), j.tolist(), S.tolist())}


def check(out, targets, sources, cutoff, cell, pbc, exclude_self=True, want=None):
    """out = (i, j, d, D, S): no duplicate, the reference's triples (the cutoff band aside), i
    sorted, dtypes, and d, D those of the triples."""
    i, j, d, D, S = (np.asarray(a) for a in out)
    assert i.dtype == np.int64 and j.dtype == np.int64 and S.dtype == np.int32
    assert d.dtype == np.float32 and D.dtype == np.float32
    assert S.shape == (len(i), 3) and D.shape == (len(i), 3) and d.shape == (len(i),)
    assert np.all(np.diff(i) >= 0), "i is sorted"
    found = triples(i, j, S)
    assert len(found) == len(i), "a triple appears twice"
    inside, edge = want if want is not None else reference(targets, sources, cutoff, cell, pbc,
                                                           exclude_self)
    assert found - edge == inside - edge
    cell = np.zeros((3, 3)) if cell is None else np.asarray(cell, np.float64)
    t = np.asarray(targets, np.float64)
    s = np.asarray(sources, np.float64)
    r = s[j] - t[i] + S.astype(np.float64) @ cell
    scale = max(1.0, float(np.abs(t).max(initial=0)), float(np.abs(s).max(initial=0)))
    np.testing.assert_allclose(D, r, rtol=0, atol=4e-6 * scale)
    np.testing.assert_allclose(d, np.linalg.norm(r, axis=1), rtol=0, atol=4e-6 * scale)
    assert not np.any(S[:, ~np.broadcast_to(np.asarray(pbc, bool), (3,))]), "S = 0 on open axes"
    return found


# ---- systems -----------------------------------------------------------------------------------

TRICLINIC = np.array([[1.0, 0.0, 0.0], [0.4, 0.9, 0.0], [0.3, -0.2, 0.8]])


def inside_cell(n, cell, pbc=(True,) * 3, spread=1.5, seed=0):
    """n points with fractional coordinates in [0, 1) along periodic axes and in [0, spread)
    along open ones (of the completed cell), float32."""
    rng = np.random.default_rng(seed)
    frac = rng.random((n, 3))
    for k in range(3):
        if not pbc[k]:
            frac[:, k] *= spread
    return (frac @ completed_cell(cell, pbc)).astype(np.float32)


def unwrapped(x, cell, pbc, boxes, seed):
    """x moved by random whole cells (up to `boxes` along each periodic axis)."""
    rng = np.random.default_rng(seed)
    n = rng.integers(-boxes, boxes + 1, (len(x), 3)) * np.asarray(pbc, bool)
    return (x.astype(np.float64) + n @ np.asarray(cell, np.float64)).astype(np.float32)


CASES = {  # name: (N, cell, pbc, cutoff)
    "cubic": (60, np.eye(3), (True, True, True), 0.3),
    "triclinic": (60, TRICLINIC, (True, True, True), 0.35),
    "small-cubic": (8, np.eye(3), (True, True, True), 1.3),  # < 2C: images, self-images
    "small-triclinic": (10, 0.5 * TRICLINIC, (True, True, True), 0.6),
    "tiny": (3, 0.3 * np.eye(3), (True, True, True), 0.5),  # several images per axis
    "slab": (50, np.diag([1.0, 1.0, 0.0]), (True, True, False), 0.3),
    "wire": (40, np.diag([0.6, 0.0, 0.0]), (True, False, False), 0.4),
    "mixed-triclinic": (40, TRICLINIC, (True, False, True), 0.4),
    "one-particle": (1, 0.7 * np.eye(3), (True, True, True), 1.0),
    "empty": (0, np.eye(3), (True, True, True), 0.3),
}


def case(name, seed=0):
    n, cell, pbc, cutoff = CASES[name]
    return inside_cell(n, cell, pbc, seed=seed), cell, pbc, cutoff


@pytest.mark.parametrize("name", sorted(CASES))
def test_periodic_vs_brute_force(system_method, name):
    x, cell, pbc, cutoff = case(name)
    out = pyraycut.neighbor_list("ijdDS", x, cutoff, cell=cell, pbc=pbc, method=system_method)
    found = check(out, x, x, cutoff, cell, pbc)
    if name.startswith("small") or name == "tiny":
        assert any(a == b for a, b, *_ in found), "self-images expected in a small cell"


@pytest.mark.parametrize("name", sorted(CASES))
def test_float64_positions_give_float64_distances(system_method, name):
    """float64 host positions far from the origin and unwrapped by whole cells: d and D come in
    float64, computed from those positions (not widened from the float32 search), for the
    reference's triples."""
    if pyraycut.Engine(system_method).space != "host":
        pytest.skip("float64 positions are decided in double on the host methods")
    x, cell, pbc, cutoff = case(name, seed=3)
    rng = np.random.default_rng(7)
    x = x.astype(np.float64) + rng.random(x.shape) * 1e-3
    x = x + rng.integers(-4, 5, (len(x), 3)) * np.asarray(pbc, bool) @ np.asarray(cell) + 1e3
    i, j, d, D, S = pyraycut.neighbor_list("ijdDS", x, cutoff, cell=cell, pbc=pbc,
                                           method=system_method)
    assert d.dtype == np.float64 and D.dtype == np.float64
    inside, edge = reference(x, x, cutoff, cell, pbc)
    found = triples(i, j, S)
    assert found - edge == inside - edge
    r = x[j] - x[i] + S.astype(np.float64) @ np.asarray(cell, np.float64)
    np.testing.assert_allclose(D, r, rtol=0, atol=1e-12)
    np.testing.assert_allclose(d, np.linalg.norm(r, axis=1), rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", ["cubic", "triclinic", "small-triclinic", "slab",
                                  "mixed-triclinic"])
@pytest.mark.parametrize("boxes", [3, 40])
def test_unwrapped_positions(system_method, name, boxes):
    x, cell, pbc, cutoff = case(name, seed=5)
    xu = unwrapped(x, cell, pbc, boxes, seed=6)
    out = pyraycut.neighbor_list("ijdDS", xu, cutoff, cell=cell, pbc=pbc, method=system_method)
    check(out, xu, xu, cutoff, cell, pbc)
    # The same vectors as for the wrapped positions (up to the rounding of the moved
    # positions): only S changes.
    i, d = pyraycut.neighbor_list("id", x, cutoff, cell=cell, pbc=pbc, method=system_method)
    assert len(i) == len(out[0])
    np.testing.assert_array_equal(np.bincount(i, minlength=len(x)),
                                  np.bincount(out[0], minlength=len(x)))
    np.testing.assert_allclose(np.sort(d), np.sort(out[2]), rtol=0, atol=1e-5 * boxes)


@pytest.mark.parametrize("name", ["cubic", "triclinic", "small-cubic", "tiny", "wire"])
def test_half_orientation(system_method, name):
    x, cell, pbc, cutoff = case(name, seed=2)
    full = triples(*pyraycut.neighbor_list("ijS", x, cutoff, cell=cell, pbc=pbc,
                                         method=system_method))
    out = pyraycut.neighbor_list("ijdDS", x, cutoff, cell=cell, pbc=pbc, half=True,
                               method=system_method)
    inside, edge = reference(x, x, cutoff, cell, pbc)

    def kept(t):  # of (i, j, S) and (j, i, -S): i < j, or i == j and S lexicographically > 0
        i, j, s = t[0], t[1], t[2:]
        return i < j or (i == j and s > (0, 0, 0))

    half = check(out, x, x, cutoff, cell, pbc,
                 want=({t for t in inside if kept(t)}, {t for t in edge if kept(t)}))
    assert all(kept(t) for t in half)
    assert half == {t for t in full if kept(t)}
    mirrored = {(t[1], t[0], -t[2], -t[3], -t[4]) for t in half}
    assert half | mirrored == full and 2 * len(half) == len(full)


def test_cell_and_pbc_forms(system_method):
    x, _, _, cutoff = case("cubic", seed=3)
    cell = np.diag([1.0, 0.8, 1.2])
    ref = triples(*pyraycut.neighbor_list("ijS", x, cutoff, cell=cell, pbc=[True] * 3,
                                        method=system_method))
    for c, p in (([1.0, 0.8, 1.2], True), (cell, None), (cell.tolist(), np.ones(3, bool)),
                 ((1, 0.8, 1.2), [1, 1, 1])):
        got = triples(*pyraycut.neighbor_list("ijS", x, cutoff, cell=c, pbc=p,
                                            method=system_method))
        assert got == ref, (c, p)
    # A cell with no periodic axis is an open system; so is pbc without any True.
    open_ = triples(*pyraycut.neighbor_list("ijS", x, cutoff, method=system_method))
    assert triples(*pyraycut.neighbor_list("ijS", x, cutoff, cell=cell, pbc=False,
                                         method=system_method)) == open_
    assert triples(*pyraycut.neighbor_list("ijS", x, cutoff, pbc=[False] * 3,
                                         method=system_method)) == open_
    assert all(t[2:] == (0, 0, 0) for t in open_)


# ---- batches -----------------------------------------------------------------------------------

SIZES = [5, 0, 1, 30, 0, 20, 0]  # empty systems first, inside and last; a single particle
BATCH_CELLS = [np.eye(3), 2 * np.eye(3), 0.5 * np.eye(3), TRICLINIC, np.eye(3),
               np.diag([0.7, 0.0, 0.0]), np.eye(3)]
BATCH_PBC = [(True,) * 3, (True,) * 3, (True,) * 3, (True,) * 3, (False,) * 3,
             (True, False, False), (True,) * 3]


def batched(sizes, cells, pbcs, seed=0):
    xs = [inside_cell(n, c, p, seed=seed + k) for k, (n, c, p) in enumerate(zip(sizes, cells,
                                                                                  pbcs))]
    x = np.concatenate(xs) if xs else np.zeros((0, 3), np.float32)
    batch = np.repeat(np.arange(len(sizes)), sizes)
    return x, batch


def batch_reference(x, batch, cutoff, cells, pbcs, queries=None, batch_queries=None):
    """The union of the systems' references, with global indices."""
    inside, edge = set(), set()
    targets = x if queries is None else queries
    target_batch = batch if queries is None else batch_queries
    for s in range(len(cells)):
        src = np.flatnonzero(batch == s)
        tgt = np.flatnonzero(target_batch == s)
        a, b = reference(targets[tgt], x[src], cutoff, cells[s], pbcs[s],
                         exclude_self=queries is None)
        inside |= {(int(tgt[t[0]]), int(src[t[1]])) + t[2:] for t in a}
        edge |= {(int(tgt[t[0]]), int(src[t[1]])) + t[2:] for t in b}
    return inside, edge


def test_batch_per_system_boxes(system_method):
    cutoff = 0.45
    x, batch = batched(SIZES, BATCH_CELLS, BATCH_PBC)
    out = pyraycut.neighbor_list("ijdDS", x, cutoff, cell=np.stack(BATCH_CELLS),
                               pbc=np.array(BATCH_PBC), batch=batch, method=system_method)
    i, j, S = out[0], out[1], out[4]
    assert np.array_equal(batch[i], batch[j]), "pairs never cross systems"
    want = batch_reference(x, batch, cutoff, BATCH_CELLS, BATCH_PBC)
    # D with each pair's own system's cell.
    i, j, d, D, S = out
    cells = np.stack(BATCH_CELLS)[batch[i]]
    r = x[j].astype(np.float64) - x[i] + np.einsum("pk,pkl->pl", S.astype(np.float64), cells)
    np.testing.assert_allclose(D, r, atol=4e-6, rtol=0)
    found = triples(i, j, S)
    assert len(found) == len(i)
    inside, edge = want
    assert found - edge == inside - edge
    # Each system alone gives its own pairs.
    for s in (0, 3, 5):
        lo = int(np.searchsorted(batch, s))
        alone = pyraycut.neighbor_list("ijS", x[batch == s], cutoff, cell=BATCH_CELLS[s],
                                     pbc=BATCH_PBC[s], method=system_method)
        mine = {(t[0] - lo, t[1] - lo) + t[2:] for t in found if batch[t[0]] == s}
        assert mine == triples(*alone)


def test_float64_batch_takes_each_pairs_own_cell(system_method):
    """float64 positions of a batch with a cell per system: D and d from each pair's own cell in
    float64 (the extension's one pass over the pairs), d rounded as NumPy's norm of D."""
    if pyraycut.Engine(system_method).space != "host":
        pytest.skip("float64 positions are decided in double on the host methods")
    x, batch = batched(SIZES, BATCH_CELLS, BATCH_PBC)
    x = x.astype(np.float64) + np.random.default_rng(8).random(x.shape) * 1e-4
    i, j, d, D, S = pyraycut.neighbor_list("ijdDS", x, 0.45, cell=np.stack(BATCH_CELLS),
                                           pbc=np.array(BATCH_PBC), batch=batch,
                                           method=system_method)
    assert d.dtype == np.float64 and D.dtype == np.float64 and len(i) > 0
    cells = np.stack(BATCH_CELLS).astype(np.float64)[batch[i]]
    r = x[j] - x[i] + np.einsum("pk,pkl->pl", S.astype(np.float64), cells)
    np.testing.assert_allclose(D, r, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(d, np.sqrt(np.sum(D * D, axis=1)))
    with pytest.raises(ValueError, match="outside"):
        pyraycut._raycut.pair_vectors(x, x, i, j + len(x), S, cells[:1], None)


def test_batch_shared_box_and_open(system_method):
    cutoff = 0.3
    sizes = [0, 40, 1, 25]
    x, batch = batched(sizes, [np.eye(3)] * 4, [(True,) * 3] * 4, seed=7)
    for cell, pbc in ((np.eye(3), True), (None, None)):
        out = pyraycut.neighbor_list("ijdDS", x, cutoff, cell=cell, pbc=pbc, batch=batch,
                                   method=system_method)
        cells = [np.eye(3) if cell is not None else np.zeros((3, 3))] * 4
        pbcs = [(cell is not None,) * 3] * 4
        check(out, x, x, cutoff, cell, (cell is not None,) * 3,
              want=batch_reference(x, batch, cutoff, cells, pbcs))
        assert np.array_equal(batch[out[0]], batch[out[1]])
    # Shared cell, per-system pbc.
    pbcs = [(True,) * 3, (False,) * 3, (True, True, False), (True, False, True)]
    out = pyraycut.neighbor_list("ijdDS", x, cutoff, cell=np.eye(3), pbc=pbcs, batch=batch,
                               method=system_method)
    inside, edge = batch_reference(x, batch, cutoff, [np.eye(3)] * 4, pbcs)
    found = triples(out[0], out[1], out[4])
    assert found - edge == inside - edge


def test_batch_torch_cluster_style_index_and_empty_input(system_method):
    # Only the index says which system: any integer dtype, and batches of nothing.
    x, batch = batched([10, 10], [np.eye(3)] * 2, [(True,) * 3] * 2, seed=9)
    ref = triples(*pyraycut.neighbor_list("ijS", x, 0.4, cell=np.eye(3), batch=batch,
                                        method=system_method))
    for b in (batch.astype(np.int32), batch.astype(np.uint8), batch.tolist()):
        assert triples(*pyraycut.neighbor_list("ijS", x, 0.4, cell=np.eye(3), batch=b,
                                             method=system_method)) == ref
    i, j = pyraycut.neighbor_list("ij", np.zeros((0, 3), np.float32), 0.4, cell=np.eye(3),
                                batch=np.zeros(0, np.int64), method=system_method)
    assert len(i) == 0 and len(j) == 0
    i = pyraycut.neighbor_list("i", np.zeros((0, 3), np.float32), 0.4, cell=np.stack([np.eye(3)] * 3),
                             batch=np.zeros(0, np.int64), method=system_method)
    assert len(i) == 0


# ---- query sets --------------------------------------------------------------------------------


def test_radius_open(system_method):
    rng = np.random.default_rng(11)
    points = rng.random((120, 3)).astype(np.float32)
    queries = np.concatenate([rng.random((40, 3)), points[:5]]).astype(np.float32)
    cutoff = 0.2
    out = pyraycut.radius(points, queries, cutoff, method=system_method, quantities="ijdDS")
    found = check(out, queries, points, cutoff, None, (False,) * 3, exclude_self=False)
    assert all((40 + k, k, 0, 0, 0) in found for k in range(5)), "no self-exclusion"
    i, j = pyraycut.radius(points, queries, cutoff, method=system_method)
    assert triples(i, j, np.zeros((len(i), 3), np.int32)) == {t[:2] + (0, 0, 0) for t in found}


def test_radius_matches_scipy(system_method):
    spatial = pytest.importorskip("scipy.spatial", reason="scipy is not installed")
    rng = np.random.default_rng(11)
    points = rng.random((300, 3)).astype(np.float32)
    queries = rng.random((50, 3)).astype(np.float32)
    cutoff = 0.15
    i, j = pyraycut.radius(points, queries, cutoff, method=system_method)
    rows = spatial.cKDTree(points.astype(np.float64)).query_ball_point(queries, cutoff)
    ours = {}
    for a, b in zip(i.tolist(), j.tolist()):
        ours.setdefault(a, set()).add(b)
    d = np.linalg.norm(points[None].astype(np.float64) - queries[:, None], axis=-1)
    for q, row in enumerate(rows):
        sure = {p for p in row if abs(d[q, p] - cutoff) > REL * cutoff}
        assert sure <= ours.get(q, set())
        assert {p for p in ours.get(q, set()) if abs(d[q, p] - cutoff) > REL * cutoff} == sure


@pytest.mark.parametrize("name", ["triclinic", "small-triclinic", "slab"])
def test_radius_periodic(system_method, name):
    points, cell, pbc, cutoff = case(name, seed=12)
    queries = unwrapped(inside_cell(25, cell, pbc, seed=13), cell, pbc, 2, seed=14)
    out = pyraycut.radius(points, queries, cutoff, cell=cell, pbc=pbc, method=system_method,
                        quantities="ijdDS")
    check(out, queries, points, cutoff, cell, pbc, exclude_self=False)


def test_radius_batched(system_method):
    cutoff = 0.45
    sizes_p = [5, 0, 12, 30, 3, 20, 0]
    sizes_q = [0, 4, 12, 10, 0, 6, 2]  # queries without points and points without queries
    points, bp = batched(sizes_p, BATCH_CELLS, BATCH_PBC, seed=20)
    queries, bq = batched(sizes_q, BATCH_CELLS, BATCH_PBC, seed=40)
    out = pyraycut.radius(points, queries, cutoff, cell=np.stack(BATCH_CELLS), pbc=BATCH_PBC,
                        batch_points=bp, batch_queries=bq, method=system_method,
                        quantities="ijdDS")
    i, j, d, D, S = out
    assert np.array_equal(bq[i], bp[j])
    assert np.all(np.diff(i) >= 0)
    found = triples(i, j, S)
    inside, edge = batch_reference(points, bp, cutoff, BATCH_CELLS, BATCH_PBC, queries, bq)
    assert found - edge == inside - edge
    # One index left out: that whole set is in system 0 (torch_cluster's convention).
    p0 = points[bp == 0]
    got = pyraycut.radius(p0, queries, cutoff, cell=np.eye(3), batch_queries=bq,
                        method=system_method, quantities="ijS")
    inside, edge = batch_reference(p0, np.zeros(len(p0), np.int64), cutoff, [np.eye(3)] * 7,
                                   [(True,) * 3] * 7, queries, bq)
    assert triples(*got) - edge == inside - edge


def test_engine_queries_and_shifts(system_method):
    points, cell, pbc, cutoff = case("small-triclinic", seed=30)
    queries = inside_cell(7, cell, pbc, seed=31)
    engine = pyraycut.Engine(system_method)
    engine.build(points, cutoff, cell=cell, pbc=pbc, queries=queries)
    assert engine.size == 7 and engine.sources == len(points)
    offsets, indices, d, D, S = engine.neighbours(distances=True, vectors=True, shifts=True)
    assert offsets.shape == (8,) and S.dtype == np.int32 and S.shape == (len(indices), 3)
    rows = np.repeat(np.arange(7), np.diff(offsets))
    found = triples(rows, indices, S)
    inside, edge = reference(queries, points, cutoff, cell, pbc, exclude_self=False)
    assert found - edge == inside - edge
    count = engine.compute("count")["count"]
    np.testing.assert_array_equal(count, np.diff(offsets))
    with pytest.raises(ValueError, match="half"):
        engine.neighbours(half=True)
    # Plain CSR without the extras: two arrays, as before.
    assert len(engine.neighbours()) == 2


def test_engine_periodic_update_and_kernels(system_method):
    x, cell, pbc, cutoff = case("small-triclinic", seed=33)
    engine = pyraycut.Engine(system_method)
    engine.build(x, cutoff, cell=cell, pbc=pbc)
    moved = unwrapped(inside_cell(len(x), cell, pbc, seed=34), cell, pbc, 2, seed=35)
    engine.update(moved)  # the box kept
    offsets, indices, S = engine.neighbours(shifts=True)
    rows = np.repeat(np.arange(len(x)), np.diff(offsets))
    inside, edge = reference(moved, moved, cutoff, cell, pbc)
    assert triples(rows, indices, S) - edge == inside - edge
    np.testing.assert_array_equal(engine.compute("count")["count"], np.diff(offsets))
    # A pair kernel sums over every image: the smooth kernel's energy from the list's vectors.
    out = engine.compute("smooth")
    r = moved[indices].astype(np.float64) - moved[rows] + S @ np.asarray(cell)
    w = cutoff**2 - (r**2).sum(1)
    np.testing.assert_allclose(out["energy"], np.bincount(rows, w**2, minlength=len(x)),
                               rtol=1e-3, atol=1e-9)
    # Queries are built, not updated.
    engine.build(x, cutoff, cell=cell, pbc=pbc, queries=x[:3])
    with pytest.raises(NotImplementedError):
        engine.update(x)


# ---- errors ------------------------------------------------------------------------------------


def test_padded_rows_carry_shifts(system_method):
    """The padded matrix with S holds each CSR row's (j, S) entries, then N with S = 0: in a cell
    thinner than the cutoff a row holds a source once per image."""
    cell = np.array([[0.6, 0.0, 0.0], [0.2, 0.7, 0.0], [0.1, 0.1, 0.8]])
    x = inside_cell(12, cell, seed=5)
    engine = pyraycut.Engine(system_method)
    engine.build(x, 1.0, cell=cell, pbc=True)
    offsets, indices, shifts = (np.asarray(a) for a in engine.neighbours(shifts=True))
    k = int(np.diff(offsets).max()) + 1
    idx, counts, report, s = engine.padded_neighbours(k, shifts=True)
    idx, counts, s = np.asarray(idx), np.asarray(counts), np.asarray(s)
    assert not report["overflowed"] and s.shape == (len(x), k, 3)
    for i in range(len(x)):
        row = slice(offsets[i], offsets[i + 1])
        want = sorted(zip(indices[row].tolist(), map(tuple, shifts[row].tolist())))
        c = int(counts[i])
        assert c == offsets[i + 1] - offsets[i]
        assert sorted(zip(idx[i, :c].tolist(), map(tuple, s[i, :c].tolist()))) == want
        assert np.all(idx[i, c:] == len(x)) and np.all(s[i, c:] == 0)
    assert len(engine.padded_neighbours(k)) == 3  # no shifts asked: the three outputs as before


def test_errors():
    x = inside_cell(10, np.eye(3))
    method = SYSTEM_METHODS[0]
    with pytest.raises(ValueError, match="linearly dependent"):  # the library's message
        pyraycut.neighbor_list("ij", x, 0.3, cell=[[1, 0, 0], [2, 0, 0], [0, 0, 1]], method=method)
    with pytest.raises(ValueError, match="zero length"):
        pyraycut.neighbor_list("ij", x, 0.3, cell=np.diag([1.0, 1.0, 0.0]), pbc=True,
                             method=method)
    with pytest.raises(ValueError, match="non-finite"):
        pyraycut.neighbor_list("ij", x, 0.3, cell=np.diag([1.0, 1.0, np.nan]), method=method)
    batch = np.array([0, 0, 1, 1, 1, 0, 2, 2, 2, 2])
    with pytest.raises(ValueError, match="sorted"):
        pyraycut.neighbor_list("ij", x, 0.3, batch=batch, method=method)
    with pytest.raises(ValueError, match="sorted"):
        pyraycut.radius(x, x, 0.3, batch_points=np.sort(batch), batch_queries=batch, method=method)
    with pytest.raises(ValueError, match="one system index per particle"):
        pyraycut.neighbor_list("ij", x, 0.3, batch=np.zeros(9, np.int64), method=method)
    with pytest.raises(ValueError, match="integers"):
        pyraycut.neighbor_list("ij", x, 0.3, batch=np.zeros(10), method=method)
    with pytest.raises(ValueError, match="negative"):
        pyraycut.neighbor_list("ij", x, 0.3, batch=np.full(10, -1), method=method)
    with pytest.raises(ValueError, match="no batch"):
        pyraycut.neighbor_list("ij", x, 0.3, cell=np.stack([np.eye(3)] * 2), method=method)
    with pytest.raises(ValueError, match="system index 2 but"):
        pyraycut.neighbor_list("ij", x, 0.3, cell=np.stack([np.eye(3)] * 2),
                             batch=np.sort(batch), method=method)
    with pytest.raises(ValueError, match="cell gives 2 systems but pbc 3"):
        pyraycut.neighbor_list("ij", x, 0.3, cell=np.stack([np.eye(3)] * 2), pbc=[[True] * 3] * 3,
                             batch=np.sort(batch) // 2, method=method)
    with pytest.raises(ValueError, match="cell must have shape"):
        pyraycut.neighbor_list("ij", x, 0.3, cell=np.eye(2), method=method)
    with pytest.raises(ValueError, match="pbc must be"):
        pyraycut.neighbor_list("ij", x, 0.3, cell=np.eye(3), pbc=[True, False], method=method)
    with pytest.raises(ValueError, match="pbc without a cell"):
        pyraycut.neighbor_list("ij", x, 0.3, pbc=True, method=method)
    engine = pyraycut.Engine(method)
    engine.build(x, 0.3, queries=x)
    with pytest.raises(ValueError, match="half lists are not defined for query sets"):
        engine.neighbours(half=True)
    with pytest.raises(ValueError, match="queries must have shape"):
        pyraycut.radius(x, np.zeros((4, 2), np.float32), 0.3, method=method)
    with pytest.raises(ValueError, match="batch_queries without queries"):
        pyraycut.Engine(method).build(x, 0.3, batch_queries=np.zeros(10, np.int64))
    with pytest.raises(ValueError, match="unknown quantity"):
        pyraycut.radius(x, x, 0.3, quantities="ijk", method=method)
    # NaN positions still name their index with a box.
    bad = x.copy()
    bad[4, 2] = np.nan
    with pytest.raises(ValueError, match="index 4"):
        pyraycut.neighbor_list("ij", bad, 0.3, cell=np.eye(3), method=method)


@pytest.mark.parametrize("method", [m for m in AVAILABLE if m not in SYSTEM_METHODS])
def test_methods_without_systems_say_so(method):
    x = inside_cell(20, np.eye(3))
    with pytest.raises(NotImplementedError):
        pyraycut.neighbor_list("ij", x, 0.3, cell=np.eye(3), method=method)
    with pytest.raises(NotImplementedError):
        pyraycut.radius(x, x, 0.3, method=method)
    pyraycut.neighbor_list("ij", x, 0.3, method=method)  # open single systems as before


# ---- PyTorch autograd --------------------------------------------------------------------------


def torch_double():
    torch = pytest.importorskip("torch", reason="PyTorch is not installed (the GPU machine has it)")
    return torch


def pooled(torch, n, i, d, D):
    """Per-particle sums of smooth functions of d and D: independent of the order of pairs, so
    gradcheck's perturbed calls compare like with like."""
    energy = torch.zeros(n, dtype=d.dtype).index_add(0, i, torch.exp(-d * d))
    field = torch.zeros(n, 3, dtype=D.dtype).index_add(0, i, D * torch.cos(d)[:, None])
    return energy, field


@pytest.mark.parametrize("name", ["triclinic", "small-triclinic", "mixed-triclinic"])
def test_torch_gradcheck_positions_and_cell(system_method, name):
    torch = torch_double()
    x, cell, pbc, cutoff = case(name, seed=50)
    x = torch.tensor(unwrapped(x, cell, pbc, 2, seed=51), dtype=torch.float64,
                     requires_grad=True)
    c = torch.tensor(cell, dtype=torch.float64, requires_grad=True)

    def f(x, c):
        i, d, D = pyraycut.neighbor_list("idD", x, cutoff, cell=c, pbc=pbc, method=system_method)
        assert d.dtype == torch.float64 and D.dtype == torch.float64
        return pooled(torch, len(x), i, d, D)

    assert torch.autograd.gradcheck(f, (x, c), eps=1e-6, atol=1e-6)
    # D is x[j] - x[i] + S @ cell, as the library's float32 vectors.
    i, j, D, S = pyraycut.neighbor_list("ijDS", x, cutoff, cell=c, pbc=pbc, method=system_method)
    want = x[j] - x[i] + S.double() @ c
    torch.testing.assert_close(D, want)
    D32 = pyraycut.neighbor_list("D", x.detach().float(), cutoff, cell=cell, pbc=pbc,
                               method=system_method)
    assert D32.shape == D.shape


def test_torch_cell_forms_and_devices_of_outputs(system_method):
    torch = torch_double()
    x, cell, pbc, cutoff = case("small-cubic", seed=55)
    edges = torch.tensor([1.0, 1.0, 1.0], dtype=torch.float64, requires_grad=True)
    xt = torch.tensor(x, dtype=torch.float64, requires_grad=True)
    i, j, d, S = pyraycut.neighbor_list("ijdS", xt, cutoff, cell=edges, method=system_method)
    assert S.dtype == torch.int32 and i.dtype == torch.int64 and d.dtype == torch.float64
    (g,) = torch.autograd.grad(d.sum(), edges)
    # d |r| / d L_k = sum over pairs of S_k r_k / |r| (r = x_j - x_i + S L).
    r = xt.detach()[j] - xt.detach()[i] + S.double() * edges.detach()
    torch.testing.assert_close(g, (S.double() * r / d.detach()[:, None]).sum(0))
    one = pyraycut.neighbor_list("d", xt, cutoff, cell=torch.eye(3, dtype=torch.float64)[None],
                               method=system_method)
    torch.testing.assert_close(torch.sort(one.detach()).values, torch.sort(d.detach()).values)


def test_torch_gradcheck_batch_and_radius(system_method):
    torch = torch_double()
    cutoff = 0.45
    sizes = [4, 0, 6, 5]
    cells, pbcs = BATCH_CELLS[:4], BATCH_PBC[:4]
    x, batch = batched(sizes, cells, pbcs, seed=60)
    x = torch.tensor(x, dtype=torch.float64, requires_grad=True)
    c = torch.tensor(np.stack(cells), dtype=torch.float64, requires_grad=True)
    b = torch.from_numpy(batch)

    def f(x, c):
        i, d, D = pyraycut.neighbor_list("idD", x, cutoff, cell=c, pbc=pbcs, batch=b,
                                       method=system_method)
        return pooled(torch, len(x), i, d, D)

    assert torch.autograd.gradcheck(f, (x, c), eps=1e-6, atol=1e-6)
    q = torch.tensor(inside_cell(6, cells[3], pbcs[3], seed=61), dtype=torch.float64,
                     requires_grad=True)
    p = x.detach()[torch.from_numpy(batch == 3)].clone().requires_grad_()
    c3 = c.detach()[3].clone().requires_grad_()

    def g(p, q, c):
        i, d, D = pyraycut.radius(p, q, cutoff, cell=c, method=system_method, quantities="idD")
        return pooled(torch, len(q), i, d, D)

    assert torch.autograd.gradcheck(g, (p, q, c3), eps=1e-6, atol=1e-6)


def test_torch_stress_from_cell_gradient(system_method):
    """The virial from the cell gradient of a pair energy equals -sum r_ij (x) f_ij (what ML
    potentials compute their stress from)."""
    torch = torch_double()
    x, cell, pbc, cutoff = case("small-triclinic", seed=70)
    x = torch.tensor(x, dtype=torch.float64, requires_grad=True)
    strain = torch.zeros(3, 3, dtype=torch.float64, requires_grad=True)
    c0 = torch.tensor(cell, dtype=torch.float64)
    deform = torch.eye(3, dtype=torch.float64) + strain
    d = pyraycut.neighbor_list("d", x @ deform, cutoff, cell=c0 @ deform, pbc=pbc,
                             method=system_method)
    energy = 0.5 * torch.sum((cutoff - d) ** 2)
    (g_strain,) = torch.autograd.grad(energy, strain)
    D = pyraycut.neighbor_list("D", x, cutoff, cell=c0, pbc=pbc, method=system_method).detach()
    dd = torch.linalg.vector_norm(D, dim=1)
    dE_dD = (-(cutoff - dd) / dd)[:, None] * D  # per pair of the full list
    # D = D0 @ (1 + strain): dE/dstrain = sum over pairs of D0 (outer) dE/dD.
    torch.testing.assert_close(g_strain, D.T @ dE_dD, rtol=1e-6, atol=1e-9)
