"""Ctrl-C during a run with a compensator written in Python saves the run so far, as it does a
native run (issue 25, item 9): the first Ctrl-C ends the core's loop at the tick it lands in
(the compensator's ``step`` is not interrupted), ``hc.simulate`` raises ``RunInterrupted`` with
the run so far (status ``interrupted``, never ``ok``), and ``hilcontact run --compensator``
writes the folder, prints one line and exits 130. A second Ctrl-C is a plain
KeyboardInterrupt.

The signals are sent by the compensator itself at a given tick (in the process) or once the
compensator has printed that it runs (across processes): no fixed waits."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pandas as pd
import pytest

import hilcontact as hc

FORBIDDEN = ("Traceback", "panicked", "PanicException", "Failed to access NumPy", "Aborted!", "PluginError")
LINE = re.compile(
    r"^interrupted: the simulation stopped at t = (?P<t>[0-9.]+) s of 300 s, saved as 'interrupted'; "
    r"stopped after saving (?P<saved>.+)$"
)


class SignalAt(hc.Compensator):
    """Passes the measured wrench through (as ``none``) and sends this process SIGINT at the
    ticks in ``at`` (0-based), from inside its step: a Ctrl-C landing in the compensator."""

    at: tuple[int, ...] = ()

    def reset(self, context):
        self.tick = 0

    def step(self, inp):
        if self.tick in self.at:
            os.kill(os.getpid(), signal.SIGINT)
        self.tick += 1
        return {"applied_force": inp.measured_force, "applied_moment": inp.measured_moment}


class SignalOnce(SignalAt):
    at = (500,)


class SignalTwice(SignalAt):
    """Two Ctrl-Cs in tick 500's step: the second once the first has been handled."""

    def step(self, inp):
        if self.tick == 500:
            os.kill(os.getpid(), signal.SIGINT)
            for _ in range(100_000):  # until the first one's handler has run (it hands Ctrl-C back)
                if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
                    break
                time.sleep(0)
            os.kill(os.getpid(), signal.SIGINT)
        return super().step(inp)


class NoSignal(SignalAt):
    at = ()


def test_ctrl_c_in_a_python_compensator_returns_the_run_so_far(core):
    scenario = hc.load_scenario("paper-table1", {"simulation.duration": 2.0})
    whole = hc.simulate(scenario, compensator=NoSignal)
    assert whole.status != "interrupted" and len(whole.timeseries) == 2001
    with pytest.raises(hc.RunInterrupted) as caught:
        hc.simulate(scenario, compensator=SignalOnce)
    run = caught.value.run
    assert isinstance(caught.value, KeyboardInterrupt)
    assert run.status == "interrupted"
    assert run.metrics["stop"]["kind"] == "user"
    # the loop ends at the tick the signal landed in (tick 500, t = 0.5 s), or the next
    n = len(run.timeseries)
    assert n in (501, 502), n
    assert run.metrics["stop"]["time"] == pytest.approx((n - 1) * 0.001, abs=1e-12)
    assert caught.value.time == pytest.approx(run.metrics["stop"]["time"], abs=1e-12)
    assert run.metrics["compensator"].startswith("py:")
    # the run so far is the whole run's beginning, tick for tick; the reference the same span
    assert len(run.reference) == n
    pd.testing.assert_frame_equal(run.timeseries, whole.timeseries.iloc[:n])
    pd.testing.assert_frame_equal(run.reference, whole.reference.iloc[:n])
    # Python's own Ctrl-C handler is back, and the module stays usable
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    again = hc.simulate(scenario, compensator=NoSignal)
    assert again.status == whole.status and len(again.timeseries) == len(whole.timeseries)


def test_a_second_ctrl_c_is_a_plain_keyboard_interrupt(core):
    scenario = hc.load_scenario("paper-table1", {"simulation.duration": 2.0})
    with pytest.raises(KeyboardInterrupt) as caught:
        hc.simulate(scenario, compensator=SignalTwice)
    assert not isinstance(caught.value, hc.RunInterrupted)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


COMPENSATOR = """
    import sys

    import hilcontact as hc


    class Announcing(hc.Compensator):
        \"\"\"`none`, which says once on stdout that it runs.\"\"\"

        def reset(self, context):
            self.tick = 0

        def step(self, inp):
            self.tick += 1
            if self.tick == 300:
                print("running", flush=True)
            return {"applied_force": inp.measured_force, "applied_moment": inp.measured_moment}
"""


@pytest.mark.skipif(sys.platform == "win32", reason="signals to a child process")
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_ctrl_c_in_a_run_with_a_python_compensator_saves_it(core, tmp_path, signum):
    (tmp_path / "announcing.py").write_text(textwrap.dedent(COMPENSATOR), encoding="utf-8")
    package_root = str(Path(hc.__file__).resolve().parent.parent)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [package_root, os.environ.get("PYTHONPATH")])))
    args = ("run", "paper-table1", "--set", "simulation.duration=300", "--no-plots", "--out", "out",
            "--compensator", "announcing.py:Announcing")
    proc = subprocess.Popen([sys.executable, "-m", "hilcontact", *args], cwd=tmp_path, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        first = proc.stdout.readline()  # blocks until the compensator has run 300 ticks
        assert first.strip() == "running", (first, proc.stderr.read() if proc.poll() is not None else "")
        proc.send_signal(signum)  # SIGTERM: the command turns it into a Ctrl-C
        out, err = proc.communicate(timeout=600)
    finally:
        if proc.poll() is None:
            proc.kill()
    for word in FORBIDDEN:
        assert word not in err, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert proc.returncode == 130, (proc.returncode, err)
    assert len(lines) == 1, err
    match = LINE.match(lines[0])
    assert match, err
    stopped_at = float(match["t"])
    assert 0.299 <= stopped_at < 300, err
    assert match["saved"] == "out", err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["announcing.py", "out"]

    folder = tmp_path / "out"
    metrics = json.loads((folder / "metrics.json").read_text())
    assert metrics["status"] == "interrupted"
    assert metrics["stop"]["kind"] == "user"
    assert metrics["compensator"].startswith("py:")
    assert abs(metrics["stop"]["time"] - stopped_at) < 1e-3
    timeseries = pd.read_parquet(folder / "timeseries.parquet")
    reference = pd.read_parquet(folder / "reference.parquet")
    assert len(timeseries) == len(reference) == round(metrics["stop"]["time"] / 0.001) + 1
    assert (timeseries["time"].to_numpy() == reference["time"].to_numpy()).all()
    assert timeseries.notna()[["contact_force_x", "tip_position_x", "energy"]].all().all()
    for c in metrics["collisions"]:
        assert c["end"] <= stopped_at + 1e-9
    run = hc.Run.load(folder)
    assert run.status == "interrupted" and len(run.timeseries) == len(timeseries)
