"""The PyTorch operators torch.ops.raycut.neighbor_list / .radius on the CPU, and
pyraycut.neighbor_list / pyraycut.radius through them, in every framework mode: eager (against a
float64 brute force over explicit images), TorchScript, torch.compile(fullgraph=True) with
dynamic sizes and no recompilation, torch.export with a dynamic N, an AOTInductor package, and
gradcheck / gradgradcheck of an energy with respect to positions and cell. Skipped (with the
reason) without PyTorch or where the operators were not built."""
import os
import subprocess
import sys

import numpy as np
import pytest
from test_periodic import TRICLINIC, inside_cell, reference, triples

import pyraycut

torch = pytest.importorskip("torch", reason="PyTorch is not installed")
if pyraycut._torch_ops() is None:
    pytest.skip("raycut's PyTorch operators are not built (the build's Python had no torch)",
                allow_module_level=True)

OPS = torch.ops.raycut


def periodic_system(n, cell, pbc, seed, dtype=torch.float64):
    x = inside_cell(n, cell, pbc, seed=seed).astype(np.float64)
    return torch.tensor(x, dtype=dtype), torch.tensor(np.asarray(cell), dtype=dtype)


# ---- eager -------------------------------------------------------------------------------------


@pytest.mark.parametrize("scale, cutoff", [(1.0, 0.35), (0.5, 0.6)])  # the second: < 2C, images
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_op_periodic_triclinic_vs_brute_force(scale, cutoff, dtype):
    cell = scale * TRICLINIC
    x, c = periodic_system(40, cell, (True, True, True), seed=3, dtype=dtype)
    i, j, S, count = OPS.neighbor_list(x, cutoff, c, torch.tensor([True, True, True]))
    assert i.dtype == torch.int64 and j.dtype == torch.int64 and S.dtype == torch.int32
    assert count.dim() == 0 and int(count) == len(i) > 0
    assert torch.all(i[1:] >= i[:-1]), "i is sorted"
    found = triples(i, j, S)
    assert len(found) == len(i)
    inside, edge = reference(x.double().numpy(), x.double().numpy(), cutoff, cell, (True,) * 3)
    assert found - edge == inside - edge
    # The same call through pyraycut.neighbor_list: its d and D in the positions' dtype.
    i2, j2, d, D, S2 = pyraycut.neighbor_list("ijdDS", x, cutoff, cell=c)
    assert triples(i2, j2, S2) == found and d.dtype == dtype and D.dtype == dtype
    want = x[j2] - x[i2] + S2.to(dtype) @ c
    torch.testing.assert_close(D, want, rtol=0, atol=0)
    torch.testing.assert_close(d, torch.linalg.vector_norm(want, dim=1), rtol=0, atol=0)


def test_float64_cpu_positions_decide_in_double():
    # Two points 1 - 1e-9 apart at 1e6: as float32 they round to 1.0 apart (no pair); float64
    # CPU positions are decided in double (the engine's Float64Positions).
    x = torch.tensor([[1e6 + 0.01, 0.0, 0.0], [1e6 + 1.01 - 1e-9, 0.0, 0.0]], dtype=torch.float64)
    i, j, S, count = OPS.neighbor_list(x, 1.0)
    assert int(count) == 2 and sorted(i.tolist()) == [0, 1]
    d = pyraycut.neighbor_list("d", x, 1.0)
    assert d.dtype == torch.float64 and torch.all(d < 1.0)
    assert int(OPS.neighbor_list(x.float(), 1.0)[3]) == 0
    # In a box 10^4 cutoffs wide: every pair the float64 answer, and symmetric.
    cell = torch.eye(3, dtype=torch.float64) * 1e4
    y = torch.tensor([[0.3004, 5000.0, 5000.0], [9999.30078125, 5000.0, 5000.0]],
                     dtype=torch.float64)
    i, j, S, count = OPS.neighbor_list(y, 1.0, cell)
    assert triples(i, j, S) == {(0, 1, -1, 0, 0), (1, 0, 1, 0, 0)}


def test_half_and_numpy_agreement():
    x, c = periodic_system(50, TRICLINIC, (True, False, True), seed=4, dtype=torch.float32)
    pbc = torch.tensor([True, False, True])
    full = triples(*pyraycut.neighbor_list("ijS", x, 0.4, cell=c, pbc=pbc))
    numpy_full = triples(*pyraycut.neighbor_list("ijS", x.numpy(), 0.4, cell=c.numpy(),
                                               pbc=[True, False, True]))
    assert full == numpy_full
    i, j, S = pyraycut.neighbor_list("ijS", x, 0.4, cell=c, pbc=pbc, half=True)
    half = triples(i, j, S)
    assert len(half) * 2 == len(full)
    for a, b, s0, s1, s2 in half:  # i < j, or i == j and S lexicographically positive
        assert a < b or (a == b and (s0, s1, s2) > (0, 0, 0))
    assert {(b, a, -s0, -s1, -s2) for a, b, s0, s1, s2 in half} | half == full


def test_batch_with_per_system_boxes_and_an_empty_system():
    cells = [TRICLINIC, np.eye(3), 0.6 * np.eye(3)]
    pbcs = [(True, True, True), (True, True, False), (True, True, True)]
    sizes = [20, 0, 12]
    xs = [inside_cell(n, cells[s], pbcs[s], seed=10 + s).astype(np.float64)
          for s, n in enumerate(sizes)]
    x = torch.tensor(np.concatenate(xs))
    batch = torch.repeat_interleave(torch.arange(3), torch.tensor(sizes))
    cutoff = 0.45
    i, j, S, count = OPS.neighbor_list(x, cutoff, torch.tensor(np.stack(cells)),
                                       torch.tensor(pbcs), batch)
    found = triples(i, j, S)
    want, edge, start = set(), set(), 0
    for s, n in enumerate(sizes):
        inside, band = reference(xs[s], xs[s], cutoff, cells[s], pbcs[s])
        want |= {(a + start, b + start) + tuple(t) for a, b, *t in inside}
        edge |= {(a + start, b + start) + tuple(t) for a, b, *t in band}
        start += n
    assert found - edge == want - edge and int(count) == len(i)
    # A shared box and a sparse index: the numbers only group.
    sparse = torch.tensor([0] * 20 + [10**9] * 12)
    one = OPS.neighbor_list(x, cutoff, torch.tensor(cells[0]), None, sparse)
    dense = OPS.neighbor_list(x, cutoff, torch.tensor(cells[0]), None,
                              torch.tensor([0] * 20 + [1] * 12))
    assert triples(*one[:3]) == triples(*dense[:3])


def test_outputs_own_their_list_and_dropped_ones_are_refilled():
    """CPU outputs wrap the library's list without a copy: held ones never change, whatever
    later calls list, and the memory of dropped ones is refilled by the next call (no fresh
    pages), even when the same amount of memory was asked for in between."""
    cell = 1.0 * TRICLINIC
    x, c = periodic_system(60, cell, (True, True, True), seed=5, dtype=torch.float32)
    y, _ = periodic_system(90, cell, (True, True, True), seed=6, dtype=torch.float32)
    held = OPS.neighbor_list(x, 0.35, c)
    kept = [t.clone() for t in held]
    for z in (y, x[:30], y):
        i, j, S, count = OPS.neighbor_list(z, 0.35, c)
        assert int(count) == len(i) and triples(i, j, S) == reference_triples(z, cell, 0.35)
        for a, b in zip(held, kept):
            assert torch.equal(a, b)
    del i, j, S, count
    first = OPS.neighbor_list(y, 0.35, c)
    where, pairs = first[0].data_ptr(), len(first[0])
    del first  # the newest idle list: the next call's
    other = torch.ones(pairs, dtype=torch.int64)  # malloc would hand it the freed block
    again = OPS.neighbor_list(y, 0.35, c)
    assert again[0].data_ptr() == where != other.data_ptr()


def reference_triples(x, cell, cutoff):
    inside, edge = reference(x.double().numpy(), x.double().numpy(), cutoff, cell, (True,) * 3)
    assert not edge, "no pair this close to the cutoff here"
    return inside


def test_max_pairs_padding_and_overflow():
    x, c = periodic_system(30, np.eye(3), (True,) * 3, seed=5)
    i, j, S, count = OPS.neighbor_list(x, 0.4, c)
    pairs = int(count)
    assert pairs == len(i) > 2
    pi, pj, pS, pcount = OPS.neighbor_list(x, 0.4, c, max_pairs=pairs + 3)
    assert pi.shape == (pairs + 3,) and pS.shape == (pairs + 3, 3) and int(pcount) == pairs
    assert torch.equal(pi[:pairs], i) and torch.equal(pj[:pairs], j) and torch.equal(pS[:pairs], S)
    assert torch.all(pi[pairs:] == 30) and torch.all(pj[pairs:] == 30)
    assert torch.all(pS[pairs:] == 0)
    # One short: the count says so (the first max_pairs pairs are kept), the wrapper raises.
    si, sj, sS, scount = OPS.neighbor_list(x, 0.4, c, max_pairs=pairs - 1)
    assert si.shape == (pairs - 1,) and int(scount) == pairs
    with pytest.raises(pyraycut.CapacityError, match=f"{pairs} pairs"):
        pyraycut.neighbor_list("ij", x, 0.4, cell=c, max_pairs=pairs - 1)
    # Through the wrapper, padding entries have d = 0 and D = 0.
    d, D = pyraycut.neighbor_list("dD", x, 0.4, cell=c, max_pairs=pairs + 3)
    assert torch.all(d[pairs:] == 0) and torch.all(D[pairs:] == 0) and torch.all(d[:pairs] > 0)


def test_radius_op_periodic_batched_and_padded():
    cell = 0.8 * TRICLINIC
    points = inside_cell(25, cell, seed=20).astype(np.float64)
    queries = inside_cell(9, cell, seed=21).astype(np.float64)
    cutoff = 0.5
    p, q, c = torch.tensor(points), torch.tensor(queries), torch.tensor(cell)
    i, j, S, count = OPS.radius(p, q, cutoff, c)
    inside, edge = reference(queries, points, cutoff, cell, (True,) * 3, exclude_self=False)
    assert triples(i, j, S) - edge == inside - edge and int(count) == len(i)
    i2, j2, d = pyraycut.radius(p, q, cutoff, cell=c, quantities="ijd")
    assert torch.equal(i2, i) and torch.equal(j2, j)
    torch.testing.assert_close(d, torch.linalg.vector_norm(p[j] - q[i] + S.double() @ c, dim=1))
    pi, pj, _, pcount = OPS.radius(p, q, cutoff, c, max_pairs=len(i) + 2)
    assert torch.all(pi[len(i):] == 9) and torch.all(pj[len(i):] == 25)
    # Batched: queries meet only the points of their system.
    bp = torch.tensor([0] * 10 + [1] * 15)
    bq = torch.tensor([0] * 4 + [1] * 5)
    bi, bj, _, _ = OPS.radius(p, q, cutoff, c, None, bp, bq)
    assert len(bi) > 0 and torch.equal(bp[bj], bq[bi])


def test_op_errors_name_the_argument():
    x = torch.rand(10, 3)
    # The numbers in the message too: a module with its own static libstdc++ writes none
    # (cmake/shared_libstdcxx.cmake).
    with pytest.raises(ValueError, match=r"positions must have shape \(N, 3\), got \[10, 2\]"):
        OPS.neighbor_list(torch.rand(10, 2), 0.3)
    with pytest.raises(ValueError, match="float32 or float64"):
        OPS.neighbor_list(x.half(), 0.3)
    with pytest.raises(ValueError, match="batch must be sorted"):
        OPS.neighbor_list(x, 0.3, batch=torch.tensor([0, 1] * 5))
    with pytest.raises(ValueError, match="no batch"):
        OPS.neighbor_list(x, 0.3, torch.eye(3).expand(2, 3, 3))
    with pytest.raises(ValueError, match="max_pairs must be >= 0"):
        OPS.neighbor_list(x, 0.3, max_pairs=-1)
    with pytest.raises(ValueError, match="cutoff"):
        OPS.neighbor_list(x, -1.0)
    x[3, 1] = float("nan")
    with pytest.raises(ValueError, match="3"):
        OPS.neighbor_list(x, 0.3)


# ---- compiled modes ----------------------------------------------------------------------------


def lj_energy(x, cell):
    """A Lennard-Jones energy through pyraycut.neighbor_list (the op underneath)."""
    d = pyraycut.neighbor_list("d", x, 0.45, cell=cell)
    inv6 = (0.2 / d) ** 6
    return 2.0 * (inv6 * inv6 - inv6).sum()


class PairCount(torch.nn.Module):
    def forward(self, x: torch.Tensor, cell: torch.Tensor) -> torch.Tensor:
        i, j, S, count = torch.ops.raycut.neighbor_list(x, 0.45, cell, None, None, False, None)
        r = x[j] - x[i] + S.to(x.dtype) @ cell
        return (r * r).sum(1).sqrt().sum() + count.to(x.dtype)


def test_torchscript_module_calls_the_op():
    scripted = torch.jit.script(PairCount())
    for n in (20, 35):
        x, c = periodic_system(n, np.eye(3), (True,) * 3, seed=n)
        torch.testing.assert_close(scripted(x, c), PairCount()(x, c))
    assert "raycut::neighbor_list" in str(scripted.graph)
    assert pyraycut.load_torch_ops().endswith(".so") and "_torch_ops" in pyraycut.load_torch_ops()


def test_compile_fullgraph_dynamic_no_recompilation():
    from torch._dynamo.testing import CompileCounterWithBackend

    torch._dynamo.reset()
    counter = CompileCounterWithBackend("aot_eager")
    compiled = torch.compile(lj_energy, backend=counter, fullgraph=True)
    pair_counts = set()
    for n in (30, 45, 60):
        x, c = periodic_system(n, np.eye(3), (True,) * 3, seed=n)
        x.requires_grad_()
        torch._dynamo.mark_dynamic(x, 0)
        energy = compiled(x, c)
        (force,) = torch.autograd.grad(-energy, x)
        want = lj_energy(x, c)
        (want_force,) = torch.autograd.grad(-want, x)
        torch.testing.assert_close(energy, want)
        torch.testing.assert_close(force, want_force)
        pair_counts.add(len(pyraycut.neighbor_list("i", x, 0.45, cell=c)))
    assert len(pair_counts) == 3, "the pair count changed from call to call"
    assert counter.frame_count == 1, "recompiled when N or the pair count changed"


def test_compile_radius_fullgraph_with_gradients():
    from torch._dynamo.testing import CompileCounterWithBackend

    def pooled(points, queries, cell):
        return pyraycut.radius(points, queries, 0.3, cell=cell, quantities="d").sum()

    torch._dynamo.reset()
    counter = CompileCounterWithBackend("aot_eager")
    compiled = torch.compile(pooled, backend=counter, fullgraph=True)
    for n in (50, 70):
        p, c = periodic_system(n, np.eye(3), (True,) * 3, seed=n)
        q = periodic_system(10, np.eye(3), (True,) * 3, seed=100 + n)[0]
        p.requires_grad_()
        torch._dynamo.mark_dynamic(p, 0)
        got, want = compiled(p, q, c), pooled(p, q, c)
        torch.testing.assert_close(got, want)
        torch.testing.assert_close(torch.autograd.grad(got, p)[0], torch.autograd.grad(want, p)[0])
    assert counter.frame_count == 1


def test_compile_inductor_static_capacity():
    torch._dynamo.reset()

    def energy(x, cell):
        d = pyraycut.neighbor_list("d", x, 0.45, cell=cell, max_pairs=2000)
        inv6 = torch.where(d > 0, (0.2 / d.clamp_min(1e-3)) ** 6, 0.0)  # padding: d = 0
        return 2.0 * (inv6 * inv6 - inv6).sum()

    compiled = torch.compile(energy, fullgraph=True, dynamic=True)
    for n in (30, 40):
        x, c = periodic_system(n, np.eye(3), (True,) * 3, seed=n)
        assert len(pyraycut.neighbor_list("i", x, 0.45, cell=c)) < 2000
        torch.testing.assert_close(compiled(x, c), lj_energy(x, c))


def test_export_dynamic_n_and_aoti_package(tmp_path):
    n = torch.export.Dim("n", min=2, max=100_000)
    x, c = periodic_system(30, np.eye(3), (True,) * 3, seed=30)
    program = torch.export.export(PairCount(), (x, c), dynamic_shapes={"x": {0: n}, "cell": None})
    assert any("raycut.neighbor_list" in str(node.target) for node in program.graph.nodes)
    x2, c2 = periodic_system(47, np.eye(3), (True,) * 3, seed=47)
    torch.testing.assert_close(program.module()(x2, c2), PairCount()(x2, c2))
    # Packaged, loaded and run in a process of its own, as a deployment does, with an Inductor
    # cache of its own (docs/python.md, "AOTInductor", says what crashes on one GPU machine).
    inputs = [periodic_system(25, np.eye(3), (True,) * 3, seed=25), (x2, c2)]
    torch.save(inputs, tmp_path / "inputs.pt")
    script = (
        "import sys, torch, pyraycut\n"
        "pyraycut._torch_ops()  # registers torch.ops.raycut\n"
        "sys.path.insert(0, sys.argv[4])\n"
        "from test_torch_ops import PairCount, periodic_system\n"
        "import numpy as np\n"
        "n = torch.export.Dim('n', min=2, max=100_000)\n"
        "x, c = periodic_system(30, np.eye(3), (True,) * 3, seed=30)\n"
        "program = torch.export.export(PairCount(), (x, c),\n"
        "                              dynamic_shapes={'x': {0: n}, 'cell': None})\n"
        "path = torch._inductor.aoti_compile_and_package(program, package_path=sys.argv[1])\n"
        "runner = torch._inductor.aoti_load_package(path)\n"
        "inputs = torch.load(sys.argv[2])\n"
        "torch.save([runner(x, c) for x, c in inputs], sys.argv[3])\n")
    # Inductor's own cache apart from this process's: its compiled code may not be shared.
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p),
               TORCHINDUCTOR_CACHE_DIR=str(tmp_path / "inductor"))
    done = subprocess.run([sys.executable, "-c", script, str(tmp_path / "pairs.pt2"),
                           str(tmp_path / "inputs.pt"), str(tmp_path / "outputs.pt"),
                           os.path.dirname(__file__)], env=env, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert (tmp_path / "pairs.pt2").stat().st_size > 0
    outputs = torch.load(tmp_path / "outputs.pt")
    for (x3, c3), got in zip(inputs, outputs):
        torch.testing.assert_close(got, PairCount()(x3, c3))


# ---- gradients ---------------------------------------------------------------------------------


def smooth_energy(x, cell, cutoff=0.45):
    """An energy that goes to zero with its first two derivatives at the cutoff."""
    d = pyraycut.neighbor_list("d", x, cutoff, cell=cell)
    return ((cutoff - d) ** 3 * torch.cos(3 * d)).sum()


def test_gradcheck_and_gradgradcheck_positions_and_cell():
    x, c = periodic_system(12, 0.9 * TRICLINIC, (True,) * 3, seed=7)
    x.requires_grad_()
    c.requires_grad_()
    assert torch.autograd.gradcheck(smooth_energy, (x, c), eps=1e-6, atol=1e-6)
    assert torch.autograd.gradgradcheck(smooth_energy, (x, c), eps=1e-6, atol=1e-5)


# ---- the fused Lennard-Jones operator -----------------------------------------------------------


def test_lj_forces_op_matches_the_engine_and_autograd():
    x, c = periodic_system(80, 4.0 * TRICLINIC, (True,) * 3, seed=11, dtype=torch.float32)
    energy, force, virial = OPS.lj_forces(x, 1.6, 0.5, 0.4, c)
    assert energy.shape == (80,) and force.shape == (80, 3) and virial.shape == (80, 6)
    engine = pyraycut.Engine("cell-list")
    engine.build(x.numpy(), 1.6, cell=c.numpy())
    want = engine.compute("lj_forces", lj_epsilon=0.5, lj_sigma=0.4)
    for name, got in (("energy", energy), ("force", force), ("virial", virial)):
        assert torch.equal(got, torch.as_tensor(want[name])), name
    # The forces are -dU/dx of the pair energy summed over the list (float64 in torch).
    xd = x.double().requires_grad_()
    d = pyraycut.neighbor_list("d", xd, 1.6, cell=c.double())
    u = (0.4 / d) ** 6
    total = 0.5 * (4 * 0.5 * (u * u - u)).sum()
    (grad,) = torch.autograd.grad(total, xd)
    torch.testing.assert_close(force.double(), -grad, rtol=1e-3, atol=1e-3 * grad.abs().max())
    # Per-atom energies hold half of each pair: they sum to the system's energy.
    torch.testing.assert_close(energy.double().sum(), total.detach(), rtol=1e-4, atol=1e-4)
    with pytest.raises(RuntimeError, match="not differentiable"):
        OPS.lj_forces(x.clone().requires_grad_(), 1.6)[0].sum().backward()


def test_lj_forces_op_under_compile_with_dynamic_n():
    from torch._dynamo.testing import CompileCounterWithBackend

    torch._dynamo.reset()
    counter = CompileCounterWithBackend("aot_eager")

    def step(x, cell):
        energy, force, _ = torch.ops.raycut.lj_forces(x, 0.45, 1.0, 0.2, cell)
        return x + 1e-4 * force, energy.sum()

    compiled = torch.compile(step, backend=counter, fullgraph=True)
    for n in (30, 50):
        x, c = periodic_system(n, np.eye(3), (True,) * 3, seed=n, dtype=torch.float32)
        torch._dynamo.mark_dynamic(x, 0)
        got, want = compiled(x, c), step(x, c)
        torch.testing.assert_close(got[0], want[0])
        torch.testing.assert_close(got[1], want[1])
    assert counter.frame_count == 1
