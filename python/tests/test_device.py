"""CUDA inputs (PyTorch, CuPy, JAX, __cuda_array_interface__): outputs in the caller's framework
on its device, zero-copy, equal to the host path. Skipped (with the reason) without the framework,
a CUDA device, or raycut's CUDA methods."""
import numpy as np
import pytest
from conftest import (AVAILABLE, CUTOFF, DEVICE_METHODS, INPUTS, SYSTEM_METHODS, cupy_cuda, pair_set,
                      torch_cuda, uniform)

import pyraycut

if not pyraycut.cuda_available():
    pytest.skip("raycut was built without CUDA or no CUDA device is usable here",
                allow_module_level=True)

# Device methods, and a CPU method fed device arrays (outputs copied to the device).
METHODS = DEVICE_METHODS + ["cell-list"]


def sorted_rows(i, j, *rest):
    order = np.lexsort((j, i))
    return [np.asarray(a)[order] for a in (i, j) + rest]


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("family", sorted(INPUTS))
def test_torch_equals_host(method, family):
    torch = torch_cuda()
    x = INPUTS[family]()
    host = pyraycut.neighbor_list("ijdD", x, CUTOFF, method=method)
    out = pyraycut.neighbor_list("ijdD", torch.from_numpy(x).cuda(), CUTOFF, method=method)
    for t, dtype in zip(out, (torch.int64, torch.int64, torch.float32, torch.float32)):
        assert isinstance(t, torch.Tensor) and t.device.type == "cuda" and t.dtype == dtype
    got = sorted_rows(*(t.cpu().numpy() for t in out))
    want = sorted_rows(*host)
    for g, w in zip(got[:2], want[:2]):
        np.testing.assert_array_equal(g, w)
    np.testing.assert_allclose(got[2], want[2], rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(got[3], want[3], rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize("method", DEVICE_METHODS)
def test_torch_zero_copy(method):
    torch = torch_cuda()
    x = torch.from_numpy(uniform(2000)).cuda()
    torch.cuda.synchronize()
    before = torch.cuda.memory_allocated()
    engine = pyraycut.Engine(method)
    engine.build(x, CUTOFF)
    offsets, indices, d = engine.neighbours(distances=True)
    i, j, D = pyraycut.neighbor_list("ijD", x, CUTOFF, method=method)
    # The outputs are the library's device memory, wrapped: torch's allocator holds none of it,
    # and nothing went through the host.
    assert torch.cuda.memory_allocated() == before
    for t in (offsets, indices, d, i, j, D):
        assert t.device.type == "cuda" and t.device == x.device
        assert t.data_ptr() != 0
    assert offsets.dtype == torch.int64 and indices.dtype == torch.int32
    # The tensors are views of the extension's arrays (which wrap the list's own buffer), whose
    # DLPack device is CUDA.
    with pyraycut._arrays.device_context(engine._like):
        raw = engine._engine.neighbours(False, True, False, False)
    raw = [pyraycut._arrays.dlpack_object(a, engine._like) for a in raw]
    assert raw[0].__dlpack_device__()[0] == 2  # kDLCUDA
    first = torch.from_dlpack(raw[1])
    assert first.data_ptr() != 0
    assert torch.from_dlpack(raw[2]).data_ptr() != first.data_ptr()
    assert torch.cuda.memory_allocated() == before
    count = engine.compute("count")["count"]
    assert count.device.type == "cuda" and count.dtype == torch.int32
    assert torch.equal(offsets[1:] - offsets[:-1], count.to(torch.int64))
    assert torch.equal(torch.bincount(i, minlength=len(x)), count.to(torch.int64))
    # Kept alive by the tensors alone.
    del engine
    torch.cuda.synchronize()
    assert int(offsets[-1]) == len(indices) == len(j)


@pytest.mark.parametrize("method", METHODS)
def test_torch_engine_equals_host(method):
    torch = torch_cuda()
    x = uniform(1500)
    host = pyraycut.Engine(method)
    host.build(x, 0.12)
    dev = pyraycut.Engine(method)
    dev.build(torch.from_numpy(x).cuda().requires_grad_(), 0.12)  # grad: detached, still fine
    def close(got, want):  # float sums in another order: errors relative to the largest term
        want = np.asarray(want, np.float64)
        scale = float(np.abs(want).max()) if want.size else 0.0
        np.testing.assert_allclose(got.cpu().numpy(), want, rtol=1e-3, atol=1e-4 * scale)

    kw = dict(sph_mass=1.0, sph_viscosity=0.1, lj_sigma=0.01)
    for kernel in ("count", "lj", "lj_forces", "smooth", "sph_density"):
        a = host.compute(kernel, **kw)
        b = dev.compute(kernel, **kw)
        assert set(a) == set(b)
        for name in a:
            assert b[name].device.type == "cuda" and b[name].shape == a[name].shape
            close(b[name], a[name])
    n = len(x)
    a = host.compute("sph_force", velocity=np.zeros((n, 3), np.float32),
                     density=np.ones(n, np.float32), pressure=np.ones(n, np.float32), **kw)
    b = dev.compute("sph_force", velocity=torch.zeros((n, 3), device="cuda"),
                    density=torch.ones(n, device="cuda"), pressure=torch.ones(n, device="cuda"),
                    **kw)
    close(b["force"], a["force"])
    # Host kernel inputs for a device engine (copied over), device ones for a host engine.
    c = dev.compute("sph_force", velocity=np.zeros((n, 3), np.float32),
                    density=np.ones(n, np.float32), pressure=np.ones(n, np.float32), **kw)
    close(c["force"], a["force"])
    # coulomb_dsf: charges read at the source of every pair, device and host charges alike.
    q = np.sin(np.arange(n) * 0.7).astype(np.float32)
    a = host.compute("coulomb_dsf", charge=q, alpha=8.0)
    for charge in (torch.from_numpy(q).cuda(), q):
        b = dev.compute("coulomb_dsf", charge=charge, alpha=8.0)
        for name in ("energy", "force", "virial"):
            close(b[name], a[name])
    idx, counts, report = dev.padded_neighbours(8)
    idx_h, counts_h, report_h = host.padded_neighbours(8)
    assert idx.device.type == "cuda" and report == report_h
    np.testing.assert_array_equal(counts.cpu().numpy(), counts_h)


def test_torch_inputs_of_another_precision_or_layout_and_errors():
    """float64 and non-contiguous CUDA tensors are converted on their device (float64 in, float64
    distances out), with the pairs of the float32 tensor; a wrong shape and a NaN are refused,
    naming what and where."""
    torch = torch_cuda()
    x = torch.from_numpy(uniform(100)).cuda()
    want = pair_set(*(t.cpu().numpy() for t in pyraycut.neighbor_list("ij", x, CUTOFF)))
    assert want, "too few pairs for the test to mean anything"
    i, j, d = pyraycut.neighbor_list("ijd", x.double(), CUTOFF)
    assert d.is_cuda and d.dtype == torch.float64
    assert pair_set(i.cpu().numpy(), j.cpu().numpy()) == want
    strided = x.t().contiguous().t()
    assert not strided.is_contiguous()
    i, j = pyraycut.neighbor_list("ij", strided, CUTOFF)
    assert pair_set(i.cpu().numpy(), j.cpu().numpy()) == want
    with pytest.raises(ValueError, match="shape"):
        pyraycut.neighbor_list("ij", x[:, :2].contiguous(), CUTOFF)
    bad = x.clone()
    bad[7, 2] = float("nan")
    with pytest.raises(ValueError, match="index 7"):
        pyraycut.neighbor_list("ij", bad, CUTOFF)


@pytest.mark.parametrize("method", METHODS)
def test_cupy_equals_host(method):
    cupy = cupy_cuda()
    x = INPUTS["clustered"]()
    host = pyraycut.neighbor_list("ijd", x, CUTOFF, method=method)
    out = pyraycut.neighbor_list("ijd", cupy.asarray(x), CUTOFF, method=method)
    for a in out:
        assert isinstance(a, cupy.ndarray)
    got = sorted_rows(*(a.get() for a in out))
    want = sorted_rows(*host)
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_array_equal(got[1], want[1])
    np.testing.assert_allclose(got[2], want[2], rtol=1e-6)
    engine = pyraycut.Engine(method)
    engine.build(cupy.asarray(x), CUTOFF)
    count = engine.compute("count")["count"]
    assert isinstance(count, cupy.ndarray)
    np.testing.assert_array_equal(count.get(), np.bincount(want[0], minlength=len(x)))


def test_cuda_array_interface_only():
    cupy = cupy_cuda()
    x = cupy.asarray(uniform(500))

    class Foreign:  # an array known only through __cuda_array_interface__ (as Numba's)
        def __init__(self, a):
            self.a = a
            self.__cuda_array_interface__ = a.__cuda_array_interface__

    i, j = pyraycut.neighbor_list("ij", Foreign(x), CUTOFF)
    i, j = cupy.from_dlpack(i), cupy.from_dlpack(j)  # DLPack-capable device arrays
    assert pair_set(i.get(), j.get()) == pair_set(*pyraycut.neighbor_list("ij", x.get(), CUTOFF))


def test_jax_equals_host():
    jax = pytest.importorskip("jax", reason="JAX is not installed")
    try:
        gpus = jax.devices("gpu")
    except RuntimeError:
        gpus = []
    if not gpus:
        pytest.skip("JAX sees no GPU")
    x = uniform(800)
    i, j, d = pyraycut.neighbor_list("ijd", jax.device_put(x, gpus[0]), CUTOFF)
    assert isinstance(i, jax.Array) and next(iter(i.devices())).platform == "gpu"
    got = sorted_rows(np.asarray(i), np.asarray(j), np.asarray(d))
    want = sorted_rows(*pyraycut.neighbor_list("ijd", x, CUTOFF))
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_array_equal(got[1], want[1])


def test_all_methods_agree_on_device():
    torch = torch_cuda()
    x = torch.from_numpy(INPUTS["coincident"]()).cuda()
    ref = None
    for method in AVAILABLE:
        pairs = pair_set(*(t.cpu().numpy() for t in pyraycut.neighbor_list("ij", x, CUTOFF,
                                                                         method=method)))
        ref = pairs if ref is None else ref
        assert pairs == ref, method


def test_torch_cuda_gradients():
    from test_frameworks import check_torch_gradients

    torch = torch_cuda()
    check_torch_gradients(torch, torch.from_numpy(uniform(1000)).cuda())


# ---- periodic boxes, batches, query sets on the device ------------------------------------------

SYSTEM_DEVICE = [m for m in DEVICE_METHODS if m in SYSTEM_METHODS] + ["cell-list"]
TRICLINIC = np.array([[1.0, 0.0, 0.0], [0.4, 0.9, 0.0], [0.3, -0.2, 0.8]])


def periodic_batch(seed=0):
    """Three systems (one empty) with their own cells, thinner than 2C in the last: (x, batch,
    cells, pbc, cutoff), x unwrapped by a few cells."""
    rng = np.random.default_rng(seed)
    sizes = [200, 0, 30]
    cells = np.stack([2.0 * TRICLINIC, np.eye(3), 0.35 * np.eye(3)])
    pbc = np.array([[True, True, True], [True, True, True], [True, False, True]])
    xs = [(rng.random((n, 3)) + rng.integers(-2, 3, (n, 3)) * p) @ c
          for n, c, p in zip(sizes, cells, pbc)]
    return (np.concatenate(xs).astype(np.float32), np.repeat(np.arange(3), sizes), cells, pbc,
            0.4)


def sorted_triples(i, j, S, *rest):
    i, j, S = (np.asarray(a) for a in (i, j, S))
    order = np.lexsort((S[:, 2], S[:, 1], S[:, 0], j, i))
    return [np.asarray(a)[order] for a in (i, j, S) + rest]


def same_triples(got, want):
    got = sorted_triples(*got)
    want = sorted_triples(*want)
    for g, w in zip(got[:3], want[:3]):
        np.testing.assert_array_equal(g, w)
    for g, w in zip(got[3:], want[3:]):
        np.testing.assert_allclose(g, w, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("method", SYSTEM_DEVICE)
def test_torch_periodic_batch_equals_host(method):
    torch = torch_cuda()
    x, batch, cells, pbc, cutoff = periodic_batch()
    host = pyraycut.neighbor_list("ijSdD", x, cutoff, cell=cells, pbc=pbc, batch=batch,
                                method=method)
    xd = torch.from_numpy(x).cuda()
    torch.cuda.synchronize()
    before = torch.cuda.memory_allocated()
    out = pyraycut.neighbor_list("ijSdD", xd, cutoff, cell=torch.from_numpy(cells).cuda(),
                               pbc=torch.from_numpy(pbc), batch=torch.from_numpy(batch).cuda(),
                               method=method)
    for t, dtype in zip(out, (torch.int64, torch.int64, torch.int32, torch.float32,
                              torch.float32)):
        assert isinstance(t, torch.Tensor) and t.device == xd.device and t.dtype == dtype
    assert out[2].shape == (len(out[0]), 3)
    if method in DEVICE_METHODS:  # the library's device buffers, wrapped: no torch allocation
        assert torch.cuda.memory_allocated() == before
    same_triples([t.cpu().numpy() for t in out], host)
    assert any(a == b for a, b in zip(host[0].tolist(), host[1].tolist())), "self-images"
    half = pyraycut.neighbor_list("ijS", xd, cutoff, cell=cells, pbc=pbc, batch=batch, half=True,
                                method=method)
    same_triples([t.cpu().numpy() for t in half],
                 pyraycut.neighbor_list("ijS", x, cutoff, cell=cells, pbc=pbc, batch=batch,
                                      half=True, method=method))


@pytest.mark.parametrize("dtype", ["int32", "int64", "int16"])
def test_torch_cuda_batch_index(dtype):
    """A CUDA batch index is checked and turned into offsets on the device: the same offsets and
    errors as the host path, empty systems (leading, inner, trailing) included."""
    torch = torch_cuda()
    from pyraycut import _systems

    host = np.array([1, 1, 3, 3, 3, 4, 6], np.int64)
    b = torch.from_numpy(host.astype(dtype)).cuda()
    got = _systems.batch(None, len(host), b)
    want = _systems.batch(None, len(host), host)
    assert got.systems == want.systems == 7
    np.testing.assert_array_equal(got.offsets, want.offsets)
    np.testing.assert_array_equal(got.offsets, [0, 0, 2, 2, 5, 6, 6, 7])
    per_system = _systems.boxes(np.stack([np.eye(3)] * 9), True)  # 9 systems, the last 2 empty
    np.testing.assert_array_equal(_systems.batch(per_system, len(host), b).offsets,
                                  [0, 0, 2, 2, 5, 6, 6, 7, 7, 7])
    one = _systems.batch(None, 1, torch.zeros(1, dtype=b.dtype, device="cuda"))
    np.testing.assert_array_equal(one.offsets, [0, 1])
    bad = host.copy()
    bad[4] = 2  # 3 > 2 at k = 3
    with pytest.raises(ValueError, match=r"batch\[3\] = 3 > batch\[4\] = 2"):
        _systems.batch(None, len(bad), torch.from_numpy(bad.astype(dtype)).cuda())
    with pytest.raises(ValueError, match="negative"):
        _systems.batch(None, 3, torch.tensor([-1, 0, 0], device="cuda"))
    with pytest.raises(ValueError, match="cell/pbc give 2 systems"):
        _systems.batch(_systems.boxes(np.stack([np.eye(3)] * 2), True), len(host), b)


@pytest.mark.parametrize("method", SYSTEM_DEVICE)
def test_torch_padded_shifts_equal_host(method):
    """The padded matrix with S from CUDA positions: CUDA tensors (the library's buffers, wrapped,
    for a device method) holding the host engine's rows, S included, in a cell thinner than 2C."""
    torch = torch_cuda()
    x, batch, cells, pbc, cutoff = periodic_batch()
    x, cell = x[batch == 2], cells[2]
    host, dev = pyraycut.Engine(method), pyraycut.Engine(method)
    host.build(x, cutoff, cell=cell, pbc=pbc[2])
    dev.build(torch.from_numpy(x).cuda(), cutoff, cell=cell, pbc=pbc[2])
    k = int(host.compute("count")["count"].max()) + 2
    want = host.padded_neighbours(k, shifts=True)
    got = dev.padded_neighbours(k, shifts=True)
    for t in (got[0], got[1], got[3]):
        assert isinstance(t, torch.Tensor) and t.device.type == "cuda"
    assert got[3].shape == (len(x), k, 3) and got[2] == want[2] and not got[2]["overflowed"]
    idx, counts, s = (t.cpu().numpy() for t in (got[0], got[1], got[3]))
    np.testing.assert_array_equal(counts, want[1])
    assert np.any(s != 0), "images in a cell thinner than 2C"
    for i in range(len(x)):
        c = int(counts[i])
        rows = [sorted(zip(a[i, :c].tolist(), map(tuple, b[i, :c].tolist())))
                for a, b in ((idx, s), (want[0], want[3]))]
        assert rows[0] == rows[1]
        assert np.all(idx[i, c:] == len(x)) and np.all(s[i, c:] == 0)


@pytest.mark.parametrize("method", SYSTEM_DEVICE)
def test_torch_radius_equals_host(method):
    torch = torch_cuda()
    x, batch, cells, pbc, cutoff = periodic_batch(1)
    q, bq, _, _, _ = periodic_batch(2)
    host = pyraycut.radius(x, q, cutoff, cell=cells, pbc=pbc, batch_points=batch,
                         batch_queries=bq, method=method, quantities="ijSD")
    out = pyraycut.radius(torch.from_numpy(x).cuda(), torch.from_numpy(q).cuda(), cutoff,
                        cell=cells, pbc=pbc, batch_points=torch.from_numpy(batch).cuda(),
                        batch_queries=torch.from_numpy(bq).cuda(), method=method,
                        quantities="ijSD")
    assert all(t.device.type == "cuda" for t in out)
    same_triples([t.cpu().numpy() for t in out], host)


@pytest.mark.parametrize("method", SYSTEM_DEVICE)
def test_cupy_periodic_equals_host(method):
    cupy = cupy_cuda()
    x, batch, cells, pbc, cutoff = periodic_batch(3)
    host = pyraycut.neighbor_list("ijSd", x, cutoff, cell=cells, pbc=pbc, batch=batch,
                                method=method)
    out = pyraycut.neighbor_list("ijSd", cupy.asarray(x), cutoff, cell=cupy.asarray(cells),
                               pbc=pbc, batch=cupy.asarray(batch), method=method)
    assert all(isinstance(a, cupy.ndarray) for a in out)
    same_triples([a.get() for a in out], host)


@pytest.mark.parametrize("method", SYSTEM_DEVICE)
def test_torch_cuda_periodic_gradcheck(method):
    torch = torch_cuda()
    x, batch, cells, pbc, cutoff = periodic_batch(4)
    keep = np.flatnonzero(batch == 2)  # the small cell: images and self-images
    xd = torch.tensor(x[keep], dtype=torch.float64, device="cuda", requires_grad=True)
    cd = torch.tensor(cells[2], dtype=torch.float64, device="cuda", requires_grad=True)

    def f(x, c):
        i, d, D = pyraycut.neighbor_list("idD", x, cutoff, cell=c, pbc=pbc[2], method=method)
        energy = torch.zeros(len(x), dtype=d.dtype, device=d.device).index_add(0, i, d.cos())
        field = torch.zeros(len(x), 3, dtype=D.dtype, device=D.device).index_add(0, i, D.sin())
        return energy, field

    # On CUDA the backward of x[j] and index_add accumulates with atomics, in no fixed order:
    # two backward passes differ by double round-off, which gradcheck calls non-reentrant.
    assert torch.autograd.gradcheck(f, (xd, cd), eps=1e-6, atol=1e-6, nondet_tol=1e-12)
