"""Stub of raycut's nanobind extension. Use the raycut package; this module is its engine room.

Arrays returned here are NumPy arrays (host) or DLPack-capable arrays wrapping device memory
that the array owns (device); the raycut package converts them to the caller's framework.
"""
from typing import Any, Optional

has_cuda: bool

class CapacityError(RuntimeError):
    """A fixed-size output (the padded neighbour list) is too small: grow it and retry."""

def methods() -> list[dict[str, Any]]: ...
def auto_method() -> str: ...
def prefer_small_systems(particles: int, systems: int) -> bool: ...
def kernel_catalogue() -> list[dict[str, Any]]:
    """The built-in kernels ("count", "lj", "lj_forces", "smooth", "sph_density", "sph_force",
    "coulomb_dsf"): name, parameters, inputs and outputs of each."""
def cuda_device_available() -> bool: ...
def device_index_summary(index: Any, stream: int) -> tuple[int, int, int, int, int]:
    """(first, last, k, index[k], index[k + 1]) of a 1-D int32/int64 CUDA index, k the first
    place it decreases (N - 1 when sorted)."""
def device_index_offsets(index: Any, systems: int, stream: int) -> Any:
    """Systems offsets (S + 1, uint64 NumPy) of a sorted 1-D int32/int64 CUDA index."""
def pair_vectors(targets: Any, sources: Any, i: Any, j: Any, shifts: Optional[Any],
                 cells: Optional[Any], cell_of: Optional[Any]) -> tuple[Any, Any]:
    """(r (P, 3), its length (P,)): r = x_j - x_i + S . cell in float64 for pairs (i, j, S)."""
def release_idle_lists() -> None:
    """Frees the host list buffers kept for reuse (pyraycut.clear_engine_cache calls it)."""
def current_device() -> int:
    """The CUDA device current in this thread (where a GPU method allocates), -1 without one."""

class Engine:
    def __init__(self, method: str = "auto") -> None: ...
    @property
    def method(self) -> str: ...
    @property
    def space(self) -> str: ...
    @property
    def size(self) -> int: ...
    @property
    def sources(self) -> int: ...
    @property
    def cutoff(self) -> float: ...
    def set_stream(self, stream: int) -> None: ...
    def set_timed(self, timed: bool) -> None: ...
    def build(self, positions: Any, cutoff: float, cells: Optional[Any] = None,
              pbc: Optional[Any] = None, offsets: Optional[Any] = None,
              queries: Optional[Any] = None, query_offsets: Optional[Any] = None,
              positions64: Optional[Any] = None) -> None:
        """cells (B, 3, 3) float64 and pbc (B, 3) bool (B = 1: one box for all), offsets and
        query_offsets (S + 1,) uint64, queries (M, 3) float32: raycut::Systems. positions64:
        the (N, 3) float64 host positions that `positions` rounds (raycut::Float64Positions)."""
    def update(self, positions: Any, positions64: Optional[Any] = None) -> None: ...
    def set_skin(self, skin: float) -> None: ...
    def compute(self, kernel: str, parameters: dict[str, Any] = ...,
                inputs: dict[str, Any] = ..., to_host: bool = True) -> dict[str, Any]:
        """run() and results() in one call under the engine's lock (a run of another thread in
        between would take the results). parameters: names of kernel_catalogue()'s parameters
        to numbers (flags); inputs: the kernel's input names to arrays."""
    def results(self, kernel: str, to_host: bool) -> dict[str, Any]:
        """The last run's arrays, handed over (Engine::take_results; host copies of device
        results with to_host): the engine holds no results after it."""
    def neighbours(self, half: bool, distances: bool, vectors: bool, to_host: bool,
                   shifts: bool = False
                   ) -> tuple[Any, Any, Optional[Any], Optional[Any], Optional[Any]]: ...
    def pairs(self, half: bool, distances: bool, vectors: bool, to_host: bool,
              shifts: bool = False, radii: Optional[Any] = None, species: Optional[Any] = None,
              table: Optional[Any] = None
              ) -> tuple[Any, Any, Optional[Any], Optional[Any], Optional[Any]]: ...
    def padded(self, k: int, raise_on_overflow: bool, to_host: bool,
               shifts: bool = ..., half: bool = ...) -> tuple[Any, Any, dict[str, Any], Any]: ...
    def timings(self) -> dict[str, Any]: ...
    def _cpp_loop_us(self, positions: Any, cutoff: float, kernel: str, build: bool,
                     calls: int) -> list[float]:
        """Benchmarks: [build +] run + results_view `calls` times in C++, us per call."""

class VerletList:
    def __init__(self, cutoff: float, skin: float, method: str = "auto", half: bool = False,
                 distances: bool = False, vectors: bool = False, shifts: bool = False,
                 cells: Optional[Any] = None, pbc: Optional[Any] = None,
                 offsets: Optional[Any] = None) -> None:
        """cells (B, 3, 3) float64, pbc (B, 3) bool, offsets (S + 1,) uint64: raycut::Systems
        without query points, as Engine.build takes them."""
    @property
    def method(self) -> str: ...
    @property
    def space(self) -> str: ...
    @property
    def size(self) -> int: ...
    @property
    def cutoff(self) -> float: ...
    @property
    def skin(self) -> float: ...
    @property
    def rebuilds(self) -> int: ...
    @property
    def half(self) -> bool: ...
    @property
    def distances(self) -> bool: ...
    @property
    def vectors(self) -> bool: ...
    @property
    def shifts(self) -> bool: ...
    def set_stream(self, stream: int) -> None: ...
    def update(self, positions: Any) -> bool: ...
    def neighbours(self, to_host: bool
                   ) -> tuple[Any, Any, Optional[Any], Optional[Any], Optional[Any]]:
        """(offsets, indices, distances, vectors, shifts), None where not asked."""
