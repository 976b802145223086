"""torch_cluster's graph builders on raycut's search, for PyTorch Geometric users: ``radius``,
``radius_graph``, ``knn`` and ``knn_graph`` with torch_cluster's signatures and ``edge_index``
conventions (docs/compatibility.md). Open boxes (and periodic ones for kNN); ``batch`` vectors
as torch_cluster takes them.

Where they differ from torch_cluster, on purpose:

- ``max_num_neighbors`` defaults to None: no cap. With a cap, each row keeps its nearest
  neighbours (ties broken by index), deterministically, and a row over the cap is never cut
  silently: a ``RuntimeWarning`` names how many rows were cut (``on_overflow="raise"``:
  ``pyraycut.CapacityError`` instead).
- ``knn`` is exact: the k nearest points of each query (ties broken by index), found by radius
  searches whose radius doubles for the queries that have fewer than k points within it (a
  query whose open system has fewer than k points gets them all).
- ``knn`` and ``knn_graph`` also take periodic boxes (``cell``, ``pbc``): the k nearest images,
  returned with their shifts as ``(edge_index, shifts)``, which torch_cluster has no slot for.
"""
from __future__ import annotations

import math
import warnings
from typing import Any, Optional

import torch

from . import CapacityError, Engine, _host_cell, _systems, neighbor_list
from . import radius as _radius_pairs


def _by_row_nearest_first(i: torch.Tensor, d: torch.Tensor,
                          ties: tuple[torch.Tensor, ...]) -> torch.Tensor:
    """The order of the entries by row i, nearest first (d >= 0), equal distances by ``ties``
    (most significant first). One sort of an int64 key, i and the bits of d in float32 (which
    order like d), then the full comparison for the entries whose keys tie. (A stable sort per
    key over every entry, as before, took 664 ms for 1.6M entries against 70-100 ms, one CPU
    thread, 2026-12-05.)"""
    key = (i.to(torch.int64) << 32) | d.to(torch.float32).contiguous().view(torch.int32).to(torch.int64)
    order = torch.argsort(key, stable=True)  # stable: entries equal in every key keep their order
    if len(order) < 2:
        return order
    sorted_key = key[order]
    tied = sorted_key[1:] == sorted_key[:-1]
    if bool(tied.any()):
        # The tied entries hold whole groups of equal keys, in key order: sorting them all by the
        # full (i, d, ties) puts each group in order without moving it.
        mark = torch.zeros(len(order), dtype=torch.bool, device=order.device)
        mark[1:] |= tied
        mark[:-1] |= tied
        sub = order[mark]
        within = torch.arange(len(sub), device=sub.device)
        for column in (*reversed(ties), d, i):  # least significant first
            within = within[torch.argsort(column[sub][within], stable=True)]
        order[mark] = sub[within]
    return order


def _keep_nearest(i: torch.Tensor, j: torch.Tensor, d: torch.Tensor, k: Optional[int],
                  rows: int, on_overflow: str) -> tuple[torch.Tensor, torch.Tensor]:
    """At most k entries per row i: the nearest (ties by j), in (i, d, j) order; k None: every
    entry, in the order given (no cap, nothing to sort: the sort was a third of radius_graph)."""
    if k is None:
        return i, j
    order = _by_row_nearest_first(i, d, (j,))
    i, j = i[order], j[order]
    counts = torch.bincount(i, minlength=rows)
    over = int((counts > k).sum())
    if over == 0:
        return i, j
    message = (f"max_num_neighbors={k}: {over} of {rows} rows had more neighbours; each kept its "
               f"{k} nearest (the largest row had {int(counts.max())})")
    if on_overflow == "raise":
        raise CapacityError(message)
    warnings.warn(message, RuntimeWarning, stacklevel=3)
    starts = torch.cumsum(counts, 0) - counts
    rank = torch.arange(len(i), device=i.device) - starts[i]
    keep = rank < k
    return i[keep], j[keep]


def _check_overflow_mode(on_overflow: str) -> None:
    if on_overflow not in ("warn", "raise"):
        raise ValueError(f"on_overflow must be 'warn' or 'raise', got {on_overflow!r}")


def _check_flow(flow: str) -> None:
    if flow not in ("source_to_target", "target_to_source"):
        raise ValueError(f"flow must be 'source_to_target' or 'target_to_source', got {flow!r}")


def radius(x: torch.Tensor, y: torch.Tensor, r: float, batch_x: Any = None, batch_y: Any = None,
           max_num_neighbors: Optional[int] = None, on_overflow: str = "warn") -> torch.Tensor:
    """For each point of ``y``, the points of ``x`` within ``r``: ``edge_index`` (2, E) with
    row 0 indexing ``y`` and row 1 indexing ``x`` (torch_cluster.radius)."""
    _check_overflow_mode(on_overflow)
    if max_num_neighbors is None:  # no cap: no distances, nothing to order
        i, j = _radius_pairs(x, y, r, batch_points=batch_x, batch_queries=batch_y)
        return torch.stack([i, j])
    i, j, d = _radius_pairs(x, y, r, batch_points=batch_x, batch_queries=batch_y,
                            quantities="ijd")
    i, j = _keep_nearest(i, j, d.detach(), max_num_neighbors, len(y), on_overflow)
    return torch.stack([i, j])


def radius_graph(x: torch.Tensor, r: float, batch: Any = None, loop: bool = False,
                 max_num_neighbors: Optional[int] = None, flow: str = "source_to_target",
                 on_overflow: str = "warn") -> torch.Tensor:
    """Every pair of points of ``x`` within ``r`` as ``edge_index`` (2, E): with
    ``flow="source_to_target"`` row 0 holds the neighbour (source) and row 1 the centre (target),
    as torch_cluster.radius_graph. ``loop``: each point is its own neighbour too (counted in the
    cap, as the nearest). Edges come centre by centre (ascending); within a centre, nearest
    first with ``max_num_neighbors``, else in the list's order (its own edge first)."""
    _check_overflow_mode(on_overflow)
    _check_flow(flow)
    if max_num_neighbors is None:  # no cap: no distances, nothing to order
        i, j = neighbor_list("ij", x, r, batch=batch)
        if loop:
            i, j = _with_loops(i, j, len(x))
    else:
        i, j, d = neighbor_list("ijd", x, r, batch=batch)
        d = d.detach()
        if loop:
            own = torch.arange(len(x), device=i.device)
            i, j = torch.cat([i, own]), torch.cat([j, own])
            d = torch.cat([d, torch.zeros(len(x), dtype=d.dtype, device=d.device)])
        i, j = _keep_nearest(i, j, d, max_num_neighbors, len(x), on_overflow)
    return torch.stack([j, i] if flow == "source_to_target" else [i, j])


def _with_loops(i: torch.Tensor, j: torch.Tensor, n: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The rows (i ascending) with each point's own edge first in its row, where a sorted list
    would put it (the nearest), without sorting."""
    own = torch.arange(n, device=i.device)
    counts = torch.bincount(i, minlength=n)
    out_i = torch.empty(len(i) + n, dtype=i.dtype, device=i.device)
    out_j = torch.empty_like(out_i)
    at_own = torch.cumsum(counts, 0) - counts + own  # the row's start, after the rows before
    at = torch.arange(len(i), device=i.device) + i + 1  # one own edge per row up to i's
    out_i[at_own], out_j[at_own] = own, own
    out_i[at], out_j[at] = i, j
    return out_i, out_j


def _system_sizes(batch: Any, n: int, systems: int, device: torch.device) -> torch.Tensor:
    if batch is None:  # every point in system 0 (torch_cluster's convention)
        sizes = torch.zeros(systems, dtype=torch.int64, device=device)
        sizes[0] = n
        return sizes
    return torch.bincount(torch.as_tensor(batch, device=device).long(), minlength=systems)


_SMALLEST_RADIUS = 2.0**-59  # the library takes cutoffs from 2^-60: all points coincide


def _nearest_first(i: torch.Tensor, j: torch.Tensor, d: torch.Tensor,
                   shifts: torch.Tensor) -> torch.Tensor:
    """The order (i, d, j, S) of the entries: by row, nearest first, ties by index then shift."""
    return _by_row_nearest_first(i, d, (j, shifts[:, 0], shifts[:, 1], shifts[:, 2]))


def _first_round_mean(k: int) -> float:
    """The mean count of points within the first radius of a kNN search that minimises the pairs
    of a uniform cloud over two rounds: lam for the first, and 8 lam (twice the radius) for the
    queries with fewer than k, P(Poisson(lam) < k). Aiming at lam = k left half the queries of
    a uniform cloud for the second round: 2.5x the pairs needed (2026-12-05, 100,000 uniform
    points, one CPU thread: k = 16 2.38 -> 1.05 s, k = 64 11.9 -> 5.4 s)."""
    if k > 200:  # near the optimum where the count is nearly normal: 3 sigma
        return k + 3 * math.sqrt(k)

    def pairs(lam: float) -> float:
        below = sum(math.exp(c * math.log(lam) - lam - math.lgamma(c + 1)) for c in range(k))
        return lam * (1 + 8 * below)

    return min((k + 0.1 * step * math.sqrt(k) for step in range(61)), key=pairs)


def _nearest_round(x: torch.Tensor, y: torch.Tensor, queries: torch.Tensor, r: float,
                   want: torch.Tensor, exclude_self: bool, cells: Optional[torch.Tensor],
                   qb: torch.Tensor, r_in: float, settled: torch.Tensor, cell: Any, pbc: Any,
                   batch_x: Any, batch_y: Any, own_rows: bool = False) -> tuple:
    """One kNN round on the CPU for the query points y[queries]: the library keeps each one's
    nearest points within r (a padded list of each row's K nearest, nearest first, distances in
    double), so no other pair reaches Python. A query is done when it has its `want` and the
    last of them lies within r_in, or when `settled` says so. `own_rows`: the queries are every
    point of x, in order and batched alike, and a point is not its own neighbour. Returns (done,
    and for the done rows their neighbours j (rows, width) int32 and S (rows, width, 3) int32,
    nearest first, and how many of each row's are taken)."""
    width = int(want.max()) + int(exclude_self) if len(want) else 1
    engine = Engine("cell-list")
    if own_rows:
        # Every point a query of its own set, itself excluded: the plain list, which never has
        # (i, i, 0), holds the same rows without a second copy of the points (2026-12-05,
        # 100,000 uniform points, k = 16, one thread: the round's library time 280 -> 170 ms).
        engine.build(x.detach(), r, cell=_host_cell(cell), pbc=pbc, batch=batch_x)
    else:
        engine.build(x.detach(), r, cell=_host_cell(cell), pbc=pbc, batch=batch_x,
                     queries=y[queries].detach(), batch_queries=batch_y)
    j, counts, _, shifts = engine.padded_neighbours(max(width, 1), shifts=True, nearest=True)
    found = torch.clamp(counts.long(), max=j.shape[1])
    if exclude_self and not own_rows:
        # A point's own image at S = 0 is no neighbour (its other images are): the entries after
        # it move one column left.
        own = (j == queries.unsqueeze(1).to(j.dtype)) & (shifts == 0).all(2)
        own &= torch.arange(j.shape[1]) < found.unsqueeze(1)
        has_own = own.any(1)
        at = torch.where(has_own, own.int().argmax(1), j.shape[1])
        columns = torch.arange(j.shape[1])
        columns = torch.clamp(columns + (columns >= at.unsqueeze(1)).long(), max=j.shape[1] - 1)
        j = j.gather(1, columns)
        shifts = shifts.gather(1, columns.unsqueeze(2).expand(-1, -1, 3))
        found -= has_own.long()
    taken = torch.minimum(found, want)
    # The last neighbour taken, in the positions' own dtype: within r_in, nothing nearer was missed.
    rows = torch.arange(len(queries))
    column = torch.clamp(taken - 1, min=0)
    jl, sl = j[rows, column].long(), shifts[rows, column]
    v = x.detach()[torch.clamp(jl, max=len(x) - 1)] - y.detach()[queries]
    if cells is not None:
        c = cells[0] if len(cells) == 1 else cells[qb[queries]]
        v = v + (sl.to(v.dtype).unsqueeze(1) @ c).squeeze(1)
    inside = torch.linalg.vector_norm(v, dim=1) < r_in
    done = ((taken >= want) & ((want == 0) | inside)) | settled
    return done, j[done], shifts[done], taken[done]


def _knn_pairs(x: torch.Tensor, y: torch.Tensor, k: int, batch_x: Any, batch_y: Any,
               exclude_self: bool, cell: Any = None,
               pbc: Any = None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(i, j, S): for each y[i] its k nearest images x[j] + S @ cell (ties by j, then S),
    exactly, nearest first within each row; S (E, 3) int32, zeros without periodic axes."""
    if not isinstance(k, int) or isinstance(k, bool) or k < 1:
        raise ValueError(f"k must be a whole number >= 1, got {k!r}")
    m, n = len(y), len(x)
    empty = torch.zeros(0, dtype=torch.int64, device=y.device)
    no_shifts = torch.zeros((0, 3), dtype=torch.int32, device=y.device)
    if m == 0 or n == 0:
        return empty, empty, no_shifts
    boxes = _systems.boxes(cell.detach() if isinstance(cell, torch.Tensor) else cell, pbc)
    qb = (torch.zeros(m, dtype=torch.int64, device=y.device) if batch_y is None
          else torch.as_tensor(batch_y, device=y.device).long())
    systems = int(qb.max()) + 1
    if batch_x is not None:
        systems = max(systems, int(torch.as_tensor(batch_x).max()) + 1)
    if boxes is not None and boxes.count > 1:
        systems = max(systems, boxes.count)
    # Whether each query's system repeats along some axis: then its images never run out.
    periodic = torch.zeros(systems, dtype=torch.bool, device=y.device)
    if boxes is not None:
        if boxes.count not in (1, systems):
            raise ValueError(f"the batch has system index {systems - 1} but cell/pbc give "
                             f"{boxes.count} systems")
        periodic[:] = torch.as_tensor(boxes.pbc.any(axis=1), device=y.device)
    periodic = periodic[qb]
    sizes = _system_sizes(batch_x, n, systems, y.device)[qb]
    # What each query can have: k, or (open boxes) every point of its system (less itself).
    want = torch.where(periodic & (sizes > 0), torch.full_like(sizes, k),
                       torch.clamp(sizes - int(exclude_self), min=0, max=k))
    # Each pair's vector in the positions' own dtype (float64 stays float64), for the order.
    xd, yd = x.detach(), y.detach()
    cells = None
    if boxes is not None and boxes.periodic:
        cells = torch.as_tensor(boxes.cells, dtype=xd.dtype, device=xd.device)
    lo = torch.minimum(xd.min(0).values, yd.min(0).values)
    hi = torch.maximum(xd.max(0).values, yd.max(0).values)
    extent = float(torch.linalg.vector_norm(hi - lo))
    volume = float(torch.prod(torch.clamp(hi - lo, min=extent * 1e-3 + 1e-30)))
    scale = float(torch.maximum(lo.abs(), hi.abs()).max())
    # A first radius that holds _first_round_mean(k) points of a uniform cloud, doubled for the
    # queries that have fewer than k within it.
    expected = _first_round_mean(k)
    r = max((3 * volume * expected / (4 * math.pi * n)) ** (1 / 3), extent * 1e-6,
            _SMALLEST_RADIUS)
    if cells is not None:  # a point alone in its box has its images a cell row away
        periodic_rows = torch.as_tensor(boxes.pbc, device=cells.device)
        rows = torch.linalg.vector_norm(cells, dim=2)[periodic_rows]
        r = max(r, 0.5 * float(rows[rows > 0].min()) if bool((rows > 0).any()) else r)
    # On the CPU the library picks each query's nearest (_nearest_round), exactly where it holds
    # the queries exactly: they are float32 there (float64 ones are rounded), and a float64
    # query off float32 takes the pair lists below, ordered in float64.
    nearest_in_library = x.device.type == "cpu" and (
        yd.dtype == torch.float32 or bool((yd.to(torch.float32).to(yd.dtype) == yd).all()))
    pending = torch.arange(m, device=y.device)
    # Every query's neighbours as a row of a (m, k) matrix, nearest first, and how many it has:
    # each round writes its done rows, and one mask over the matrix gives the edges in the end,
    # ordered by query (no concatenation of the rounds, nor a sort).
    neighbours = torch.zeros((m, k), dtype=torch.int32, device=y.device)
    # S only where there are images: (m, k, 3) int32 is 12 bytes an edge.
    images = None if cells is None else torch.zeros((m, k, 3), dtype=torch.int32, device=y.device)
    has = torch.zeros(m, dtype=torch.int64, device=y.device)
    while len(pending):
        # Past the whole extent every point of an open system is within r: its last round.
        last = r > 2 * extent
        sub_batch = None if batch_y is None else qb[pending]
        # The search decides |r| < radius in float32: only pairs clearly inside count towards
        # k, so that no nearer image can have been missed at the edge.
        r_in = r * (1 - 1e-3) - 1e-6 * scale
        # An open system's queries are done in its last round, with what they have.
        settled = ~periodic[pending] if last else torch.zeros_like(pending, dtype=torch.bool)
        if nearest_in_library:
            own_rows = (exclude_self and y is x and batch_y is batch_x and
                        len(pending) == len(x))
            done, j, shifts, taken = _nearest_round(x, y, pending, r, want[pending],
                                                    exclude_self, cells, qb, r_in, settled, cell,
                                                    pbc, batch_x, sub_batch, own_rows)
            rows = pending[done]
            width = min(k, j.shape[1])
            neighbours[rows, :width] = j[:, :width]
            if images is not None:
                images[rows, :width] = shifts[:, :width]
            has[rows] = taken
        else:
            i, j, shifts = _radius_pairs(x, y[pending], r, cell=cell, pbc=pbc,
                                         batch_points=batch_x, batch_queries=sub_batch,
                                         quantities="ijS")
            shifts = shifts.to(torch.int32)
            if exclude_self:
                keep = (pending[i] != j) | (shifts != 0).any(1)  # own images are neighbours
                i, j, shifts = i[keep], j[keep], shifts[keep]
            v = xd[j] - yd[pending[i]]
            if cells is not None:
                c = cells[0] if len(cells) == 1 else cells[qb[pending[i]]]
                v = v + (shifts.to(v.dtype).unsqueeze(1) @ c).squeeze(1)
            d = torch.linalg.vector_norm(v, dim=1)
            counts = torch.bincount(i[d < r_in], minlength=len(pending))
            done = (counts >= want[pending]) | settled
            take = done[i]
            i, j, d, shifts = i[take], j[take], d[take], shifts[take]
            order = _nearest_first(i, j, d, shifts)
            i, j, shifts = i[order], j[order], shifts[order]
            counts = torch.bincount(i, minlength=len(pending))
            starts = torch.cumsum(counts, 0) - counts
            column = torch.arange(len(i), device=i.device) - starts[i]
            first = column < want[pending][i]
            i, j, shifts, column = i[first], j[first], shifts[first], column[first]
            rows = pending[i]
            neighbours[rows, column] = j.to(torch.int32)
            if images is not None:
                images[rows, column] = shifts
            has.index_add_(0, rows, torch.ones_like(rows))
        pending = pending[~done]
        r *= 2
    taken = torch.arange(k, device=y.device) < has.unsqueeze(1)
    flat = taken.reshape(-1).nonzero().squeeze(1)
    i = torch.div(flat, k, rounding_mode="floor")
    shifts = (no_shifts.new_zeros((1, 3)).expand(len(flat), 3) if images is None else
              images.reshape(-1, 3).index_select(0, flat))
    return i, neighbours.reshape(-1).index_select(0, flat).long(), shifts


def knn(x: torch.Tensor, y: torch.Tensor, k: int, batch_x: Any = None, batch_y: Any = None,
        cell: Any = None, pbc: Any = None) -> Any:
    """For each point of ``y``, its ``k`` nearest points of ``x`` (ties broken by index):
    ``edge_index`` (2, E) with row 0 indexing ``y`` and row 1 indexing ``x`` (torch_cluster.knn),
    each row's edges nearest first. A query of an open system with fewer than k points gets them
    all.

    ``cell``, ``pbc``: periodic boxes as ``pyraycut.neighbor_list`` takes them ((3,), (3, 3) or
    (B, 3, 3) per system of the batch; pbc one, 3 or (B, 3) bools). The neighbours are then the
    k nearest periodic images (ties by index, then by image shift, lexicographically), so a
    point may be a neighbour several times, through several images (k above the points of a
    small box). ``edge_index`` cannot say which image, so with a ``cell`` this returns
    ``(edge_index, shifts)``: ``shifts`` (E, 3) int32 with the neighbour's image at
    ``x[j] + shifts @ cell`` (the vector ``x[j] - y[i] + shifts @ cell``)."""
    i, j, shifts = _knn_pairs(x, y, k, batch_x, batch_y, exclude_self=False, cell=cell, pbc=pbc)
    edge_index = torch.stack([i, j])
    return edge_index if cell is None else (edge_index, shifts)


def knn_graph(x: torch.Tensor, k: int, batch: Any = None, loop: bool = False,
              flow: str = "source_to_target", cell: Any = None, pbc: Any = None) -> Any:
    """Each point's ``k`` nearest other points (itself too with ``loop``) as ``edge_index``
    (2, E); ``flow`` as in ``radius_graph`` (torch_cluster.knn_graph). Without ``loop`` a point
    is never its own neighbour, even where points coincide.

    ``cell``, ``pbc``: periodic boxes, as in ``knn``: returns ``(edge_index, shifts)``, the
    vector from a centre c to its neighbour n being ``x[n] - x[c] + shifts @ cell`` (either
    flow). A point's own images (shift not 0) are neighbours like any other, ``loop`` or not."""
    _check_flow(flow)
    i, j, shifts = _knn_pairs(x, x, k, batch, batch, exclude_self=not loop, cell=cell, pbc=pbc)
    edge_index = torch.stack([j, i] if flow == "source_to_target" else [i, j])
    return edge_index if cell is None else (edge_index, shifts)
