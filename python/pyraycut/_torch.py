"""PyTorch tensors through the raycut operators (torch.ops.raycut.neighbor_list and .radius), so
that the same ``pyraycut.neighbor_list`` / ``pyraycut.radius`` call works in eager mode, under
``torch.compile(fullgraph=True)``, ``torch.export`` and in AOTInductor packages.

The operators (C++, pyraycut/_torch_ops.so) return integer pairs only: (i, j, S, count). Distances
and vectors are computed here in PyTorch from them and the caller's own positions and cell
(``r = x[j] - x[i] + S @ cell``), in the positions' dtype, so autograd flows to positions and
cell to any order and never reaches the operator. Importing this module imports torch, loads the
operators and registers their fake implementations (the output shapes that torch.compile and
torch.export trace with: an unbacked size for the exact pair count, ``max_pairs`` otherwise).

Everything below runs under Dynamo's tracing too: torch operations and Python only, no NumPy
and no reads of tensor values except in eager mode on the CPU (the capacity check). CUDA calls
with ``max_pairs`` read nothing back either: the operator's small-system pass queues its work on
the current stream without waiting, so the whole call can be captured in a CUDA graph.
"""
from __future__ import annotations

from typing import Any, Optional

import numpy as np
import torch

from . import _arrays
from . import _raycut
from . import _systems
from . import _PLAN_OUTGROWN, check_pair_count

LIBRARY = _arrays.built_library("_torch_ops", "raycut's PyTorch operators are", "torch",
                                "RAYCUT_BUILD_TORCH")
try:
    torch.ops.load_library(LIBRARY)
except OSError as e:  # built against another torch (the classic C++ API binds to one version)
    raise ImportError(f"raycut's PyTorch operators ({LIBRARY}) do not load with torch "
                      f"{torch.__version__}: rebuild raycut against it ({e}); PyTorch tensors "
                      "go through the extension meanwhile", path=LIBRARY) from e


@torch.library.register_fake("raycut::neighbor_list")
def _neighbor_list_fake(positions, cutoff, cell=None, pbc=None, batch=None, half=False,
                        max_pairs=None):
    torch._check(positions.dim() == 2 and positions.shape[1] == 3,
                 lambda: f"positions must have shape (N, 3), got {tuple(positions.shape)}")
    return _fake_pairs(positions, max_pairs)


@torch.library.register_fake("raycut::radius")
def _radius_fake(points, queries, cutoff, cell=None, pbc=None, batch_points=None,
                 batch_queries=None, max_pairs=None):
    for name, x in (("points", points), ("queries", queries)):
        torch._check(x.dim() == 2 and x.shape[1] == 3,
                     lambda: f"{name} must have shape (N, 3), got {tuple(x.shape)}")
    return _fake_pairs(points, max_pairs)


@torch.library.register_fake("raycut::lj_forces")
def _lj_forces_fake(positions, cutoff, epsilon=1.0, sigma=1.0, cell=None, pbc=None, batch=None):
    torch._check(positions.dim() == 2 and positions.shape[1] == 3,
                 lambda: f"positions must have shape (N, 3), got {tuple(positions.shape)}")
    n = positions.shape[0]
    return tuple(positions.new_empty(shape, dtype=torch.float32)
                 for shape in ((n,), (n, 3), (n, 6)))


def _lj_forces_backward(ctx, *grads):
    raise RuntimeError("torch.ops.raycut.lj_forces is not differentiable (it returns the forces "
                       "themselves): for gradients, compute the energy from "
                       "pyraycut.neighbor_list's d, or pass positions.detach()")


torch.library.register_autograd("raycut::lj_forces", _lj_forces_backward)


def _fake_pairs(like: torch.Tensor, max_pairs: Optional[int]) -> tuple:
    if max_pairs is None:
        size = torch.library.get_ctx().new_dynamic_size()  # the pair count: known after the op
    else:
        size = max_pairs
    return (like.new_empty((size,), dtype=torch.int64), like.new_empty((size,), dtype=torch.int64),
            like.new_empty((size, 3), dtype=torch.int32), like.new_empty((), dtype=torch.int64))


# The CUDA kernel is built where raycut has CUDA and torch is a CUDA build (RAYCUT_TORCH_CUDA):
# without it CUDA tensors take the extension's path.
_CUDA_KERNEL = torch._C._dispatch_has_kernel_for_dispatch_key("raycut::neighbor_list", "CUDA")


def routes(x: Any, method: str, max_pairs: Optional[int] = None, queries: bool = False,
           cell: Any = None, pbc: Any = None, count: bool = False) -> bool:
    """Whether a call on ``x`` goes through the operators: PyTorch tensors on a device they have
    a kernel for, with the method that kernel runs (the CPU cell list, the CUDA grid) or
    ``"auto"``. CUDA tensors take the operator where only it serves, static capacity
    (``max_pairs``), tracing (torch.compile) and the pair ``count``, and, with method
    ``"auto"``, where it is faster: neighbour lists (not ``queries``) of systems small enough
    for its stream-ordered pass (``_small_systems``; 4-5x faster than the extension at 128 and
    1,000 particles). Other eager calls keep the extension's zero-copy path (the library's own
    device buffers wrapped, no copy into torch's), an explicit ``"grid"`` among them."""
    if not isinstance(x, torch.Tensor):
        return False
    if x.device.type == "cpu":
        return method in ("auto", "cell-list")
    return (x.device.type == "cuda" and _CUDA_KERNEL and method in ("auto", "grid") and
            (max_pairs is not None or count or torch.compiler.is_compiling() or
             (method == "auto" and not queries and _small_systems(x, cell, pbc))))


def _small_systems(x: torch.Tensor, cell: Any, pbc: Any) -> bool:
    """Whether the operator lists these positions with its small-system pass: the operator's own
    rule (raycut::prefer_small_systems: N <= 4096 or N^2 <= 2^23 B), with B the number of cells
    of a (B, 3, 3) cell and 1 otherwise (the batch index is data on the device, never read to
    decide); pbc without a cell stays on the engine there."""
    if (pbc is not None and cell is None) or x.dim() != 2:  # bad shapes: the extension says why
        return False
    shape = getattr(cell, "shape", None)
    if shape is None and cell is not None and not isinstance(cell, (int, float)):
        shape = np.shape(cell)
    systems = shape[0] if shape is not None and len(shape) == 3 else 1
    return _raycut.prefer_small_systems(x.shape[0], systems)


def _cell(cell: Any, like: torch.Tensor) -> Optional[torch.Tensor]:
    """The cell as a (3, 3) or (B, 3, 3) tensor of the positions' dtype, the caller's tensor
    itself where it is one (so gradients reach it); 3 numbers: an orthorhombic box."""
    if cell is None:
        return None
    c = cell if isinstance(cell, torch.Tensor) else torch.as_tensor(cell, dtype=torch.float64)
    c = c.to(dtype=like.dtype, device=like.device)
    if c.dim() == 1 and c.shape[0] == 3:
        c = torch.diag_embed(c)
    if not (c.dim() in (2, 3) and c.shape[-2:] == (3, 3)):
        raise ValueError(f"cell must have shape (3,) (orthorhombic edges), (3, 3) (rows: lattice "
                         f"vectors a, b, c) or (B, 3, 3) (one per system of a batch), got "
                         f"{tuple(c.shape)}")
    return c


def _any_true(values: Any) -> bool:
    """Whether host flags (a bool, a nested sequence of them, or an array) hold a True, read in
    Python so that no tensor value is read under tracing."""
    if hasattr(values, "tolist"):
        values = values.tolist()
    if isinstance(values, (list, tuple)):
        return any(_any_true(v) for v in values)
    return bool(values)


_PBC_FLAGS: dict = {}  # (device, bool) -> its (3,) flags on that device (_pbc)


def _pbc(pbc: Any, cell: Optional[torch.Tensor], like: torch.Tensor,
         on_device: bool) -> Optional[torch.Tensor]:
    """pbc as a bool tensor: on the positions' device where the operator's CUDA pass reads it
    there (``on_device``: the small-system pass, and compiled code, so that the call copies
    nothing from the host), else on the host, where the engine reads it without waiting for the
    GPU. Host values without a cell are checked here and dropped when all False, so that the
    operator never has to read a device tensor to check them."""
    if pbc is None:
        return None
    if cell is None and not isinstance(pbc, torch.Tensor):
        if _any_true(pbc):
            raise ValueError("pbc without a cell: periodic axes need their lattice vectors (pass "
                             "cell, rows a, b, c)")
        return None
    device = like.device if on_device else None  # None: a tensor stays where it is
    if isinstance(pbc, bool):
        if device is not None and not torch.compiler.is_compiling():
            # One constant per device and value, never written: a new one each call was a
            # kernel launch each call. Not kept from a CUDA graph's capture, where its fill is
            # only recorded, not run.
            key = (device, pbc)
            flags = _PBC_FLAGS.get(key)
            if flags is None:
                flags = torch.full((3,), pbc, dtype=torch.bool, device=device)
                if not torch.cuda.is_current_stream_capturing():
                    _PBC_FLAGS[key] = flags
            return flags
        flags = torch.full((3,), pbc, dtype=torch.bool, device=device)
    else:
        flags = torch.as_tensor(pbc).to(device=device, dtype=torch.bool)
    if flags.dim() == 0:
        flags = flags.expand(3)
    return flags


def _index(batch: Any, name: str, device: Optional[torch.device]) -> Optional[torch.Tensor]:
    """A system index as int64 on ``device`` (a host one is copied there), or where it is for
    None: the engine reads it on the host, where a host index costs no copy and no wait."""
    if batch is None:
        return None
    b = batch if isinstance(batch, torch.Tensor) else torch.as_tensor(batch)
    if b.is_floating_point() or b.dtype == torch.bool:
        raise ValueError(f"{name} must be integers (the system of each particle), got {b.dtype}")
    return b.to(device=device, dtype=torch.int64)


def _on(index: Optional[torch.Tensor], like: torch.Tensor, needed: bool) -> Optional[torch.Tensor]:
    """The index on the positions' device where the pair vectors need it (per-system cells), made
    before the operator's work is queued, so that the copy does not wait for it."""
    return index.to(like.device) if index is not None and needed else index


def _checked_call(call: Any, max_pairs: Optional[int], letters: str) -> Any:
    """The operator's (i, j, S, count). In eager mode, a list cut short by max_pairs raises,
    unless the caller asked for the count ("c") and so checks it where it may wait: on CUDA
    reading it waits for the GPU, which static capacity is there to avoid. Compiled code reads
    ``count`` itself. A count that says the operator's reused plan no longer fits is followed by
    one more call, which plans afresh (the count read back is what tells the engine)."""
    out = call()
    if max_pairs is None or "c" in letters or torch.compiler.is_compiling():
        return out
    found = int(out[3])
    if found == _PLAN_OUTGROWN:
        out = call()
        found = int(out[3])
    check_pair_count(found, max_pairs)
    return out


def _padded(x: torch.Tensor) -> torch.Tensor:
    """x with one zero row more: padding entries index it (i = j = N) and get a zero vector."""
    return torch.cat([x, x.new_zeros((1,) + tuple(x.shape[1:]))])


def _vectors(sources: torch.Tensor, targets: torch.Tensor, i: torch.Tensor, j: torch.Tensor,
             shifts: torch.Tensor, cell: Optional[torch.Tensor], target_batch: Any,
             padded: bool) -> torch.Tensor:
    """r = sources[j] - targets[i] + S @ cell (the cell of target i's system), differentiable."""
    if padded:
        sources, targets = _padded(sources), _padded(targets)
    vectors = sources.index_select(0, j) - targets.index_select(0, i)
    if cell is None:
        return vectors

    def pair_systems() -> torch.Tensor:  # the system of each pair: that of its target
        systems = target_batch if target_batch is not None else torch.zeros(
            targets.shape[0] - int(padded), dtype=torch.int64, device=targets.device)
        if padded:
            systems = torch.cat([systems, systems.new_zeros(1)])
        return systems.index_select(0, i)

    return _systems.add_shifts(torch, vectors, shifts, cell, pair_systems)


def _quantities(letters: str, i, j, shifts, count, vectors_of) -> Any:
    vectors = vectors_of() if ("d" in letters or "D" in letters) else None
    found = {"i": i, "j": j, "S": shifts, "D": vectors, "c": count}
    if "d" in letters:
        found["d"] = torch.linalg.vector_norm(vectors, dim=1)
    out = tuple(found[letter] for letter in letters)
    return out[0] if len(out) == 1 else out


def _floating(x: torch.Tensor, name: str) -> None:
    _arrays._refuse_complex(name, x.dtype, x.is_complex())  # the same words as every interface
    if x.dtype not in (torch.float32, torch.float64):
        raise ValueError(f"{name} must be float32 or float64, got {x.dtype}")


def neighbor_list(letters: str, positions: torch.Tensor, cutoff: float, cell: Any, pbc: Any,
                  batch: Any, half: bool, max_pairs: Optional[int]) -> Any:
    _floating(positions, "positions")
    c = _cell(cell, positions)
    # Where the operator's CUDA pass reads pbc and batch on the device (the small-system pass:
    # small systems, compiled code, and any size while a CUDA graph is being captured, where the
    # engine cannot run); elsewhere the engine reads them on the host.
    on_device = positions.is_cuda and (torch.compiler.is_compiling() or
                                       torch.cuda.is_current_stream_capturing() or
                                       _small_systems(positions, c, pbc))
    b = _index(batch, "batch", positions.device if on_device else None)
    vectors_batch = _on(b, positions, c is not None and ("d" in letters or "D" in letters))
    flags = _pbc(pbc, c, positions, on_device)
    i, j, shifts, count = _checked_call(
        lambda: torch.ops.raycut.neighbor_list(positions.detach(), float(cutoff),
                                               None if c is None else c.detach(), flags, b,
                                               bool(half), max_pairs), max_pairs, letters)
    return _quantities(
        letters, i, j, shifts, count,
        lambda: _vectors(positions, positions, i, j, shifts, c, vectors_batch,
                         max_pairs is not None))


def radius(letters: str, points: torch.Tensor, queries: Any, cutoff: float, cell: Any, pbc: Any,
           batch_points: Any, batch_queries: Any, max_pairs: Optional[int]) -> Any:
    _floating(points, "points")
    if not isinstance(queries, torch.Tensor):
        raise ValueError(f"queries must be a PyTorch tensor like points, got "
                         f"{type(queries).__name__}")
    _floating(queries, "queries")
    c = _cell(cell, points)
    # The operator's engine reads pbc and the batches on the host (compiled code keeps them on
    # the device).
    on_device = points.is_cuda and torch.compiler.is_compiling()
    device = points.device if on_device else None
    bq = _index(batch_queries, "batch_queries", device)
    vectors_batch = _on(bq, points, c is not None and ("d" in letters or "D" in letters))
    flags = _pbc(pbc, c, points, on_device)
    bp = _index(batch_points, "batch_points", device)
    i, j, shifts, count = _checked_call(
        lambda: torch.ops.raycut.radius(points.detach(), queries.detach().to(points.dtype),
                                        float(cutoff), None if c is None else c.detach(), flags,
                                        bp, bq, max_pairs), max_pairs, letters)
    return _quantities(
        letters, i, j, shifts, count,
        lambda: _vectors(points, queries.to(points.dtype), i, j, shifts, c, vectors_batch,
                         max_pairs is not None))
