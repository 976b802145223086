"""No host round trip for device inputs: with CUDA PyTorch positions, pyraycut.neighbor_list returns
CUDA tensors over the library's own device memory, and the PyTorch profiler (CUPTI, which records
every memcpy of the process, the library's included) shows no device-to-host copy of positions,
pairs or per-particle arrays during the call.

What is asserted, for N particles and P pairs (P > N here):
- the outputs are CUDA tensors on the positions' device, and torch's allocator holds no more
  memory after the call than before (they wrap memory the library allocated: nothing was copied
  into tensors of torch's own);
- every "Memcpy DtoH" the profiler reports during the call, and their sum, is below 4 N bytes:
  the smallest per-particle array (N int32; positions are 12 N, each pair array >= 4 P). What
  does come back is scalars: the library's finiteness check reads one 8-byte index with
  cudaMemcpy, the pair and image counts come through mapped pinned memory (no memcpy at all),
  and a CUDA batch index is validated and turned into offsets on the device (4 scalars, then the
  S + 1 offsets). The copies seen are printed (pytest -s) for the record;
- the detector works: in the same profiler setup, x.cpu() shows a 12 N-byte DtoH copy, and the
  call's own kernels show up (so CUDA activity of the call was recorded at all).

Skipped without PyTorch, a CUDA device, or raycut's CUDA methods."""
import json

import numpy as np
import pytest
from conftest import torch_cuda

import pyraycut

DENSITY, CUTOFF = 0.8442, 2.5  # the LJ liquid of the benchmarks: ~55 neighbours each


def liquid(torch, n, seed=0):
    side = (n / DENSITY) ** (1 / 3)
    x = np.random.default_rng(seed).random((n, 3)) * side
    return torch.from_numpy(x.astype(np.float32)).cuda(), side


def profiled(torch, tmp_path, fn):
    """fn()'s result, the DtoH copies (bytes, name) and the kernel count the profiler saw."""
    from torch.profiler import ProfilerActivity, profile

    torch.cuda.synchronize()
    with profile(activities=[ProfilerActivity.CPU, ProfilerActivity.CUDA]) as prof:
        out = fn()
        torch.cuda.synchronize()
    path = tmp_path / "trace.json"
    prof.export_chrome_trace(str(path))
    events = json.loads(path.read_text())["traceEvents"]
    copies, kernels = [], 0
    for e in events:
        cat, name = str(e.get("cat", "")).lower(), str(e.get("name", ""))
        if cat == "kernel":
            kernels += 1
        if ("memcpy" in cat or name.startswith("Memcpy")) and "DtoH" in name:
            args = e.get("args", {})
            assert "bytes" in args, f"the profiler gives no size for {name}: {e}"
            copies.append((int(args["bytes"]), name))
    return out, copies, kernels


def test_the_detector_sees_a_positions_copy(tmp_path):
    torch = torch_cuda()
    x, _ = liquid(torch, 8192)
    _, copies, _ = profiled(torch, tmp_path, lambda: x.cpu())
    assert any(b >= 12 * len(x) for b, _ in copies), copies


@pytest.mark.parametrize("cache", [True, False], ids=["engine-cache", "fresh-engine"])
@pytest.mark.parametrize("batched", [False, True], ids=["one-box", "batch"])
def test_neighbor_list_keeps_device_data_on_the_device(tmp_path, batched, cache):
    torch = torch_cuda()
    n = 8192
    if batched:  # 64 periodic boxes of 128 (side 5.3 < 2 cutoff: images), one cell for all
        parts = [liquid(torch, n // 64, seed=s) for s in range(64)]
        x, side = torch.cat([p[0] for p in parts]), parts[0][1]
        batch = torch.arange(64, device="cuda").repeat_interleave(n // 64)
    else:
        x, side = liquid(torch, n)
        batch = None
    cell = [side] * 3

    def call():
        return pyraycut.neighbor_list("ijS", x, CUTOFF, cell=cell, pbc=True, batch=batch)

    pyraycut.set_engine_cache(cache)
    try:
        call()  # warm-up: CUDA context, modules, the cached engine
        torch.cuda.synchronize()
        before = torch.cuda.memory_allocated()
        (i, j, S), copies, kernels = profiled(torch, tmp_path, call)
        after = torch.cuda.memory_allocated()
    finally:
        pyraycut.set_engine_cache(True)
    pairs = len(i)
    print(f"\nN = {n}, P = {pairs}, batched = {batched}, cache = {cache}: DtoH copies during "
          f"the call (bytes, name): {copies}; {kernels} kernels")
    assert pairs > n  # so 4 N bounds every pair array too
    for t, dtype in zip((i, j, S), (torch.int64, torch.int64, torch.int32)):
        assert isinstance(t, torch.Tensor) and t.device == x.device and t.dtype == dtype
        assert t.data_ptr() != 0
    assert after == before, "outputs (or leftovers) in torch's allocator: something was copied"
    assert kernels > 0, "no kernel of the call was recorded: the profiler missed CUDA activity"
    limit = 4 * n
    assert all(b < limit for b, _ in copies), f"a DtoH copy of >= 4 N = {limit} bytes: {copies}"
    assert sum(b for b, _ in copies) < limit, f"DtoH copies add up to >= {limit} bytes: {copies}"
    # And the pairs are right: every i, j within the cutoff through S.
    c = torch.tensor(cell, device="cuda").diag()
    d = (x[j] - x[i] + S.to(torch.float32) @ c).norm(dim=1)
    assert bool((d < CUTOFF * (1 + 1e-5)).all())


def test_device_batch_index_matches_the_host_one():
    """The CUDA batch index path (validated and turned into offsets on the device) gives the host
    path's offsets and raises its errors, word for word."""
    torch = torch_cuda()
    from pyraycut import _systems

    rng = np.random.default_rng(7)
    index = np.sort(rng.choice([0, 2, 3, 3, 6], 300))  # systems 1, 4 and 5 empty
    for dtype in (torch.int64, torch.int32, torch.uint8):
        device = torch.from_numpy(index).to(dtype).cuda()
        for boxes in (None, _systems.boxes(np.eye(3)[None].repeat(9, 0), True)):
            got = _systems.batch(boxes, len(index), device)
            want = _systems.batch(boxes, len(index), index)
            assert got.systems == want.systems
            np.testing.assert_array_equal(got.offsets, want.offsets)
            assert got.offsets.dtype == np.uint64
    empty = _systems.batch(None, 0, torch.zeros(0, dtype=torch.int64, device="cuda"))
    assert empty.offsets.tolist() == [0, 0]
    leading_empty = _systems.batch(None, 3, torch.full((3,), 2, device="cuda"))
    assert leading_empty.offsets.tolist() == [0, 0, 0, 3]
    # More systems than points + 1: the host renumbers the used ones densely; on the device
    # that would mean reading the index back, so it is refused with the way out.
    with pytest.raises(ValueError, match="renumber them densely"):
        _systems.batch(None, 1, torch.full((1,), 2, device="cuda"))
    assert _systems.batch(None, 1, np.array([2])).offsets.tolist() == [0, 1]
    bad = {
        "unsorted": np.array([0, 0, 2, 1, 3]),
        "negative": np.array([-1, 0, 0]),
        "float": np.array([0.0, 1.0]),
        "shape": np.zeros((2, 2), np.int64),
    }
    for label, b in bad.items():
        with pytest.raises(ValueError) as host:
            _systems.batch(None, None, b)
        with pytest.raises(ValueError) as device:
            _systems.batch(None, None, torch.from_numpy(b).cuda())
        message = str(device.value).replace("torch.float64", "float64")
        assert message == str(host.value), label
    with pytest.raises(ValueError, match="cell/pbc give 2"):
        _systems.batch(_systems.boxes(np.eye(3)[None].repeat(2, 0), True), 3,
                       torch.tensor([0, 1, 2], device="cuda"))
