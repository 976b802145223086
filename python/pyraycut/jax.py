"""raycut's neighbour list inside JAX programs: an XLA FFI custom call on the CPU
(python/src/jax_ffi.cpp, pyraycut/_jax_ffi.so) with static-capacity outputs, so that it runs under
``jax.jit``; vectors and distances come from ``vectors``, in JAX, so ``jax.grad`` flows to
positions and cell.

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
"""
from __future__ import annotations

import ctypes
from typing import Any, Optional

import jax
import jax.numpy as jnp
import numpy as np

from . import _arrays

_TARGET = "raycut_neighbor_list"
LIBRARY = _arrays.built_library("_jax_ffi", "pyraycut.jax's custom call is", "jax",
                                "RAYCUT_BUILD_JAX")
_handler = ctypes.cdll.LoadLibrary(LIBRARY).RaycutNeighborList
jax.ffi.register_ffi_target(_TARGET, jax.ffi.pycapsule(_handler), platform="cpu")


def neighbor_list(positions: Any, cutoff: float, cell: Any = None, pbc: Any = None,
                  max_pairs: Optional[int] = None, half: bool = False) -> tuple:
    """Every pair (i, j, S) with ``|x[j] - x[i] + S @ cell| < cutoff``, as pyraycut.neighbor_list
    finds them, in arrays of the static size ``max_pairs`` (K):

    - ``i``, ``j`` (K,) int32: the pairs first (sorted by i), then padding ``i = j = N``;
    - ``S`` (K, 3) int32: the image shifts (0 in padding);
    - ``count`` () int32: the number of pairs. ``count > max_pairs``: the list was cut and is
      not valid; call again with a larger ``max_pairs`` (outside ``jit``, or check ``count``).

    ``positions`` (N, 3); ``cell`` (3, 3) (rows: lattice vectors) or 3 edge lengths, None: open;
    ``pbc`` 3 bools (default: all, with a cell). ``half``: each pair once. ``jax.vmap`` over
    positions (and cells) gives every system its own K slots and count, in one search.
    """
    if max_pairs is None or int(max_pairs) != max_pairs or max_pairs < 0:
        raise ValueError(f"pyraycut.jax.neighbor_list needs max_pairs, a whole number >= 0 (the "
                         f"static size of its outputs), got {max_pairs!r}")
    x = jnp.asarray(jax.lax.stop_gradient(positions), jnp.float32)
    if x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"positions must have shape (N, 3), got {x.shape}")
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


def vectors(positions: Any, i: Any, j: Any, shifts: Any, cell: Any = None) -> Any:
    """``r = x[j] - x[i] + S @ cell`` for the pairs of ``neighbor_list`` (0 for padding), in the
    positions' dtype, differentiable with respect to positions and cell."""
    x = jnp.concatenate([positions, jnp.zeros((1, 3), positions.dtype)])  # padding: i = j = N
    r = x[j] - x[i]
    c = _cell(cell)
    if c is None:
        return r
    return r + shifts.astype(r.dtype) @ c.astype(r.dtype)
