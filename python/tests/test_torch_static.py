"""torch.ops.raycut.neighbor_list with max_pairs on CUDA tensors: the stream-ordered small-system
pass (no host synchronisation, CUDA-graph capturable) against the CPU operator's pairs, capacity
overflow, bad data as a negative count, sync-debug mode, CUDA graphs, a side stream and
torch.compile. Skipped without a GPU or without the operators' CUDA kernel; the count checks
of pyraycut.check_pair_count run everywhere."""
import importlib.util

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="PyTorch is not installed")
import pyraycut  # noqa: E402

try:
    pyraycut.load_torch_ops()
    OPS = True
except ImportError:
    OPS = False

CUDA_KERNEL = (OPS and torch.cuda.is_available() and
               torch._C._dispatch_has_kernel_for_dispatch_key("raycut::neighbor_list", "CUDA"))
cuda = pytest.mark.skipif(not CUDA_KERNEL, reason="needs a GPU and the operators' CUDA kernel "
                          "(RAYCUT_TORCH_CUDA)")


def rng(seed):
    return np.random.default_rng(seed)


class Case:
    """Positions, cutoff, cell, pbc and batch on the host, in the dtype the test asks for."""

    def __init__(self, x, cutoff, cell=None, pbc=None, batch=None):
        self.x, self.cutoff, self.cell, self.pbc, self.batch = x, cutoff, cell, pbc, batch

    def on(self, device, dtype):
        def move(t, kind=None):
            return None if t is None else torch.as_tensor(t, dtype=kind).to(device)
        return (move(self.x, dtype), self.cutoff, move(self.cell, dtype),
                move(self.pbc, torch.bool), move(self.batch, torch.int64))


def cube():
    """A periodic cube (N=128, L=5.3, C=2.5), positions partly outside the box (unwrapped)."""
    x = rng(1).random((128, 3)) * 6.0 - 0.35
    return Case(x, 2.5, 5.3 * np.eye(3))


def triclinic():
    """A skewed cell thinner than twice the cutoff: pairs through several images, own images."""
    cell = np.array([[4.0, 0.0, 0.0], [1.3, 3.7, 0.0], [0.6, -0.9, 2.1]])
    x = rng(2).random((96, 3)) @ cell
    return Case(x, 2.5, cell)


def slab():
    """pbc (True, True, False): periodic in a and b, open along c."""
    cell = np.diag([4.5, 5.0, 7.0])
    x = rng(3).random((100, 3)) * [4.5, 5.0, 9.0]
    return Case(x, 2.2, cell, np.array([True, True, False]))


def batched():
    """Three systems with their own (B, 3, 3) cells and pbc rows, the middle one empty."""
    cells = np.stack([np.diag([5.0, 5.5, 6.0]),
                      np.diag([4.0, 4.0, 4.0]),
                      np.array([[4.2, 0.0, 0.0], [1.0, 4.0, 0.0], [0.0, 0.8, 4.4]])])
    pbc = np.array([[True, True, True], [True, True, True], [True, False, True]])
    sizes = [60, 0, 70]
    batch = np.repeat(np.arange(3), sizes)
    frac = rng(4).random((sum(sizes), 3))
    x = np.einsum("nk,nkl->nl", frac, cells[batch])
    return Case(x, 2.3, cells, pbc, batch)


CASES = {"cube": cube, "triclinic": triclinic, "slab": slab, "batch": batched}


def reference(case, dtype, half):
    """The CPU operator's pairs on the same numbers: the positions and cell as the CUDA call
    holds them (rounded to dtype), given to the CPU in float64, where every pair is decided in
    double, as the small-system pass decides it."""
    x, cutoff, cell, pbc, batch = case.on("cpu", dtype)
    i, j, s, count = torch.ops.raycut.neighbor_list(
        x.double(), cutoff, None if cell is None else cell.double(), pbc, batch, half, None)
    assert int(count) == len(i)
    return triples(i, j, s, len(i))


def triples(i, j, s, count):
    i, j, s = i[:count].cpu().tolist(), j[:count].cpu().tolist(), s[:count].cpu().tolist()
    found = [(a, b, *shift) for a, b, shift in zip(i, j, s)]
    assert len(set(found)) == len(found), "a pair listed twice"
    return set(found)


def static(case, dtype, half, max_pairs, device="cuda"):
    x, cutoff, cell, pbc, batch = case.on(device, dtype)
    return torch.ops.raycut.neighbor_list(x, cutoff, cell, pbc, batch, half, max_pairs)


def check_layout(out, n, max_pairs):
    """Static shapes and dtypes on the GPU, rows ascending, padding (N, N, 0) after the count."""
    i, j, s, count = out
    assert i.is_cuda and j.is_cuda and s.is_cuda and count.is_cuda
    assert i.shape == (max_pairs,) and j.shape == (max_pairs,) and s.shape == (max_pairs, 3)
    assert (i.dtype, j.dtype, s.dtype, count.dtype) == (torch.int64, torch.int64, torch.int32,
                                                        torch.int64)
    assert count.dim() == 0
    found = min(int(count), max_pairs)
    assert bool((i[:found][1:] >= i[:found][:-1]).all()), "rows not ascending"
    assert bool((i[found:] == n).all()) and bool((j[found:] == n).all())
    assert bool((s[found:] == 0).all())


@cuda
@pytest.mark.parametrize("half", [False, True])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("name", sorted(CASES))
def test_static_pass_equals_the_cpu_operator(name, dtype, half):
    case = CASES[name]()
    want = reference(case, dtype, half)
    assert want, "the case has pairs"
    max_pairs = len(want) + 17
    out = static(case, dtype, half, max_pairs)
    check_layout(out, len(case.x), max_pairs)
    i, j, s, count = out
    assert int(count) == len(want)
    assert triples(i, j, s, int(count)) == want


@cuda
def test_several_images_of_one_pair_are_listed():
    case = triclinic()
    i, j, s, count = static(case, torch.float64, False, 200_000)
    pairs = triples(i, j, s, int(count))
    per_pair = {}
    for a, b, *shift in pairs:
        per_pair.setdefault((a, b), set()).add(tuple(shift))
    assert max(len(v) for v in per_pair.values()) > 1
    assert any(a == b for a, b, *_ in pairs), "own images of a thin cell"


@cuda
def test_capacity_short_by_one_reports_the_true_count():
    case = cube()
    want = reference(case, torch.float32, False)
    full = static(case, torch.float32, False, len(want) + 5)
    short = static(case, torch.float32, False, len(want) - 1)
    check_layout(short, len(case.x), len(want) - 1)
    i, j, s, count = short
    assert int(count) == len(want) > len(want) - 1  # not cut silently: the count says so
    # The pairs that fit are the first of the fixed order, all of them real pairs.
    for cut, whole in zip(short[:3], full[:3]):
        assert torch.equal(cut, whole[:len(want) - 1])
    assert triples(i, j, s, len(want) - 1) <= want
    with pytest.raises(pyraycut.CapacityError, match="max_pairs = %d" % (len(want) - 1)):
        pyraycut.check_pair_count(count, len(want) - 1)
    assert pyraycut.check_pair_count(full[3], len(want) + 5) == len(want)


@cuda
def test_bad_data_is_a_negative_count_not_a_raise():
    case = batched()
    x, cutoff, cell, pbc, batch = case.on("cuda", torch.float32)
    nan = x.clone()
    nan[7, 1] = float("nan")
    count = torch.ops.raycut.neighbor_list(nan, cutoff, cell, pbc, batch, False, 5000)[3]
    assert int(count) == -1
    with pytest.raises(ValueError, match="NaN"):
        pyraycut.check_pair_count(count, 5000)
    unsorted = batch.flip(0)
    count = torch.ops.raycut.neighbor_list(x, cutoff, cell, pbc, unsorted, False, 5000)[3]
    assert int(count) == -2
    beyond = batch.clone()
    beyond[-5:] = 3  # no fourth cell
    count = torch.ops.raycut.neighbor_list(x, cutoff, cell, pbc, beyond, False, 5000)[3]
    assert int(count) == -4


def pair_set(i, j, s, count):
    found = int(count)
    assert found >= 0, f"the count is the code {found}, not a number of pairs"
    rows = torch.cat([i[:found, None], j[:found, None], s[:found].long()], 1).cpu().numpy()
    return set(map(tuple, rows.tolist()))


def liquid_and_crowded():
    """n, cutoff, a periodic liquid of n particles above the small systems (host positions), the
    same squeezed against the face x = 0 (every particle within the cutoff of it: far more
    periodic images than the liquid has), and the cubic cell."""
    n, cutoff = 6000, 2.5
    side = (n / 0.8442) ** (1 / 3)
    x = torch.as_tensor(rng(9).random((n, 3)) * side, dtype=torch.float32)
    crowded = x.clone()
    crowded[:, 0] *= 0.1
    return n, cutoff, x, crowded, side * torch.eye(3)


@cuda
def test_the_engine_reuses_its_plan_and_says_when_it_no_longer_fits(monkeypatch):
    """Above the small systems the operator's grid reuses the last call's plan (the default;
    RAYCUT_REUSE_PLAN=1 sets it here whatever the environment says), reading nothing back: the
    same pairs as the CPU operator call after call; a plan that no longer fits (every particle
    moved next to a face: far more periodic images) gives the count -6, which check_pair_count
    raises as CapacityError, and the next call plans afresh; without "c" the call itself calls
    once more."""
    monkeypatch.setenv("RAYCUT_REUSE_PLAN", "1")
    n, cutoff, x, crowded, cell = liquid_and_crowded()
    for step, host in enumerate((x, x + 0.05, crowded, crowded + 0.05, x)):
        want = pair_set(*torch.ops.raycut.neighbor_list(host, cutoff, cell, None, None, False,
                                                        4_000_000))
        on = host.cuda()
        out = torch.ops.raycut.neighbor_list(on, cutoff, cell, None, None, False, 4_000_000)
        if step in (2, 4):  # the plan of the step before does not fit
            assert int(out[3]) == -6, step
            with pytest.raises(pyraycut.CapacityError, match="call again"):
                pyraycut.check_pair_count(out[3], 4_000_000)
            out = torch.ops.raycut.neighbor_list(on, cutoff, cell, None, None, False, 4_000_000)
        assert pair_set(*out) == want, step
    # Without "c": the wrapper reads the count, and calls once more for a plan that no longer
    # fits.
    i, j, s = pyraycut.neighbor_list("ijS", crowded.cuda(), cutoff, cell=cell, pbc=True,
                                     max_pairs=4_000_000)
    want = pair_set(*torch.ops.raycut.neighbor_list(crowded, cutoff, cell, None, None, False,
                                                    4_000_000))
    assert pair_set(i, j, s, int((i < n).sum())) == want


@cuda
def test_reuse_plan_0_plans_every_call(monkeypatch):
    """RAYCUT_REUSE_PLAN=0: every grid call plans afresh, so positions that no plan of an
    earlier call would fit still give their pairs at once, never the count -6."""
    monkeypatch.setenv("RAYCUT_REUSE_PLAN", "0")
    _, cutoff, x, crowded, cell = liquid_and_crowded()
    for step, host in enumerate((x, crowded, x)):
        want = pair_set(*torch.ops.raycut.neighbor_list(host, cutoff, cell, None, None, False,
                                                        4_000_000))
        out = torch.ops.raycut.neighbor_list(host.cuda(), cutoff, cell, None, None, False,
                                             4_000_000)
        assert int(out[3]) >= 0, step
        assert pair_set(*out) == want, step


@cuda
def test_a_device_cell_is_not_copied_while_unchanged_and_a_change_is_reported(monkeypatch):
    """Where plans are reused (the default), a static call with a CUDA cell takes the boxes of
    the last copy of it while the device finds it unchanged; a cell changed in place gives the
    count -6, and the next call copies the new one."""
    monkeypatch.setenv("RAYCUT_REUSE_PLAN", "1")
    n, cutoff = 6000, 2.5
    side = (n / 0.8442) ** (1 / 3)
    x = torch.as_tensor(rng(10).random((n, 3)) * side, dtype=torch.float32)
    cell = side * torch.eye(3)
    on, cell_on = x.cuda(), cell.cuda()
    want = pair_set(*torch.ops.raycut.neighbor_list(x, cutoff, cell, None, None, False, 500_000))
    # The operator's engine may hold the plan of an earlier call of as many particles, which
    # these positions need not fit: the first call may say so (-6), and the next one plans.
    out = torch.ops.raycut.neighbor_list(on, cutoff, cell_on, None, None, False, 500_000)
    assert int(out[3]) in (-6, len(want))
    for _ in range(3):
        out = torch.ops.raycut.neighbor_list(on, cutoff, cell_on, None, None, False, 500_000)
        assert pair_set(*out) == want
    cell_on.mul_(1.02)  # in place: the same tensor, another cell
    out = torch.ops.raycut.neighbor_list(on, cutoff, cell_on, None, None, False, 500_000)
    assert int(out[3]) == -6
    out = torch.ops.raycut.neighbor_list(on, cutoff, cell_on, None, None, False, 500_000)
    want = pair_set(*torch.ops.raycut.neighbor_list(x, cutoff, cell_on.cpu(), None, None, False,
                                                    500_000))
    assert pair_set(*out) == want


@cuda
@pytest.mark.parametrize("through", ["operator", "wrapper"])
def test_a_captured_call_runs_the_engine_that_reuses_its_plan(monkeypatch, through):
    """Where plans are reused (the default), a static call captured in a CUDA graph after eager
    calls of the same systems runs the engine's grid (its recorded plan, the watched cell and
    pbc: a CUDA tensor given to the operator, pbc=True to the wrapper, which sends it to the
    device only under capture), not the small pass: each replay over positions changed in place
    lists the CPU operator's pairs, and a cell changed in place gives the count -6 at replay
    (the small pass would read the new cell)."""
    monkeypatch.setenv("RAYCUT_REUSE_PLAN", "1")
    n, cutoff, max_pairs = 7000, 2.5, 600_000  # above the small systems
    side = (n / 0.8442) ** (1 / 3)
    x = torch.as_tensor(rng(12).random((n, 3)) * side, dtype=torch.float32)
    cell = side * torch.eye(3)
    on, cell_on = x.cuda(), cell.cuda()
    flags = torch.ones(3, dtype=torch.bool, device="cuda")

    def call():
        if through == "wrapper":
            return pyraycut.neighbor_list("ijSc", on, cutoff, cell=cell_on, pbc=True,
                                          max_pairs=max_pairs)
        return torch.ops.raycut.neighbor_list(on, cutoff, cell_on, flags, None, False, max_pairs)

    warm = torch.cuda.Stream()
    warm.wait_stream(torch.cuda.current_stream())
    with torch.cuda.stream(warm):
        # Plans and records (the first call may find an earlier test's plan outgrown: -6), then
        # reuses; the cell and pbc are watched.
        first = int(call()[3])
        assert first == -6 or first >= 0
        for _ in range(2):
            assert int(call()[3]) >= 0
    torch.cuda.current_stream().wait_stream(warm)
    graph = torch.cuda.CUDAGraph()
    with torch.cuda.graph(graph):
        out = call()
    moves = rng(13)
    for step in range(3):
        moved = x + torch.as_tensor(moves.uniform(-0.05, 0.05, (n, 3)), dtype=torch.float32)
        on.copy_(moved.cuda())
        graph.replay()
        torch.cuda.synchronize()
        want = pair_set(*torch.ops.raycut.neighbor_list(moved, cutoff, cell, None, None, False,
                                                        max_pairs))
        assert pair_set(*out) == want, step
    cell_on.mul_(1.02)
    graph.replay()
    assert int(out[3]) == -6


@cuda
def test_no_host_synchronisation():
    case = batched()
    x, cutoff, cell, pbc, batch = case.on("cuda", torch.float32)
    max_pairs = len(reference(case, torch.float32, False)) + 10
    cube_x = torch.as_tensor(cube().x, dtype=torch.float32).to("cuda")
    torch.cuda.synchronize()
    torch.cuda.set_sync_debug_mode("error")
    try:
        ops = torch.ops.raycut.neighbor_list(x, cutoff, cell, pbc, batch, True, max_pairs)
        # Asking for the count ("c") takes charge of the check: nothing is read back.
        i, j, d, count = pyraycut.neighbor_list("ijdc", x, cutoff, cell=cell, pbc=pbc,
                                                batch=batch, max_pairs=max_pairs)
        open_x = x[:60]
        pyraycut.neighbor_list("ijc", open_x, cutoff, pbc=False, max_pairs=max_pairs)
        pyraycut.neighbor_list("ijSc", cube_x, 2.5, cell=5.3 * torch.eye(3, device="cuda"),
                               pbc=True, max_pairs=max_pairs)
    finally:
        torch.cuda.set_sync_debug_mode(0)
    full = torch.ops.raycut.neighbor_list(x, cutoff, cell, pbc, batch, False, max_pairs)
    assert torch.equal(i, full[0]) and torch.equal(j, full[1])
    assert int(ops[3]) * 2 == int(full[3])  # the half list holds each pair once
    real = i < len(x)
    assert bool((d[real] < cutoff * (1 + 1e-6)).all()) and bool((d[~real] == 0).all())


@cuda
@pytest.mark.parametrize("name", ["cube", "batch"])
def test_cuda_graph_replays_equal_eager_bit_for_bit(name):
    case = CASES[name]()
    x, cutoff, cell, pbc, batch = case.on("cuda", torch.float32)
    max_pairs = len(reference(case, torch.float32, False)) * 2
    captured_x = x.clone()

    def call(positions):
        return torch.ops.raycut.neighbor_list(positions, cutoff, cell, pbc, batch, False,
                                              max_pairs)

    side = torch.cuda.Stream()  # warm up off the capture, as torch.cuda.graphs asks
    side.wait_stream(torch.cuda.current_stream())
    with torch.cuda.stream(side):
        for _ in range(2):
            call(captured_x)
    torch.cuda.current_stream().wait_stream(side)
    graph = torch.cuda.CUDAGraph()
    with torch.cuda.graph(graph):
        captured = call(captured_x)
    generator = torch.Generator(device="cuda").manual_seed(5)
    counts = set()
    for step in range(3):
        moved = x + 0.15 * torch.randn(x.shape, device="cuda", generator=generator)
        captured_x.copy_(moved)
        graph.replay()
        torch.cuda.synchronize()
        eager = call(moved)
        for replayed, direct in zip(captured, eager):
            assert torch.equal(replayed, direct), step
        counts.add(int(eager[3]))
    assert len(counts) > 1, "the pair count changed from step to step"


@cuda
def test_non_default_stream():
    case = batched()
    want = reference(case, torch.float64, False)
    x, cutoff, cell, pbc, batch = case.on("cuda", torch.float64)
    side = torch.cuda.Stream()
    side.wait_stream(torch.cuda.current_stream())
    with torch.cuda.stream(side):
        # Positions written late on the side stream: a pass queued anywhere else would read
        # them before they are there.
        torch.cuda._sleep(50_000_000)
        moved = x.clone()
        i, j, s, count = torch.ops.raycut.neighbor_list(moved, cutoff, cell, pbc, batch, False,
                                                        len(want) + 3)
    torch.cuda.current_stream().wait_stream(side)
    assert int(count) == len(want)
    assert triples(i, j, s, int(count)) == want


@cuda
def test_large_systems_go_through_the_engine():
    """Above raycut::prefer_small_systems the engine's grid lists the same pairs."""
    # float32 on both sides: the engine's float32 predicate, the same on the CPU and the GPU.
    x = torch.as_tensor(rng(6).random((6000, 3)) * 30.0, dtype=torch.float32)
    cell = 30.0 * torch.eye(3)
    i, j, s, count = torch.ops.raycut.neighbor_list(x, 1.2, cell, None, None, False, None)
    out = torch.ops.raycut.neighbor_list(x.cuda(), 1.2, cell.cuda(), None, None, False,
                                         len(i) + 100)
    assert int(out[3]) == len(i)
    assert triples(*out[:3], len(i)) == triples(i, j, s, len(i))


@cuda
@pytest.mark.parametrize("name", ["cube", "batch", "triclinic"])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_without_max_pairs_small_systems_are_sized_exactly(name, dtype):
    """No max_pairs: the small-system pass with one read-back of the count (a second pass when
    the capacity guessed from the last call was short: the first call here, 1024 slots)."""
    case = CASES[name]()
    want = reference(case, dtype, False)
    for _ in range(2):  # the second call sizes from the first
        i, j, s, count = torch.ops.raycut.neighbor_list(*case.on("cuda", dtype), False, None)
        assert i.is_cuda and len(i) == int(count) == len(want)
        assert triples(i, j, s, len(i)) == want
    bad = case.on("cuda", dtype)
    bad[0][3, 1] = float("nan")
    with pytest.raises(ValueError, match="NaN"):
        torch.ops.raycut.neighbor_list(*bad, False, None)


@cuda
@pytest.mark.parametrize("name", ["cube", "batch"])
def test_eager_small_lists_take_the_operator(name):
    """pyraycut.neighbor_list on CUDA tensors of at most 4,096 particles, without max_pairs: the
    operator's pass, whose outputs torch allocates, with the pairs (and S) of the CPU operator;
    4,097 particles alone keep the extension's zero-copy path (torch's allocator holds nothing)."""
    case = CASES[name]()
    want = reference(case, torch.float32, False)
    x, cutoff, cell, pbc, batch = case.on("cuda", torch.float32)
    torch.cuda.synchronize()
    before = torch.cuda.memory_allocated()
    i, j, s = pyraycut.neighbor_list("ijS", x, cutoff, cell=cell, pbc=pbc, batch=batch)
    assert torch.cuda.memory_allocated() > before, "outputs not from torch: no operator"
    assert i.is_cuda and triples(i, j, s, len(i)) == want
    del i, j, s
    big = torch.rand((4097, 3), device="cuda") * 16.0
    torch.cuda.synchronize()
    before = torch.cuda.memory_allocated()
    i, j = pyraycut.neighbor_list("ij", big, 1.0)
    assert len(i) > 0 and torch.cuda.memory_allocated() == before


@cuda
def test_torch_compile_fullgraph():
    if not hasattr(torch, "compile"):
        pytest.skip("torch.compile is not available")
    case = cube()
    x, cutoff, cell, pbc, _ = case.on("cuda", torch.float32)
    max_pairs = len(reference(case, torch.float32, False)) + 50

    def energy(positions):
        i, d = pyraycut.neighbor_list("id", positions, cutoff, cell=cell, pbc=True,
                                      max_pairs=max_pairs)
        real = i < positions.shape[0]  # padding: i = N
        return torch.where(real, torch.exp(-d), 0.0).sum()

    backend = "inductor" if importlib.util.find_spec("triton") else "aot_eager"
    compiled = torch.compile(energy, fullgraph=True, backend=backend)
    for scale in (1.0, 1.01):
        moved = x * scale
        assert torch.allclose(compiled(moved), energy(moved), rtol=1e-5)


@cuda
def test_compiled_step_replays_as_a_cuda_graph():
    """torch.compile(mode="reduce-overhead") records the whole step (list, energy, forces) as a
    CUDA graph, which a host synchronisation inside it would forbid: no step is skipped, and the
    replays equal eager on moved positions."""
    if not importlib.util.find_spec("triton"):
        pytest.skip("Inductor's CUDA graphs need triton")
    from torch._dynamo.utils import counters

    case = cube()
    x, cutoff, cell, pbc, _ = case.on("cuda", torch.float32)
    max_pairs = len(reference(case, torch.float32, False)) + 50

    def step(positions):
        i, d, D = pyraycut.neighbor_list("idD", positions, cutoff, cell=cell, pbc=True,
                                         max_pairs=max_pairs)
        real = i < positions.shape[0]  # padding: i = N
        weight = torch.where(real, torch.exp(-d), 0.0)
        forces = torch.zeros_like(positions).index_add_(0, torch.where(real, i, 0),
                                                        weight[:, None] * D)
        return weight.sum(), forces

    counters.clear()
    compiled = torch.compile(step, fullgraph=True, mode="reduce-overhead")
    generator = torch.Generator(device="cuda").manual_seed(9)
    for _ in range(4):  # recorded on the second call, replayed after
        moved = x + 0.05 * torch.randn(x.shape, device="cuda", generator=generator)
        torch.compiler.cudagraph_mark_step_begin()
        energy, forces = (t.clone() for t in compiled(moved))
        want_energy, want_forces = step(moved)
        assert torch.allclose(energy, want_energy, rtol=1e-5)
        assert torch.allclose(forces, want_forces, rtol=1e-4, atol=1e-5)
    assert counters["inductor"]["cudagraph_skips"] == 0, dict(counters["inductor"])


@cuda
def test_a_large_system_is_captured_in_a_cuda_graph():
    """Above the small-system policy an eager call takes the engine, which plans on the host and
    cannot be captured; while a graph is being captured the same call takes the stream-ordered
    pass (with cells at 6,000 particles): the capture succeeds, and its replays list the eager
    call's pairs on moved positions."""
    n, side, cutoff = 6000, 19.15, 2.5
    assert not pyraycut._raycut.prefer_small_systems(n, 1)
    generator = torch.Generator(device="cuda").manual_seed(11)
    x = torch.rand((n, 3), device="cuda", generator=generator) * side
    cell = side * torch.eye(3, device="cuda")
    eager = pyraycut.neighbor_list("ijS", x, cutoff, cell=cell, pbc=True)
    max_pairs = len(eager[0]) + 2000

    def call(positions):
        return pyraycut.neighbor_list("ijSc", positions, cutoff, cell=cell, pbc=True,
                                      max_pairs=max_pairs)

    work = x.clone()
    side_stream = torch.cuda.Stream()
    side_stream.wait_stream(torch.cuda.current_stream())
    with torch.cuda.stream(side_stream):
        call(work)  # warm-up, as torch.cuda.graph asks
    torch.cuda.current_stream().wait_stream(side_stream)
    graph = torch.cuda.CUDAGraph()
    with torch.cuda.graph(graph):
        i, j, shifts, count = call(work)
    for step in range(3):
        moved = x + 0.1 * step * torch.randn(x.shape, device="cuda", generator=generator)
        work.copy_(moved)
        graph.replay()
        want = pyraycut.neighbor_list("ijS", moved, cutoff, cell=cell, pbc=True)
        assert int(count) == len(want[0]) <= max_pairs, step
        assert triples(i, j, shifts, int(count)) == triples(*want, len(want[0])), step


def test_check_pair_count_names_bad_input_and_overflow():
    assert pyraycut.check_pair_count(torch.tensor(12), 12) == 12
    with pytest.raises(pyraycut.CapacityError, match="at least 13"):
        pyraycut.check_pair_count(torch.tensor(13), 12)
    for code, words in ((-1, "NaN"), (-2, "not sorted"), (-3, "cell"), (-4, "no cell")):
        with pytest.raises(ValueError, match=words):
            pyraycut.check_pair_count(torch.tensor(code), 12)
    # A reused plan that no longer fits: an overflow of a kind, cured by calling again.
    with pytest.raises(pyraycut.CapacityError, match="call again"):
        pyraycut.check_pair_count(torch.tensor(-6), 12)


@pytest.mark.skipif(not OPS, reason="the PyTorch operators are not built")
def test_a_count_of_a_plan_outgrown_is_followed_by_one_more_call():
    """Without "c", the wrapper reads the count and calls the operator once more for -6 (the
    call that plans afresh); with "c" it leaves the count to the caller."""
    from pyraycut import _torch
    counts = [-6, 7]
    calls = []

    def call():
        calls.append(1)
        return None, None, None, torch.tensor(counts[len(calls) - 1])

    assert int(_torch._checked_call(call, 12, "ijS")[3]) == 7 and len(calls) == 2
    calls.clear()
    assert int(_torch._checked_call(call, 12, "ijSc")[3]) == -6 and len(calls) == 1
    calls.clear()
    counts[:] = [-6, -6]
    with pytest.raises(pyraycut.CapacityError, match="call again"):
        _torch._checked_call(call, 12, "ijS")


@pytest.mark.skipif(not OPS, reason="the PyTorch operators are not built")
def test_host_pbc_without_a_cell():
    x = torch.rand(50, 3)
    with pytest.raises(ValueError, match="pbc without a cell"):
        pyraycut.neighbor_list("ij", x, 0.3, pbc=[True, False, False])
    i, j = pyraycut.neighbor_list("ij", x, 0.3, pbc=False)
    want_i, want_j = pyraycut.neighbor_list("ij", x, 0.3)
    assert torch.equal(i, want_i) and torch.equal(j, want_j)


@cuda
def test_without_the_count_an_overflow_raises_and_with_it_the_count_says_so():
    """Never silent: without "c" the eager call checks the count (one read-back) and raises;
    with "c" the caller gets the true count above max_pairs."""
    case = cube()
    x, cutoff, cell, pbc, batch = case.on("cuda", torch.float32)
    pairs = len(reference(case, torch.float32, False))
    with pytest.raises(pyraycut.CapacityError, match=f"{pairs} pairs"):
        pyraycut.neighbor_list("ij", x, cutoff, cell=cell, pbc=pbc, max_pairs=pairs - 1)
    i, count = pyraycut.neighbor_list("ic", x, cutoff, cell=cell, pbc=pbc, max_pairs=pairs - 1)
    assert count.device.type == "cuda" and int(count) == pairs and i.shape == (pairs - 1,)


def test_the_count_letter_comes_with_the_operator():
    x = torch.rand(10, 3)
    with pytest.raises(ValueError, match="'c'"):
        pyraycut.neighbor_list("ijc", x.numpy(), 0.5)
    i, count = pyraycut.neighbor_list("ic", x, 0.5)
    assert count.dim() == 0 and int(count) == len(i)
    i, count = pyraycut.neighbor_list("ic", x, 0.5, max_pairs=200)
    assert count.dim() == 0 and int(count) == int((i < 10).sum())


@pytest.mark.skipif(not OPS, reason="the operators are not built")
def test_small_systems_rule_is_the_operators():
    """pyraycut sends eager CUDA lists to the operator where its small-system pass takes them:
    N <= 4096 or N^2 <= 2^23 B (raycut::prefer_small_systems), B from a (B, 3, 3) cell, else
    1."""
    from pyraycut import _torch

    def small(n, cell=None, pbc=None):
        return _torch._small_systems(torch.zeros((n, 3)), cell, pbc)

    assert small(4096) and not small(4097)
    assert small(4097, cell=torch.eye(3)) is False
    assert small(8192, cell=np.zeros((8, 3, 3))) and not small(8193, cell=np.zeros((8, 3, 3)))
    assert small(8192, cell=[[[1, 0, 0]] * 3] * 8)
    assert not small(10, pbc=True), "pbc without a cell stays on the engine"


@cuda
def test_the_count_comes_with_any_size_on_cuda():
    """"c" sends a CUDA call through the operator at any size: the small pass below the rule,
    the engine's grid above it, each with the count of its pairs."""
    for n in (200, 6000):
        x = torch.rand((n, 3), device="cuda", generator=None) * (n / 0.8442) ** (1 / 3)
        i, j, count = pyraycut.neighbor_list("ijc", x, 2.5)
        assert count.is_cuda and count.dim() == 0 and int(count) == len(i) == len(j) > 0
