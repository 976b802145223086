"""torch_cluster's graph builders on raycut's search, for PyTorch Geometric users: ``radius``,
``radius_graph``, ``knn`` and ``knn_graph`` with torch_cluster's signatures and ``edge_index``
conventions (docs/compatibility.md). Open boxes; ``batch`` vectors as torch_cluster takes them.

Where they differ from torch_cluster, on purpose:

- ``max_num_neighbors`` defaults to None: no cap. With a cap, each row keeps its nearest
  neighbours (ties broken by index), deterministically, and a row over the cap is never cut
  silently: a ``RuntimeWarning`` names how many rows were cut (``on_overflow="raise"``:
  ``pyraycut.CapacityError`` instead).
- ``knn`` is exact: the k nearest points of each query (ties broken by index), found by radius
  searches whose radius doubles for the queries that have fewer than k points within it (a
  query whose system has fewer than k points gets them all).
"""
from __future__ import annotations

import math
import warnings
from typing import Any, Optional

import torch

from . import CapacityError, neighbor_list
from . import radius as _radius_pairs


def _keep_nearest(i: torch.Tensor, j: torch.Tensor, d: torch.Tensor, k: Optional[int],
                  rows: int, on_overflow: str) -> tuple[torch.Tensor, torch.Tensor]:
    """At most k entries per row i: the nearest (ties by j), in (i, d, j) order."""
    order = torch.argsort(j, stable=True)
    order = order[torch.argsort(d[order], stable=True)]
    order = order[torch.argsort(i[order], stable=True)]
    i, j = i[order], j[order]
    if k is None:
        return i, j
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
    cap, as the nearest)."""
    _check_overflow_mode(on_overflow)
    _check_flow(flow)
    i, j, d = neighbor_list("ijd", x, r, batch=batch)
    d = d.detach()
    if loop:
        own = torch.arange(len(x), device=i.device)
        i, j = torch.cat([i, own]), torch.cat([j, own])
        d = torch.cat([d, torch.zeros(len(x), dtype=d.dtype, device=d.device)])
    i, j = _keep_nearest(i, j, d, max_num_neighbors, len(x), on_overflow)
    return torch.stack([j, i] if flow == "source_to_target" else [i, j])


def _system_sizes(batch: Any, n: int, systems: int, device: torch.device) -> torch.Tensor:
    if batch is None:
        return torch.full((systems,), n, device=device)
    return torch.bincount(torch.as_tensor(batch, device=device).long(), minlength=systems)


def _knn_pairs(x: torch.Tensor, y: torch.Tensor, k: int, batch_x: Any, batch_y: Any,
               exclude_self: bool) -> tuple[torch.Tensor, torch.Tensor]:
    """(i, j): for each y[i] its k nearest x[j] (ties by j), exactly."""
    if not isinstance(k, int) or k < 1:
        raise ValueError(f"k must be a whole number >= 1, got {k!r}")
    m, n = len(y), len(x)
    empty = torch.zeros(0, dtype=torch.int64, device=y.device)
    if m == 0 or n == 0:
        return empty, empty
    qb = (torch.zeros(m, dtype=torch.int64, device=y.device) if batch_y is None
          else torch.as_tensor(batch_y, device=y.device).long())
    systems = int(qb.max()) + 1
    if batch_x is not None:
        systems = max(systems, int(torch.as_tensor(batch_x).max()) + 1)
    # What each query can have: k, or every point of its system (less itself).
    want = torch.clamp(_system_sizes(batch_x, n, systems, y.device)[qb] - int(exclude_self),
                       max=k)
    lo = torch.minimum(x.detach().min(0).values, y.detach().min(0).values)
    hi = torch.maximum(x.detach().max(0).values, y.detach().max(0).values)
    extent = float(torch.linalg.vector_norm(hi - lo))
    volume = float(torch.prod(torch.clamp(hi - lo, min=extent * 1e-3 + 1e-30)))
    # A radius that holds ~k points of a uniform cloud, then doubled until every query has its.
    r = max((3 * volume * k / (4 * math.pi * n)) ** (1 / 3), extent * 1e-6, 1e-30)
    pending = torch.arange(m, device=y.device)
    found_i, found_j = [], []
    while len(pending):
        # Past the whole extent every point of a query's system is within r: the last round.
        last = r > 2 * extent
        sub_batch = None if batch_y is None else qb[pending]
        i, j, d = _radius_pairs(x, y[pending], r, batch_points=batch_x, batch_queries=sub_batch,
                                quantities="ijd")
        d = d.detach()
        if exclude_self:
            keep = pending[i] != j
            i, j, d = i[keep], j[keep], d[keep]
        counts = torch.bincount(i, minlength=len(pending))
        done = counts >= want[pending]
        if last:
            done[:] = True
        take = done[i]
        i, j = _keep_nearest(i[take], j[take], d[take], None, len(pending), "warn")
        counts = torch.bincount(i, minlength=len(pending))
        starts = torch.cumsum(counts, 0) - counts
        rank = torch.arange(len(i), device=i.device) - starts[i]
        first = rank < want[pending][i]
        found_i.append(pending[i[first]])
        found_j.append(j[first])
        pending = pending[~done]
        r *= 2
    i, j = torch.cat(found_i), torch.cat(found_j)
    order = torch.argsort(i, stable=True)
    return i[order], j[order]


def knn(x: torch.Tensor, y: torch.Tensor, k: int, batch_x: Any = None,
        batch_y: Any = None) -> torch.Tensor:
    """For each point of ``y``, its ``k`` nearest points of ``x`` (ties broken by index):
    ``edge_index`` (2, E) with row 0 indexing ``y`` and row 1 indexing ``x`` (torch_cluster.knn).
    A query whose system has fewer than k points gets them all."""
    i, j = _knn_pairs(x, y, k, batch_x, batch_y, exclude_self=False)
    return torch.stack([i, j])


def knn_graph(x: torch.Tensor, k: int, batch: Any = None, loop: bool = False,
              flow: str = "source_to_target") -> torch.Tensor:
    """Each point's ``k`` nearest other points (itself too with ``loop``) as ``edge_index``
    (2, E); ``flow`` as in ``radius_graph`` (torch_cluster.knn_graph). Without ``loop`` a point
    is never its own neighbour, even where points coincide."""
    _check_flow(flow)
    i, j = _knn_pairs(x, x, k, batch, batch, exclude_self=not loop)
    return torch.stack([j, i] if flow == "source_to_target" else [i, j])
