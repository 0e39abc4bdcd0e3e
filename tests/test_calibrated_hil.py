"""`model-mediated` with a calibration file in real time across processes, on loopback (issue 23:
"real time over EGM and RSI as in simulation"): `hilcontact facility paper-table1` (the honest
facility: hardware mounted 0.5 mm and 0.5° off nominal, k 7 % high, 0.2 N sensor noise, 5 ms
sensor delay, 0.03 mm robot repeatability, 40 ms robot delay) in one process, `hilcontact hil
paper-table1 --set compensator.kind=model-mediated --calibration cal.toml` in another; then the
same `hil` without the file, and the same run in simulation (`hilcontact run`) with it; over
ABB EGM and over KUKA RSI (4 ms, 4 ms sensor delay).

The file comes from `hilcontact calibrate --simulate` on the same facility (under a second);
calibrating across processes is `tests/test_calibrate_realtime.py`'s subject and takes ~90 s for
both walls (docs/calibration.md, "Measured, real time", has the table with files made that way).

Bounds and why: with the file every collision is rendered from the model, its |CoV − 1| within
0.02 (the issue's target; measured 0.000-0.002 over EGM and RSI at 40-120 ms) and its CoF within
the scenario's tolerance 1.2, which the simulated run also meets; not the issue's 1.05: the
robot's unreported repeatability (0.03 mm against the rear wall's 0.25 mm press) gives CoF 0.91-1.10 in
real time and 0.96-1.07 in simulation, the realisation of the drift differing between the two
(with `facility.robot_repeatability=0` both give 0.99-1.01: docs/calibration.md). Without the
file the first contact is pida's, CoF 1.77 measured (1.81 in simulation): the calibrated first
contact must be at least 0.4 below it. A busy machine's late ticks cost little here (overruns
1-11 of 5501 ticks in the measurements).

`metrics.contact_threshold` is 2 N, not the default 0.5 N, in all three runs: over the device
links the physical contact force is the measured one, and 0.2 N of noise per axis puts |F| above
0.5 N in a few per cent of the free-flight ticks (440 one-tick "collisions" in 5.5 s, all
extra, the run `unfaithful`); in simulation the trace's contact force has no noise.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from test_calibrate_realtime import MOUNT_OFFSET, MOUNT_ROTATION, facility_process, set_args
from test_cli import invoke
from test_realtime_e2e import run_hil

#: The honest facility of the issue's targets at 40 ms (both walls), the repeatability's seed
#: that docs/calibration.md's real-time rows use; the sensor delay is the link's (LINKS).
FACILITY = (
    "facility.robot_delay=0.04", "facility.sensor_noise=0.2",
    "facility.robot_repeatability=3e-5", f"facility.mount_offset={list(MOUNT_OFFSET)}",
    f"facility.mount_rotation={list(MOUNT_ROTATION)}", "facility.stiffness_error=1.07", "facility.seed=7",
)
#: Per robot link: its scenario settings (RSI: the robot's 4 ms cycle paces the loop, the sensor
#: delay the whole period nearest 5 ms) and the facility's protocol argument.
LINKS = {
    "egm": (("facility.sensor_delay=0.005",), ()),
    "rsi": (("facility.sensor_delay=0.004", "simulation.period=0.004"), ("--robot-protocol", "rsi")),
}
#: The loop's and the simulation's settings besides the facility's (threshold: module docstring).
RUN = ("compensator.kind=model-mediated", "metrics.contact_threshold=2")


def real_time(tmp_path: Path, out: Path, link: str, *extra: str) -> dict:
    """`hil` with FACILITY and RUN against a `facility` process with FACILITY over RDT and
    ``link``; asserts that it completed (exit 0) and returns its metrics.json."""
    sets, protocol = LINKS[link]
    with facility_process(tmp_path, FACILITY + sets, *protocol) as ports:
        ports = {**ports, "sensor_protocol": "rdt", "robot_protocol": link}
        result = run_hil(ports, out, *FACILITY, *sets, *RUN, extra=extra)
    assert result.returncode == 0, result.stderr + result.stdout
    metrics = json.loads((out / "metrics.json").read_text())
    stop = metrics["realtime"]["stop"]
    assert stop["kind"] == "completed" and not stop["safety_stop"], stop
    return metrics


def complete(metrics: dict) -> list[dict]:
    """The run's complete collisions, each matched to a reference collision (no extra ones)."""
    collisions = [c for c in metrics["collisions"] if c["complete"]]
    assert all(c["cov"] is not None for c in collisions), collisions
    return collisions


@pytest.mark.parametrize("link", sorted(LINKS))
def test_model_mediated_with_a_calibration_renders_from_the_first_contact_in_real_time(core, tmp_path, link):
    sets = LINKS[link][0]
    cal = tmp_path / "cal.toml"
    calibrated = invoke("calibrate", "paper-table1", "--simulate", *set_args(FACILITY + sets), "--out", str(cal))
    assert calibrated.exit_code == 0, calibrated.output

    rt = real_time(tmp_path, tmp_path / "rt", link, "--calibration", str(cal))
    sim_out = tmp_path / "sim"
    simulated = invoke("run", "paper-table1", *set_args(FACILITY + sets + RUN), "--calibration", str(cal),
                       "--out", str(sim_out), "--no-plots")
    assert simulated.exit_code == 0, simulated.output
    sim = json.loads((sim_out / "metrics.json").read_text())
    rt_collisions, sim_collisions = complete(rt), complete(sim)
    print("real time CoV/CoF:", [(round(c["cov"], 3), round(c["cof"], 3)) for c in rt_collisions])
    print("simulated CoV/CoF:", [(round(c["cov"], 3), round(c["cof"], 3)) for c in sim_collisions])
    assert rt["status"] == "ok" and sim["status"] == "ok", (rt["reason"], sim["reason"])
    # paper-table1's five contacts in 5.5 s, each rendered from the calibration, the first included
    assert len(rt_collisions) == len(sim_collisions) == 5, (rt_collisions, sim_collisions)
    for run in (rt_collisions, sim_collisions):
        assert [c["rendering"] for c in run] == ["model"] * 5, run
        assert all(abs(c["cov"] - 1.0) <= 0.02 for c in run), run
        assert all(c["cof"] <= 1.2 for c in run), run

    # the contrast: without the file each wall's first contact is pida's, far harder (the later
    # ones may gain speed, 3 of 8 runs: docs/calibration.md; not this test's subject)
    bare = real_time(tmp_path, tmp_path / "rt-bare", link)["collisions"]
    print("real time without the file:", [(c["cov"], c["cof"], c["rendering"]) for c in bare])
    assert bare[0]["rendering"] == "pida-no-prior" and bare[0]["cof"] is not None, bare[0]
    assert rt_collisions[0]["cof"] <= bare[0]["cof"] - 0.4, (rt_collisions[0], bare[0])
