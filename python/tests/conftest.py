"""Shared fixtures: the repository root and the independent NumPy/SciPy plant reference."""
import importlib.util
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def root():
    return ROOT


@pytest.fixture(scope="session")
def reference():
    """host-sim/reference/plant_scipy.py: the plant written from docs/plant-model.md
    independently of the Rust code."""
    path = ROOT / "host-sim" / "reference" / "plant_scipy.py"
    spec = importlib.util.spec_from_file_location("plant_scipy", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
