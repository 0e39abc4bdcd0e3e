"""Shared fixtures. Integration tests need the native extension; they skip (only) when
``hilcontact._core`` cannot be imported, e.g. in a pure-Python checkout."""

from __future__ import annotations

import importlib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import hilcontact as hc
from hilcontact.run import REFERENCE_COLUMNS, TIMESERIES_COLUMNS


def _core_import_error() -> str | None:
    try:
        importlib.import_module("hilcontact._core")
    except ImportError as exc:
        return str(exc)
    return None


@pytest.fixture(scope="session")
def core():
    """The native module; skips the test if it is not built."""
    error = _core_import_error()
    if error is not None:
        pytest.skip(f"hilcontact._core is not importable: {error}")
    return importlib.import_module("hilcontact._core")


@pytest.fixture(scope="session")
def paper_run(core) -> hc.Run:
    """paper-table1 simulated once per session (through the real core)."""
    return hc.simulate(hc.load_scenario("paper-table1"))


def synthetic_run(estimates: bool = False, lateral: float = 0.0, spin: float = 0.0) -> hc.Run:
    """A Run with made-up data (no core): for save/plot/table tests only, no physics.
    ``lateral``: the HIL tip's y velocity, a share of its x velocity; ``spin``: a relative
    angular velocity about z (rad/s) in both the HIL and the reference (a 6-DOF run)."""
    scenario = hc.load_scenario("paper-table1")
    t = np.arange(0, 1001) * 1e-3
    v = 0.02 * np.cos(2 * np.pi * t)
    ts = {name: np.zeros_like(t) for name in TIMESERIES_COLUMNS}
    ts["time"] = t
    ts["tip_velocity_x"] = v
    ts["tip_velocity_y"] = lateral * v
    ts["contact_force_x"] = np.maximum(0.0, 100.0 * np.sin(4 * np.pi * t))
    ts["energy"] = 0.5 * 279.07 * v**2
    if estimates:
        ts["stiffness_estimate"] = np.full_like(t, 170000.0)
        ts["damping_estimate"] = np.full_like(t, 1.0)
    ref = {name: np.zeros_like(t) for name in REFERENCE_COLUMNS}
    ref["time"] = t
    ref["tip_velocity_x"] = 0.9 * v
    ref["energy"] = 0.5 * 279.07 * (0.9 * v) ** 2
    ts["angular_velocity_z"] = np.full_like(t, spin)
    ref["angular_velocity_z"] = np.full_like(t, spin)
    metrics = {
        "scenario": scenario.name,
        "compensator": "none",
        "status": "ok",
        "diverged_at": None,
        "reason": None,
        "collisions": [
            {"index": 1, "start": 0.1, "end": 0.2, "peak_force": 120.0, "complete": True, "rebound_speed": 0.025,
             "reference": 1, "cov": 1.25, "cof": 1.2, "velocity_error": 0.25},
            {"index": 2, "start": 0.6, "end": 0.7, "peak_force": 150.0, "complete": True, "rebound_speed": 0.03,
             "reference": None, "cov": None, "cof": None},
        ],
        "reference_collisions": [
            {"index": 1, "start": 0.1, "end": 0.2, "peak_force": 100.0, "rebound_speed": 0.02},
        ],
        "summary": {"collisions": 2, "mean_cov": 1.25, "worst_cov": 1.25, "mean_cof": 1.2, "worst_cof": 1.2},
        "identification": None,
        "energy": {"initial": 0.0558, "final": 0.06, "reference_final": 0.0558, "max": 0.07},
    }
    return hc.Run(scenario=scenario, metrics=metrics, timeseries=pd.DataFrame(ts), reference=pd.DataFrame(ref))


@pytest.fixture
def fake_run() -> hc.Run:
    return synthetic_run()


@pytest.fixture
def scenario_file(tmp_path: Path):
    """Write TOML text to a file and return its path."""

    def write(text: str, name: str = "scenario.toml") -> Path:
        path = tmp_path / name
        path.write_text(text, encoding="utf-8")
        return path

    return write
