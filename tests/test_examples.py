"""The scripts in examples/ run as a user would run them (small settings to stay fast)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def run_example(name: str, *args: str) -> subprocess.CompletedProcess[str]:
    result = subprocess.run([sys.executable, str(EXAMPLES / name), *args], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr + result.stdout
    return result


def test_every_example_is_tested():
    tested = {"compare_your_scenario.py", "sweep_stability_map.py", "identify_a_recording.py"}
    assert {p.name for p in EXAMPLES.glob("*.py")} == tested


def test_compare_your_scenario(core, tmp_path):
    out = tmp_path / "cmp"
    result = run_example("compare_your_scenario.py", str(out), "--duration", "2")
    for kind in ("none", "pic", "pida", "tdpa-impedance"):
        assert kind in result.stdout and (out / kind / "metrics.json").is_file()
    assert (out / "comparison.csv").is_file() and (out / "compare_cov_cof.png").is_file()
    assert "faithful and closest to the ideal rebound:" in result.stdout


def test_sweep_stability_map(core, tmp_path):
    out = tmp_path / "sweep"
    result = run_example("sweep_stability_map.py", str(out), "--points", "2")
    rows = pd.read_parquet(out / "results.parquet")
    assert len(rows) == 2 * 2 * 2  # delays × stiffnesses × compensators
    assert (out / "stability" / "stability_map.png").is_file()
    assert "largest faithful robot delay" in result.stdout


def test_identify_a_recording(core, tmp_path):
    result = run_example("identify_a_recording.py", str(tmp_path / "id"))
    lines = [line for line in result.stdout.splitlines() if line.startswith("collision ")]
    assert len(lines) >= 2, result.stdout
    for line in lines:  # the truth is known: within 1 % on k, 0.5° and 0.5 mm on the wall
        k, true_k = (float(v) for v in (line.split("k = ")[1].split(" ")[0], line.split("(true ")[1].split(")")[0]))
        assert abs(k / true_k - 1) < 0.01, line
        assert float(line.split("normal off by ")[1].split("°")[0]) < 0.5, line
        assert abs(float(line.split("plane off by ")[1].split(" mm")[0])) < 0.5, line
