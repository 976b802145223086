"""examples/python/model_every_mode.py run small: a learned pair potential on raycut's periodic
neighbour list trained on Lennard-Jones energies and forces (the loss falls), then equal in
eager PyTorch, torch.compile(fullgraph=True, dynamic=True), an AOTInductor package of
torch.export (dynamic N) and JAX (jit, float64)."""
import importlib.util
from pathlib import Path

import pytest

torch = pytest.importorskip("torch", reason="PyTorch is not installed")
pytest.importorskip("jax", reason="JAX is not installed")
import pyraycut  # noqa: E402

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "python" / "model_every_mode.py"


def load_example():
    spec = importlib.util.spec_from_file_location("raycut_example_model_every_mode", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def example():
    if pyraycut._torch_ops() is None:
        pytest.skip("raycut's PyTorch operators are not built (the build's Python had no torch)")
    return load_example()


def test_every_mode_agrees(example, tmp_path):
    result = example.main(side=3, configurations=2, steps=20, sides=(2, 3),
                          package_path=str(tmp_path / "model.pt2"))
    losses = result["losses"]
    assert len(losses) == 20 and losses[-1] < 0.5 * losses[0], losses
    assert all(e == e and e != 0.0 for e in result["energies"])  # finite, not a zero model
    scale = max(1.0, max(abs(e) for e in result["energies"]))
    assert result["compiled_energy_error"] <= 1e-9 * scale
    assert result["compiled_force_error"] <= 1e-9
    assert result["aoti_energy_error"] <= 1e-9 * scale
    assert result["jax_energy_error"] <= 1e-9 * scale
    assert (tmp_path / "model.pt2").stat().st_size > 0
    assert result["ok"]


def test_the_model_is_periodic_and_its_forces_are_the_gradient(example):
    """Forces by autograd against central differences of the energy; the energy unchanged when
    an atom is moved by a lattice vector (the list sees the same images)."""
    model = example.PairPotential(seed=3)
    x, cell = example.lattice(2, 5)
    energy, forces = example.energy_and_forces(model, x, cell)
    h = 1e-5
    for atom, axis in ((0, 0), (3, 2), (7, 1)):
        step = torch.zeros_like(x)
        step[atom, axis] = h
        with torch.no_grad():
            slope = (model(x + step, cell) - model(x - step, cell)) / (2 * h)
        assert abs(float(forces[atom, axis] + slope)) <= 1e-6 * max(1.0, abs(float(slope)))
    moved = x.clone()
    moved[4] += cell[1] - cell[2]
    with torch.no_grad():
        assert abs(float(model(moved, cell) - energy)) <= 1e-10 * max(1.0, abs(float(energy)))
