"""raycut: particle interactions and neighbour lists within a cutoff, on GPUs and CPUs.

Every pair (i, j), i != j, with ``|x_j - x_i|^2 < cutoff^2`` (one shared float32 predicate) is
found exactly once per direction, by every method. Methods: ``methods()``; ``"auto"`` picks the
CUDA grid with a GPU and the CPU cell list without.

Positions are an (N, 3) float32 array: NumPy, array likes, or anything with ``__dlpack__`` or
``__cuda_array_interface__`` (PyTorch, CuPy, JAX, ...), read in place when float32 and
C-contiguous; other float dtypes and non-contiguous NumPy, PyTorch, CuPy and JAX arrays are
converted by their own framework, on their device (a copy), and float64 inputs get float64
distances, vectors and kernel results. Complex dtypes and devices other than the CPU and CUDA
are refused. Outputs come back in the caller's framework on the caller's device: NumPy in, NumPy
out; CUDA tensors in, CUDA tensors out, wrapping the library's device memory without a copy (the
arrays keep it alive).

Threads: calls on one ``Engine`` or ``VerletList`` from several threads are serialised by its
lock (taken with the GIL released); calls on different objects run in parallel. Sizes above the
memory budget (``RAYCUT_MAX_MEMORY``, e.g. ``300M``, else the memory available to the process)
raise ``MemoryError`` before anything is allocated (docs/limits.md, "Threads" and "Memory").

Errors carry the library's message: ``ValueError`` for bad input (NaN coordinate: its index;
cutoff <= 0; unknown method or kernel), ``MemoryError`` when it does not fit,
``NotImplementedError`` for what this build or machine cannot do (a GPU method without a GPU),
``CapacityError`` (a ``RuntimeError``) when a padded list is asked to raise on overflow,
``OSError`` for files and ``RuntimeError`` for device faults.

Periodic boxes (``cell``: rows are the lattice vectors, ASE's convention; ``pbc`` per axis),
batches of independent systems (``batch``: the system of each particle, sorted, as
torch_cluster's) and query sets (``radius``) follow docs/periodic.md, "Semantics": a pair is (i, j, S) with
``r_ij = x_j - x_i + S @ cell``, S the integer image shift (``"S"``), every image within the
cutoff (boxes thinner than twice the cutoff give a pair once per image, and a particle its own
images). The CPU methods and the CUDA ``grid`` and ``brute-force-gpu`` support them; the others
raise ``NotImplementedError``.

``neighbor_list`` and ``radius`` reuse one engine per method and CUDA device from call to call
(its structure buffers are not allocated again); ``clear_engine_cache()`` frees them and
``set_engine_cache(False)`` turns the reuse off. Their outputs are new arrays every call.
"""
from __future__ import annotations

import numbers
import os
import sys
import warnings
from typing import Any, Optional

import numpy as np

# OpenMP threads sleep between parallel regions instead of spinning on cores that the caller's
# own threads (or other processes) need. Read when the OpenMP runtime starts, so only when
# raycut is the first to load it; set OMP_WAIT_POLICY yourself to choose otherwise.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from . import _arrays  # noqa: E402
from . import _cutoffs  # noqa: E402
from . import _raycut  # noqa: E402
from . import _systems  # noqa: E402
from ._raycut import CapacityError  # noqa: E402

__version__ = "0.1.0"
__all__ = [
    "CapacityError",
    "Engine",
    "KERNELS",
    "KERNEL_CATALOGUE",
    "VerletList",
    "auto_method",
    "check_pair_count",
    "clear_engine_cache",
    "cuda_available",
    "load_torch_ops",
    "methods",
    "neighbor_list",
    "radius",
    "set_engine_cache",
]

#: The built-in kernels of ``Engine.compute``, from the library's own catalogue: per kernel name,
#: a dict of its ``parameters`` (name, type, default, accepted min and max), its per-particle
#: ``inputs`` (name, components, ``end``: read at both ends of a pair from one array ("both"),
#: one per source ("sources") or one per query point ("queries"), positive) and its ``outputs``
#: ((name, components) pairs).
KERNEL_CATALOGUE = {k["name"]: k for k in _raycut.kernel_catalogue()}

#: The built-in kernels of ``Engine.compute`` and what each returns.
KERNELS = {name: tuple(out for out, _ in k["outputs"]) for name, k in KERNEL_CATALOGUE.items()}

# Every kernel's parameters and inputs by name (one compute call may pass every kernel's
# parameters: those the kernel does not read are ignored).
_KERNEL_PARAMETERS = {p["name"]: p for k in KERNEL_CATALOGUE.values() for p in k["parameters"]}
_KERNEL_INPUTS = {i["name"] for k in KERNEL_CATALOGUE.values() for i in k["inputs"]}


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
    if type(cutoff) in (float, int):  # the usual case, before the checks of the others
        return float(cutoff)
    if getattr(cutoff, "shape", None) == () and not isinstance(cutoff, (str, bytes)):
        dtype = getattr(cutoff, "dtype", "")
        _arrays._refuse_complex("cutoff", dtype, "complex" in str(dtype))
        return float(cutoff)  # a 0-d array or tensor: one number (the library checks its range)
    if isinstance(cutoff, (dict, list, tuple)) or hasattr(cutoff, "__len__"):
        raise ValueError("cutoff must be one number here: per-atom or per-pair cutoffs are "
                         "taken by neighbor_list")
    if not isinstance(cutoff, numbers.Real):
        raise ValueError(f"cutoff must be a real number, got {type(cutoff).__name__}")
    return float(cutoff)


_K_MAX = 2**32 - 1  # the padded list's K is a 32-bit count


class Engine:
    """A method built over positions: fused pair kernels and neighbour lists.

    >>> engine = pyraycut.Engine("auto")
    >>> engine.build(positions, cutoff=0.1)      # (N, 3) float32, NumPy or a CUDA tensor
    >>> engine.compute("lj_forces")["force"]     # (N, 3), in the positions' framework
    >>> offsets, indices = engine.neighbours()   # CSR, on the positions' device
    >>> engine.build(x, 2.5, cell=cell, pbc=True, batch=batch)   # periodic boxes, a batch
    >>> offsets, indices, shifts = engine.neighbours(shifts=True)

    The outputs of every call are new arrays of the framework and device of the positions given
    to the last ``build``/``update``: later calls never change them (neighbour lists are fresh
    buffers the arrays own; kernel results are the engine's result arrays, handed over without a
    copy: the next ``compute`` makes new ones).
    """

    def __init__(self, method: str = "auto") -> None:
        self._engine = _raycut.Engine(method)
        self._stream = 0  # the CUDA stream last given to the engine (0: the default)
        self._like = _arrays.HOST
        self._wide = False  # built from float64 host positions (decided in double)
        self._queries = False
        self._batch = _systems.Batch(None, 1, None, None)

    def __repr__(self) -> str:
        return (f"pyraycut.Engine(method={self.method!r}, space={self.space!r}, size={self.size}, "
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
        """The number of targets (rows of lists, entries of results) of the last build: N, or M
        with query points."""
        return self._engine.size

    @property
    def sources(self) -> int:
        """N, the number of particles (sources) of the last build."""
        return self._engine.sources

    @property
    def cutoff(self) -> float:
        return self._engine.cutoff

    @property
    def timings(self) -> dict:
        """Milliseconds of the last build/update and compute (``device_*``: CUDA events, GPU
        methods only, -1 otherwise)."""
        return self._engine.timings()

    def _call(self, like: _arrays.Like, function, *args, **kwargs):
        """function(*args, **kwargs) on the caller's CUDA device and stream (one lookup per API
        call: at 1,000 particles each costs a visible share of the call)."""
        if like.host and self._stream == 0:  # host arrays, the default stream set already
            return function(*args, **kwargs)
        with _arrays.device_context(like):
            self._stream = _arrays.stream_of(like)
            self._engine.set_stream(self._stream)
            return function(*args, **kwargs)

    def build(self, positions: Any, cutoff: float, *, cell: Any = None, pbc: Any = None,
              batch: Any = None, queries: Any = None, batch_queries: Any = None) -> None:
        """Validates (finite coordinates, cutoff finite and > 0) and builds the method's structure
        over (N, 3) float32 positions. Raises ValueError naming the first bad index.

        ``cell``, ``pbc``, ``batch``: periodic boxes and batches, as ``neighbor_list`` takes
        them. ``queries``: (M, 3) float32 query points (the same framework and device as the
        positions), the targets of the lists and kernels, the positions their sources; their
        systems in ``batch_queries`` (see ``radius``). Raises ValueError for a bad box (a
        singular cell, with the library's message) or batch, NotImplementedError for a method
        without boxes, batches or queries.
        """
        x, like = _arrays.prepare(positions)
        self._build(x, like, positions, cutoff, cell, pbc, batch, queries, batch_queries)

    def _build(self, x: Any, like: _arrays.Like, positions: Any, cutoff: float, cell: Any,
               pbc: Any, batch: Any, queries: Any, batch_queries: Any) -> None:
        """build() on positions already prepared (x, like: ``_arrays.prepare(positions)``)."""
        n = _points(x)
        boxes = _systems.boxes(cell, pbc)
        q = None
        m = None
        if queries is not None:
            q, query_like = _arrays.prepare(queries, "queries")
            if query_like.host != like.host:
                raise ValueError("queries and positions must be in the same memory space (both "
                                 "on the host or both on the CUDA device)")
            m = _points(q)
        elif batch_queries is not None:
            raise ValueError("batch_queries without queries")
        b = _systems.batch(boxes, n, batch, m, batch_queries)
        # No periodic axis anywhere: no images, an open build (which every method has).
        periodic = boxes is not None and boxes.periodic
        cells = boxes.cells if periodic else None
        flags = boxes.pbc if periodic else None
        # float64 host positions beside their float32 rounding: pairs decided in double.
        wide = _arrays.float64_host(positions) if like.host else None
        self._call(like, self._engine.build, _arrays.readable(x), _cutoff(cutoff), cells, flags,
                   b.offsets, None if q is None else _arrays.readable(q), b.query_offsets, wide)
        self._like = like
        self._wide = wide is not None
        self._queries = queries is not None
        self._batch = b

    def update(self, positions: Any, skin: float = 0.0) -> None:
        """New positions of the same N particles, cutoff, boxes and batch unchanged (with boxes
        or a batch: a rebuild; after a build with queries: NotImplementedError, build again).
        ``skin`` > 0 lets the OptiX
        methods refit their structure instead of rebuilding it while no particle has moved more
        than skin / 2 since the last full build."""
        x, like = _arrays.prepare(positions)
        wide = _arrays.float64_host(positions) if like.host and self._wide else None
        self._engine.set_skin(float(skin))
        self._call(like, self._engine.update, _arrays.readable(x), wide)
        self._like = like
        self._wide = wide is not None

    def _kernel_input(self, value: Any, name: str) -> Any:
        if value is None:
            return None
        if self.space == "host":
            return _arrays.to_host(value)
        x, _ = _arrays.prepare(value, name, points=False)
        return _arrays.readable(x)

    def compute(self, kernel: str = "count", **options: Any) -> dict:
        """Runs a built-in kernel over every in-range pair, fused in the method's traversal, and
        returns its per-particle results as a dict of new arrays (``KERNELS`` says which):

        - ``count`` (N,) int32: neighbours per particle;
        - ``energy`` (N,) float32 (``lj``, ``lj_forces``, ``smooth``, ``coulomb_dsf``);
        - ``force`` (N, 3) float32 (``lj_forces``, ``smooth``, ``sph_force``, ``coulomb_dsf``);
        - ``virial`` (N, 6) float32, xx yy zz xy xz yz (``lj_forces``, ``coulomb_dsf``);
        - ``density`` (N,) float32 (``sph_density``).

        ``options`` are the kernel's parameters and per-particle inputs by name
        (``KERNEL_CATALOGUE`` lists each kernel's): ``lj_epsilon`` (1), ``lj_sigma`` (1),
        ``lj_shift`` (False), ``sph_mass`` (0), ``sph_viscosity`` (0), ``alpha`` (0) and
        ``coulomb_constant`` (1); ``velocity`` (N, 3), ``density`` and ``pressure`` (N,) for
        ``sph_force``; ``charge`` (one per source) and, with query points only,
        ``query_charge`` (one per query) for ``coulomb_dsf``. Parameters of other kernels are
        ignored (one set of options can serve several kernels); an unknown name, or an input the
        kernel does not read, raises ValueError.

        Lennard-Jones conventions: ``lj_forces`` shares each pair's energy and virial half and
        half between its two atoms (LAMMPS's and ASE's per-atom convention), so
        ``energy.sum()`` is the system's energy and ``virial.sum(0)`` its virial
        ``sum_{i<j} (x_i - x_j) (x) f_ij`` (stress = -virial / volume). ``lj_shift=True``
        shifts every pair's energy to 0 at the cutoff (as ASE's ``LennardJones``; forces
        unchanged). ``lj`` is the paper's kernel: each pair counted fully on both atoms
        (``energy.sum()`` is twice the system's), never shifted (``lj_shift`` raises
        ValueError).

        ``coulomb_dsf`` is the damped shifted-force Coulomb sum of Fennell and Gezelter (2006)
        with the same per-atom convention, each atom's self term included in its energy
        (docs/kernels.md). The results are the engine's own arrays handed over without a copy
        (on the device for device positions and GPU methods), never changed by a later call.
        """
        parameters, inputs = {}, {}
        for name, value in options.items():
            if name in _KERNEL_INPUTS:
                if value is not None:
                    inputs[name] = self._kernel_input(value, name)
            elif name in _KERNEL_PARAMETERS:
                is_flag = _KERNEL_PARAMETERS[name]["type"] == "bool"
                parameters[name] = bool(value) if is_flag else float(value)
            else:
                known = sorted(_KERNEL_PARAMETERS) + sorted(_KERNEL_INPUTS)
                raise ValueError(f"compute: unknown option {name!r} (known: "
                                 f"{', '.join(known)})")
        like = self._like
        out = self._call(like, self._engine.compute, kernel, parameters, inputs, like.host)
        return {name: _arrays.output(array, like) for name, array in out.items()}

    def neighbours(self, half: bool = False, distances: bool = False, vectors: bool = False,
                   shifts: bool = False, any_row: bool = False) -> tuple:
        """The CSR neighbour list of the built positions: ``(offsets, indices)`` then
        ``distances``, ``vectors`` and ``shifts`` when asked.

        The neighbours of target i are ``indices[offsets[i]:offsets[i+1]]`` (order within a
        row unspecified). offsets (size + 1,) int64, indices int32, distances ``|r_ij|``
        float32, vectors ``r_ij = x_j - x_i + S @ cell`` (P, 3) float32, shifts S (P, 3) int32
        (zeros without a box). ``half``: each pair once: of (i, j, S) and (j, i, -S) the one
        with i < j, or i == j and S lexicographically positive, in row i (not with queries:
        ValueError). ``any_row`` (with ``half``): each pair once still, in the row of whichever
        particle the method met it from; the grid and the cell list then walk half their
        stencil, less work (for loops that add each pair to both particles). On the device for device
        positions and GPU methods, wrapping the list's own buffer (zero-copy; each call fills
        a new buffer).
        """
        self._no_half_with_queries(half)
        like = self._like
        out = self._call(like, self._engine.neighbours, bool(half), bool(distances),
                         bool(vectors), like.host, bool(shifts), bool(any_row))
        asked = (True, True, distances, vectors, shifts)
        return tuple(_arrays.output(a, like) for a, keep in zip(out, asked) if keep)

    def _no_half_with_queries(self, half: bool) -> None:
        if half and self._queries:
            raise ValueError("half lists are not defined for query sets: their pairs (query, "
                             "point) are not symmetric (pass half=False)")

    def padded_neighbours(self, k: int, raise_on_overflow: bool = False,
                          shifts: bool = False, half: bool = False, nearest: bool = False) -> tuple:
        """The padded [N, K] neighbour matrix: ``(indices, counts, report)``, and with
        ``shifts`` also S, (N, K, 3) int32 (0 in empty slots): ``(indices, counts, report, S)``.

        Row i holds min(counts[i], K) neighbours, then N (an invalid index); in a periodic box a
        row can hold a source once per image, S says which. Rows with more than K neighbours
        are never truncated silently: ``report`` says how many overflowed (``overflowed_rows``)
        and the largest row's count (``largest_count``: grow K to it and retry); with
        ``raise_on_overflow`` an overflow raises ``CapacityError``. K is a whole number in
        [1, 2^32 - 1] (ValueError otherwise); a matrix beyond the memory budget raises
        MemoryError before it is allocated, saying which K is always enough. ``half``: each
        pair once, as ``neighbours`` says. ``nearest``: each row's K nearest, nearest first
        (equal distances by index, then S), in place of its first K: distances in double from the
        positions as built (float64 ones when given, query points as float32); CPU methods only
        (NotImplementedError otherwise).
        """
        self._no_half_with_queries(half)
        if (isinstance(k, bool) or not isinstance(k, numbers.Real) or int(k) != k or int(k) < 0
                or int(k) > _K_MAX):
            raise ValueError(f"padded neighbour list: K must be a whole number in [1, 2^32 - 1 = "
                             f"{_K_MAX}], got {k!r}")
        like = self._like
        indices, counts, report, s = self._call(like, self._engine.padded, int(k),
                                                bool(raise_on_overflow), like.host, bool(shifts),
                                                bool(half), bool(nearest))
        out = (_arrays.output(indices, like), _arrays.output(counts, like), report)
        return out + (_arrays.output(s, like),) if shifts else out

    def _host_system_pairs(self, wide: np.ndarray, cutoff: float, cells: Optional[np.ndarray],
                           flags: Optional[np.ndarray]) -> tuple:
        """(i, j, S) of one system on the host given as the extension takes it: float64 (N, 3)
        C-contiguous positions (the pairs decided in double from them), cells (1, 3, 3) float64
        and flags (1, 3) bool, or None for an open system. No parsing of other input forms:
        for callers whose inputs are in these shapes already (pyraycut.ase's Atoms). Leaves the
        engine for another build, not for Engine.pairs."""
        self._call(_arrays.HOST, self._engine.build, wide.astype(np.float32), cutoff, cells, flags,
                   None, None, None, wide)
        i, j, _, _, shifts = self._call(_arrays.HOST, self._engine.pairs, False, False, False,
                                        True, True)
        return i, j, shifts

    def _pairs(self, half: bool, distances: bool, vectors: bool, shifts: bool = False,
               cutoffs: Optional[dict] = None) -> tuple:
        """COO pairs; ``cutoffs``: per-pair cutoffs (``_cutoffs.PairCutoffs.arrays()``)."""
        self._no_half_with_queries(half)
        like = self._like
        out = self._call(like, self._engine.pairs, bool(half), bool(distances), bool(vectors),
                         like.host, bool(shifts), **(cutoffs or {}))
        if like is _arrays.HOST:  # NumPy float32 in, NumPy out: nothing to convert
            return out
        return tuple(_arrays.output(a, like) for a in out)


class VerletList:
    """A Verlet neighbour list: every pair within ``cutoff + skin``, rebuilt only when some
    particle has moved more than ``skin / 2`` since the last rebuild (until then no pair within
    ``cutoff`` can be missing from it), in open or periodic boxes, of one system or a batch.

    >>> verlet = pyraycut.VerletList(cutoff=2.5, skin=0.3, shifts=True, cell=cell, pbc=True)
    >>> for step in range(steps):
    ...     x = integrate(x)                          # (N, 3) float32, NumPy or a CUDA tensor
    ...     verlet.update(x)                          # True when it rebuilt the list
    ...     offsets, indices, S = verlet.neighbours() # pairs within cutoff + skin

    The list holds every pair (i, j, S) within ``cutoff + skin`` of the positions of its last
    rebuild, not only those within ``cutoff``: the caller filters by the cutoff (compute
    ``r_ij = x[j] - x[i] + S @ cell`` from the current positions and drop pairs at or beyond
    ``cutoff``). ``distances`` and ``vectors`` are those of the last rebuild's positions, not of
    the current ones. The displacement check runs where the positions are (on the device for
    device positions: one reduction, no copy to the host). Pass unwrapped positions (do not wrap
    particles back into the cell between rebuilds): S refers to the positions as given, and a
    particle wrapped across the box moves by a whole cell, which forces a rebuild.

    ``method``: a name from ``methods()`` or ``"auto"``. ``half``: each pair once, as
    ``Engine.neighbours`` says. ``distances``/``vectors``/``shifts``: also ``|r_ij|``,
    ``r_ij = x_j - x_i + S @ cell`` and S (int32; zeros without a cell) per entry. ``cell``,
    ``pbc``, ``batch``: periodic boxes and a batch of independent systems, as ``neighbor_list``
    takes them, fixed for the list's life (``batch`` gives N: every ``update`` passes that
    many particles). Raises ValueError for a cutoff or skin out of range (``skin`` >= 0), a bad
    cell or batch, positions of another N than the first ``update`` (or than the batch), and
    bad positions, as ``Engine.build`` does; NotImplementedError for a method without boxes or
    batches (see ``neighbor_list``), at the first ``update``.
    """

    def __init__(self, cutoff: float, skin: float, method: str = "auto", half: bool = False,
                 distances: bool = False, vectors: bool = False, shifts: bool = False,
                 cell: Any = None, pbc: Any = None, batch: Any = None) -> None:
        if not isinstance(skin, numbers.Real):
            raise ValueError(f"skin must be a real number, got {type(skin).__name__}")
        boxes = _systems.boxes(_host_cell(cell), pbc)
        b = _systems.batch(boxes, None, batch)
        periodic = boxes is not None and boxes.periodic
        self._list = _raycut.VerletList(_cutoff(cutoff), float(skin), method, bool(half),
                                        bool(distances), bool(vectors), bool(shifts),
                                        boxes.cells if periodic else None,
                                        boxes.pbc if periodic else None, b.offsets)
        self._like = _arrays.HOST

    def __repr__(self) -> str:
        return (f"pyraycut.VerletList(cutoff={self.cutoff}, skin={self.skin}, "
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

    @property
    def half(self) -> bool:
        return self._list.half

    @property
    def distances(self) -> bool:
        return self._list.distances

    @property
    def vectors(self) -> bool:
        return self._list.vectors

    @property
    def shifts(self) -> bool:
        return self._list.shifts

    def update(self, positions: Any) -> bool:
        """New (N, 3) float32 positions (the same N after the first call): rebuilds the list at
        ``cutoff + skin`` when some particle has moved more than ``skin / 2`` since the last
        rebuild (always on the first call, and when the positions moved to another memory
        space: host to device or back). Returns True when it rebuilt the list. A failed call
        (ValueError for another N or a bad coordinate) leaves the list as it was."""
        x, like = _arrays.prepare(positions)
        with _arrays.device_context(like):
            self._list.set_stream(_arrays.stream_of(like))
            rebuilt = bool(self._list.update(_arrays.readable(x)))
        self._like = like
        return rebuilt

    def neighbours(self) -> tuple:
        """The CSR list of the last rebuild: ``(offsets, indices)``, then ``distances``,
        ``vectors`` and ``shifts`` when the list was made with them; dtypes, shapes and
        framework as ``Engine.neighbours`` (on the device for device positions and GPU
        methods).

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
            out = self._list.neighbours(like.host)
        return tuple(_arrays.output(a, like) for k, a in enumerate(out) if k < 2 or a is not None)


# ---- the engines neighbor_list and radius reuse ------------------------------------------------

# (method, CUDA device) -> an idle Engine. neighbor_list and radius take one out for the call and
# put it back after, so a series of calls rebuilds into the same structure buffers (grid cells,
# sort keys, image points: host and device memory that only grows) instead of allocating and
# freeing them every call; the outputs are fresh buffers every call all the same. Taking one out
# makes concurrent calls (threads) use engines of their own.
_ENGINES: dict = {}
_ENGINE_CACHE = [True]


def clear_engine_cache() -> None:
    """Frees the engines that ``neighbor_list`` and ``radius`` keep between calls (one per method
    and CUDA device, each holding the structure of its last call: memory that grows to the
    largest system it has seen; a CPU engine also keeps the rows of its last list, up to
    256 MiB, so that the next list is made in one pass without fresh memory), and the host list
    buffers kept for reuse (at most two, 256 MiB together: the memory of lists whose arrays are
    gone, refilled by the next lists without the page faults of fresh memory). Arrays already
    returned are not affected."""
    _ENGINES.clear()
    _raycut.release_idle_lists()


def set_engine_cache(enabled: bool) -> None:
    """Whether ``neighbor_list`` and ``radius`` keep their engine between calls (the default:
    True). Off: a new engine per call, which allocates its buffers and frees them after;
    ``clear_engine_cache()`` is called."""
    _ENGINE_CACHE[0] = bool(enabled)
    clear_engine_cache()


def _take_engine(method: str, like: _arrays.Like) -> tuple:
    """An engine for one call, and its cache key (None when the cache is off). The key's device
    is where a GPU method will allocate: the CUDA device current during the call."""
    if not _ENGINE_CACHE[0]:
        return _untimed_engine(method), None
    with _arrays.device_context(like):
        key = (method, _raycut.current_device())
    engine = _ENGINES.pop(key, None)
    return (engine if engine is not None else _untimed_engine(method)), key


def _untimed_engine(method: str) -> Engine:
    """An engine whose builds do not time themselves: nobody reads the times of the engine a
    call borrows, and timing a GPU build is a wait for the GPU."""
    engine = Engine(method)
    engine._engine.set_timed(False)
    return engine


def _put_back(key: Any, engine: Engine) -> None:
    """After a call that succeeded (an engine whose call raised is dropped)."""
    if key is not None and _ENGINE_CACHE[0]:
        _ENGINES[key] = engine


_QUANTITIES = "ijdDSc"


def _points(x: Any) -> Optional[int]:
    """The number of rows of an input the extension reads (None when it has no shape: an unknown
    framework's array, known only through DLPack; the library checks its size then)."""
    shape = getattr(x, "shape", None)
    if shape is None and hasattr(x, "__cuda_array_interface__"):
        shape = x.__cuda_array_interface__.get("shape")
    return int(shape[0]) if shape is not None and len(shape) else None


def _letters(quantities: Any) -> str:
    if not isinstance(quantities, str) or not quantities:
        raise ValueError("quantities must be a non-empty string of the letters i, j, d, D, S, c")
    for letter in quantities:
        if letter not in _QUANTITIES:
            raise ValueError(f"unknown quantity {letter!r} in {quantities!r} (known: i, j, d, D, "
                             "S, c)")
    return quantities


def _requires_grad(x: Any) -> bool:
    return _arrays.framework_of(x) == "torch" and bool(x.requires_grad)


def _search_input(x: Any, grad: bool) -> Any:
    """What the pair search reads: on the autograd path a detached float32 C-contiguous copy of
    a PyTorch tensor of any float dtype (gradcheck runs in float64); the input itself otherwise."""
    if not grad:
        return x
    import torch

    x = x.detach()
    return x if x.dtype == torch.float32 and x.is_contiguous() else x.to(torch.float32).contiguous()


def _pair_quantities(letters: str, engine: Engine, half: bool, grad: bool, sources: Any,
                     targets: Any, cell: Any, wide: Optional[np.ndarray] = None,
                     cutoffs: Optional[dict] = None) -> Any:
    """The letters of the built engine's pairs, in the order asked. On the autograd path ``d``
    and ``D`` are computed in PyTorch from i, j and S (docs/python.md); from ``wide``, the
    caller's float64 host positions, they are computed in float64 from i, j and S.
    ``cutoffs``: per-pair cutoffs, as ``Engine._pairs`` takes them."""
    batch = engine._batch
    periodic = batch.boxes is not None and batch.boxes.periodic
    metric = "d" in letters or "D" in letters
    grad = grad and metric
    recompute = grad or (wide is not None and metric)
    i, j, d, v, shifts = engine._pairs(half, "d" in letters and not recompute,
                                       "D" in letters and not recompute,
                                       "S" in letters or (recompute and periodic), cutoffs)
    rows = batch.query_offsets if batch.query_offsets is not None else batch.offsets
    if grad:
        import torch

        v = _systems.torch_vectors(torch, sources, targets, i, j, shifts, cell, batch.boxes,
                                   rows)
        if "d" in letters:
            d = torch.linalg.vector_norm(v, dim=1)
    elif recompute:
        host, lengths = _systems.host_vectors(
            wide, wide, _arrays.to_numpy(i), _arrays.to_numpy(j),
            None if shifts is None else _arrays.to_numpy(shifts), batch.boxes, rows)
        v = _arrays.output(host, engine._like)
        if "d" in letters:
            d = _arrays.output(lengths, engine._like)
    found = {"i": i, "j": j, "d": d, "D": v, "S": shifts}
    out = tuple(found[letter] for letter in letters)
    return out[0] if len(out) == 1 else out


def neighbor_list(quantities: str, positions: Any, cutoff: Any, cell: Any = None,
                  pbc: Any = None, batch: Any = None, half: bool = False,
                  method: str = "auto", numbers: Any = None,
                  max_pairs: Optional[int] = None) -> Any:
    """ASE-style neighbour list (``ase.neighborlist.neighbor_list``): every pair of particles
    within ``cutoff``, in open or periodic boxes, of one system or a batch of them.

    A pair is (i, j, S), S an integer image shift, with ``r_ij = x_j - x_i + S @ cell``; it is
    listed iff ``|r_ij| < cutoff``, for every such S (a box thinner than twice the cutoff gives a
    pair once per image, and particle i its own images (i, i, S != 0); (i, i, 0) never).

    ``quantities`` is a string of letters, returned in that order (one letter: the array alone,
    as ASE does):

    - ``"i"``, ``"j"``: the pairs (int64), sorted by i; every ordered pair (i, j, S) and
      (j, i, -S) (with ``half=True`` each pair once: the one with i < j, or i == j and S
      lexicographically positive);
    - ``"d"``: distances ``|r_ij|`` (float32; float64 for float64 positions on the host,
      computed in float64 from them);
    - ``"D"``: vectors ``r_ij = x_j - x_i + S @ cell`` (P, 3) float32 (float64 likewise);
    - ``"S"``: image shifts S (P, 3) int32 (zeros on open axes and without a cell);
    - ``"c"``: the pair count, a 0-d int64 tensor on the positions' device (PyTorch tensors:
      asking for it sends the call through the operator): with ``max_pairs`` the list is valid
      iff 0 <= c <= max_pairs. Asking for it is taking charge of the check: raycut then reads
      nothing back (see below).

    ``cutoff``: one number, or per atom or per pair as ASE takes them: a sequence of N radii
    (pair (i, j) within ``r_i + r_j``), ``{(Z1, Z2): rc}`` (pair cutoffs by species; pairs of
    species not listed have none) or ``{Z: r}`` (a radius per species), the species given by
    ``numbers`` (N,) integers. Those search at the largest pair cutoff, and the list pass itself
    keeps the pairs with ``|r_ij| < cutoff(i, j)`` (on the device for device positions), decided
    in double from the positions as given on the CPU methods (docs/limits.md). Any framework;
    not with ``max_pairs``.

    ``positions``: (N, 3) float32 (NumPy: any float, converted), wrapped into the cell or not
    (S refers to the positions as given). ``cell``: the box, rows the lattice vectors a, b, c
    (ASE's convention): (3, 3), or 3 numbers for an orthorhombic box, or (B, 3, 3) for one box
    per system of a batch; None: open boundaries. ``pbc``: which lattice vectors repeat: one
    bool, 3 bools, or (B, 3) per system; None: all three when a cell is given. Open axes take
    no images (their cell row may be zero). A singular cell raises ValueError.

    ``batch``: many independent systems in one call, as torch_cluster's ``batch``: the system
    index of each particle, (N,) integers, sorted (each system's particles contiguous; unsorted
    raises ValueError). Pairs never cross systems; indices stay global; systems may be empty.
    The number of systems B is that of a per-system ``cell``/``pbc``, else ``batch.max() + 1``.
    A CUDA PyTorch ``batch`` is checked and turned into offsets on the device (only B + 1
    offsets and 4 scalars reach the host); other device arrays are copied to the host first.

    The outputs are of the positions' framework and device (CUDA tensors in: CUDA tensors out,
    zero-copy). For PyTorch positions or cell that require grad, ``d`` and ``D`` are computed in
    PyTorch from i, j and S (``x[j] - x[i] + S @ cell``), so that gradients flow back to both
    (positions of any float dtype then; the search itself runs in float32). ``method``: a name
    from ``methods()`` or ``"auto"``; methods without periodic boxes or batches raise
    NotImplementedError for them. CUDA positions are never copied to the host, nor are the pairs.
    The engine is reused from call to call (see ``clear_engine_cache``).

    PyTorch CPU tensors (float32 or float64; ``method`` "auto" or "cell-list") go through the
    operator ``torch.ops.raycut.neighbor_list``, so the same call works under
    ``torch.compile(fullgraph=True)``, ``torch.export`` and AOTInductor; ``d`` and ``D`` are then
    always computed in PyTorch, in the positions' dtype (docs/python.md). ``max_pairs`` (those
    tensors only): outputs of that static size, the pairs first, then padding (i = j = N, S = 0,
    d = 0); a list that does not fit raises ``CapacityError`` in eager mode, unless ``"c"`` is
    among the quantities: then the caller checks the count (``check_pair_count`` where the host
    may wait), and a CUDA call on small systems never waits for the GPU (CUDA graphs capture it;
    docs/python.md, "Static capacity on CUDA"). CUDA tensors (method "auto" or "grid") take the
    operator's CUDA kernel, where it is built, with ``max_pairs``, under torch.compile, and for
    small systems, where it is faster (N <= 4096 or N^2 <= 2^23 B, B the systems of a (B, 3, 3)
    cell, else 1: batches up to 512 x 128); other eager calls keep the zero-copy path above.

    >>> i, j, S = pyraycut.neighbor_list("ijS", x, 3.0, cell=[10.0, 10.0, 10.0], pbc=True)
    >>> i, j = pyraycut.neighbor_list("ij", x, 3.0, cell=cells, batch=batch)   # cells (B, 3, 3)
    """
    letters = _letters(quantities)
    pair_cutoffs = None
    if _cutoffs.is_varying(cutoff):
        if max_pairs is not None or _compiling(positions):
            raise ValueError("per-atom and per-pair cutoffs: not with max_pairs nor inside "
                             "torch.compile (the operator takes one cutoff: list at the largest "
                             "and mask d < cutoff(i, j) in the model)")
        n = _points(positions)
        cutoffs = _cutoffs.PairCutoffs(
            cutoff, n if n is not None else _points(_arrays.to_host(positions)), numbers)
        cutoff, pair_cutoffs = cutoffs.search_cutoff(), cutoffs.arrays()
    elif _torch_ops_route(positions, method, max_pairs, cell=cell, pbc=pbc,
                          count="c" in letters):
        return _torch_ops().neighbor_list(letters, positions, cutoff, cell, pbc, batch, half,
                                          max_pairs)
    if "c" in letters:
        raise ValueError("the quantity 'c' (the pair count) comes with PyTorch tensors through "
                         "torch.ops.raycut (CPU tensors with method 'auto' or 'cell-list', CUDA "
                         "tensors with 'auto' or 'grid' where its CUDA kernel is built)")
    grad = _requires_grad(positions) or (_arrays.framework_of(positions) == "torch"
                                         and _requires_grad(cell))
    search = _search_input(positions, grad)
    x, like = _arrays.prepare(search)
    engine, key = _take_engine(method, like)
    # The search input itself beside x: float64 host positions are decided in double.
    engine._build(x, like, search, cutoff, _host_cell(cell), pbc, batch, None, None)
    engine._like = like  # the caller's dtype: x may be its float32 conversion
    wide = _arrays.float64_host(search) if engine._wide and not grad else None
    out = _pair_quantities(letters, engine, half, grad, positions, positions, cell, wide,
                           pair_cutoffs)
    _put_back(key, engine)
    return out


def radius(points: Any, queries: Any, cutoff: float, cell: Any = None, pbc: Any = None,
           batch_points: Any = None, batch_queries: Any = None, method: str = "auto",
           quantities: str = "ij", max_pairs: Optional[int] = None) -> Any:
    """Radius search between two point sets: for every query q, the points p within ``cutoff``
    (``torch_cluster.radius(x=points, y=queries, r=cutoff, batch_x, batch_y)``, scipy's
    ``cKDTree(points).query_ball_point(queries, cutoff)``, periodic and batched).

    Returns the letters of ``quantities`` (default ``"ij"``), as ``neighbor_list`` does, with
    ``i`` indexing ``queries`` (sorted) and ``j`` indexing ``points``: torch_cluster's
    ``edge_index = stack([i, j])``, scipy's row ``i`` holding ``j``. Pairs (i, j, S) with
    ``|points[j] - queries[i] + S @ cell| < cutoff``, every image, no self-exclusion (the sets
    differ); ``"D"`` is that vector, ``"d"`` its length, ``"S"`` the image shift (int32).
    Unlimited neighbours per query (torch_cluster's ``max_num_neighbors`` has no equivalent:
    nothing is cut).

    ``points`` (N, 3) and ``queries`` (M, 3) float32, in the same framework and memory space.
    ``cell`` and ``pbc`` as in ``neighbor_list``. ``batch_points``/``batch_queries``: the
    sorted system index of each point and query (torch_cluster's ``batch_x``/``batch_y``; one
    of them None: all of that set in system 0); queries meet only the points of their system.
    Gradients flow to points, queries and cell for PyTorch inputs that require grad.

    PyTorch CPU tensors go through ``torch.ops.raycut.radius`` as ``neighbor_list``'s do
    through its operator (``max_pairs`` too; padding: i = M, j = N).

    >>> i, j = pyraycut.radius(points, queries, 0.05)           # query i, point j
    >>> i, j, S = pyraycut.radius(points, queries, 0.05, cell=[1, 1, 1], quantities="ijS")
    """
    letters = _letters(quantities)
    if _torch_ops_route(points, method, max_pairs, queries=True, count="c" in letters):
        return _torch_ops().radius(letters, points, queries, cutoff, cell, pbc, batch_points,
                                   batch_queries, max_pairs)
    if "c" in letters:
        raise ValueError("the quantity 'c' (the pair count) comes with PyTorch tensors through "
                         "torch.ops.raycut (CPU tensors with method 'auto' or 'cell-list', CUDA "
                         "tensors with 'auto' or 'grid' where its CUDA kernel is built)")
    torch_in = _arrays.framework_of(points) == "torch"
    grad = torch_in and (_requires_grad(points) or _requires_grad(queries) or
                         _requires_grad(cell))
    x, like = _arrays.prepare(_search_input(points, grad))
    engine, key = _take_engine(method, like)
    engine.build(x, cutoff, cell=_host_cell(cell), pbc=pbc, batch=batch_points,
                 queries=_search_input(queries, grad), batch_queries=batch_queries)
    engine._like = like  # the caller's dtype: x may be its float32 conversion
    out = _pair_quantities(letters, engine, False, grad, points, queries, cell)
    _put_back(key, engine)
    return out


_TORCH_OPS: list = []  # [pyraycut._torch, or None when the operators are not built] once tried


def _torch_ops() -> Any:
    """pyraycut._torch (it imports torch and loads the operators), or None where they are not
    built: PyTorch tensors then go through the extension as other arrays do."""
    if not _TORCH_OPS:
        try:
            from . import _torch as module
        except ImportError as e:
            if e.path is not None:  # built, but not loadable (another torch): say so, once
                warnings.warn(str(e), RuntimeWarning, stacklevel=2)
            module = None
        _TORCH_OPS.append(module)
    return _TORCH_OPS[0]


def load_torch_ops() -> str:
    """Loads raycut's PyTorch operators (``torch.ops.raycut.neighbor_list``, ``.radius``,
    ``.lj_forces``) and returns their library's path: what a TorchScript module or an
    AOTInductor package needs loaded first (``import pyraycut`` after ``import torch`` does it).
    Raises ImportError when they are not built or do not load with this torch."""
    if _torch_ops() is None:
        from . import _torch  # noqa: F401  raises the ImportError that says why
    return _torch_ops().LIBRARY


def _compiling(x: Any) -> bool:
    """Whether a PyTorch tensor is being traced by torch.compile or torch.export."""
    if _arrays.framework_of(x) != "torch":
        return False
    import torch

    return bool(torch.compiler.is_compiling())


def _torch_ops_route(x: Any, method: str, max_pairs: Optional[int], queries: bool = False,
                     cell: Any = None, pbc: Any = None, count: bool = False) -> bool:
    """Whether a call goes through the PyTorch operators (pyraycut._torch.routes)."""
    if _arrays.framework_of(x) == "torch":
        ops = _torch_ops()
        if ops is not None and ops.routes(x, method, max_pairs, queries, cell, pbc, count):
            return True
    if max_pairs is not None:
        raise ValueError(f"max_pairs is for PyTorch tensors through the operators (built with "
                         f"torch): CPU tensors with method 'auto' or 'cell-list', CUDA tensors "
                         f"with 'auto' or 'grid' where the CUDA kernel is built; got "
                         f"{_arrays.framework_of(x)} input with method={method!r}")
    return False


# What a negative pair count of a static-capacity list says (raycut/device_pairs.hpp's codes):
# bad device data, found where the list was built without reading anything back.
_BAD_COUNT = {
    -1: "a position is NaN or infinite",
    -2: "batch is not sorted: the particles of each system must be contiguous",
    -3: "a cell has non-finite entries or linearly dependent periodic rows",
    -4: "a batch value is negative or has no cell or pbc row (one per system)",
    -5: "a periodic cell is so much thinner than the cutoff that a pair has over 2^24 images",
}


# The count of a static list whose engine reused its last plan, which no longer fits
# (raycut/static_pairs.hpp, count_plan_outgrown): the next call plans afresh.
_PLAN_OUTGROWN = -6


def check_pair_count(count: Any, max_pairs: int) -> int:
    """The pair count of a static-capacity list (``torch.ops.raycut.neighbor_list(...,
    max_pairs=K)``'s ``count``), checked: returns it when the list is complete (0 <= count <=
    max_pairs), raises ``CapacityError`` when it was cut (count > max_pairs: that many pairs
    exist) or when the grid planned at an earlier call no longer fits (count -6: call again,
    the next call plans afresh), and ``ValueError`` naming the bad input for another negative
    count. Reading a CUDA count
    waits for the GPU: call this where the host may wait, not in a captured or compiled step."""
    found = int(count)
    if found == _PLAN_OUTGROWN:
        raise CapacityError("the grid planned at the previous call no longer fits these "
                            "positions (more periodic images or a wider box): call again, the "
                            "next call plans afresh")
    if found < 0:
        raise ValueError(f"bad input to the pair list (count {found}): "
                         f"{_BAD_COUNT.get(found, 'unknown code')}")
    if found > max_pairs:
        raise CapacityError(f"max_pairs = {max_pairs} is too small: {found} pairs were found "
                            f"(grow max_pairs to at least {found})")
    return found


def _host_cell(cell: Any) -> Any:
    """The cell as the extension takes it (host numbers; a PyTorch cell that requires grad is
    read detached: the gradient path uses the caller's tensor)."""
    if _arrays.framework_of(cell) == "torch":
        return cell.detach()
    return cell


from . import ase  # noqa: E402  pyraycut.ase.neighbor_list: ASE Atoms in, ASE's types out

if "torch" in sys.modules:  # torch already imported: its operators now, before any tracing
    _torch_ops()
