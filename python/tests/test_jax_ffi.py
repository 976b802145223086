"""pyraycut.jax: the neighbour list as an XLA FFI custom call on the CPU, under jax.jit, with
jax.grad of an energy against finite differences. Skipped (with the reason) without JAX or where
the custom call was not built."""
import numpy as np
import pytest
from test_periodic import TRICLINIC, inside_cell, reference, triples

jax = pytest.importorskip("jax", reason="JAX is not installed")
try:
    import pyraycut.jax as rjax
except ImportError as e:
    pytest.skip(f"pyraycut.jax's custom call is not built ({e})", allow_module_level=True)
import jax.numpy as jnp  # noqa: E402

CELL = 0.9 * TRICLINIC
CUTOFF = 0.45


@pytest.fixture(autouse=True)
def on_the_cpu():
    """The CPU custom call, whatever device JAX takes by default: on a machine with a GPU, NumPy
    inputs would go to the CUDA one, which python/tests/test_jax_cuda.py compares with this."""
    with jax.default_device(jax.devices("cpu")[0]):
        yield


def test_jit_pairs_match_brute_force_and_padding():
    x = inside_cell(30, CELL, seed=8)
    listed = jax.jit(lambda x, c: rjax.neighbor_list(x, CUTOFF, cell=c, max_pairs=2000))
    i, j, S, count = (np.asarray(a) for a in listed(x, CELL))
    n = int(count)
    assert 0 < n < 2000 and i.shape == (2000,) and S.shape == (2000, 3)
    inside, edge = reference(x, x, CUTOFF, CELL, (True,) * 3)
    assert triples(i[:n], j[:n], S[:n]) - edge == inside - edge
    assert np.all(i[n:] == 30) and np.all(j[n:] == 30) and not S[n:].any()
    # One short: count says the list was cut.
    _, _, _, short = rjax.neighbor_list(x, CUTOFF, cell=CELL, max_pairs=n - 1)
    assert int(short) == n
    # Half, open, slab.
    hi, hj, hS, hcount = rjax.neighbor_list(x, CUTOFF, cell=CELL, max_pairs=2000, half=True)
    assert 2 * int(hcount) == n
    _, _, oS, ocount = rjax.neighbor_list(x, CUTOFF, max_pairs=2000)
    assert int(ocount) == len(reference(x, x, CUTOFF)[0]) and not np.asarray(oS).any()
    _, _, sS, _ = rjax.neighbor_list(x, CUTOFF, cell=CELL, pbc=[True, True, False],
                                     max_pairs=2000)
    assert not np.asarray(sS)[:, 2].any()


def energy(x, cell):
    i, j, S, count = rjax.neighbor_list(x, CUTOFF, cell=cell, max_pairs=2000)
    d = jnp.linalg.norm(rjax.vectors(x, i, j, S, cell) + (jnp.arange(len(i)) >= count)[:, None],
                        axis=1)  # padding moved to d = 1 (a safe norm), then masked out
    e = (CUTOFF - d) ** 3 * jnp.cos(3 * d)
    return jnp.sum(jnp.where(jnp.arange(len(i)) < count, e, 0.0))


def test_grad_of_energy_against_finite_differences():
    x = jnp.asarray(inside_cell(16, CELL, seed=9))
    cell = jnp.asarray(CELL, jnp.float32)
    gx, gc = jax.jit(jax.grad(energy, argnums=(0, 1)))(x, cell)
    assert float(jnp.abs(gx).max()) > 0
    h = 1e-3
    rng = np.random.default_rng(0)
    for _ in range(3):  # directional derivatives (float32: central differences, loose tolerance)
        u = jnp.asarray(rng.normal(size=x.shape), jnp.float32)
        v = jnp.asarray(rng.normal(size=(3, 3)), jnp.float32)
        numeric = (energy(x + h * u, cell + h * v) - energy(x - h * u, cell - h * v)) / (2 * h)
        analytic = jnp.sum(gx * u) + jnp.sum(gc * v)
        assert abs(float(numeric) - float(analytic)) <= 2e-2 * max(1.0, abs(float(analytic)))


def test_errors():
    with pytest.raises(ValueError, match="max_pairs"):
        rjax.neighbor_list(jnp.zeros((4, 3)), 0.5)
    with pytest.raises(ValueError, match="shape"):
        rjax.neighbor_list(jnp.zeros((4, 2)), 0.5, max_pairs=10)
    with pytest.raises(Exception, match="cutoff"):
        rjax.neighbor_list(jnp.zeros((4, 3)), -1.0, max_pairs=10)[3].block_until_ready()


def test_an_older_xla_ffi_api_is_refused_before_registration(monkeypatch):
    built = divmod(rjax._library.RaycutXlaFfiApiVersion(), 1000)
    assert rjax._xla_ffi_api_version() >= built  # this process's jaxlib took the handlers
    monkeypatch.setattr(rjax, "_xla_ffi_api_version", lambda: (built[0], built[1] - 1))
    with pytest.raises(ImportError, match=rf"XLA FFI API {built[0]}\.{built[1]}.*rebuild"):
        rjax._check_xla_ffi_api()
    monkeypatch.setattr(rjax, "_xla_ffi_api_version", lambda: (built[0], built[1] + 1))
    rjax._check_xla_ffi_api()  # a newer jaxlib keeps older handlers working


def test_vmap_is_one_batched_search_with_per_system_outputs():
    xs = np.stack([inside_cell(20, CELL, seed=s) for s in (30, 31, 32)])
    cells = np.stack([CELL, 1.1 * CELL, 0.9 * CELL]).astype(np.float32)
    batched = jax.jit(jax.vmap(lambda x, c: rjax.neighbor_list(x, CUTOFF, cell=c, max_pairs=900)))
    i, j, S, count = (np.asarray(a) for a in batched(xs, cells))
    assert i.shape == (3, 900) and S.shape == (3, 900, 3) and count.shape == (3,)
    for b in range(3):
        one = [np.asarray(a) for a in rjax.neighbor_list(xs[b], CUTOFF, cell=cells[b],
                                                         max_pairs=900)]
        n = int(count[b])
        assert n == int(one[3]) > 0
        assert triples(i[b, :n], j[b, :n], S[b, :n]) == triples(one[0][:n], one[1][:n],
                                                                one[2][:n])
        assert np.all(i[b, n:] == 20) and np.all(j[b, n:] == 20)
    # One cell for every system (not mapped), and gradients through vmap.
    shared = jax.vmap(lambda x: rjax.neighbor_list(x, CUTOFF, cell=CELL, max_pairs=900)[3])(xs)
    assert [int(c) for c in shared] == [
        int(rjax.neighbor_list(x, CUTOFF, cell=CELL, max_pairs=900)[3]) for x in xs]
    grads = jax.vmap(jax.grad(energy))(jnp.asarray(xs), jnp.asarray(cells))
    for b in range(3):
        np.testing.assert_allclose(grads[b], jax.grad(energy)(jnp.asarray(xs[b]),
                                                               jnp.asarray(cells[b])),
                                   rtol=1e-5, atol=1e-5)


# A ragged batch: 3 systems of 22, 0 and 1 particles, each with its own triclinic cell (the last
# one small and a slab: the single particle meets its own images).
RAGGED_SIZES = (22, 0, 1)
RAGGED_CELLS = np.stack([CELL, 1.1 * CELL, 0.35 * TRICLINIC]).astype(np.float32)
RAGGED_PBC = np.array([[True] * 3, [True] * 3, [True, True, False]])


def ragged_system():
    xs = [inside_cell(n, RAGGED_CELLS[b], RAGGED_PBC[b], seed=40 + b)
          for b, n in enumerate(RAGGED_SIZES)]
    batch = np.repeat(np.arange(len(RAGGED_SIZES), dtype=np.int32), RAGGED_SIZES)
    return np.concatenate(xs).astype(np.float32), batch


def ragged_reference(x, batch):
    """The float64 oracle per system, in global indices: (inside, edge) sets of triples."""
    inside, edge = set(), set()
    offsets = np.concatenate([[0], np.cumsum(RAGGED_SIZES)])
    for b in range(len(RAGGED_SIZES)):
        part = x[offsets[b]:offsets[b + 1]]
        assert np.all(batch[offsets[b]:offsets[b + 1]] == b)
        if len(part) == 0:
            continue
        got = reference(part, part, CUTOFF, RAGGED_CELLS[b], tuple(RAGGED_PBC[b]))
        for ours, theirs in zip((inside, edge), got):
            ours |= {(i + offsets[b], j + offsets[b]) + tuple(S) for i, j, *S in theirs}
    return inside, edge


def test_ragged_batch_under_jit_matches_brute_force():
    x, batch = ragged_system()
    n_points = len(x)
    listed = jax.jit(lambda x, b, c, p, half: rjax.neighbor_list(
        x, CUTOFF, cell=c, pbc=p, batch=b, max_pairs=1500, half=half), static_argnums=4)
    i, j, S, count = (np.asarray(a) for a in listed(x, batch, RAGGED_CELLS, RAGGED_PBC, False))
    n = int(count)
    assert 0 < n < 1500 and i.shape == (1500,) and S.shape == (1500, 3)
    inside, edge = ragged_reference(x, batch)
    found = triples(i[:n], j[:n], S[:n])
    assert len(found) == n and found - edge == inside - edge
    assert np.all(np.diff(i[:n]) >= 0) and np.all(batch[i[:n]] == batch[j[:n]])
    assert any(a == b == n_points - 1 for a, b in zip(i[:n], j[:n]))  # the 1-particle images
    assert np.all(i[n:] == n_points) and np.all(j[n:] == n_points) and not S[n:].any()
    # Half: each pair once, every one of them in the full list.
    hi, hj, hS, hcount = (np.asarray(a) for a in listed(x, batch, RAGGED_CELLS, RAGGED_PBC, True))
    h = int(hcount)
    assert 2 * h == n and triples(hi[:h], hj[:h], hS[:h]) <= found
    # One short: count says the list was cut.
    assert int(rjax.neighbor_list(x, CUTOFF, cell=RAGGED_CELLS, pbc=RAGGED_PBC, batch=batch,
                                  max_pairs=n - 1)[3]) == n


def test_ragged_batch_with_a_shared_cell_needs_num_systems():
    x, batch = ragged_system()
    with pytest.raises(ValueError, match="num_systems"):
        rjax.neighbor_list(x, CUTOFF, cell=CELL, batch=batch, max_pairs=10)
    with pytest.raises(ValueError, match="num_systems=2 differs"):
        rjax.neighbor_list(x, CUTOFF, cell=RAGGED_CELLS, batch=batch, num_systems=2,
                           max_pairs=10)
    i, j, S, count = (np.asarray(a) for a in rjax.neighbor_list(
        x, CUTOFF, cell=CELL, batch=batch, num_systems=3, max_pairs=1500))
    n = int(count)
    expected = {(a, b) + tuple(s) for a, b, s in zip(*[np.asarray(v) for v in rjax.neighbor_list(
        x[:22], CUTOFF, cell=CELL, max_pairs=1500)[:3]]) if a < 22}
    single = rjax.neighbor_list(x[22:], CUTOFF, cell=CELL, max_pairs=1500)
    expected |= {(22, 22) + tuple(s) for s in np.asarray(single[2])[:int(single[3])]}
    assert triples(i[:n], j[:n], S[:n]) == expected
    # Open systems (no cell): the float64 brute force per system, no pair across systems.
    oi, oj, oS, ocount = (np.asarray(a) for a in rjax.neighbor_list(
        x, CUTOFF, batch=batch, num_systems=3, max_pairs=1500))
    m = int(ocount)
    inside, edge = reference(x[:22], x[:22], CUTOFF)  # the 1-particle system has no pair
    assert triples(oi[:m], oj[:m], oS[:m]) - edge == inside - edge and not oS.any()
    # No particles at all (B = 2): all padding, i = j = N = 0.
    ei, ej, _, ecount = rjax.neighbor_list(np.zeros((0, 3), np.float32), CUTOFF, cell=CELL,
                                           batch=np.zeros(0, np.int32), num_systems=2,
                                           max_pairs=4)
    assert int(ecount) == 0 and not np.asarray(ei).any() and not np.asarray(ej).any()


def test_ragged_batch_errors_from_the_handler():
    x, batch = ragged_system()
    call = jax.jit(lambda b: rjax.neighbor_list(x, CUTOFF, cell=RAGGED_CELLS, batch=b,
                                                max_pairs=100)[3])
    with pytest.raises(Exception, match="sorted"):
        call(batch[::-1].copy()).block_until_ready()
    with pytest.raises(Exception, match=r"batch\[22\] = 3 is not a system index in \[0, 3\)"):
        call(np.where(batch == 2, 3, batch).astype(np.int32)).block_until_ready()
    with pytest.raises(ValueError, match="batch must be"):
        rjax.neighbor_list(x, CUTOFF, cell=RAGGED_CELLS, batch=batch[:-1], max_pairs=10)


def ragged_energy(x, cells, batch):
    i, j, S, count = rjax.neighbor_list(x, CUTOFF, cell=cells, pbc=RAGGED_PBC, batch=batch,
                                        max_pairs=1500)
    d = jnp.linalg.norm(rjax.vectors(x, i, j, S, cells, batch=batch)
                        + (jnp.arange(len(i)) >= count)[:, None], axis=1)
    e = (CUTOFF - d) ** 3 * jnp.cos(3 * d)
    return jnp.sum(jnp.where(jnp.arange(len(i)) < count, e, 0.0))


def test_grad_through_a_ragged_batch():
    x, batch = ragged_system()
    x, cells = jnp.asarray(x), jnp.asarray(RAGGED_CELLS)
    gx, gc = jax.jit(jax.grad(ragged_energy, argnums=(0, 1)))(x, cells, batch)
    assert float(jnp.abs(gx).max()) > 0 and float(jnp.abs(gc[2]).max()) > 0
    assert not np.asarray(gc[1]).any()  # the empty system
    # The first system's part is the gradient of its own energy (the single-system path).
    one_x, one_cell = jax.grad(energy, argnums=(0, 1))(x[:22], cells[0])
    np.testing.assert_allclose(gx[:22], one_x, rtol=1e-4, atol=1e-4)
    np.testing.assert_allclose(gc[0], one_cell, rtol=1e-4, atol=1e-4)
    h = 1e-3
    rng = np.random.default_rng(1)
    for _ in range(3):
        u = jnp.asarray(rng.normal(size=x.shape), jnp.float32)
        v = jnp.asarray(rng.normal(size=cells.shape), jnp.float32)
        numeric = (ragged_energy(x + h * u, cells + h * v, batch)
                   - ragged_energy(x - h * u, cells - h * v, batch)) / (2 * h)
        analytic = jnp.sum(gx * u) + jnp.sum(gc * v)
        assert abs(float(numeric) - float(analytic)) <= 2e-2 * max(1.0, abs(float(analytic)))
