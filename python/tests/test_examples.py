"""The Python examples (examples/python), each run small: their own checks must pass."""
import importlib.util
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "python"


def load(name):
    spec = importlib.util.spec_from_file_location(f"raycut_example_{name}", EXAMPLES / f"{name}.py")
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


def test_python_overhead_bench_runs(tmp_path):
    spec = importlib.util.spec_from_file_location(
        "raycut_bench_python_overhead", EXAMPLES.parents[1] / "bench" / "python_overhead.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    out = tmp_path / "overhead.csv"
    rows = bench.main(["--n", "200", "--calls", "5", "--warmup", "2", "--method", "cell-list",
                       "--out", str(out)])
    assert {r["api"] for r in rows} == {"count", "build+count", "neighbor_list"}
    assert out.read_text().startswith("input,method,")
    assert all(r["pairs"] > 0 and r["api_us_median"] > 0 for r in rows)
