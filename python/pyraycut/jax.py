"""raycut's neighbour list inside JAX programs: an XLA FFI custom call (python/src/jax_ffi.cpp,
pyraycut/_jax_ffi.so) with static-capacity outputs, so that it runs under ``jax.jit``; vectors and
distances come from ``vectors``, in JAX, so ``jax.grad`` flows to positions and cell. It runs on
the CPU, and on CUDA GPUs when the library was built with CUDA (python/src/jax_ffi_cuda.cu).

>>> import jax, jax.numpy as jnp, pyraycut.jax
>>> @jax.jit
... def energy(x, cell):
...     i, j, S, count = pyraycut.jax.neighbor_list(x, 2.5, cell=cell, max_pairs=20_000)
...     d = jnp.linalg.norm(pyraycut.jax.vectors(x, i, j, S, cell), axis=1)
...     inv6 = jnp.where(d > 0, 1.0 / jnp.where(d > 0, d, 1.0) ** 6, 0.0)  # padding: d = 0
...     return 2.0 * jnp.sum(inv6 * inv6 - inv6)
>>> forces = -jax.grad(energy)(x, cell)

The pair search reads the positions as float32 (the library's predicate decides each pair) and
takes no gradient: ``vectors`` computes ``x[j] - x[i] + S @ cell`` from the caller's own arrays.
Under ``jax.vmap`` (positions (B, N, 3), and a cell per system or one for all) the B systems
are searched in one call as a batch of the library's, each with its own K slots and count.
Systems of different sizes go in one ragged batch instead: ``batch`` (N,) gives each particle's
system (sorted), with a cell per system; the pairs come back in one list with global indices.

On a CUDA GPU the same call runs the library's stream-ordered small-system pass
(raycut::list_pairs_small_systems: within each system every particle, or from 2,048 particles a
system the 27 cells around each, decided in double precision)
on XLA's stream, with XLA's scratch memory, and never waits for the GPU. Under ``jax.vmap`` it
runs one pass with a list per system (each system's own K slots and count), so that every
system's count is exact. Bad data that only the GPU sees
is not an error of the call there: the count comes back negative instead (-1: a non-finite
position, -2: an unsorted ``batch``, -3: a degenerate periodic cell, -4: a ``batch`` index outside
[0, B), -5: a cell so thin that a pair has over 2^24 images), with the pairs all padding. Larger systems take it
too, with cells (10^4 atoms in about 0.37 ms on an H100, 2.4x the library's grid, which
synchronises with the host and so cannot run inside an XLA program yet).
"""
from __future__ import annotations

import ctypes
from typing import Any, Optional

import jax
import jax.numpy as jnp
import numpy as np

from . import _arrays

_TARGET = "raycut_neighbor_list"
_RAGGED_TARGET = "raycut_ragged_neighbor_list"
LIBRARY = _arrays.built_library("_jax_ffi", "pyraycut.jax's custom call is", "jax",
                                "RAYCUT_BUILD_JAX")
_library = ctypes.cdll.LoadLibrary(LIBRARY)


def _xla_ffi_api_version() -> Optional[tuple]:
    """The XLA FFI API version of this process's jaxlib, from its own headers (None if absent)."""
    import os
    import re

    try:
        with open(os.path.join(jax.ffi.include_dir(), "xla", "ffi", "api", "c_api.h")) as header:
            text = header.read()
    except OSError:
        return None
    found = [re.search(rf"#define XLA_FFI_API_{part}\s+(\d+)", text) for part in ("MAJOR", "MINOR")]
    return None if None in found else tuple(int(match.group(1)) for match in found)


def _check_xla_ffi_api() -> None:
    """Refuses a jaxlib older than the one the custom call was built with: XLA would accept the
    registration and then fail to create its CPU client, breaking every JAX computation."""
    built = divmod(_library.RaycutXlaFfiApiVersion(), 1000)
    running = _xla_ffi_api_version()
    if running is not None and (running[0] != built[0] or running[1] < built[1]):
        raise ImportError(
            f"pyraycut.jax: {LIBRARY} was built against XLA FFI API {built[0]}.{built[1]}, but "
            f"this process's jaxlib {jax.__version__} speaks {running[0]}.{running[1]}; rebuild "
            "raycut's Python package with this jax (pip install --no-build-isolation .), or "
            "install the jax it was built with")


_check_xla_ffi_api()
jax.ffi.register_ffi_target(_TARGET, jax.ffi.pycapsule(_library.RaycutNeighborList),
                            platform="cpu")
jax.ffi.register_ffi_target(_RAGGED_TARGET,
                            jax.ffi.pycapsule(_library.RaycutRaggedNeighborList), platform="cpu")
# The CUDA handlers, exported only by a library built with CUDA: HAS_CUDA says whether the custom
# call also runs on CUDA GPUs.
HAS_CUDA = hasattr(_library, "RaycutNeighborListCuda")
if HAS_CUDA:
    jax.ffi.register_ffi_target(_TARGET, jax.ffi.pycapsule(_library.RaycutNeighborListCuda),
                                platform="CUDA")
    jax.ffi.register_ffi_target(_RAGGED_TARGET,
                                jax.ffi.pycapsule(_library.RaycutRaggedNeighborListCuda),
                                platform="CUDA")


def neighbor_list(positions: Any, cutoff: float, cell: Any = None, pbc: Any = None,
                  max_pairs: Optional[int] = None, half: bool = False, batch: Any = None,
                  num_systems: Optional[int] = None) -> tuple:
    """Every pair (i, j, S) with ``|x[j] - x[i] + S @ cell| < cutoff``, as pyraycut.neighbor_list
    finds them, in arrays of the static size ``max_pairs`` (K):

    - ``i``, ``j`` (K,) int32: the pairs first (sorted by i), then padding ``i = j = N``;
    - ``S`` (K, 3) int32: the image shifts (0 in padding);
    - ``count`` () int32: the number of pairs. ``count > max_pairs``: the list was cut and is
      not valid; call again with a larger ``max_pairs`` (outside ``jit``, or check ``count``).

    ``positions`` (N, 3); ``cell`` (3, 3) (rows: lattice vectors) or 3 edge lengths, None: open;
    ``pbc`` 3 bools (default: all, with a cell). ``half``: each pair once. ``jax.vmap`` over
    positions (and cells) gives every system its own K slots and count (in one search on the
    CPU, and in one pass on a GPU).

    Ragged batches (systems of different sizes, one search): ``batch`` (N,) int32, the system
    index of each particle, sorted (torch_cluster's convention; may be traced under ``jit``);
    ``cell`` (B, 3, 3) (or (B, 3) edges) per system, or one (3, 3) for all; ``pbc`` (B, 3) or 3
    bools. B is static: the cell's leading axis, or ``num_systems`` when the cell is shared or
    None. The outputs are one list as above, with global indices (padding ``i = j = N``); an
    unsorted batch or a system index >= B is an error of the call on the CPU, and a negative
    ``count`` on a GPU (the module's docstring lists the codes).

    On a CUDA GPU the search is the library's stream-ordered small-system pass, for systems of
    up to a few thousand particles; larger systems run it too, correctly but more slowly.
    """
    if max_pairs is None or int(max_pairs) != max_pairs or max_pairs < 0:
        raise ValueError(f"pyraycut.jax.neighbor_list needs max_pairs, a whole number >= 0 (the "
                         f"static size of its outputs), got {max_pairs!r}")
    x = jnp.asarray(jax.lax.stop_gradient(positions), jnp.float32)
    if x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"positions must have shape (N, 3), got {x.shape}")
    if batch is not None:
        return _ragged_neighbor_list(x, cutoff, cell, pbc, int(max_pairs), half, batch,
                                     num_systems)
    if num_systems is not None:
        raise ValueError(f"num_systems={num_systems!r} needs batch (a ragged batch)")
    c = _cell(cell)
    c = jnp.zeros((3, 3), jnp.float32) if c is None else jax.lax.stop_gradient(c)
    if pbc is None:
        flags = jnp.full((3,), cell is not None)
    else:
        flags = jnp.broadcast_to(jnp.asarray(pbc, bool), (3,))
    k = int(max_pairs)
    shapes = (jax.ShapeDtypeStruct((k,), jnp.int32), jax.ShapeDtypeStruct((k,), jnp.int32),
              jax.ShapeDtypeStruct((k, 3), jnp.int32), jax.ShapeDtypeStruct((), jnp.int32))
    # Under jax.vmap every input gets the batch axes and the custom call searches the B systems
    # in one build (the library's batches), not in a loop.
    call = jax.ffi.ffi_call(_TARGET, shapes, vmap_method="broadcast_all")
    return tuple(call(x, c, flags, cutoff=np.float32(cutoff), half=np.int64(bool(half))))


def _ragged_neighbor_list(x, cutoff, cell, pbc, k, half, batch, num_systems) -> tuple:
    system_of = jnp.asarray(batch)
    if system_of.shape != (x.shape[0],) or not jnp.issubdtype(system_of.dtype, jnp.integer):
        raise ValueError(f"batch must be (N,) integers with N = {x.shape[0]} (the positions'), "
                         f"got shape {system_of.shape} of {system_of.dtype}")
    c = _cells(cell)
    if c is not None and c.ndim == 3:
        if num_systems is not None and num_systems != c.shape[0]:
            raise ValueError(f"num_systems={num_systems!r} differs from the cell's {c.shape[0]} "
                             f"systems (cell shape {c.shape})")
        systems = c.shape[0]
    elif num_systems is None or int(num_systems) != num_systems or num_systems < 0:
        raise ValueError(f"a ragged batch with a shared cell (or none) needs num_systems, a whole "
                         f"number >= 0 (the static B), got {num_systems!r}")
    else:
        systems = int(num_systems)
    c = jnp.zeros((3, 3), jnp.float32) if c is None else jax.lax.stop_gradient(c)
    c = jnp.broadcast_to(c, (systems, 3, 3))
    if pbc is None:
        flags = jnp.full((systems, 3), cell is not None)
    else:
        flags = jnp.asarray(pbc, bool)
        if flags.shape not in ((3,), (systems, 3)):
            raise ValueError(f"pbc must be 3 bools or ({systems}, 3) (one row per system), got "
                             f"shape {flags.shape}")
        flags = jnp.broadcast_to(flags, (systems, 3))
    shapes = (jax.ShapeDtypeStruct((k,), jnp.int32), jax.ShapeDtypeStruct((k,), jnp.int32),
              jax.ShapeDtypeStruct((k, 3), jnp.int32), jax.ShapeDtypeStruct((), jnp.int32))
    call = jax.ffi.ffi_call(_RAGGED_TARGET, shapes)
    return tuple(call(x, system_of.astype(jnp.int32), c, flags, cutoff=np.float32(cutoff),
                      half=np.int64(bool(half))))


def _cells(cell: Any) -> Any:
    """One cell (3, 3), or a cell per system (B, 3, 3) (from (B, 3) edges); None: open."""
    if cell is None:
        return None
    c = jnp.asarray(cell)
    if c.ndim == 2 and c.shape != (3, 3) and c.shape[1] == 3:
        return jax.vmap(jnp.diag)(c)
    if c.ndim == 3 and c.shape[1:] == (3, 3):
        return c
    return _cell(c)


def _cell(cell: Any) -> Any:
    if cell is None:
        return None
    c = jnp.asarray(cell)
    if c.shape == (3,):
        c = jnp.diag(c)
    if c.shape != (3, 3):
        raise ValueError(f"cell must have shape (3,) (orthorhombic edges) or (3, 3) (rows: "
                         f"lattice vectors a, b, c), got {c.shape}")
    return c


def vectors(positions: Any, i: Any, j: Any, shifts: Any, cell: Any = None,
            batch: Any = None) -> Any:
    """``r = x[j] - x[i] + S @ cell`` for the pairs of ``neighbor_list`` (0 for padding), in the
    positions' dtype, differentiable with respect to positions and cell. A ragged batch: pass
    the same ``batch``, and ``cell`` (B, 3, 3) gives each pair its system's cell."""
    x = jnp.concatenate([positions, jnp.zeros((1, 3), positions.dtype)])  # padding: i = j = N
    r = x[j] - x[i]
    c = _cell(cell) if batch is None else _cells(cell)
    if c is None:
        return r
    if c.ndim == 2:
        return r + shifts.astype(r.dtype) @ c.astype(r.dtype)
    system_of = jnp.asarray(batch)
    if system_of.shape != (positions.shape[0],):
        raise ValueError(f"batch must have shape ({positions.shape[0]},) (one system index per "
                         f"particle), got {system_of.shape}")
    # Padding (i = N) reads system 0's cell; its shifts are 0.
    pair_systems = jnp.concatenate([system_of, jnp.zeros((1,), system_of.dtype)])[i]
    pair_cells = c.astype(r.dtype)[pair_systems]
    return r + jnp.einsum("pk,pkl->pl", shifts.astype(r.dtype), pair_cells)
