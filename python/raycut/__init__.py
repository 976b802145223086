"""raycut: particle interactions and neighbour lists within a cutoff, on GPUs and CPUs.

Every pair (i, j), i != j, with ``|x_j - x_i|^2 < cutoff^2`` (one shared float32 predicate) is
found exactly once per direction, by every method. Methods: ``methods()``; ``"auto"`` picks the
CUDA grid with a GPU and the CPU cell list without.

Positions are an (N, 3) float32 array: NumPy (float64 or non-contiguous NumPy arrays and array
likes are converted on the host, with a copy), or anything with ``__dlpack__`` or
``__cuda_array_interface__`` (PyTorch, CuPy, JAX, ...), read in place: those must already be
float32 and C-contiguous (``ValueError`` otherwise). Outputs come back in the caller's framework
on the caller's device: NumPy in, NumPy out; CUDA tensors in, CUDA tensors out, wrapping the
library's device memory without a copy (the arrays keep it alive).

Errors carry the library's message: ``ValueError`` for bad input (NaN coordinate: its index;
cutoff <= 0; unknown method or kernel), ``MemoryError`` when it does not fit,
``NotImplementedError`` for what this build or machine cannot do (a GPU method without a GPU),
``CapacityError`` (a ``RuntimeError``) when a padded list is asked to raise on overflow,
``OSError`` for files and ``RuntimeError`` for device faults.

Periodic boxes (``cell``, ``pbc``, shifts ``"S"``) and batches are not supported yet: passing them
raises ``ValueError``.
"""
from __future__ import annotations

import numbers
from typing import Any, Optional

from . import _arrays
from . import _raycut
from ._raycut import CapacityError

__version__ = "0.1.0"
__all__ = [
    "CapacityError",
    "Engine",
    "KERNELS",
    "VerletList",
    "auto_method",
    "cuda_available",
    "methods",
    "neighbor_list",
]

#: The built-in kernels of ``Engine.compute`` and what each returns.
KERNELS = {
    "count": ("count",),
    "lj": ("energy",),
    "lj_forces": ("energy", "force", "virial"),
    "smooth": ("energy", "force"),
    "sph_density": ("density",),
    "sph_force": ("force",),
}


def methods() -> list[dict]:
    """Every method raycut knows, available here or not, in a stable order.

    Each is a dict: ``name``, ``summary``, ``available`` (built in and its hardware present) and
    ``why`` (why not, when unavailable; empty otherwise).
    """
    return _raycut.methods()


def auto_method() -> str:
    """The method ``method="auto"`` picks on this machine."""
    return _raycut.auto_method()


def cuda_available() -> bool:
    """True when this build has the CUDA methods and a CUDA device is usable."""
    return bool(_raycut.has_cuda) and _raycut.cuda_device_available()


def _cutoff(cutoff: Any) -> float:
    if isinstance(cutoff, (dict, list, tuple)) or hasattr(cutoff, "__len__"):
        raise ValueError("cutoff must be one number: per-atom or per-pair cutoffs are not "
                         "supported")
    if not isinstance(cutoff, numbers.Real):
        raise ValueError(f"cutoff must be a real number, got {type(cutoff).__name__}")
    return float(cutoff)


def _no_periodic(cell: Any, pbc: Any, batch: Any) -> None:
    if cell is not None:
        raise ValueError("periodic boxes are not supported yet: pass cell=None (open boundaries)")
    if pbc is not None:
        try:
            flags = [bool(p) for p in (pbc if hasattr(pbc, "__iter__") else [pbc])]
        except TypeError:
            flags = [True]
        if any(flags):
            raise ValueError("periodic boxes are not supported yet: pass pbc=None (open "
                             "boundaries)")
    if batch is not None:
        raise ValueError("batches are not supported yet: pass batch=None (one system per call)")


class Engine:
    """A method built over positions: fused pair kernels and neighbour lists.

    >>> engine = raycut.Engine("auto")
    >>> engine.build(positions, cutoff=0.1)      # (N, 3) float32, NumPy or a CUDA tensor
    >>> engine.compute("lj_forces")["force"]     # (N, 3), in the positions' framework
    >>> offsets, indices = engine.neighbours()   # CSR, on the positions' device

    The outputs of every call are new arrays of the framework and device of the positions given
    to the last ``build``/``update``: later calls never change them (neighbour lists are fresh
    buffers the arrays own; kernel results are copies, on the device for device positions).
    """

    def __init__(self, method: str = "auto") -> None:
        self._engine = _raycut.Engine(method)
        self._like = _arrays.HOST

    def __repr__(self) -> str:
        return (f"raycut.Engine(method={self.method!r}, space={self.space!r}, size={self.size}, "
                f"cutoff={self.cutoff})")

    @property
    def method(self) -> str:
        """The method's name (what ``"auto"`` resolved to)."""
        return self._engine.method

    @property
    def space(self) -> str:
        """Where the method works: ``"host"`` or ``"device"``."""
        return self._engine.space

    @property
    def size(self) -> int:
        """N, the number of particles of the last build."""
        return self._engine.size

    @property
    def cutoff(self) -> float:
        return self._engine.cutoff

    @property
    def timings(self) -> dict:
        """Milliseconds of the last build/update and compute (``device_*``: CUDA events, GPU
        methods only, -1 otherwise)."""
        return self._engine.timings()

    def _call(self, like: _arrays.Like, function, *args):
        with _arrays.device_context(like):
            self._engine.set_stream(_arrays.stream_of(like))
            return function(*args)

    def build(self, positions: Any, cutoff: float) -> None:
        """Validates (finite coordinates, cutoff finite and > 0) and builds the method's structure
        over (N, 3) float32 positions. Raises ValueError naming the first bad index."""
        x, like = _arrays.prepare(positions)
        self._call(like, self._engine.build, x, _cutoff(cutoff))
        self._like = like

    def update(self, positions: Any, skin: float = 0.0) -> None:
        """New positions of the same N particles, cutoff unchanged. ``skin`` > 0 lets the OptiX
        methods refit their structure instead of rebuilding it while no particle has moved more
        than skin / 2 since the last full build."""
        x, like = _arrays.prepare(positions)
        self._engine.set_skin(float(skin))
        self._call(like, self._engine.update, x)
        self._like = like

    def _kernel_input(self, value: Any, name: str) -> Any:
        if value is None:
            return None
        if self.space == "host":
            return _arrays.to_host(value)
        x, _ = _arrays.prepare(value, name, points=False)
        return x

    def compute(self, kernel: str = "count", *, lj_epsilon: float = 1.0, lj_sigma: float = 1.0,
                sph_mass: float = 0.0, sph_viscosity: float = 0.0, velocity: Any = None,
                density: Any = None, pressure: Any = None) -> dict:
        """Runs a built-in kernel over every in-range pair, fused in the method's traversal, and
        returns its per-particle results as a dict of new arrays (``KERNELS`` says which):

        - ``count`` (N,) int32: neighbours per particle;
        - ``energy`` (N,) float32 (``lj``, ``lj_forces``, ``smooth``);
        - ``force`` (N, 3) float32 (``lj_forces``, ``smooth``, ``sph_force``);
        - ``virial`` (N, 6) float32, xx yy zz xy xz yz (``lj_forces``);
        - ``density`` (N,) float32 (``sph_density``).

        ``sph_force`` reads per-particle ``velocity`` (N, 3), ``density`` and ``pressure`` (N,)
        float32 arrays. Results are copies (on the device for device positions): valid forever.
        """
        velocity = self._kernel_input(velocity, "velocity")
        density = self._kernel_input(density, "density")
        pressure = self._kernel_input(pressure, "pressure")
        like = self._like
        self._call(like, self._engine.run, kernel, float(lj_epsilon), float(lj_sigma),
                   float(sph_mass), float(sph_viscosity), velocity, density, pressure)
        out = self._call(like, self._engine.results, kernel, like.host)
        return {name: _arrays.output(array, like) for name, array in out.items()}

    def neighbours(self, half: bool = False, distances: bool = False,
                   vectors: bool = False) -> tuple:
        """The CSR neighbour list of the built positions: ``(offsets, indices)`` then
        ``distances`` and ``vectors`` when asked.

        The neighbours of particle i are ``indices[offsets[i]:offsets[i+1]]`` (order within a
        row unspecified). offsets (N + 1,) int64, indices int32, distances ``|r_ij|`` float32,
        vectors ``r_ij = x_j - x_i`` (P, 3) float32. ``half``: each unordered pair once, in the
        row of its smaller index. On the device for device positions and GPU methods, wrapping
        the list's own buffer (zero-copy; each call fills a new buffer).
        """
        like = self._like
        offsets, indices, d, v = self._call(like, self._engine.neighbours, bool(half),
                                            bool(distances), bool(vectors), like.host)
        out = [offsets, indices] + ([d] if distances else []) + ([v] if vectors else [])
        return tuple(_arrays.output(a, like) for a in out)

    def padded_neighbours(self, k: int, raise_on_overflow: bool = False) -> tuple:
        """The padded [N, K] neighbour matrix: ``(indices, counts, report)``.

        Row i holds min(counts[i], K) neighbours, then N (an invalid index). Rows with more than
        K neighbours are never truncated silently: ``report`` says how many overflowed
        (``overflowed_rows``) and the largest count (grow K to ``largest_count`` and retry);
        with ``raise_on_overflow`` an overflow raises ``CapacityError``.
        """
        if int(k) < 0:
            raise ValueError(f"padded neighbour list: K must be >= 1, got {k}")
        like = self._like
        indices, counts, report = self._call(like, self._engine.padded, int(k),
                                             bool(raise_on_overflow), like.host)
        return _arrays.output(indices, like), _arrays.output(counts, like), report

    def _pairs(self, half: bool, distances: bool, vectors: bool) -> tuple:
        like = self._like
        out = self._call(like, self._engine.pairs, bool(half), bool(distances), bool(vectors),
                         like.host)
        return tuple(_arrays.output(a, like) for a in out)


class VerletList:
    """A Verlet neighbour list: every pair within ``cutoff + skin``, rebuilt only when some
    particle has moved more than ``skin / 2`` since the last rebuild (until then no pair within
    ``cutoff`` can be missing from it).

    >>> verlet = raycut.VerletList(cutoff=0.1, skin=0.02)
    >>> for step in range(steps):
    ...     x = integrate(x)                          # (N, 3) float32, NumPy or a CUDA tensor
    ...     verlet.update(x)                          # True when it rebuilt the list
    ...     offsets, indices = verlet.neighbours()    # pairs within cutoff + skin

    The list holds every pair within ``cutoff + skin`` of the positions of its last rebuild, not
    only those within ``cutoff``: the caller filters by the cutoff (compute ``|x_j - x_i|`` from
    the current positions and drop pairs at or beyond ``cutoff``). ``distances`` and ``vectors``
    are those of the last rebuild's positions, not of the current ones. The displacement check
    runs where the positions are (on the device for device positions: one reduction, no copy to
    the host).

    ``method``: a name from ``methods()`` or ``"auto"``. ``half``: each unordered pair once, in
    the row of its smaller index. ``distances``/``vectors``: also ``|r_ij|`` and
    ``r_ij = x_j - x_i`` per entry. Raises ValueError for a cutoff or skin out of range
    (``skin`` >= 0), for positions of another N than the first ``update``, and for bad positions,
    as ``Engine.build`` does.
    """

    def __init__(self, cutoff: float, skin: float, method: str = "auto", half: bool = False,
                 distances: bool = False, vectors: bool = False) -> None:
        if not isinstance(skin, numbers.Real):
            raise ValueError(f"skin must be a real number, got {type(skin).__name__}")
        self._list = _raycut.VerletList(_cutoff(cutoff), float(skin), method, bool(half),
                                        bool(distances), bool(vectors))
        self._like = _arrays.HOST

    def __repr__(self) -> str:
        return (f"raycut.VerletList(cutoff={self.cutoff}, skin={self.skin}, "
                f"method={self.method!r}, size={self.size}, rebuilds={self.rebuilds})")

    @property
    def method(self) -> str:
        """The method's name (what ``"auto"`` resolved to)."""
        return self._list.method

    @property
    def space(self) -> str:
        """Where the method works (and the list lives): ``"host"`` or ``"device"``."""
        return self._list.space

    @property
    def size(self) -> int:
        """N, the number of particles (0 before the first ``update``)."""
        return self._list.size

    @property
    def cutoff(self) -> float:
        return self._list.cutoff

    @property
    def skin(self) -> float:
        return self._list.skin

    @property
    def rebuilds(self) -> int:
        """How many times the list was built (the first ``update`` included)."""
        return self._list.rebuilds

    def update(self, positions: Any) -> bool:
        """New (N, 3) float32 positions (the same N after the first call): rebuilds the list at
        ``cutoff + skin`` when some particle has moved more than ``skin / 2`` since the last
        rebuild (always on the first call, and when the positions moved to another memory
        space: host to device or back). Returns True when it rebuilt the list. A failed call
        (ValueError for another N or a bad coordinate) leaves the list as it was."""
        x, like = _arrays.prepare(positions)
        with _arrays.device_context(like):
            self._list.set_stream(_arrays.stream_of(like))
            rebuilt = bool(self._list.update(x))
        self._like = like
        return rebuilt

    def neighbours(self) -> tuple:
        """The CSR list of the last rebuild: ``(offsets, indices)``, then ``distances`` and
        ``vectors`` when the list was made with them; dtypes, shapes and framework as
        ``Engine.neighbours`` (on the device for device positions and GPU methods).

        Every pair within ``cutoff + skin``: filter by the cutoff yourself. The arrays stay valid
        and unchanged for as long as you hold them, across later rebuilds: the library reuses its
        list buffer, so they wrap a copy of it, made once per rebuild (on the device for device
        lists: a memcpy, cheap next to the rebuild) on the first ``neighbours()`` call after it.
        Calls between two rebuilds return arrays over that same copy (no copy per call): treat
        them as read-only. Raises ValueError before the first ``update``.
        """
        like = self._like
        with _arrays.device_context(like):
            self._list.set_stream(_arrays.stream_of(like))
            offsets, indices, d, v = self._list.neighbours(like.host)
        out = [offsets, indices] + ([d] if d is not None else []) + ([v] if v is not None else [])
        return tuple(_arrays.output(a, like) for a in out)


_QUANTITIES = "ijdDS"


def _requires_grad(positions: Any) -> bool:
    return _arrays.framework_of(positions) == "torch" and bool(positions.requires_grad)


def neighbor_list(quantities: str, positions: Any, cutoff: float, cell: Any = None,
                  pbc: Any = None, batch: Any = None, half: bool = False,
                  method: str = "auto") -> Any:
    """ASE-style neighbour list (``ase.neighborlist.neighbor_list``) of open-boundary positions.

    ``quantities`` is a string of letters, returned in that order (one letter: the array alone,
    as ASE does):

    - ``"i"``, ``"j"``: the pairs (int64), sorted by i; every ordered pair (i, j) and (j, i)
      within the cutoff, no self pairs (with ``half=True``: each pair once, i < j);
    - ``"d"``: distances ``|x_j - x_i|`` (float32);
    - ``"D"``: vectors ``x_j - x_i`` (P, 3) float32;
    - ``"S"``: shifts, for periodic boxes: not supported yet (ValueError).

    ``positions``: (N, 3) float32 (NumPy: any float, converted). The outputs are of the
    positions' framework and device (CUDA tensors in: CUDA tensors out, zero-copy). For PyTorch
    positions that require grad, ``d`` and ``D`` are computed in PyTorch from the pairs
    (``x[j] - x[i]``), so that gradients flow back to the positions.
    ``cell``/``pbc``: periodic boxes are not supported yet (ValueError unless None or all
    False); ``batch``: not supported yet (ValueError unless None). ``method``: a name from
    ``methods()`` or ``"auto"``.
    """
    if not isinstance(quantities, str) or not quantities:
        raise ValueError("quantities must be a non-empty string of the letters i, j, d, D")
    for letter in quantities:
        if letter not in _QUANTITIES:
            raise ValueError(f"unknown quantity {letter!r} in {quantities!r} (known: i, j, d, D; "
                             "S for periodic boxes)")
    if "S" in quantities:
        raise ValueError("quantity 'S' (cell shifts): periodic boxes are not supported yet")
    _no_periodic(cell, pbc, batch)
    engine = Engine(method)
    engine.build(positions, cutoff)
    i, j, d, v = engine._pairs(half, "d" in quantities, "D" in quantities)
    if ("d" in quantities or "D" in quantities) and _requires_grad(positions):
        # PyTorch autograd: d and D recomputed in the framework from the pairs, so gradients flow
        # to the positions (the same float32 values as the library's x_j - x_i).
        v = positions.index_select(0, j) - positions.index_select(0, i)
        if "d" in quantities:
            import torch

            d = torch.linalg.vector_norm(v, dim=1)
    found = {"i": i, "j": j, "d": d, "D": v}
    out = tuple(found[letter] for letter in quantities)
    return out[0] if len(out) == 1 else out


from . import ase  # noqa: E402  raycut.ase.neighbor_list: ASE Atoms in, ASE's types out
