"""pyraycut.torch.knn / knn_graph in periodic boxes against a float64 NumPy brute force that
enumerates the images explicitly: cubic, triclinic, partially periodic, boxes smaller than the
k nearest (a point several times, through several images), batches with a box per system,
ties (by index, then by image shift), float32 and float64."""
import itertools

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="PyTorch is not installed")
import pyraycut.torch as rt  # noqa: E402

TRICLINIC = np.array([[3.0, 0.0, 0.0], [0.9, 2.6, 0.0], [-0.7, 0.5, 2.8]])


def oracle(x, y, k, cell, pbc, exclude_self=False, reach=4):
    """For each query row of y: [(j, S), ...], its k nearest images x[j] + S @ cell (ties by j,
    then S), nearest first, from every shift with |S_a| <= reach on the periodic axes. Fails if
    an image past that reach could be nearer than the k-th."""
    x, y, cell = (np.asarray(a, np.float64) for a in (x, y, cell))
    pbc = np.broadcast_to(np.asarray(pbc, bool), (3,))
    ranges = [range(-reach, reach + 1) if p else range(1) for p in pbc]
    shifts = np.array(list(itertools.product(*ranges)), np.int64)
    # The nearest an image past the reach can be: (reach + 1 - spread) plane spacings.
    spacing = 1.0 / np.linalg.norm(np.linalg.inv(cell).T, axis=1)
    fractional = np.concatenate([x, y]) @ np.linalg.inv(cell)
    spread = fractional.max(0) - fractional.min(0)
    horizon = min([(reach + 1 - spread[a]) * spacing[a] for a in range(3) if pbc[a]],
                  default=np.inf)
    images = len(shifts)
    index = np.repeat(np.arange(len(x)), images)
    image_shifts = np.tile(shifts, (len(x), 1))
    rows = []
    for q in range(len(y)):
        v = (x[index] - y[q]) + image_shifts @ cell
        d = np.linalg.norm(v, axis=1)
        keep = ~((index == q) & ~image_shifts.any(1)) if exclude_self else np.ones(len(d), bool)
        order = np.lexsort((image_shifts[:, 2], image_shifts[:, 1], image_shifts[:, 0], index,
                            d))
        order = order[keep[order]][:k]
        if len(order) == k:
            assert d[order[-1]] < horizon, "the oracle's reach is too short"
        rows.append([(int(index[o]), tuple(int(c) for c in image_shifts[o])) for o in order])
    return rows


def rows_of(edge_index, shifts, queries, centre_row=0):
    """[(j, S), ...] per query, in the order returned."""
    centres, others = edge_index[centre_row].tolist(), edge_index[1 - centre_row].tolist()
    rows = [[] for _ in range(queries)]
    for c, o, s in zip(centres, others, shifts.tolist()):
        rows[c].append((o, tuple(s)))
    return rows


def positions(n, cell, seed, low=0.0, high=1.0, dtype=torch.float64):
    fractional = np.random.default_rng(seed).uniform(low, high, (n, 3))
    return torch.tensor(fractional @ np.asarray(cell, np.float64), dtype=dtype)


# float32 positions take the library's nearest-K list on the CPU; float64 ones off float32, the
# pair lists ordered in float64.
DTYPES = [torch.float32, torch.float64]


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("cell, pbc", [
    (np.diag([2.5, 2.5, 2.5]), True),
    (TRICLINIC, True),
    (TRICLINIC, [True, False, True]),
    (np.diag([2.0, 3.0, 2.5]), [False, False, True]),
])
def test_knn_graph_is_the_k_nearest_images(cell, pbc, dtype):
    x = positions(40, cell, 1, dtype=dtype)
    k = 7
    edge_index, shifts = rt.knn_graph(x, k, cell=torch.tensor(cell), pbc=pbc)
    assert shifts.dtype == torch.int32 and shifts.shape == (edge_index.shape[1], 3)
    # source_to_target: row 1 the centre, row 0 its neighbour.
    assert rows_of(edge_index, shifts, len(x), centre_row=1) == oracle(x, x, k, cell, pbc,
                                                                        exclude_self=True)
    open_axes = ~np.broadcast_to(np.asarray(pbc, bool), (3,))
    assert not shifts[:, torch.from_numpy(open_axes.copy())].any()


@pytest.mark.parametrize("dtype", DTYPES)
def test_knn_between_sets_in_a_triclinic_box_unwrapped(dtype):
    """Queries and points partly outside the cell: the shifts refer to the positions as given."""
    x = positions(50, TRICLINIC, 2, low=-0.3, high=1.3, dtype=dtype)
    y = positions(20, TRICLINIC, 3, low=-0.3, high=1.3, dtype=dtype)
    edge_index, shifts = rt.knn(x, y, 9, cell=torch.tensor(TRICLINIC))
    assert rows_of(edge_index, shifts, len(y)) == oracle(x, y, 9, TRICLINIC, True)
    # The vectors the shifts give are the distances' order: nearest first in each row.
    v = (x[edge_index[1]] - y[edge_index[0]]).double() + shifts.double() @ torch.tensor(TRICLINIC)
    d = v.norm(dim=1)
    same_row = edge_index[0][1:] == edge_index[0][:-1]
    assert bool((d[1:][same_row] >= d[:-1][same_row]).all())


@pytest.mark.parametrize("dtype", DTYPES)
def test_k_above_the_points_of_a_small_box_takes_several_images(dtype):
    cell = np.diag([1.2, 1.0, 1.4])
    x = positions(3, cell, 4, dtype=dtype)
    edge_index, shifts = rt.knn_graph(x, 20, cell=cell, flow="target_to_source")
    got = rows_of(edge_index, shifts, 3)  # target_to_source: row 0 the centre
    assert got == oracle(x, x, 20, cell, True, exclude_self=True)
    assert all(len(row) == 20 for row in got)
    assert all(any(j == c for j, _ in row) for c, row in enumerate(got))  # its own images
    # loop: the point itself (shift 0) first, then the same images.
    looped, looped_shifts = rt.knn_graph(x, 21, cell=cell, loop=True, flow="target_to_source")
    for c, row in enumerate(rows_of(looped, looped_shifts, 3)):
        assert row[0] == (c, (0, 0, 0)) and row[1:] == got[c]


@pytest.mark.parametrize("dtype", DTYPES)
def test_ties_are_broken_by_index_then_by_shift(dtype):
    """One particle in a cubic box: its six nearest images are at the same distance."""
    x = torch.tensor([[0.3, 0.4, 0.5]], dtype=dtype)
    edge_index, shifts = rt.knn_graph(x, 4, cell=[2.0, 2.0, 2.0])
    assert edge_index.tolist() == [[0] * 4, [0] * 4]
    assert shifts.tolist() == [[-1, 0, 0], [0, -1, 0], [0, 0, -1], [0, 0, 1]]
    # Two particles at the same place: the lower index first at equal distance.
    y = torch.tensor([[1.0, 1.0, 1.0]], dtype=dtype)
    pair = torch.cat([x, x])
    edge_index, shifts = rt.knn(pair, y, 3, cell=[2.0, 2.0, 2.0])
    assert edge_index[1].tolist() == [0, 1, 0] and shifts[0].tolist() == shifts[1].tolist()
    assert rows_of(edge_index, shifts, 1) == oracle(pair, y, 3, np.eye(3) * 2.0, True)


@pytest.mark.parametrize("dtype", DTYPES)
def test_batches_with_a_box_per_system(dtype):
    cells = np.stack([np.diag([2.0, 2.0, 2.0]), TRICLINIC, np.diag([1.5, 1.5, 3.0]),
                      np.diag([4.0, 4.0, 4.0])])
    pbc = np.array([[True, True, True], [True, False, True], [True, True, True],
                    [False, False, False]])
    sizes = [12, 15, 1, 3]  # system 2: one particle; system 3: open, fewer than k
    x = torch.cat([positions(s, c, 10 + b, dtype=dtype)
                   for b, (s, c) in enumerate(zip(sizes, cells))])
    batch = torch.repeat_interleave(torch.arange(4), torch.tensor(sizes))
    k = 5
    edge_index, shifts = rt.knn_graph(x, k, batch, cell=torch.tensor(cells), pbc=pbc)
    got = rows_of(edge_index, shifts, len(x), centre_row=1)
    start = 0
    for b, size in enumerate(sizes):
        part = x[start:start + size]
        want = oracle(part, part, k, cells[b], pbc[b], exclude_self=True)
        want = [[(j + start, s) for j, s in row] for row in want]
        assert got[start:start + size] == want, b
        start += size
    assert [len(row) for row in got[-3:]] == [2, 2, 2]  # the open system: all the others
    # Queries of a batch against points of a batch (knn), one query system empty.
    y = torch.cat([positions(4, cells[0], 20, dtype=dtype),
                   positions(3, cells[1], 21, dtype=dtype)])
    batch_y = torch.tensor([0, 0, 0, 0, 1, 1, 1])
    edge_index, shifts = rt.knn(x, y, k, batch, batch_y, cell=torch.tensor(cells), pbc=pbc)
    got = rows_of(edge_index, shifts, len(y))
    for q, b in enumerate(batch_y.tolist()):
        start = sum(sizes[:b])
        part = x[start:start + sizes[b]]
        want = oracle(part, y[q:q + 1], k, cells[b], pbc[b])[0]
        assert got[q] == [(j + start, s) for j, s in want], q


def test_queries_of_a_system_without_points_get_none():
    """batch_x None: every point is in system 0, so queries of system 1 have no neighbour
    (torch_cluster's convention), periodic or not."""
    cell = np.diag([2.0, 2.0, 2.0])
    x, y = positions(6, cell, 7), positions(3, cell, 8)
    edge_index, shifts = rt.knn(x, y, 4, None, torch.tensor([0, 0, 1]), cell=cell)
    assert edge_index[0].tolist() == [0] * 4 + [1] * 4
    assert rows_of(edge_index, shifts, 3) == oracle(x, y[:2], 4, cell, True) + [[]]
    assert rt.knn(x, y, 4, None, torch.tensor([0, 0, 1]))[0].tolist() == [0] * 4 + [1] * 4


def test_float32_positions_and_open_boxes_keep_their_forms():
    cell = np.diag([2.2, 2.4, 2.6])
    x64 = positions(30, cell, 5)
    edge_index, shifts = rt.knn_graph(x64.float(), 6, cell=torch.tensor(cell, dtype=torch.float32))
    assert rows_of(edge_index, shifts, 30, 1) == oracle(x64, x64, 6, cell, True, exclude_self=True)
    # No cell: edge_index alone, as torch_cluster returns it.
    open_graph = rt.knn_graph(x64, 6)
    assert isinstance(open_graph, torch.Tensor) and open_graph.shape == (2, 180)
    # A cell with no periodic axis: the open answer, with zero shifts.
    edge_index, shifts = rt.knn_graph(x64, 6, cell=cell, pbc=False)
    assert torch.equal(edge_index, open_graph) and not shifts.any()


def test_bad_periodic_input_is_named():
    x = positions(5, np.eye(3), 6)
    with pytest.raises(ValueError, match="cell must have shape"):
        rt.knn_graph(x, 2, cell=[1.0, 2.0])
    with pytest.raises(ValueError, match="pbc without a cell"):
        rt.knn(x, x, 2, pbc=True)
    with pytest.raises(ValueError, match="system index 2 but cell/pbc give 2 systems"):
        rt.knn_graph(x, 2, torch.tensor([0, 0, 1, 2, 2]), cell=np.stack([np.eye(3)] * 2))
    with pytest.raises(ValueError, match="k must be a whole number >= 1, got 0"):
        rt.knn_graph(x, 0, cell=np.eye(3))


def test_coincident_points_and_a_lone_point_on_one_periodic_axis():
    """Zero extent: the first radius is still one the library takes."""
    graph = rt.knn_graph(torch.zeros(5, 3), 2)
    assert graph[1].tolist() == [0, 0, 1, 1, 2, 2, 3, 3, 4, 4]
    assert graph[0].tolist() == [1, 2, 0, 2, 0, 1, 0, 1, 0, 1]  # ties: the lowest indices
    x = torch.zeros(1, 3, dtype=torch.float64)
    edge_index, shifts = rt.knn_graph(x, 3, cell=[1.0, 1.0, 1.0], pbc=[True, False, False])
    assert shifts.tolist() == [[-1, 0, 0], [1, 0, 0], [-2, 0, 0]]
