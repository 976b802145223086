"""The engines neighbor_list and radius keep between calls (one per method and CUDA device): later
calls never change earlier outputs, a failed call leaves no engine behind, threads get engines of
their own, and the cache can be cleared and turned off."""
import threading

import numpy as np
import pytest
from conftest import CUTOFF, SYSTEM_METHODS, assert_same_pairs, uniform

import pyraycut


@pytest.fixture(autouse=True)
def fresh_cache():
    pyraycut.set_engine_cache(True)
    yield
    pyraycut.set_engine_cache(True)


def cached():
    return dict(pyraycut._ENGINES)


def rows(out):
    """The pairs (i, j[, S]) as sorted tuples."""
    columns = [np.asarray(a).reshape(len(out[0]), -1) for a in out]
    return sorted(tuple(r) for r in np.concatenate(columns, axis=1).tolist())


def test_outputs_survive_later_calls(method):
    x, y = uniform(500, seed=1), uniform(700, seed=2)
    i, j, d = pyraycut.neighbor_list("ijd", x, CUTOFF, method=method)
    kept = [a.copy() for a in (i, j, d)]
    assert list(cached()) == [(method, pyraycut._raycut.current_device())]
    engine = cached()[(method, pyraycut._raycut.current_device())]
    i2, j2 = pyraycut.neighbor_list("ij", y, CUTOFF, method=method)
    assert cached()[(method, pyraycut._raycut.current_device())] is engine  # reused
    for a, b in zip((i, j, d), kept):
        np.testing.assert_array_equal(a, b)
    assert_same_pairs(i, j, x, CUTOFF)
    assert_same_pairs(i2, j2, y, CUTOFF)
    if method not in SYSTEM_METHODS:  # grid-paper, optix-*: no query points (docs/methods.md)
        return
    # radius shares it: a query build after a plain one, and a plain one after that.
    qi, qj = pyraycut.radius(x, y[:50], CUTOFF, method=method)
    assert len(qi) > 0 and np.all(np.diff(qi) >= 0)
    i3, j3 = pyraycut.neighbor_list("ij", x, CUTOFF, method=method)
    assert_same_pairs(i3, j3, x, CUTOFF)


def test_periodic_then_open_then_batch_on_one_engine(system_method):
    x = uniform(300, seed=3)
    cell = np.eye(3)
    a = pyraycut.neighbor_list("ijS", x, 0.3, cell=cell, pbc=True, method=system_method)
    b = pyraycut.neighbor_list("ij", x, 0.3, method=system_method)
    batch = np.repeat([0, 1, 2], 100)
    c = pyraycut.neighbor_list("ij", x, 0.3, batch=batch, method=system_method)
    assert len(cached()) == 1
    pyraycut.set_engine_cache(False)
    a0 = pyraycut.neighbor_list("ijS", x, 0.3, cell=cell, pbc=True, method=system_method)
    b0 = pyraycut.neighbor_list("ij", x, 0.3, method=system_method)
    c0 = pyraycut.neighbor_list("ij", x, 0.3, batch=batch, method=system_method)
    assert not cached()
    for got, want in ((a, a0), (b, b0), (c, c0)):
        assert rows(got) == rows(want)
    assert len(a[0]) > len(b[0]) > len(c[0])  # images add pairs; the batch removes some


def test_a_failed_call_leaves_no_engine():
    x = uniform(100)
    pyraycut.neighbor_list("ij", x, CUTOFF, method="cell-list")
    assert len(cached()) == 1
    bad = x.copy()
    bad[3, 0] = np.nan
    with pytest.raises(ValueError, match="3"):
        pyraycut.neighbor_list("ij", bad, CUTOFF, method="cell-list")
    assert not cached()  # taken out for the call, dropped when it raised
    i, j = pyraycut.neighbor_list("ij", x, CUTOFF, method="cell-list")
    assert_same_pairs(i, j, x, CUTOFF)
    assert len(cached()) == 1


def test_clear_and_turn_off():
    x = uniform(100)
    pyraycut.neighbor_list("ij", x, CUTOFF, method="cell-list")
    pyraycut.neighbor_list("ij", x, CUTOFF, method="brute-force")
    assert {k[0] for k in cached()} == {"cell-list", "brute-force"}
    pyraycut.clear_engine_cache()
    assert not cached()
    pyraycut.set_engine_cache(False)
    pyraycut.neighbor_list("ij", x, CUTOFF, method="cell-list")
    pyraycut.radius(x, x[:10], CUTOFF, method="cell-list")
    assert not cached()


def test_threads_get_engines_of_their_own():
    inputs = [uniform(400 + 50 * k, seed=10 + k) for k in range(4)]
    want = [pyraycut.neighbor_list("ij", x, CUTOFF, method="cell-list") for x in inputs]
    errors, results = [], {}

    def work(k):
        try:
            for _ in range(5):
                results[k] = pyraycut.neighbor_list("ij", inputs[k], CUTOFF, method="cell-list")
                got = results[k]
                assert len(got[0]) == len(want[k][0])
        except Exception as e:  # noqa: BLE001  reported below
            errors.append(e)

    threads = [threading.Thread(target=work, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors, errors
    for k, x in enumerate(inputs):
        assert_same_pairs(*results[k], x, CUTOFF)
    assert len(cached()) == 1  # one idle engine per key is kept; the others were freed


def test_dropped_host_lists_are_refilled_and_held_ones_never():
    """A list whose arrays are all gone lends its memory to a later list (no fresh pages); one
    still held is never written, whatever the later calls ask (other sizes and letters)."""
    x, y = uniform(500, seed=4), uniform(800, seed=5)
    pyraycut.clear_engine_cache()  # no buffer kept from earlier tests
    i, j = pyraycut.neighbor_list("ij", x, CUTOFF, method="cell-list")
    where, pairs = i.__array_interface__["data"][0], len(i)
    del i, j
    # Memory of the same size asked for meanwhile: malloc would hand it the freed block.
    other = np.ones(pairs, np.int64)
    held = pyraycut.neighbor_list("ijd", x, CUTOFF, method="cell-list")
    assert held[0].__array_interface__["data"][0] == where  # the dropped list's memory
    kept = [a.copy() for a in held]
    for k in range(4):  # more pairs, fewer pairs, other letters: held stays as it was
        z = y if k % 2 else x[:300]
        out = pyraycut.neighbor_list("ijdD" if k % 2 else "ij", z, CUTOFF, method="cell-list")
        assert_same_pairs(out[0], out[1], z, CUTOFF)
        for a, b in zip(held, kept):
            np.testing.assert_array_equal(a, b)
    pyraycut.clear_engine_cache()
    del held, out, other
    i, j = pyraycut.neighbor_list("ij", x, CUTOFF, method="cell-list")
    assert_same_pairs(i, j, x, CUTOFF)
