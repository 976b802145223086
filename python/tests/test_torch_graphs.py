"""pyraycut.torch (radius, radius_graph, knn, knn_graph: torch_cluster's signatures and
edge_index conventions) against a float64 brute force, batched, with caps, loops and flows."""
import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="PyTorch is not installed")
import pyraycut  # noqa: E402
import pyraycut.torch as rt  # noqa: E402


def cloud(n, seed, scale=1.0):
    return torch.from_numpy(np.random.default_rng(seed).random((n, 3)).astype(np.float32) * scale)


def distances(y, x):
    return torch.cdist(y.double(), x.double())


def same_system(by, bx, m, n):
    by = torch.zeros(m, dtype=torch.int64) if by is None else by
    bx = torch.zeros(n, dtype=torch.int64) if bx is None else bx
    return by[:, None] == bx[None, :]


def edges(edge_index):
    return set(map(tuple, edge_index.t().tolist()))


@pytest.mark.parametrize("batched", [False, True])
def test_radius_and_radius_graph_match_brute_force(batched):
    x, y = cloud(200, 1), cloud(50, 2)
    bx = torch.repeat_interleave(torch.arange(4), 50) if batched else None
    by = torch.repeat_interleave(torch.arange(4), torch.tensor([10, 0, 25, 15])) if batched else None
    within = (distances(y, x) < 0.2) & same_system(by, bx, 50, 200)
    want = {(int(a), int(b)) for a, b in zip(*torch.nonzero(within, as_tuple=True))}
    assert edges(rt.radius(x, y, 0.2, bx, by)) == want
    graph = rt.radius_graph(x, 0.2, bx)
    self_within = (distances(x, x) < 0.2) & same_system(bx, bx, 200, 200)
    self_within.fill_diagonal_(False)
    centre, neighbour = torch.nonzero(self_within, as_tuple=True)
    assert edges(graph) == {(int(b), int(a)) for a, b in zip(centre, neighbour)}  # (source, target)
    flipped = rt.radius_graph(x, 0.2, bx, flow="target_to_source")
    assert edges(flipped) == {(b, a) for a, b in edges(graph)}
    looped = rt.radius_graph(x, 0.2, bx, loop=True)
    assert edges(looped) == edges(graph) | {(p, p) for p in range(200)}


def test_max_num_neighbors_keeps_the_nearest_and_says_so():
    x = cloud(300, 3)
    d = distances(x, x)
    with pytest.warns(RuntimeWarning, match="max_num_neighbors=4"):
        graph = rt.radius_graph(x, 0.3, max_num_neighbors=4)
    d.fill_diagonal_(float("inf"))
    for target in range(300):
        got = sorted(graph[0][graph[1] == target].tolist())
        order = sorted(range(300), key=lambda j: (float(d[target, j]), j))
        within = [j for j in order if d[target, j] < 0.3]
        assert got == sorted(within[:4]), target
    with pytest.raises(pyraycut.CapacityError, match="max_num_neighbors=4"):
        rt.radius_graph(x, 0.3, max_num_neighbors=4, on_overflow="raise")
    # No cap by default: every pair, no warning.
    assert rt.radius_graph(x, 0.3).shape[1] == int((d < 0.3).sum())


@pytest.mark.parametrize("batched", [False, True])
def test_knn_is_exact(batched):
    x = cloud(400, 4)
    y = cloud(60, 5)
    x[7] = x[8]  # a tie: broken by index
    bx = torch.repeat_interleave(torch.arange(3), torch.tensor([395, 3, 2])) if batched else None
    by = torch.repeat_interleave(torch.arange(3), 20) if batched else None
    k = 6
    got = rt.knn(x, y, k, bx, by)
    d = distances(y, x)
    allowed = same_system(by, bx, 60, 400)
    for q in range(60):
        candidates = [j for j in range(400) if allowed[q, j]]
        want = sorted(candidates, key=lambda j: (float(d[q, j]), j))[:k]
        assert sorted(got[1][got[0] == q].tolist()) == sorted(want), q  # systems of 3 and 2: all


def test_knn_graph_loops_and_far_clusters():
    # Two clusters 1e4 apart: the doubling radius reaches the far one only where it must.
    x = torch.cat([cloud(100, 6), cloud(5, 7) + 1e4])
    k = 8
    graph = rt.knn_graph(x, k)
    assert not any(a == b for a, b in edges(graph))
    d = distances(x, x)
    d.fill_diagonal_(float("inf"))
    for target in range(105):
        want = sorted(range(105), key=lambda j: (float(d[target, j]), j))[:k]
        assert sorted(graph[0][graph[1] == target].tolist()) == sorted(want), target
    looped = rt.knn_graph(x, k, loop=True)
    assert all((p, p) in edges(looped) for p in range(105))
    assert looped.shape[1] == 105 * k


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_rows_nearest_first_breaks_ties_by_index_then_shift(dtype):
    # The order knn and capped radius lists keep: by row, nearest first, equal distances by j,
    # then by S. Distances from 4 values (and float64 ones that round to one float32) tie often.
    g = torch.Generator().manual_seed(3)
    n = 3000
    i = torch.randint(0, 40, (n,), generator=g)
    j = torch.randint(0, 50, (n,), generator=g)
    s = torch.randint(-1, 2, (n, 3), generator=g, dtype=torch.int32)
    d = torch.randint(0, 4, (n,), generator=g).to(dtype)
    if dtype == torch.float64:
        d = d + torch.randint(0, 2, (n,), generator=g).to(dtype) * 1e-12
    order = rt._nearest_first(i, j, d, s).tolist()
    key = [(int(i[e]), float(d[e]), int(j[e]), *s[e].tolist(), e) for e in range(n)]
    assert order == [t[-1] for t in sorted(key)]


def test_uncapped_radius_graph_rows_stay_in_order_with_each_loop_first():
    """No max_num_neighbors: the list's rows as they come (i ascending), nothing sorted by
    distance; with loop, each point's own edge opens its row, and the edges are the list's plus
    one loop per point."""
    x = torch.rand(300, 3, generator=torch.Generator().manual_seed(8))
    i, j = rt.radius_graph(x, 0.2, loop=True, flow="target_to_source")
    assert bool((i[1:] >= i[:-1]).all())
    first = torch.ones(len(i), dtype=torch.bool)
    first[1:] = i[1:] != i[:-1]
    assert torch.equal(i[first], torch.arange(300)) and torch.equal(j[first], i[first])
    li, lj = pyraycut.neighbor_list("ij", x, 0.2)
    assert sorted(zip(i[~first].tolist(), j[~first].tolist())) == sorted(zip(li.tolist(),
                                                                             lj.tolist()))
