"""The Python examples (examples/python), each run small: their own checks must pass."""
import importlib.util
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "python"


def load(name):
    return load_path(EXAMPLES / f"{name}.py")


def load_path(path):
    spec = importlib.util.spec_from_file_location(f"raycut_example_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_point_cloud_radius():
    result = load("point_cloud_radius").main(size=3000, subset=100)
    assert result["ok"], result
    assert result["pairs"] > 0 and result["checked"] == 100


def test_sph_from_python():
    result = load("sph_from_python").main(size=1000)
    assert result["ok"], result
    assert result["max_relative_error"] < 1e-4


def test_lj_md_torch():
    pytest.importorskip("torch", reason="PyTorch is not installed (the example skips without it)")
    result = load("lj_md_torch").main(size=64, steps=50)
    assert not result["skipped"] and result["ok"], result
    assert result["builds"] >= 6  # 51 force evaluations, rebuilt every 10 at least


def test_lj_md_torch_skips_cleanly_without_torch(monkeypatch, capsys):
    module = load("lj_md_torch")
    monkeypatch.setattr(module, "torch", None)
    assert module.main(size=8) == {"skipped": True, "ok": True}
    assert "PyTorch is not installed" in capsys.readouterr().out


def load_bench(name):
    """bench/<name>.py as a module (the benches are scripts, not part of the package)."""
    spec = importlib.util.spec_from_file_location(f"raycut_bench_{name}",
                                                  EXAMPLES.parents[1] / "bench" / f"{name}.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    return bench


def test_python_overhead_bench_runs(tmp_path):
    bench = load_bench("python_overhead")
    out = tmp_path / "overhead.csv"
    rows = bench.main(["--n", "200", "--calls", "5", "--warmup", "2", "--method", "cell-list",
                       "--out", str(out)])
    assert {r["api"] for r in rows} == {"count", "build+count", "neighbor_list"}
    assert out.read_text().startswith("input,method,")
    assert all(r["pairs"] > 0 and r["api_us_median"] > 0 for r in rows)


def test_python_lists_bench_runs_tiny(tmp_path):
    bench = load_bench("python_lists")
    out = tmp_path / "lists.csv"
    # NumPy input with a CPU method: the bench's bound-engine variants read host arrays.
    rows = bench.main(["--tiny", "--numpy", "--method", "cell-list", "--reps", "2", "--warmup", "1",
                       "--out", str(out)])
    variants = {"cpp_list", "cpp_pairs", "python", "python_csr", "python_nocache"}
    by = {}
    for r in rows:
        by.setdefault(r["workload"], {})[r["variant"]] = r
    assert set(by) == {"lj-pbc-full", "lj-pbc-half", "batch-pbc", "uniform-open"}
    for workload, v in by.items():
        assert set(v) == variants, workload
        assert all(r["check"] == "ok" and r["ms"] > 0 and r["reps"] == 2 for r in v.values())
        assert all(r["engine_build_ms"] > 0 for k, r in v.items() if k.startswith("cpp"))
    # ~55 neighbours each in the liquid (4 pi rc^3 / 3 x density), half of them in the half list
    full, half = by["lj-pbc-full"]["python"], by["lj-pbc-half"]["python"]
    assert 45 < full["pairs"] / full["n"] < 65
    assert half["pairs"] * 2 == full["pairs"]
    assert by["batch-pbc"]["python"]["systems"] == 8
    assert out.read_text().startswith("workload,input,method,")
    table = (tmp_path / "lists.md").read_text()
    assert "| lj-pbc-full | numpy |" in table and "Python / C++ list" in table
    # neighbour_bench's figures of the same workload, operation and method, matched by key.
    native = tmp_path / "native.csv"
    native.write_text("suite,param,p,method,N,cutoff,operation,mode,ms,min,max\n"
                      "lj-liquid-pbc,1,4096,cell-list,4096,2.5,list_full_s,prepared,1.5,1,2\n"
                      "lj-liquid-pbc,1,4096,cell-list,4096,2.5,list_half_s,prepared,9.0,9,9\n")
    rows = bench.main(["--tiny", "--numpy", "--reps", "1", "--warmup", "0", "--method",
                       "cell-list", "--workload", "lj-pbc-full", "--native", str(native),
                       "--out", str(tmp_path / "native-lists.csv")])
    assert {r["native_prepared_ms"] for r in rows} == {1.5}
    assert all(r["native_cold_ms"] != r["native_cold_ms"] for r in rows)  # NaN: no cold row
    assert "native prepared ms" in (tmp_path / "native-lists.md").read_text()


def test_torch_aoti_runner_without_python(tmp_path):
    """examples/torch_aoti: the model packaged by AOTInductor, run by a C++ program linked
    against libtorch (built here with CMake), checked there against the operator itself."""
    import shutil
    import subprocess
    import sys

    torch = pytest.importorskip("torch", reason="PyTorch is not installed")
    import pyraycut

    if pyraycut._torch_ops() is None:
        pytest.skip("raycut's PyTorch operators are not built (the build's Python had no torch)")
    if shutil.which("cmake") is None or shutil.which("c++") is None:
        pytest.skip("cmake or a C++ compiler is missing")
    example = EXAMPLES.parent / "torch_aoti"
    model = load_path(example / "model.py")
    package = model.package(str(tmp_path / "energy.pt2"))
    build = tmp_path / "build"
    for command in (["cmake", "-S", str(example), "-B", str(build),
                     f"-DPython_EXECUTABLE={sys.executable}", "-DCMAKE_BUILD_TYPE=Release"],
                    ["cmake", "--build", str(build), "-j2"]):
        subprocess.run(command, check=True, capture_output=True)
    for side in ("5", "7"):  # two N through one package
        out = subprocess.run([str(build / "torch_aoti_runner"), package, pyraycut.load_torch_ops(),
                              side], capture_output=True, text=True)
        assert out.returncode == 0, out.stdout + out.stderr
        words = out.stdout.split()
        assert words[-1] == "ok" and int(words[1]) == int(side) ** 3 and int(words[3]) > 0
        # The same energy in eager PyTorch is what the runner's own check compares against: here
        # the packaged value must also be finite and negative (a bound liquid-like lattice).
        assert float(words[5]) < 0 and torch.isfinite(torch.tensor(float(words[5])))
    # Any (x, cell) -> energy package runs there: the learned potential of model_every_mode.py,
    # checked against the energy its eager model gives on the runner's own lattice.
    every_mode = load("model_every_mode")
    learned = every_mode.PairPotential()
    learned_package = every_mode.package(learned, str(tmp_path / "learned.pt2"))
    for side in (3, 5):
        expected = every_mode.expected_energy(learned, side)
        out = subprocess.run([str(build / "torch_aoti_runner"), learned_package,
                              pyraycut.load_torch_ops(), str(side), repr(expected)],
                             capture_output=True, text=True)
        assert out.returncode == 0, out.stdout + out.stderr
        words = out.stdout.split()
        assert words[-1] == "ok" and words[6] == "expected" and int(words[1]) == side**3
        assert abs(float(words[5]) - expected) <= 1e-9 * max(1.0, abs(expected))
    bad = subprocess.run([str(build / "torch_aoti_runner"), learned_package,
                          pyraycut.load_torch_ops(), "3", "nan"], capture_output=True, text=True)
    assert bad.returncode == 2 and "expected energy must be a finite number, got nan" in bad.stderr


LATENCY_HEADER = ("workload,systems,n_per_system,interface,mode,capacity,us_per_call,kernels,"
                  "syncs,gpu,driver,cuda\n")


def test_plot_latency_reads_groups_and_plots(tmp_path):
    """bench/plot_latency.py on hand-written rows of both benches: one line per (interface,
    mode, capacity), single systems and batches apart, the machine in the title, a PNG."""
    plot = load_bench("plot_latency")
    cpp = tmp_path / "cpp.csv"
    cpp.write_text(LATENCY_HEADER +
                   "lj-pbc,1,1000,cpp,eager,static,40.5,3,0,NVIDIA H200,580.1,13.0\n"
                   "lj-pbc,1,128,cpp,eager,static,20.0,3,0,NVIDIA H200,580.1,13.0\n"
                   "lj-pbc,1,128,cpp,graph,static,8.25,3,0,NVIDIA H200,580.1,13.0\n"
                   "lj-pbc,32,100,cpp,eager,exact,900,,,NVIDIA H200,580.1,13.0\n")
    python = tmp_path / "python.csv"
    python.write_text(LATENCY_HEADER +
                      "lj-pbc,1,128,python-torch,eager,exact,350.0,12,4,NVIDIA H200,580.1,12.8\n")
    rows = plot.read_rows([str(cpp), str(python)])
    assert [r["particles"] for r in rows] == [1000, 128, 128, 3200, 128]
    lines = plot.series(rows)
    assert set(lines) == {("cpp", "eager", "static"), ("cpp", "graph", "static"),
                          ("cpp", "eager", "exact"), ("python-torch", "eager", "exact")}
    assert lines[("cpp", "eager", "static")]["single"] == [(128, 20.0), (1000, 40.5)]
    assert lines[("cpp", "eager", "exact")] == {"single": [], "batch": [(3200, 900.0)]}
    title = plot.title(rows)
    assert "NVIDIA H200, driver 580.1, CUDA 13.0" in title and "CUDA 12.8" in title
    pytest.importorskip("matplotlib", reason="matplotlib is not installed (the plot needs it)")
    png = tmp_path / "latency.png"
    plot.main([str(cpp), str(python), "--png", str(png)])
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_plot_latency_labels_each_csvs_lines(tmp_path):
    """--labels: the same calls from two CSVs become two lines, named by their labels; a label
    count that differs from the CSVs' is refused."""
    plot = load_bench("plot_latency")
    planned, reused = tmp_path / "planned.csv", tmp_path / "reused.csv"
    planned.write_text(LATENCY_HEADER + "lj-pbc,1,10000,python-torch,eager,static,175.4,20,5,"
                       "NVIDIA H100,580.1,13.0\n")
    reused.write_text(LATENCY_HEADER + "lj-pbc,1,10000,python-torch,eager,static,135.8,22,1,"
                      "NVIDIA H100,580.1,13.0\n")
    lines = plot.series(plot.read_rows([str(planned), str(reused)], ["planned", "reused"]))
    assert lines[("python-torch", "eager", "static", "planned")]["single"] == [(10000, 175.4)]
    assert lines[("python-torch", "eager", "static", "reused")]["single"] == [(10000, 135.8)]
    with pytest.raises(SystemExit, match="1 labels for 2 CSVs"):
        plot.main([str(planned), str(reused), "--png", str(tmp_path / "x.png"), "--labels", "a"])


def test_plot_latency_refuses_bad_csv(tmp_path):
    plot = load_bench("plot_latency")
    wrong = tmp_path / "wrong.csv"
    wrong.write_text("workload,systems\nlj-pbc,1\n")
    with pytest.raises(ValueError, match="wrong.csv: missing columns n_per_system"):
        plot.read_rows([str(wrong)])
    bad = tmp_path / "bad.csv"
    bad.write_text(LATENCY_HEADER + "lj-pbc,1,128,cpp,eager,static,fast,3,0,g,d,c\n")
    with pytest.raises(ValueError, match="bad.csv, line 2"):
        plot.read_rows([str(bad)])


def test_python_latency_counts_kernels_and_syncs():
    """What the profiler's events count as: kernels on the device (not copies or memsets),
    synchronisations (the runtime's waits and copies into pageable host memory, not copies
    into pinned memory, which do not block)."""
    bench = load_bench("python_latency")
    events = [("grid_count_kernel", True), ("Memcpy DtoH (Device -> Pageable)", True),
              ("Memcpy DtoH (Device -> Pinned)", True),
              ("Memcpy HtoD (Pageable -> Device)", True), ("Memset (Device)", True),
              ("void cub::DeviceScanKernel<...>", True), ("cudaStreamSynchronize", False),
              ("cudaDeviceSynchronize", False), ("cudaEventSynchronize", False),
              ("cudaLaunchKernel", False), ("cudaMemcpyAsync", False), ("aten::empty", False)]
    assert bench.count_profile(events) == (2, 4)
    assert bench.count_profile([]) == (0, 0)


def test_python_latency_runs_tiny_on_the_cpu(tmp_path, capsys):
    """bench/python_latency.py with PyTorch CPU tensors: the three eager capacities of each
    workload and its Verlet update (no CUDA graph row on the CPU), the CSV's columns, and a second
    run appending to the same file."""
    pytest.importorskip("torch", reason="PyTorch is not installed")
    import pyraycut

    if pyraycut._torch_ops() is None:
        pytest.skip("raycut's PyTorch operators are not built (the build's Python had no torch)")
    bench = load_bench("python_latency")
    out = tmp_path / "latency.csv"
    args = ["--device", "cpu", "--sizes", "64", "--batches", "3x40", "--reps", "2",
            "--min-loop-ms", "0.05", "--output", str(out)]
    rows = bench.main(args)
    per_workload = [("python-torch", "static"), ("python-torch", "static-checked"),
                    ("python-torch", "exact"), ("python-torch-verlet-update", "exact")]
    assert [(r["systems"], r["n_per_system"], r["interface"], r["capacity"]) for r in rows] == [
        (s, n, interface, capacity) for s, n in ((1, 64), (3, 40))
        for interface, capacity in per_workload]
    assert all(r["mode"] == "eager" for r in rows)
    assert all(float(r["us_per_call"]) > 0 for r in rows)
    text = out.read_text()
    assert text.startswith(LATENCY_HEADER) and text.count("\n") == 9
    bench.main(args[:5] + ["none"] + args[6:])  # appended: 4 rows, no second header
    text = out.read_text()
    assert text.count("\n") == 13 and text.count("workload,") == 1
    other = tmp_path / "other.csv"
    other.write_text("a,b\n1,2\n")
    with pytest.raises(SystemExit, match="holds other columns"):
        bench.main(args[:-1] + [str(other)])
    assert "wrote 8 rows" in capsys.readouterr().out


def test_python_compiled_runs_tiny_on_the_cpu(tmp_path):
    """bench/python_compiled.py with PyTorch CPU tensors: the operator's row and the LJ step
    eager and compiled (checked against eager inside the script), in the latency CSV's columns."""
    pytest.importorskip("torch", reason="PyTorch is not installed")
    import pyraycut

    if pyraycut._torch_ops() is None:
        pytest.skip("raycut's PyTorch operators are not built (the build's Python had no torch)")
    bench = load_bench("python_compiled")
    out = tmp_path / "compiled.csv"
    rows = bench.main(["--device", "cpu", "--sizes", "40", "--reps", "1", "--min-loop-ms",
                       "0.05", "--output", str(out)])
    assert [(r["interface"], r["mode"]) for r in rows] == [
        ("python-torch-op", "eager"), ("python-torch-step", "eager"),
        ("python-torch-step", "compiled")]
    assert all(r["capacity"] == "static" and float(r["us_per_call"]) > 0 for r in rows)
    assert out.read_text().startswith(LATENCY_HEADER)
