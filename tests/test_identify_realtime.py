"""Identification of a real-time run across processes on loopback (`hilcontact facility` and
`hilcontact hil`, 20 ms robot delay, pida, no noise): the summary prints it, and `identify` of
the run pairs each sensor record with the kinematics that produced it, so that its k̂ lies
within its stated uncertainty of the truth however many ticks had no new record."""

from __future__ import annotations

import json

import pandas as pd

from test_cli import invoke
from test_realtime_e2e import ROBOT_DELAY, facility_process, run_hil

K_TRUE = 176275.0  # N/m, paper-table1


def test_a_real_time_runs_identification_is_printed_and_identified_offline(core, tmp_path):
    out = tmp_path / "rt"
    with facility_process(tmp_path) as ports:
        result = run_hil(ports, out, ROBOT_DELAY, "compensator.kind=pida", "simulation.duration=3.5")
    assert result.returncode == 0, result.stderr + result.stdout
    metrics = json.loads((out / "metrics.json").read_text())
    ident = metrics["identification"]
    # the summary's line: the estimates, the scenario's values and the mean errors
    line = next(line for line in result.stdout.splitlines() if line.startswith("identification: k̂ "))
    assert "(scenario 176.28 N/mm, 0.000 N·s/mm)" in line, line
    assert f"k {ident['stiffness_error'] * 100:.3g} %" in line, line
    drifts = ident["stiffness_error"] > 0.02 or ident["damping_error"] > 50.0
    assert ("the identification drifts" in result.stdout) == drifts, result.stdout
    # offline: each collision's k̂ within 4 of its stated σ (and 2 %) of the truth
    series = pd.read_parquet(out / "timeseries.parquet")
    assert "sensor_age" in series.columns
    id_out = tmp_path / "id"
    identified = invoke("identify", str(out), "--out", str(id_out), "--no-plots")
    assert identified.exit_code == 0, identified.output
    collisions = pd.read_csv(id_out / "collisions.csv")
    assert len(collisions) >= 3, collisions
    for _, c in collisions.iterrows():
        assert abs(c["stiffness"] - K_TRUE) <= 4 * c["stiffness_std"] + 0.02 * K_TRUE, c.to_dict()
