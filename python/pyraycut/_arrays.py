"""Arrays in and out of the extension: which framework and device an input lives on, and the
same framework and device for the outputs.

Inputs are read in place (DLPack or ``__cuda_array_interface__``); only NumPy inputs (and array
likes: lists, tuples) are converted on the host, to float32 C-contiguous, with a copy when they
are not already. Outputs come back from the extension as NumPy arrays (host) or DLPack-capable
arrays wrapping device memory the library allocated (device); here they become arrays of the
caller's framework through its own ``from_dlpack``, without a copy.
"""
from __future__ import annotations

import contextlib
import glob
import os
from dataclasses import dataclass
from typing import Any

import numpy as np

# DLPack device types (dlpack.h): kDLCPU, kDLCUDAHost.
_DLPACK_HOST = (1, 3)


@dataclass(frozen=True)
class Like:
    """Where the caller's arrays live: outputs follow it."""

    framework: str  # "numpy", "torch", "cupy", "jax" or "other"
    device: Any = None  # the framework's device object (torch.device, cupy device id, jax Device)
    host: bool = True  # the outputs are wanted in host memory
    index: int = 0  # the CUDA device index (torch), read once: every call of the API needs it
    float64: bool = False  # the input was float64: float outputs (d, D, kernels) come back so


HOST = Like("numpy")
HOST_FLOAT64 = Like("numpy", float64=True)


def framework_of(x: Any) -> str:
    if isinstance(x, np.ndarray):
        return "numpy"
    module = type(x).__module__.split(".", 1)[0]
    if module in ("torch", "cupy"):
        return module
    if module in ("jax", "jaxlib"):
        return "jax"
    if hasattr(x, "__dlpack__") or hasattr(x, "__cuda_array_interface__"):
        return "other"
    return "numpy"  # lists, tuples, array likes


def _refuse_complex(name: str, dtype: Any, complex_: bool) -> None:
    if complex_:
        raise ValueError(f"{name} must be real numbers, got dtype {dtype}: the imaginary part "
                         "would be dropped (pass the real part if that is what you mean)")


def _is_float64(dtype: Any) -> bool:
    return str(dtype).rsplit(".", 1)[-1] == "float64"


def built_library(stem: str, what: str, framework: str, option: str) -> str:
    """The path of the package's shared library `stem`*.so (the PyTorch operators, the JAX
    custom call); ImportError saying how it gets built when it is not there."""
    here = os.path.dirname(os.path.abspath(__file__))
    found = sorted(glob.glob(os.path.join(here, stem + "*.so")))
    if not found:
        raise ImportError(
            f"{what} not built in {here}: it is built when the Python that configures raycut "
            f"imports {framework} (pip install --no-build-isolation ., or the CMake build with "
            f"{option}=ON)")
    return found[0]


def float64_host(x: Any) -> Any:
    """The caller's float64 positions as a NumPy (N, 3) C-contiguous array when they are on the
    host (NumPy, array likes, CPU PyTorch tensors), for the engine to decide in double what their
    float32 rounding could (``Float64Positions``); None for any other input."""
    framework = framework_of(x)
    if framework == "numpy":
        array = np.asarray(x)
        return (np.ascontiguousarray(array, dtype=np.float64).reshape(-1, 3)
                if array.dtype == np.float64 else None)
    if framework == "torch" and x.device.type == "cpu" and _is_float64(x.dtype):
        return x.detach().contiguous().numpy().reshape(-1, 3)
    return None


def prepare(x: Any, name: str = "positions", points: bool = True) -> tuple[Any, Like]:
    """The object the extension reads (in place) and where the caller's outputs go. Float
    arrays of another precision and non-contiguous ones are converted to float32 C-contiguous
    by their own framework (a copy, on their device); float64 inputs get float64 outputs."""
    framework = framework_of(x)
    if framework == "numpy":
        try:
            array = np.asarray(x)
            _refuse_complex(name, array.dtype, array.dtype.kind == "c")
            wide = array.dtype == np.float64
            array = np.ascontiguousarray(array, dtype=np.float32)
        except (TypeError, ValueError) as e:
            if "complex" in str(e):
                raise
            raise TypeError(f"{name} must be a NumPy array, an array like, or an array with "
                            f"__dlpack__ or __cuda_array_interface__; got {type(x).__name__} "
                            f"({e})") from None
        if points and array.size == 0 and array.ndim < 2:
            array = array.reshape(0, 3)  # [] -> no particles
        return array, (HOST_FLOAT64 if wide else HOST)
    if framework == "torch":
        if x.requires_grad:  # DLPack refuses tensors that require grad; the list does not need it
            x = x.detach()
        device = x.device
        if device.type not in ("cpu", "cuda"):
            raise ValueError(f"{name} is on the {device.type!r} device: raycut reads tensors on "
                             "the CPU and on CUDA devices (move it with .cpu() or .cuda())")
        torch = _torch()
        wide = False
        if x.dtype is not torch.float32:  # the usual case costs one comparison
            _refuse_complex(name, x.dtype, x.is_complex())
            wide = x.dtype is torch.float64
            if x.is_floating_point():
                x = x.to(torch.float32)
        if not x.is_contiguous():
            x = x.contiguous()
        return x, Like("torch", device, device.type == "cpu", device.index or 0, wide)
    if framework == "cupy":
        import cupy

        _refuse_complex(name, x.dtype, x.dtype.kind == "c")
        wide = x.dtype == cupy.float64
        if x.dtype.kind == "f" and x.dtype != cupy.float32:
            x = x.astype(cupy.float32)
        return cupy.ascontiguousarray(x), Like("cupy", x.device.id, False, 0, wide)
    if framework == "jax":
        _refuse_complex(name, x.dtype, "complex" in str(x.dtype))
        device = next(iter(x.devices()))
        wide = _is_float64(x.dtype)
        if "float" in str(x.dtype) and not str(x.dtype).endswith("float32"):
            import jax.numpy as jnp

            x = x.astype(jnp.float32)
        return x, Like("jax", device, device.platform == "cpu", 0, wide)
    if hasattr(x, "__dlpack_device__"):
        host = int(x.__dlpack_device__()[0]) in _DLPACK_HOST
    else:
        host = False  # __cuda_array_interface__ only
    return x, Like("other", None, host)


_TORCH = []  # the torch module once imported (an import statement costs ~1 us a call)


def _torch() -> Any:
    if not _TORCH:
        import torch

        _TORCH.append(torch)
    return _TORCH[0]


def device_context(like: Like):
    """The caller's CUDA device as the current one while the library works on its arrays."""
    if like.host:
        return contextlib.nullcontext()
    if like.framework == "torch":
        import torch

        if torch.cuda.current_device() == like.index:  # the usual case: nothing to switch
            return contextlib.nullcontext()
        return torch.cuda.device(like.index)
    if like.framework == "cupy":
        import cupy

        return cupy.cuda.Device(like.device)
    return contextlib.nullcontext()


def stream_of(like: Like) -> int:
    """The caller's current CUDA stream (the library queues its work there), 0: the default."""
    if like.host:
        return 0
    if like.framework == "torch":
        import torch

        # The raw handle without a Stream object (torch.cuda.current_stream costs ~10 us a call,
        # a third of the overhead budget); the public call where torch lacks the private one.
        raw = getattr(torch._C, "_cuda_getCurrentRawStream", None)
        if raw is not None:
            return int(raw(like.index))
        return int(torch.cuda.current_stream(like.device).cuda_stream)
    if like.framework == "cupy":
        import cupy

        return int(cupy.cuda.get_current_stream().ptr)
    return 0


_TORCH_DLPACK = []  # torch.utils.dlpack once imported: the import statement costs ~1 us a call


def _torch_dlpack() -> Any:
    if not _TORCH_DLPACK:
        from torch.utils import dlpack

        _TORCH_DLPACK.append(dlpack)
    return _TORCH_DLPACK[0]


def readable(x: Any) -> Any:
    """What the extension reads in place: a PyTorch tensor as its DLPack capsule (torch's C
    ``to_dlpack``, where ``Tensor.__dlpack__``, which nanobind would call, is Python code with
    stream checks the library does not need: it synchronises its own work), anything else as
    it is."""
    if framework_of(x) == "torch":
        return _torch_dlpack().to_dlpack(x)
    return x


def to_host(x: Any) -> np.ndarray:
    """A host float32 copy of an input array of any framework (kernel inputs of a CPU method)."""
    return np.ascontiguousarray(to_numpy(x), dtype=np.float32)


def to_numpy(x: Any) -> np.ndarray:
    """A host NumPy view or copy of an array of any framework, its dtype kept (small inputs: cells,
    pbc flags, batch indices; a device array is copied to the host)."""
    framework = framework_of(x)
    if framework == "torch":
        x = x.detach().cpu().numpy()
    elif framework == "cupy":
        x = x.get()
    elif framework == "jax":
        x = np.asarray(x)
    elif framework == "other" and hasattr(x, "__dlpack__"):
        try:
            x = np.from_dlpack(x)
        except (RuntimeError, BufferError, TypeError):
            raise ValueError("cannot read a device array of an unknown framework on the host: "
                             "pass a NumPy array") from None
    return np.asarray(x)


class DLPackCapsule:
    """A bare DLPack capsule as an object with __dlpack__ and __dlpack_device__: older nanobind
    releases return capsules for framework-less arrays, which jax and the array API expect as
    such objects. A capsule can be consumed once."""

    def __init__(self, capsule: Any, device_id: int):
        self.capsule = capsule
        self.device_id = device_id

    def __dlpack__(self, stream: Any = None, **kwargs: Any) -> Any:
        return self.capsule

    def __dlpack_device__(self) -> tuple:
        return (2, self.device_id)  # kDLCUDA: the extension returns capsules for device memory


def device_id(like: Like) -> int:
    """The CUDA device index of the caller's arrays (0 when not known)."""
    device = like.device
    for name in ("index", "id"):
        value = getattr(device, name, None)
        if isinstance(value, int):
            return value
    return device if isinstance(device, int) else 0


def dlpack_object(array: Any, like: Like) -> Any:
    """The extension's device array as an object with __dlpack__ (wrapping a bare capsule)."""
    if type(array).__name__ == "PyCapsule":
        return DLPackCapsule(array, device_id(like))
    return array


def output(array: Any, like: Like) -> Any:
    """An array from the extension (NumPy on the host, DLPack on the device) in the caller's
    framework and device: zero-copy where it already is there, a copy to the caller's device
    when the method worked elsewhere; float arrays in float64 for float64 inputs (a copy)."""
    out = _output(array, like)
    if like.float64 and out is not None and _is_float32(out):
        if like.framework == "torch":
            return out.to(_torch().float64)
        return out.astype("float64")
    return out


def _is_float32(x: Any) -> bool:
    """Whether an output array holds float32 (a dtype comparison: its str() costs ~3 us)."""
    if isinstance(x, np.ndarray):
        return x.dtype == np.float32
    if type(x).__module__.startswith("torch"):
        return x.dtype is _torch().float32
    return str(x.dtype).endswith("float32")


def _output(array: Any, like: Like) -> Any:
    if array is None or like.framework == "numpy":
        return array
    on_host = isinstance(array, np.ndarray)
    if not on_host:
        array = dlpack_object(array, like)
    if like.framework == "torch":
        import torch

        if on_host:
            tensor = torch.from_numpy(array)
            return tensor if like.host else tensor.to(like.device)
        # The capsule itself: torch.from_dlpack on the array would ask for the current stream
        # to synchronise with, and the library's work is already complete.
        return _torch_dlpack().from_dlpack(array.__dlpack__())
    if like.framework == "cupy":
        import cupy

        if on_host:
            with cupy.cuda.Device(like.device):
                return cupy.asarray(array)
        return cupy.from_dlpack(array)
    if like.framework == "jax":
        import jax

        if on_host:
            return jax.device_put(array, like.device)
        return jax.dlpack.from_dlpack(array)
    return array  # other: NumPy on the host, DLPack-capable arrays on the device
