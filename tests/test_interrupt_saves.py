"""Ctrl-C during a simulation saves the run so far (issue 25, item 9): the core's HIL loop
stops at its next tick, the run is returned as ``interrupted`` with its records, the
reference over the same span, and ``hilcontact run`` writes the output folder (and the MCAP
recording up to there), prints one line naming the time and what it saved, and exits 130.

Across processes the signal is sent once the simulation is running: the core's thread
(``hilcontact-core``) exists and has used CPU past the reference's share (read from
``/proc``, CPU time not wall time, so a busy machine only makes the test slower)."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pandas as pd
import pytest

import hilcontact as hc

pytestmark = pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="needs /proc (Linux)")

FORBIDDEN = ("Traceback", "panicked", "PanicException", "Failed to access NumPy", "Aborted!")
LINE = re.compile(
    r"^interrupted: the simulation stopped at t = (?P<t>[0-9.]+) s of 300 s, saved as 'interrupted'; "
    r"stopped after saving (?P<saved>.+)$"
)


def _start(args: tuple[str, ...], cwd: Path) -> subprocess.Popen:
    package_root = str(Path(hc.__file__).resolve().parent.parent)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [package_root, os.environ.get("PYTHONPATH")])))
    return subprocess.Popen([sys.executable, "-m", "hilcontact", *args], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _core_thread_cpu(pid: int) -> float | None:
    """CPU time (s) the process's ``hilcontact-core`` thread has used, None while it has none."""
    tick = os.sysconf("SC_CLK_TCK")
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            if (task / "comm").read_text().strip() != "hilcontact-core":
                continue
            fields = (task / "stat").read_text().rsplit(")", 1)[1].split()
            return (int(fields[11]) + int(fields[12])) / tick  # utime, stime
        except (OSError, IndexError, ValueError):
            continue
    return None


def _interrupt_when_running(proc: subprocess.Popen, cpu: float, seconds: float = 600) -> None:
    """SIGINT once the simulation's thread has used ``cpu`` s of CPU."""
    deadline = time.monotonic() + seconds
    while proc.poll() is None and time.monotonic() < deadline:
        used = _core_thread_cpu(proc.pid)
        if used is not None and used >= cpu:
            proc.send_signal(signal.SIGINT)
            return
        time.sleep(0.005)
    raise AssertionError("the simulation never ran long enough to be interrupted")


#: CPU time (s) of the simulation's thread before the signal, one per attempt: the reference
#: runs first (it cannot be stopped; a signal there stops the loop at its first tick, t = 0),
#: so an attempt that lands there is repeated with a longer wait.
ATTEMPTS = (0.3, 1.0, 2.5)


def test_ctrl_c_in_a_run_saves_it_up_to_the_stop(core, tmp_path):
    args = ("run", "paper-table1", "--set", "compensator.kind=pida", "--set", "simulation.duration=300",
            "--no-plots", "--out", "out", "--mcap", "run.mcap")
    for cpu in ATTEMPTS:
        for p in tmp_path.iterdir():
            shutil.rmtree(p) if p.is_dir() else p.unlink()
        proc = _start(args, tmp_path)
        _interrupt_when_running(proc, cpu)
        _, err = proc.communicate(timeout=600)
        for word in FORBIDDEN:
            assert word not in err, err
        lines = [line for line in err.splitlines() if line.strip()]
        assert proc.returncode == 130, (proc.returncode, err)
        assert len(lines) == 1, err
        match = LINE.match(lines[0])
        assert match, err
        stopped_at = float(match["t"])
        if stopped_at > 0:  # the loop had started (not still in the reference): the case wanted
            break
    assert 0 < stopped_at < 300, err
    assert sorted(match["saved"].split(", ")) == ["out", "run.mcap"], err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "run.mcap"]

    folder = tmp_path / "out"
    metrics = json.loads((folder / "metrics.json").read_text())
    assert metrics["status"] == "interrupted"
    assert metrics["stop"]["kind"] == "user"
    assert abs(metrics["stop"]["time"] - stopped_at) < 1e-3
    assert metrics["reason"] == f"stopped by the user at {stopped_at:.3f} s"
    timeseries = pd.read_parquet(folder / "timeseries.parquet")
    reference = pd.read_parquet(folder / "reference.parquet")
    period = 0.001
    assert len(timeseries) == len(reference) == round(metrics["stop"]["time"] / period) + 1
    assert (timeseries["time"].to_numpy() == reference["time"].to_numpy()).all()
    assert timeseries["time"].iloc[-1] == pytest.approx(metrics["stop"]["time"], abs=1e-12)
    assert timeseries.notna()[["contact_force_x", "tip_position_x", "energy"]].all().all()
    # every collision compared lies within the span
    for c in metrics["collisions"]:
        assert c["end"] <= stopped_at + 1e-9
    # it reloads as a run, and the MCAP recording holds the same ticks
    run = hc.Run.load(folder)
    assert run.status == "interrupted" and len(run.timeseries) == len(timeseries)
    reader = pytest.importorskip("mcap.reader")
    with open(tmp_path / "run.mcap", "rb") as f:
        summary = reader.make_reader(f).get_summary()
    topics = {c.id: c.topic for c in summary.channels.values()}
    counts = {topics[i]: n for i, n in summary.statistics.channel_message_counts.items()}
    assert counts["/hil/contact_force"] == len(timeseries)


def _sigint_after(seconds: float) -> threading.Timer:
    timer = threading.Timer(seconds, lambda: os.kill(os.getpid(), signal.SIGINT))
    timer.start()
    return timer


def test_simulate_returns_the_run_so_far_in_its_interrupt(core):
    scenario = hc.load_scenario("paper-table1", {"compensator.kind": "pida", "simulation.duration": 120})
    start = time.monotonic()
    whole = hc.simulate(scenario)
    elapsed = time.monotonic() - start
    # a busy machine may run the second run faster than half the first: a signal that would
    # come after it is cancelled, and the next try comes earlier
    interrupt = None
    for fraction in (0.5, 0.25, 0.1, 0.05, 0.02):
        timer = _sigint_after(elapsed * fraction)
        try:
            hc.simulate(scenario)
        except hc.RunInterrupted as e:
            interrupt = e
        timer.cancel()
        timer.join()
        if interrupt is not None:
            break
    assert interrupt is not None, "no SIGINT landed during a run"
    run = interrupt.run
    assert isinstance(interrupt, KeyboardInterrupt)
    if run.status != "interrupted":  # landed after the last tick: the whole run, as it was
        assert len(run.timeseries) == len(whole.timeseries)
        return
    n = len(run.timeseries)
    assert 1 <= n < len(whole.timeseries)
    assert len(run.reference) == n
    assert run.metrics["stop"]["kind"] == "user"
    assert interrupt.time == pytest.approx(run.metrics["stop"]["time"], abs=1e-12)
    # the run so far is the whole run's beginning, tick for tick
    pd.testing.assert_frame_equal(run.timeseries, whole.timeseries.iloc[:n])
    pd.testing.assert_frame_equal(run.reference, whole.reference.iloc[:n])
    # the module stays usable
    again = hc.simulate(hc.load_scenario("paper-table1", {"simulation.duration": 0.3}))
    assert again.status == "ok"
