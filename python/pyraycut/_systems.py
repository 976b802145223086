"""Periodic boxes, batches and query sets as the extension takes them (raycut::Systems): cells
(B, 3, 3) float64 and pbc (B, 3) bool, B = 1 for a box shared by every system; per-system index
arrays (torch_cluster's ``batch``) turned into offsets (on the device for CUDA PyTorch indices);
the differentiable vectors of the PyTorch path (D = x_j - x_i + S . cell in PyTorch), and the
same vectors in float64 on the host from float64 positions.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

from . import _arrays, _raycut


@dataclass
class Boxes:
    """cells (B, 3, 3) float64 and pbc (B, 3) bool; B = 1: one box for every system."""

    cells: np.ndarray
    pbc: np.ndarray

    def __post_init__(self) -> None:
        # Some axis repeats: asked several times a call, and pbc.any() costs ~1 us each.
        self.periodic = bool(self.pbc.any())

    @property
    def count(self) -> int:
        return len(self.cells)


def _flags(pbc: Any) -> np.ndarray:
    flags = _arrays.to_numpy(pbc) if not isinstance(pbc, (bool, np.bool_)) else np.asarray(pbc)
    flags = np.asarray(flags)
    if flags.dtype != bool:
        if not np.issubdtype(flags.dtype, np.integer) or not np.isin(flags, (0, 1)).all():
            raise ValueError(f"pbc must be booleans (one, 3, or (B, 3)), got {flags.dtype} "
                             f"{flags.tolist() if flags.size <= 9 else flags.shape}")
        flags = flags.astype(bool)
    if flags.ndim == 0:
        return np.full((1, 3), bool(flags))
    if flags.shape == (3,):
        return flags.reshape(1, 3)
    if flags.ndim == 2 and flags.shape[1] == 3:
        return flags
    raise ValueError(f"pbc must be one bool, 3 bools or (B, 3) bools (one row per system), got "
                     f"shape {flags.shape}")


def _cells(cell: Any) -> np.ndarray:
    try:
        c = np.asarray(_arrays.to_numpy(cell), dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise ValueError(f"cell must be numbers: 3 (orthorhombic), (3, 3) or (B, 3, 3), rows the "
                         f"lattice vectors ({e})") from None
    if c.shape == (3,):
        return np.diag(c).reshape(1, 3, 3)  # orthorhombic edge lengths, as ASE takes them
    if c.shape == (3, 3):
        return c.reshape(1, 3, 3)
    if c.ndim == 3 and c.shape[1:] == (3, 3):
        return c
    raise ValueError(f"cell must have shape (3,) (orthorhombic edges), (3, 3) (rows: lattice "
                     f"vectors a, b, c) or (B, 3, 3) (one per system of a batch), got {c.shape}")


def boxes(cell: Any, pbc: Any) -> Optional[Boxes]:
    """The boxes of ``cell`` and ``pbc``, or None for open boundaries (no cell, pbc None or all
    False). A cell without pbc is periodic on all three axes."""
    if cell is None:
        if pbc is not None and _flags(pbc).any():
            raise ValueError("pbc without a cell: periodic axes need their lattice vectors "
                             "(pass cell=..., rows a, b, c)")
        return None
    cells = _cells(cell)
    flags = np.ones((1, 3), bool) if pbc is None else _flags(pbc)
    if len(cells) != len(flags) and 1 not in (len(cells), len(flags)):
        raise ValueError(f"cell gives {len(cells)} systems but pbc {len(flags)}")
    count = max(len(cells), len(flags))
    if len(cells) != count:  # broadcast_to only where needed: it costs more than the rest here
        cells = np.broadcast_to(cells, (count, 3, 3))
    if len(flags) != count:
        flags = np.broadcast_to(flags, (count, 3))
    return Boxes(np.ascontiguousarray(cells, dtype=np.float64),
                 np.ascontiguousarray(flags, dtype=bool))


def _not_integers(name: str, dtype: Any) -> ValueError:
    return ValueError(f"{name} must be integers (the system of each particle), got {dtype}")


def _wrong_length(name: str, n: Optional[int], shape: Any) -> ValueError:
    return ValueError(f"{name} must have one system index per particle, shape "
                      f"({'N' if n is None else n},), got shape {tuple(shape)}")


def _unsorted(name: str, k: int, here: int, after: int) -> ValueError:
    return ValueError(f"{name} must be sorted (each system's particles contiguous, systems in "
                      f"order): {name}[{k}] = {here} > {name}[{k + 1}] = {after}; sort the "
                      "particles by system first")


class HostIndex:
    """A sorted per-particle system index on the host, validated."""

    def __init__(self, index: np.ndarray):
        self.index = index
        self.last = int(index[-1]) if len(index) else None

    def offsets(self, systems: int) -> np.ndarray:
        return offsets(self.index, systems)


class TorchCudaIndex:
    """A sorted per-particle system index in a CUDA tensor, validated and turned into offsets on
    the device by the extension (one kernel and one small read-back each): what reaches the host
    is a summary (first, last, where it decreases) and then the S + 1 offsets, never the N
    indices. Torch's own ops did the same in ~10 launches and 2 synchronisations: 0.35 ms a call,
    as much as the whole list of a 512 x 128 batch (docs/python.md)."""

    def __init__(self, torch: Any, b: Any, n: Optional[int], name: str):
        if b.dtype == torch.bool or b.is_floating_point() or b.is_complex():
            raise _not_integers(name, b.dtype)
        if b.dim() != 1 or (n is not None and len(b) != n):
            raise _wrong_length(name, n, b.shape)
        if b.dtype not in (torch.int32, torch.int64):
            b = b.to(torch.int64)
        self.index, self.last = b.contiguous(), None
        self.like = _arrays.Like("torch", b.device, False, b.device.index or 0)
        if len(b) == 0:
            return
        first, last, k, here, after = self._device(_raycut.device_index_summary)
        if first < 0:
            raise ValueError(f"{name} holds a negative system index ({int(b.min())})")
        if k + 1 < len(b):
            raise _unsorted(name, k, here, after)
        self.last = last

    def _device(self, function, *args):
        with _arrays.device_context(self.like):
            return function(_arrays.readable(self.index), *args, _arrays.stream_of(self.like))

    def offsets(self, systems: int) -> np.ndarray:
        """offsets[s] = the number of particles of systems below s: S + 1 integers."""
        if len(self.index) == 0:
            return np.zeros(systems + 1, np.uint64)
        return self._device(_raycut.device_index_offsets, systems)


def _system_index(batch: Any, n: Optional[int], name: str) -> Any:
    if _arrays.framework_of(batch) == "torch" and batch.device.type == "cuda":
        import torch

        return TorchCudaIndex(torch, batch.detach(), n, name)
    b = np.asarray(_arrays.to_numpy(batch))
    if b.dtype == bool or not np.issubdtype(b.dtype, np.integer):
        if b.size == 0 and b.ndim == 1:
            b = b.astype(np.int64)
        else:
            raise _not_integers(name, b.dtype)
    if b.ndim != 1 or (n is not None and len(b) != n):
        raise _wrong_length(name, n, b.shape)
    n = len(b)
    if n and b.dtype.kind == "u" and b.dtype.itemsize >= 8 and int(b.max()) > np.iinfo(np.int64).max:
        raise ValueError(f"{name} holds system index {int(b.max())}, above the largest supported "
                         f"2^63 - 1 = {np.iinfo(np.int64).max} (system indices are int64)")
    if n and b[0] < 0:
        raise ValueError(f"{name} holds a negative system index ({int(b.min())})")
    if n > 1:
        down = np.flatnonzero(np.diff(b) < 0)
        if len(down):
            k = int(down[0])
            raise _unsorted(name, k, int(b[k]), int(b[k + 1]))
    return HostIndex(b.astype(np.int64, copy=False))


def offsets(index: np.ndarray, systems: int) -> np.ndarray:
    """Systems::offsets (S + 1, uint64) of a sorted per-particle system index."""
    counts = np.bincount(index, minlength=systems)
    return np.concatenate([[0], np.cumsum(counts)]).astype(np.uint64)


@dataclass
class Batch:
    """What build() passes for boxes and batches, and what the PyTorch path needs again."""

    boxes: Optional[Boxes]
    systems: int  # S (1 without a batch)
    offsets: Optional[np.ndarray]  # sources, S + 1
    query_offsets: Optional[np.ndarray]  # queries, S + 1


def batch(boxes_: Optional[Boxes], n: Optional[int], batch_: Any, m: Optional[int] = None,
          batch_queries: Any = None) -> Batch:
    """Offsets of the batch (sources ``batch_`` of n particles; queries ``batch_queries`` of m
    points when m is not None). None for one index with the other given: every point in system
    0 (torch_cluster.radius's convention). The number of systems: the boxes' count when they are
    per system, else the largest index + 1. A CUDA PyTorch index is read on the device (only its
    offsets come to the host); other device arrays are copied to the host."""
    per_system = boxes_ is not None and boxes_.count > 1
    if batch_ is None and batch_queries is None:
        if per_system:
            raise ValueError(f"cell/pbc give {boxes_.count} systems (shape (B, 3, 3) / (B, 3)) "
                             "but no batch says which particles belong to which: pass batch=")
        return Batch(boxes_, 1, None, None)
    names = ("batch", "batch_queries") if m is None else ("batch_points", "batch_queries")
    if batch_ is None and n is None:
        raise ValueError(f"positions without a shape (known only through DLPack) need "
                         f"{names[0]} given")
    index = (_system_index(batch_, n, names[0]) if batch_ is not None
             else HostIndex(np.zeros(n, np.int64)))
    query_index = None
    if m is not None:
        query_index = (_system_index(batch_queries, m, names[1]) if batch_queries is not None
                       else HostIndex(np.zeros(m, np.int64)))
    largest = max([a.last for a in (index, query_index) if a is not None and a.last is not None],
                  default=-1)
    points = (n or 0) + (m or 0)
    if not per_system and largest + 1 > points + 1:
        # More system indices than points: most systems are empty, and each costs memory
        # (offsets, a frame), so [0, 10**9] asked for gigabytes. With one box for all, a
        # system's number means nothing beyond grouping: renumber the used ones densely.
        indices = [a for a in (index, query_index) if a is not None]
        if not all(isinstance(a, HostIndex) for a in indices):
            raise ValueError(f"the batch's system indices go up to {largest} for {points} "
                             "points: renumber them densely (e.g. torch.unique(batch, "
                             "return_inverse=True)[1])")
        used = np.unique(np.concatenate([a.index for a in indices]))
        for a in indices:
            a.index = np.searchsorted(used, a.index).astype(np.int64)
            a.last = int(a.index[-1]) if len(a.index) else None
        largest = len(used) - 1
    systems = boxes_.count if per_system else max(largest + 1, 1)
    if largest >= systems:
        raise ValueError(f"the batch has system index {largest} but cell/pbc give {systems} "
                         "systems")
    return Batch(boxes_, systems, index.offsets(systems),
                 None if query_index is None else query_index.offsets(systems))


def torch_vectors(torch: Any, sources: Any, targets: Any, i: Any, j: Any, shifts: Any,
                  cell: Any, boxes_: Optional[Boxes], target_offsets: Any) -> Any:
    """r_ij = x_j - x_i + S . cell in PyTorch from the pairs, so that autograd flows to the
    positions and the cell (``cell`` as the caller gave it: a tensor that may require grad)."""
    vectors = sources.index_select(0, j) - targets.index_select(0, i)
    if boxes_ is None or not boxes_.periodic or shifts is None:
        return vectors
    dtype, device = vectors.dtype, vectors.device
    if isinstance(cell, torch.Tensor):
        c = cell.to(device=device, dtype=dtype)
    else:
        c = torch.as_tensor(np.asarray(_arrays.to_numpy(cell), np.float64), dtype=dtype,
                            device=device)
    if c.shape == (3,):
        c = torch.diag(c)
    if c.dim() == 3 and (c.shape[0] == 1 or boxes_.count == 1):
        c = c[0]  # one box for every system
    def pair_systems() -> Any:  # one cell per system: the system of each pair's target row
        rows = torch.as_tensor(np.asarray(target_offsets, np.int64), device=device)
        return torch.searchsorted(rows, i, right=True) - 1

    return add_shifts(torch, vectors, shifts, c, pair_systems)


def add_shifts(torch: Any, vectors: Any, shifts: Any, cell: Any, pair_systems: Any) -> Any:
    """vectors + S @ cell, differentiable: ``cell`` (3, 3), or (B, 3, 3) with
    ``pair_systems()`` the system of each pair (called only then)."""
    s = shifts.to(device=vectors.device, dtype=vectors.dtype)
    if cell.dim() == 2:
        return vectors + s @ cell
    return vectors + torch.bmm(s.unsqueeze(1), cell.index_select(0, pair_systems())).squeeze(1)


def host_vectors(sources: np.ndarray, targets: np.ndarray, i: np.ndarray, j: np.ndarray,
                 shifts: Optional[np.ndarray], boxes_: Optional[Boxes],
                 target_offsets: Any) -> tuple:
    """(r_ij, its length): r_ij = x_j - x_i + S . cell in float64 from the caller's float64
    (N, 3) positions (and the cells as the engine took them), so that ``d`` and ``D`` carry the
    input's precision rather than the float32 search's: one pass over the pairs in the
    extension."""
    periodic = boxes_ is not None and boxes_.periodic and shifts is not None
    cell_of = None
    if periodic and boxes_.count > 1:
        cell_of = np.searchsorted(np.asarray(target_offsets, np.int64), i, side="right") - 1
    return _raycut.pair_vectors(
        np.ascontiguousarray(targets, np.float64), np.ascontiguousarray(sources, np.float64),
        np.ascontiguousarray(i, np.int64), np.ascontiguousarray(j, np.int64),
        np.ascontiguousarray(shifts) if periodic else None,
        np.ascontiguousarray(boxes_.cells, np.float64) if periodic else None,
        None if cell_of is None else cell_of.astype(np.int64))
