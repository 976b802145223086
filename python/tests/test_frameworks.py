"""Host arrays of other frameworks (PyTorch and JAX on the CPU): read in place through DLPack,
outputs of the same framework on the CPU. Skipped (with the reason) without the framework."""
import numpy as np
import pytest
from conftest import CUTOFF, INPUTS, pair_set, uniform

import pyraycut


def test_torch_cpu_tensors_stay_on_cpu():
    torch = pytest.importorskip("torch", reason="PyTorch is not installed")
    x = uniform(300)
    i, j, d = pyraycut.neighbor_list("ijd", torch.from_numpy(x).requires_grad_(), CUTOFF)
    assert isinstance(i, torch.Tensor) and i.device.type == "cpu" and i.dtype == torch.int64
    assert pair_set(i.numpy(), j.numpy()) == pair_set(*pyraycut.neighbor_list("ij", x, CUTOFF))
    engine = pyraycut.Engine("cell-list")
    engine.build(torch.from_numpy(x), CUTOFF)
    count = engine.compute("count")["count"]
    assert isinstance(count, torch.Tensor) and count.dtype == torch.int32
    # float64 is accepted (it was refused); integers and float16 are not positions.
    i64, j64 = pyraycut.neighbor_list("ij", torch.from_numpy(x).double(), CUTOFF)
    assert pair_set(i64.numpy(), j64.numpy()) == pair_set(i.numpy(), j.numpy())
    with pytest.raises(ValueError, match="float32"):
        pyraycut.neighbor_list("ij", torch.zeros((3, 3), dtype=torch.int32), CUTOFF)
    with pytest.raises(ValueError, match="float32"):
        pyraycut.neighbor_list("ij", torch.from_numpy(x).half(), CUTOFF)


def test_jax_cpu_arrays_stay_on_cpu():
    jax = pytest.importorskip("jax", reason="JAX is not installed")
    cpu = jax.devices("cpu")[0]
    for family in ("clustered", "empty"):
        x = INPUTS[family]()
        i, j, D = pyraycut.neighbor_list("ijD", jax.device_put(x, cpu), CUTOFF)
        assert isinstance(i, jax.Array) and next(iter(i.devices())).platform == "cpu"
        ref = pyraycut.neighbor_list("ijD", x, CUTOFF)
        assert pair_set(np.asarray(i), np.asarray(j)) == pair_set(ref[0], ref[1])
        assert np.asarray(D).shape == (len(ref[0]), 3)
    engine = pyraycut.Engine()
    x = uniform(200)
    engine.build(jax.device_put(x, cpu), CUTOFF)
    out = engine.compute("lj_forces")
    assert isinstance(out["force"], jax.Array) and out["force"].shape == (200, 3)


def check_torch_gradients(torch, x):
    """d and D of positions that require grad: autograd flows to the positions."""
    x = x.detach().clone().requires_grad_()
    i, j, d, D = pyraycut.neighbor_list("ijdD", x, CUTOFF)
    assert d.requires_grad and D.requires_grad
    ref_i, ref_j, ref_d, ref_D = pyraycut.neighbor_list("ijdD", x.detach(), CUTOFF)
    torch.testing.assert_close(D.detach(), ref_D, rtol=0, atol=0)
    torch.testing.assert_close(d.detach(), ref_d, rtol=1e-6, atol=1e-7)
    (grad,) = torch.autograd.grad(d.sum(), x)
    u = (D / d[:, None]).detach()
    want = torch.zeros_like(x).index_add_(0, j, u).index_add_(0, i, -u)
    torch.testing.assert_close(grad, want, rtol=1e-4, atol=1e-5)


def test_torch_cpu_gradients():
    torch = pytest.importorskip("torch", reason="PyTorch is not installed")
    check_torch_gradients(torch, torch.from_numpy(uniform(300)))
