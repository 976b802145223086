"""Every refusal names the argument, its value and what is accepted; sizes beyond the memory
budget are MemoryError before anything that large is allocated; inputs that are only another
precision or layout of valid positions are accepted; distances agree with their vectors."""
import os
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

import pyraycut

N = 50


def cloud(n=N, seed=0):
    return np.random.default_rng(seed).random((n, 3)).astype(np.float32)


def built(n=N, cutoff=0.3):
    e = pyraycut.Engine("cell-list")
    e.build(cloud(n), cutoff)
    return e


def sph_force(**arrays):
    e = built()
    inputs = {"velocity": np.zeros((N, 3), np.float32), "density": np.ones(N, np.float32),
              "pressure": np.ones(N, np.float32)}
    inputs.update(arrays)
    return e.compute("sph_force", sph_mass=1.0, **inputs)


def torch_tensor(make):
    torch = pytest.importorskip("torch", reason="PyTorch is not installed")
    return make(torch)


# (row, action, exception, the message must match): one row per refusal of the issue.
ROWS = [
    ("cutoff 1e-50 (0 in float)", lambda: built().build(cloud(), 1e-50), ValueError,
     r"cutoff 1e-50 is outside the supported range \[2\^-60, 2\^60\]"),
    ("cutoff 1e39 (inf in float)", lambda: built().build(cloud(), 1e39), ValueError,
     r"cutoff 1e\+39 is outside the supported range \[2\^-60, 2\^60\]"),
    ("neighbor_list cutoff 1e-50", lambda: pyraycut.neighbor_list("ij", cloud(), 1e-50), ValueError,
     r"1e-50.*\[2\^-60, 2\^60\]"),
    ("VerletList cutoff 1e39", lambda: pyraycut.VerletList(1e39, 0.1), ValueError,
     r"1e\+39.*\[2\^-60, 2\^60\]"),
    ("VerletList skin 1e39", lambda: pyraycut.VerletList(1.0, 1e39), ValueError,
     r"cutoff \+ skin \(the list's reach\): cutoff 1e\+39 is outside the supported range"),
    ("padded K = 2^32", lambda: built().padded_neighbours(2**32), ValueError,
     r"K must be a whole number in \[1, 2\^32 - 1 = 4294967295\], got 4294967296"),
    ("padded K = 2^70", lambda: built().padded_neighbours(2**70), ValueError,
     r"K must be a whole number in \[1, 2\^32 - 1 = 4294967295\]"),
    ("padded K = -1", lambda: built().padded_neighbours(-1), ValueError, r"got -1"),
    ("padded K = 2^31 on 50 particles", lambda: built().padded_neighbours(2**31), MemoryError,
     r"K = 2147483648.*needs .*GiB.*budget.*K = 50 is always enough"),
    ("uint64 batch above 2^63 - 1",
     lambda: pyraycut.neighbor_list("ij", cloud(4), 0.3,
                                  batch=np.array([0, 0, 2**63, 2**64 - 1], np.uint64)),
     ValueError, r"batch holds system index 18446744073709551615, above the largest supported "
                 r"2\^63 - 1"),
    ("torch tensor on the meta device",
     lambda: pyraycut.neighbor_list("ij", torch_tensor(lambda t: t.zeros((4, 3), device="meta")),
                                  0.3),
     ValueError, r"positions is on the 'meta' device: raycut reads tensors on the CPU and on "
                 r"CUDA devices"),
    ("complex NumPy positions", lambda: pyraycut.neighbor_list("ij", cloud().astype(complex), 0.3),
     ValueError, r"positions must be real numbers, got dtype complex128"),
    ("complex torch positions",
     lambda: pyraycut.neighbor_list("ij", torch_tensor(lambda t: t.zeros((4, 3),
                                                                        dtype=t.complex64)), 0.3),
     ValueError, r"positions must be real numbers, got dtype torch.complex64"),
    ("complex cutoff", lambda: pyraycut.neighbor_list("ij", cloud(), np.array(0.3 + 1j)),
     ValueError, r"cutoff must be real numbers"),
    ("SPH density of shape (25, 2)", lambda: sph_force(density=np.ones((25, 2), np.float32)),
     ValueError, r"density must have shape \(50,\) \(one value per particle\), got \(25, 2\)"),
    ("SPH velocity of shape (150,)", lambda: sph_force(velocity=np.zeros(150, np.float32)),
     ValueError, r"velocity must have shape \(50, 3\)"),
    ("SPH density 0", lambda: sph_force(density=np.zeros(N, np.float32)), ValueError,
     r"density\[0\] = 0: must be finite and > 0"),
    ("SPH density NaN",
     lambda: sph_force(density=np.where(np.arange(N) == 7, np.nan, 1).astype(np.float32)),
     ValueError, r"density\[7\] = nan"),
    ("SPH pressure inf",
     lambda: sph_force(pressure=np.where(np.arange(N) == 3, np.inf, 1).astype(np.float32)),
     ValueError, r"pressure\[3\] = inf: must be finite"),
]


@pytest.mark.parametrize("row, action, error, message", ROWS, ids=[r[0] for r in ROWS])
def test_every_refusal_names_the_argument_its_value_and_the_range(row, action, error, message):
    with pytest.raises(error, match=message):
        action()


def run_child(code: str, budget: str, timeout: float = 120) -> subprocess.CompletedProcess:
    env = dict(os.environ, RAYCUT_MAX_MEMORY=budget)
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True,
                          text=True, timeout=timeout, env=env)


def test_a_list_beyond_the_budget_is_a_memory_error_before_allocation():
    """12,000 points within a cutoff of each other: 1.44e8 pairs (2.1 GiB as i, j, d), under
    RAYCUT_MAX_MEMORY=300M: MemoryError naming the size, the budget and the knob, quickly (it was
    the OOM killer in a container with less memory)."""
    result = run_child("""
        import time
        import numpy as np
        import pyraycut
        x = np.random.default_rng(0).random((12000, 3)).astype(np.float32)
        start = time.perf_counter()
        try:
            pyraycut.neighbor_list("ijd", x, 10.0, method="cell-list")
        except MemoryError as e:
            print("MemoryError", round(time.perf_counter() - start, 2), e)
        """, "300M")
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("MemoryError"), result.stdout
    assert "143988000 pairs" in result.stdout and "RAYCUT_MAX_MEMORY=300M" in result.stdout
    assert float(result.stdout.split()[1]) < 30


def test_padded_k_beyond_the_budget_and_a_malformed_budget():
    result = run_child("""
        import numpy as np
        import pyraycut
        e = pyraycut.Engine("cell-list")
        e.build(np.random.default_rng(0).random((50, 3)).astype(np.float32), 0.3)
        try:
            e.padded_neighbours(2**31)
        except MemoryError as err:
            print("MemoryError", err)
        """, "300M")
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("MemoryError"), result.stdout
    assert "RAYCUT_MAX_MEMORY=300M" in result.stdout and "K = 50 is always enough" in result.stdout
    result = run_child("""
        import numpy as np
        import pyraycut
        try:
            # The host method: RAYCUT_MAX_MEMORY is the host's budget (a GPU method would
            # first find the list too large for the device).
            pyraycut.neighbor_list("ij", np.zeros((10**6, 3), np.float32), 0.1,
                                   method="cell-list")
        except ValueError as err:
            print("ValueError", err)
        """, "a lot")
    assert "RAYCUT_MAX_MEMORY must be a number of bytes" in result.stdout, result
    assert "got 'a lot'" in result.stdout


# ---- inputs that are accepted -------------------------------------------------------------------

def by_pair(i, j, *values):
    """The entries sorted by (i, j): the order within a row is not part of the contract (float64
    positions take the engine's float64 route, whose rows may list the same pairs in another
    order)."""
    i, j = np.asarray(i), np.asarray(j)
    order = np.lexsort((j, i))
    return (i[order], j[order]) + tuple(np.asarray(v)[order] for v in values)


def test_float64_positions_give_float64_distances_and_vectors():
    x = cloud(300, 3)
    i32, j32, d32, D32 = by_pair(*pyraycut.neighbor_list("ijdD", x, 0.2))
    i, j, d, D = pyraycut.neighbor_list("ijdD", x.astype(np.float64), 0.2)
    assert d.dtype == np.float64 and D.dtype == np.float64
    i, j, d, D = by_pair(i, j, d, D)
    np.testing.assert_array_equal(i, i32)
    np.testing.assert_array_equal(j, j32)
    # float64 positions are searched in their own frame: r may differ by a float32 rounding
    # of the coordinates (~1e-7 in this unit cube).
    np.testing.assert_allclose(d, d32.astype(np.float64), rtol=0, atol=2e-7)
    np.testing.assert_allclose(D, D32.astype(np.float64), rtol=0, atol=2e-7)


def test_float64_and_non_contiguous_torch_tensors_are_accepted():
    torch = pytest.importorskip("torch", reason="PyTorch is not installed")
    x = cloud(300, 4)
    i32, j32, d32 = pyraycut.neighbor_list("ijd", x, 0.2)
    wide = torch.from_numpy(x.astype(np.float64))
    i, j, d = pyraycut.neighbor_list("ijd", wide, 0.2)
    assert d.dtype == torch.float64
    i, j, d = by_pair(i.numpy(), j.numpy(), d.numpy())
    i32s, j32s, d32s = by_pair(i32, j32, d32)
    np.testing.assert_array_equal(i, i32s)
    np.testing.assert_array_equal(j, j32s)
    # CPU tensors go through the PyTorch operator: d from the float64 positions themselves.
    np.testing.assert_allclose(d, d32s.astype(np.float64), rtol=3e-7)
    # A transposed view (strides (1, N)): copied to C order, not refused.
    strided = torch.from_numpy(np.ascontiguousarray(x.T)).T
    assert not strided.is_contiguous()
    i, j, d = pyraycut.neighbor_list("ijd", strided, 0.2)
    assert d.dtype == torch.float32
    # By pair: where a GPU is present the NumPy call above may run on it, in another row order.
    i, j = by_pair(i.numpy(), j.numpy())
    np.testing.assert_array_equal(i, i32s)
    np.testing.assert_array_equal(j, j32s)
    e = pyraycut.Engine("cell-list")
    e.build(wide, 0.2)
    assert e.compute("lj_forces")["energy"].dtype == torch.float64


def test_non_contiguous_numpy_positions_are_accepted():
    x = cloud(300, 5)
    i32, j32 = pyraycut.neighbor_list("ij", x, 0.2)
    strided = np.ascontiguousarray(x.T).T
    assert not strided.flags.c_contiguous
    i, j = pyraycut.neighbor_list("ij", strided, 0.2)
    np.testing.assert_array_equal(i, i32)
    np.testing.assert_array_equal(j, j32)


def test_zero_dimensional_cutoff():
    x = cloud(300, 6)
    want = pyraycut.neighbor_list("ij", x, 0.2)
    got = pyraycut.neighbor_list("ij", x, np.array(0.2))
    np.testing.assert_array_equal(got[0], want[0])
    torch = pytest.importorskip("torch", reason="PyTorch is not installed")
    got = pyraycut.neighbor_list("ij", x, torch.tensor(0.2, dtype=torch.float64))
    np.testing.assert_array_equal(got[0], want[0])
    # A sequence is per-atom cutoffs: two for 300 particles is refused, naming both counts.
    with pytest.raises(ValueError, match="2 per-atom cutoffs for 300 particles"):
        pyraycut.neighbor_list("ij", x, np.array([0.2, 0.3]))


def test_padded_report_gives_the_largest_row_without_overflow():
    e = built(200)
    count = e.compute("count")["count"]
    _, counts, report = e.padded_neighbours(int(count.max()) + 5)
    assert not report["overflowed"]
    assert report["largest_count"] == int(count.max()) > 0


# ---- distances ---------------------------------------------------------------------------------

@pytest.mark.parametrize("separation", [1e-22, 1e-20, 1e-12, 1.0, 1e12])
def test_distances_are_the_length_of_their_vectors(separation):
    """d = |D| to float precision across the cutoff range: a pair 1e-22 apart at C = 1e-18 had d
    off by 1 % (r^2 is a subnormal float there)."""
    x = np.array([[0, 0, 0], [separation, 0.6 * separation, 0.3 * separation]], np.float32)
    cutoff = max(4 * separation, 1e-18)
    d, D = pyraycut.neighbor_list("dD", x, cutoff, method="cell-list")
    length = np.sqrt((D.astype(np.float64) ** 2).sum(1))
    np.testing.assert_allclose(d.astype(np.float64), length, rtol=2**-22)


def test_float64_numpy_positions_decide_in_double():
    # Two points 1 - 1e-9 apart at 1e6: their float32 rounding is 1.0 apart (no pair); float64
    # NumPy positions go to the engine beside it, which decides in double.
    x = np.array([[1e6 + 0.01, 0.0, 0.0], [1e6 + 1.01 - 1e-9, 0.0, 0.0]])
    i, j, d = pyraycut.neighbor_list("ijd", x, 1.0)
    # In range in double; d is the engine's float32 distance widened (1 - 1e-9 rounds to 1).
    assert sorted(i.tolist()) == [0, 1] and d.dtype == np.float64 and np.all(d <= 1.0)
    assert len(pyraycut.neighbor_list("i", x.astype(np.float32), 1.0)) == 0
    engine = pyraycut.Engine("cell-list")
    engine.build(x, 1.0)
    assert engine.compute("count")["count"].tolist() == [1, 1]
    moved = x.copy()
    moved[1, 0] += 2e-9  # 1 + 1e-9 apart: out
    engine.update(moved)
    assert engine.compute("count")["count"].tolist() == [0, 0]
    # A periodic box 10^4 cutoffs wide: the pair across the face, both ways.
    y = np.array([[0.3004, 5000.0, 5000.0], [9999.30078125, 5000.0, 5000.0]])
    i, j, S = pyraycut.neighbor_list("ijS", y, 1.0, cell=np.eye(3) * 1e4)
    assert sorted(zip(i.tolist(), j.tolist(), S[:, 0].tolist())) == [(0, 1, -1), (1, 0, 1)]

