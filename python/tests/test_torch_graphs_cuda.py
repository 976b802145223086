"""pyraycut.torch (radius_graph, knn, knn_graph) on CUDA tensors against a float64 brute force,
on every input family (uniform, clustered, coincident points, far clusters, batches with empty
systems, periodic cubic, triclinic and partially periodic boxes, positions outside the cell),
float32 and float64. Outputs stay on the device, and equal the CPU's edge for edge, in order."""
import numpy as np
import pytest

import pyraycut
from conftest import clustered, coincident, uniform

torch = pytest.importorskip("torch", reason="PyTorch is not installed")
if not (pyraycut.cuda_available() and torch.cuda.is_available()):
    pytest.skip("no CUDA device that both raycut and PyTorch can use", allow_module_level=True)
import pyraycut.torch as rt  # noqa: E402
from test_torch_knn_periodic import TRICLINIC, oracle, positions, rows_of  # noqa: E402

CUDA = torch.device("cuda")


def brute_knn(x, y, k, allowed=None, exclude_self=False):
    """Per query, its k nearest points of x by float64 distance, ties by index."""
    d = torch.cdist(y.double().cpu(), x.double().cpu())
    rows = []
    for q in range(len(y)):
        candidates = [j for j in range(len(x))
                      if (allowed is None or allowed[q, j]) and not (exclude_self and j == q)]
        rows.append(sorted(candidates, key=lambda j: (float(d[q, j]), j))[:k])
    return rows


def on_cuda(*tensors):
    for t in tensors:
        assert t.device.type == "cuda", t.device


FAMILIES = {
    "uniform": lambda: uniform(500, 11),
    "clustered": lambda: clustered(400, 12),
    "coincident": lambda: coincident(200, 13),
    "far clusters": lambda: np.concatenate([uniform(120, 14), uniform(6, 15) + 1e4]),
}


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("family", list(FAMILIES))
def test_knn_graph_is_the_k_nearest(family, dtype):
    x = torch.from_numpy(FAMILIES[family]()).to(dtype)
    k = 7
    graph = rt.knn_graph(x.to(CUDA), k)
    on_cuda(graph)
    want = brute_knn(x, x, k, exclude_self=True)
    for target, row in enumerate(want):  # coincident points tie at 0: broken by index
        assert sorted(graph[0][graph[1] == target].tolist()) == sorted(row), target
    assert torch.equal(graph.cpu(), rt.knn_graph(x, k))


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_knn_between_batched_sets_with_an_empty_system(dtype):
    x = torch.from_numpy(uniform(400, 16)).to(dtype)
    y = torch.from_numpy(uniform(60, 17)).to(dtype)
    x[7] = x[8]  # a tie: broken by index
    bx = torch.repeat_interleave(torch.arange(4), torch.tensor([395, 3, 0, 2]))
    by = torch.repeat_interleave(torch.arange(4), torch.tensor([20, 15, 5, 20]))
    k = 6
    got = rt.knn(x.to(CUDA), y.to(CUDA), k, bx.to(CUDA), by.to(CUDA))
    on_cuda(got)
    allowed = by[:, None] == bx[None, :]
    for q, row in enumerate(brute_knn(x, y, k, allowed)):
        assert sorted(got[1][got[0] == q].tolist()) == sorted(row), q
    assert not bool((got[0] >= 35).logical_and(got[0] < 40).any())  # system 2 has no points
    assert torch.equal(got.cpu(), rt.knn(x, y, k, bx, by))


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("cell, pbc", [
    (np.diag([2.5, 2.5, 2.5]), True),
    (TRICLINIC, True),
    (TRICLINIC, [True, False, True]),
    (np.diag([2.0, 3.0, 2.5]), [False, False, True]),
])
def test_periodic_knn_graph_is_the_k_nearest_images(cell, pbc, dtype):
    x = positions(40, cell, 1, dtype=dtype)
    k = 7
    edge_index, shifts = rt.knn_graph(x.to(CUDA), k, cell=torch.tensor(cell).to(CUDA), pbc=pbc)
    on_cuda(edge_index, shifts)
    assert rows_of(edge_index.cpu(), shifts.cpu(), len(x), centre_row=1) == oracle(
        x, x, k, cell, pbc, exclude_self=True)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_periodic_knn_unwrapped_and_a_small_box(dtype):
    x = positions(50, TRICLINIC, 2, low=-0.3, high=1.3, dtype=dtype)
    y = positions(20, TRICLINIC, 3, low=-0.3, high=1.3, dtype=dtype)
    edge_index, shifts = rt.knn(x.to(CUDA), y.to(CUDA), 9, cell=torch.tensor(TRICLINIC))
    on_cuda(edge_index, shifts)
    assert rows_of(edge_index.cpu(), shifts.cpu(), len(y)) == oracle(x, y, 9, TRICLINIC, True)
    # k above the points of the box: a point through several of its images.
    cell = np.diag([1.2, 1.0, 1.4])
    small = positions(3, cell, 4, dtype=dtype)
    edge_index, shifts = rt.knn_graph(small.to(CUDA), 20, cell=cell, flow="target_to_source")
    assert rows_of(edge_index.cpu(), shifts.cpu(), 3) == oracle(small, small, 20, cell, True,
                                                                exclude_self=True)


@pytest.mark.parametrize("family", list(FAMILIES))
def test_radius_graph_matches_brute_force(family):
    x = torch.from_numpy(FAMILIES[family]())
    r = 0.12
    graph = rt.radius_graph(x.to(CUDA), r)
    on_cuda(graph)
    d = torch.cdist(x.double(), x.double())
    d.fill_diagonal_(float("inf"))
    want = {(int(b), int(a)) for a, b in zip(*torch.nonzero(d < r, as_tuple=True))}
    edge = {(int(b), int(a))
            for a, b in zip(*torch.nonzero((d - r).abs() <= 1e-5 * r, as_tuple=True))}
    got = set(map(tuple, graph.cpu().t().tolist()))
    assert got - edge == want - edge
