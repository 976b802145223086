"""`raycut neighbours` (the command-line tool) against pyraycut.neighbor_list: its .npz, read by
NumPy, and its .csv hold the same pairs, dtypes and values. The tool is found through
$RAYCUT_CLI, next to the build's Python package (build/apps/raycut), or on PATH."""
import os
import pathlib
import shutil
import subprocess

import numpy as np
import pytest

import pyraycut


def find_cli():
    candidates = [os.environ.get("RAYCUT_CLI"),
                  pathlib.Path(pyraycut.__file__).resolve().parents[2] / "apps" / "raycut",
                  shutil.which("raycut")]
    for c in candidates:
        if c and pathlib.Path(c).is_file() and os.access(c, os.X_OK):
            return str(c)
    pytest.skip("the raycut command-line tool is not built here (set RAYCUT_CLI)")


def write_xyz(path, x, cell=None, pbc="T T T"):
    lattice = "" if cell is None else 'Lattice="' + " ".join(repr(float(v)) for v in
                                                             np.ravel(cell)) + f'" pbc="{pbc}" '
    lines = [str(len(x)), lattice + "Properties=species:S:1:pos:R:3"]
    lines += [f"Ar {a!r} {b!r} {c!r}" for a, b, c in x.astype(np.float32).tolist()]
    path.write_text("\n".join(lines) + "\n")


def run(*args):
    out = subprocess.run([find_cli(), *map(str, args)], capture_output=True, text=True)
    return out.returncode, out.stdout, out.stderr


def rows(i, j, S):
    r = np.column_stack([i, j, S]).astype(np.int64)
    return np.lexsort(r.T[::-1])


@pytest.mark.parametrize("half", [False, True])
@pytest.mark.parametrize("periodic", [False, True])
def test_npz_equals_neighbor_list(tmp_path, half, periodic):
    rng = np.random.default_rng(3)
    x = (rng.random((300, 3)) * 6.0).astype(np.float32)
    cell = np.array([[6.0, 0, 0], [0.5, 6.0, 0], [0.3, -0.4, 6.0]]) if periodic else None
    write_xyz(tmp_path / "in.xyz", x, cell, pbc="T T F")
    args = ["neighbours", "-m", "cell-list", "-i", tmp_path / "in.xyz", "-c", 1.7,
            "-o", tmp_path / "pairs.npz", "-q"] + (["--half"] if half else [])
    code, out, err = run(*args)
    assert code == 0, err
    assert err == ""  # -q: no progress line
    got = np.load(tmp_path / "pairs.npz")
    assert sorted(got.files) == ["D", "S", "d", "i", "j"]
    kw = dict(cell=cell, pbc=[True, True, False]) if periodic else {}
    want = pyraycut.neighbor_list("ijdDS", x, 1.7, half=half, method="cell-list", **kw)
    assert len(want[0]) > 300
    for letter, w in zip("ijdDS", want):
        assert got[letter].dtype == w.dtype and got[letter].shape == w.shape, letter
    a, b = rows(got["i"], got["j"], got["S"]), rows(want[0], want[1], want[4])
    for letter, w in zip("ijdDS", want):
        np.testing.assert_array_equal(got[letter][a], w[b], err_msg=letter)
    assert f"{len(want[0])} pairs" in out


def test_csv_and_letters(tmp_path):
    rng = np.random.default_rng(4)
    x = (rng.random((100, 3)) * 4.0).astype(np.float32)
    write_xyz(tmp_path / "in.xyz", x)
    code, _, err = run("neighbours", "-i", tmp_path / "in.xyz", "-c", 1.2, "-o",
                       tmp_path / "pairs.csv", "--quantities", "jid", "-m", "cell-list")
    assert code == 0, err
    text = (tmp_path / "pairs.csv").read_text().splitlines()
    assert text[0] == "j,i,d"
    table = np.loadtxt(tmp_path / "pairs.csv", delimiter=",", skiprows=1, ndmin=2)
    j, i, d = pyraycut.neighbor_list("jid", x, 1.2, method="cell-list")
    assert len(table) == len(i) > 0
    order = np.lexsort((table[:, 0], table[:, 1]))
    want = np.lexsort((j, i))
    np.testing.assert_array_equal(table[order, 1], i[want])
    np.testing.assert_array_equal(table[order, 0], j[want])
    np.testing.assert_array_equal(table[order, 2].astype(np.float32), d[want])  # 9 digits
    # Bad letters and extensions: exit 2, one line naming them; nothing written.
    for output, letters, named in ((tmp_path / "bad.npz", "ijx", "ijx"),
                                   (tmp_path / "bad.npz", "ii", "'ii'"),
                                   (tmp_path / "p.txt", "ij", "p.txt")):
        code, _, err = run("neighbours", "-i", tmp_path / "in.xyz", "-c", 1.0, "-o", output,
                           "--quantities", letters)
        assert code == 2 and len(err.strip().splitlines()) == 1 and named in err, err
    assert not (tmp_path / "bad.npz").exists() and not (tmp_path / "p.txt").exists()


def test_version():
    code, out, _ = run("--version")
    assert code == 0 and out.strip() == f"raycut {pyraycut.__version__}"


def test_progress_lines_carry_an_eta_and_quiet_silences_them(tmp_path):
    """check, neighbours and bench print progress with an ETA on stderr (every step here:
    RAYCUT_PROGRESS_SECONDS=0; by default only past 3 s), never on stdout, and nothing with -q; a
    malformed RAYCUT_PROGRESS_SECONDS is refused by name."""
    cli = find_cli()
    xyz = tmp_path / "in.xyz"
    write_xyz(xyz, np.random.default_rng(5).random((300, 3)) * 4.0, cell=np.eye(3) * 4.0)
    commands = {
        "check": ["check", "-m", "cell-list", "-f", "uniform", "lattice-k1", "-n", "200", "-c",
                  "0.1"],
        "neighbours": ["neighbours", "-i", xyz, "-c", "1.0", "-o", tmp_path / "pairs.npz"],
        "bench": ["bench", "-s", "uniform", "--param", "4", "-m", "cell-list", "--reps", "1", "-o",
                  tmp_path / "bench.csv"],
    }
    env = dict(os.environ, RAYCUT_PROGRESS_SECONDS="0")
    for name, args in commands.items():
        done = subprocess.run([cli, *map(str, args)], capture_output=True, text=True, env=env)
        assert done.returncode == 0, (name, done.stderr)
        assert "ETA" in done.stderr and "ETA" not in done.stdout, (name, done.stderr)
        quiet = subprocess.run([cli, *map(str, args), "-q"], capture_output=True, text=True,
                               env=env)
        assert quiet.returncode == 0 and "ETA" not in quiet.stderr, (name, quiet.stderr)
    bad = subprocess.run([cli, *map(str, commands["check"])], capture_output=True, text=True,
                         env=dict(os.environ, RAYCUT_PROGRESS_SECONDS="soon"))
    assert bad.returncode == 2 and "RAYCUT_PROGRESS_SECONDS=soon" in bad.stderr
