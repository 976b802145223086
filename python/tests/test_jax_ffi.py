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
