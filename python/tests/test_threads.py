"""Threads: calls on one Engine or VerletList from many Python threads are serialised (each
object holds a lock, taken with the GIL released), calls on different objects run in parallel,
and the engines neighbor_list and radius reuse are never shared by two calls at once.

The hammering runs in a child process: before the locks it crashed (segfault, or glibc's
``malloc(): invalid next size``), which must fail this test, not end the test session."""
import os
import subprocess
import sys
import textwrap
import threading
import time

import numpy as np
import pytest

import pyraycut
from conftest import AVAILABLE

# Every method here: on a machine with a GPU the CUDA engines are hammered too (host inputs).
METHODS = AVAILABLE


def run_child(code: str, timeout: float = 300) -> str:
    result = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True,
                            text=True, timeout=timeout, env=dict(os.environ))
    assert result.returncode == 0, (f"child exited {result.returncode} (negative: killed by that "
                                    f"signal)\nstdout:\n{result.stdout}\nstderr:\n{result.stderr}")
    return result.stdout


HAMMER = """
import sys, threading
import numpy as np
import pyraycut

method = sys.argv[1] if len(sys.argv) > 1 else "{method}"
rng = np.random.default_rng(0)
x = rng.random((3000, 3)).astype(np.float32)
y = (x + 0.001).astype(np.float32)
CUTOFF = 0.08


def rows(offsets, indices):
    return [sorted(indices[offsets[i]:offsets[i + 1]].tolist()) for i in range(len(offsets) - 1)]


def snapshot(engine, positions):
    offsets, indices = engine.neighbours()
    count = engine.compute("count")["count"]
    energy = engine.compute("lj_forces", lj_sigma=0.01)["energy"]
    idx, counts, report = engine.padded_neighbours(64)
    return rows(offsets, indices), count.tolist(), energy, counts.tolist(), report["largest_count"]


reference = {{}}
for name, positions in (("x", x), ("y", y)):
    e = pyraycut.Engine(method)
    e.build(positions, CUTOFF)
    reference[name] = snapshot(e, positions)
verlet_reference = pyraycut.VerletList(CUTOFF, 0.02, method=method)
verlet_reference.update(x)
verlet_rows = rows(*verlet_reference.neighbours())

shared = pyraycut.Engine(method)
verlet = pyraycut.VerletList(CUTOFF, 0.02, method=method)
errors = []


def same(a, b):
    # Energies to rounding: a method's update may keep the previous build's cell order, and
    # the sums then run in another order (grid-paper). Lists and counts exactly.
    if isinstance(a, np.ndarray) and a.dtype.kind == "f":
        return a.shape == b.shape and np.allclose(a, b, rtol=1e-5, atol=0)
    return np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b


def worker(k):
    try:
        for step in range(6):
            name = "x" if (k + step) % 2 else "y"
            positions = x if name == "x" else y
            # The other threads build the same positions or the other set in between: each
            # output (one call, serialised) must be that of one of the two inputs.
            shared.build(positions, CUTOFF)
            shared.update(positions)
            got = snapshot(shared, positions)
            for c, value in enumerate(got):
                if not (same(value, reference["x"][c]) or same(value, reference["y"][c])):
                    errors.append(f"thread {{k}} step {{step}}: output {{c}} matches neither input")
            verlet.update(x)
            if rows(*verlet.neighbours()) != verlet_rows:
                errors.append(f"thread {{k}} step {{step}}: the Verlet list differs")
            i, j = pyraycut.neighbor_list("ij", positions, CUTOFF, method=method)
            if len(i) != sum(len(r) for r in reference[name][0]):
                errors.append(f"thread {{k}} step {{step}}: neighbor_list found {{len(i)}} pairs")
    except Exception as e:  # noqa: BLE001  reported by the parent
        errors.append(f"thread {{k}}: {{type(e).__name__}}: {{e}}")


threads = [threading.Thread(target=worker, args=(k,)) for k in range(8)]
for t in threads:
    t.start()
for t in threads:
    t.join()
print("\\n".join(errors) if errors else "ok")
"""


@pytest.mark.parametrize("method", METHODS)
def test_one_engine_and_one_verlet_list_hammered_by_8_threads(method):
    """8 threads share one Engine, one VerletList and the engine cache: build, update, CSR,
    kernels, the padded matrix, the Verlet list and neighbor_list. Every result equals a
    single-threaded one and nothing crashes."""
    out = run_child(HAMMER.format(method=method))
    assert out.strip() == "ok", out


@pytest.mark.parametrize("method", METHODS)
def test_different_engines_run_in_parallel(method):
    """Engines of their own per thread: results as single-threaded, and their calls overlap in
    time (the GIL is released and no lock is shared between objects; a global lock would make
    every call wait for the others)."""
    rng = np.random.default_rng(1)
    n = 5000 if method.startswith("brute-force") else 60000  # brute force is O(N^2)
    inputs = [rng.random((n, 3)).astype(np.float32) for _ in range(4)]
    cutoff = 0.03
    want = []
    for x in inputs:
        e = pyraycut.Engine(method)
        e.build(x, cutoff)
        want.append(e.compute("count")["count"])
    intervals = [[] for _ in inputs]
    got = [None] * len(inputs)

    def worker(k):
        e = pyraycut.Engine(method)
        e.build(inputs[k], cutoff)
        for _ in range(3):
            start = time.perf_counter()
            got[k] = e.compute("count")["count"]
            intervals[k].append((start, time.perf_counter()))

    start = time.perf_counter()
    threads = [threading.Thread(target=worker, args=(k,)) for k in range(len(inputs))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    parallel = time.perf_counter() - start
    for k in range(len(inputs)):
        np.testing.assert_array_equal(got[k], want[k])
    overlapping = sum(1 for a in range(len(inputs)) for b in range(a + 1, len(inputs))
                      for s0, e0 in intervals[a] for s1, e1 in intervals[b]
                      if s0 < e1 and s1 < e0)
    assert overlapping > 0, f"no two calls on different engines overlapped in time: {intervals}"
    print(f"{len(inputs)} engines x 3 counts in {parallel:.3f} s, {overlapping} overlapping calls")


def test_engine_cache_hands_each_thread_its_own_engine():
    """neighbor_list from 8 threads at once: the cached engine is taken out for a call, so two
    concurrent calls never share one; every answer is the single-threaded one."""
    rng = np.random.default_rng(2)
    inputs = [rng.random((2000, 3)).astype(np.float32) for _ in range(8)]
    want = [pyraycut.neighbor_list("ij", x, 0.06) for x in inputs]
    failures = []

    def worker(k):
        for _ in range(5):
            i, j = pyraycut.neighbor_list("ij", inputs[k], 0.06)
            if not (np.array_equal(i, want[k][0]) and np.array_equal(j, want[k][1])):
                failures.append(k)

    threads = [threading.Thread(target=worker, args=(k,)) for k in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not failures
