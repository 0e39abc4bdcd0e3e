"""The live loop's stated uncertainty in real time (`hilcontact hil` against a `hilcontact
facility` process on loopback, 20 ms robot delay, pida, a damped contact and a noisy sensor):
over several runs, the σ that the summary prints for the loop's final ĉ and k̂
(`recording.online_identification`) holds their error. A loaded machine starves the emulator
and holds sensor records, which is what this checks; one run may still drift past its 2σ, so
the bound is on the runs together (at least two of three), never on one. Measured at load 5-6:
ĉ 17.0 ± 434.8, −237.1 ± 383.3, 95.1 ± 333.1 N s/m for c = 130 (the σ is mostly the robot
feedback's timing, 1.9-2.0 ms RMS, times k̂); k̂ 174673 ± 6584, 172639 ± 2997, 175916 ± 345 N/m."""

from __future__ import annotations

import numpy as np
import pandas as pd

from test_realtime_e2e import ROBOT_DELAY, facility_process, run_hil

K_TRUE = 176275.0  # N/m, paper-table1
C_TRUE = 130.0  # N s/m, set below
SETS = (f"contact.damping={C_TRUE}", "facility.sensor_noise=0.2")
RUNS = 3


def test_the_loops_stated_sigma_covers_its_final_estimates_error_over_runs(core, tmp_path):
    from hilcontact.recording import online_identification, read_recording

    covered = {"k": 0, "c": 0}
    report = []
    for run in range(RUNS):
        out = tmp_path / f"rt{run}"
        with facility_process(tmp_path, *(a for s in SETS for a in ("--set", s))) as ports:
            result = run_hil(ports, out, ROBOT_DELAY, "compensator.kind=pida", "simulation.duration=3.5", *SETS)
        assert result.returncode == 0, result.stderr + result.stdout
        # the summary prints the loop's final estimate with its 1σ
        line = next(line for line in result.stdout.splitlines() if line.startswith("identification: k̂ "))
        assert "1σ of the loop's final estimate" in line, line
        series = pd.read_parquet(out / "timeseries.parquet")
        k_loop = series["stiffness_estimate"].dropna().to_numpy()[-1]
        c_loop = series["damping_estimate"].dropna().to_numpy()[-1]
        online = online_identification(read_recording(out))
        assert online is not None and np.isfinite(online["stiffness_std"]) and online["damping_std"] > 0, online
        # k: its σ leaves out the timing (it moves k̂ by k·c·δ/m, 0.01 % here), and the records'
        # arrival in bursts moves it by up to about 1.5 % (docs/identification.md): 2σ + 1 %
        covered["k"] += abs(k_loop - K_TRUE) <= 2 * online["stiffness_std"] + 0.01 * K_TRUE
        covered["c"] += abs(c_loop - C_TRUE) <= 2 * online["damping_std"]
        report.append((k_loop, online["stiffness_std"], c_loop, online["damping_std"]))
        print(f"run {run}: k̂ {k_loop:.0f} ± {online['stiffness_std']:.0f} N/m, ĉ {c_loop:.1f} ± "
              f"{online['damping_std']:.1f} N s/m (timing {online.get('timing', 0.0) * 1e3:.2f} ms)")
    assert covered["c"] >= RUNS - 1, report
    assert covered["k"] >= RUNS - 1, report
