"""Shared inputs and the brute-force reference of the Python tests."""
import os

os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")  # JAX: leave the GPU to others

import numpy as np
import pytest

import pyraycut

AVAILABLE = [m["name"] for m in pyraycut.methods() if m["available"]]
DEVICE_METHODS = [m for m in AVAILABLE if m not in ("brute-force", "cell-list")]
# Methods with periodic boxes, batches and query sets (the others raise NotImplementedError).
SYSTEM_METHODS = [m for m in AVAILABLE
                  if m in ("brute-force", "cell-list", "brute-force-gpu", "grid")]
CUTOFF = 0.1


def uniform(n, seed=0):
    return np.random.default_rng(seed).random((n, 3)).astype(np.float32)


def clustered(n, seed=1):
    rng = np.random.default_rng(seed)
    centres = rng.random((5, 3))
    x = centres[rng.integers(0, 5, n)] + rng.normal(0, 0.02, (n, 3))
    return x.astype(np.float32)


def coincident(n, seed=2):
    x = uniform(n, seed)
    x[: n // 2] = x[0]  # half of them on one point
    x[n // 2 : n // 2 + 10] = x[n // 2]
    return x


INPUTS = {
    "uniform": lambda: uniform(600),
    "clustered": lambda: clustered(400),
    "coincident": lambda: coincident(200),
    "empty": lambda: np.zeros((0, 3), np.float32),
    "single": lambda: np.array([[0.5, 0.5, 0.5]], np.float32),
}


def brute_force(x, cutoff, rel=1e-5):
    """Pairs (i, j), i != j, with |x_j - x_i| < cutoff in double precision, and the ambiguous
    pairs within rel * cutoff of it (either answer is right for float32)."""
    x = np.asarray(x, np.float64)
    n = len(x)
    if n == 0:
        return set(), set()
    r = np.sqrt(((x[None, :, :] - x[:, None, :]) ** 2).sum(-1))
    np.fill_diagonal(r, np.inf)
    inside = {(int(a), int(b)) for a, b in zip(*np.nonzero(r < cutoff))}
    edge = {(int(a), int(b)) for a, b in zip(*np.nonzero(np.abs(r - cutoff) <= rel * cutoff))}
    return inside, edge


def pair_set(i, j):
    return set(zip(np.asarray(i).tolist(), np.asarray(j).tolist()))


def assert_same_pairs(i, j, x, cutoff, half=False):
    found = pair_set(i, j)
    assert len(found) == len(np.asarray(i)), "a pair appears twice"
    inside, edge = brute_force(x, cutoff)
    if half:
        inside = {(a, b) for a, b in inside if a < b}
        edge = {(a, b) for a, b in edge if a < b}
    assert found - edge == inside - edge

def torch_cuda():
    """PyTorch on CUDA with raycut's CUDA methods, or skip saying which is missing."""
    if not pyraycut.cuda_available():
        pytest.skip("raycut was built without CUDA or no CUDA device is usable here")
    torch = pytest.importorskip("torch", reason="PyTorch is not installed")
    if not torch.cuda.is_available():
        pytest.skip("PyTorch sees no CUDA device")
    return torch


def cupy_cuda():
    """CuPy on CUDA with raycut's CUDA methods, or skip saying which is missing."""
    if not pyraycut.cuda_available():
        pytest.skip("raycut was built without CUDA or no CUDA device is usable here")
    cupy = pytest.importorskip("cupy", reason="CuPy is not installed")
    try:
        if cupy.cuda.runtime.getDeviceCount() == 0:
            pytest.skip("CuPy sees no CUDA device")
    except cupy.cuda.runtime.CUDARuntimeError as e:
        pytest.skip(f"CuPy sees no CUDA device ({e})")
    return cupy


def pytest_report_header(config):
    return [f"raycut: {pyraycut.__file__}", f"raycut methods here: {', '.join(AVAILABLE)}"]


@pytest.fixture(params=AVAILABLE)
def method(request):
    return request.param


@pytest.fixture(params=SYSTEM_METHODS)
def system_method(request):
    return request.param
