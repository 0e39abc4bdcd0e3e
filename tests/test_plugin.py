"""Compensators written in Python (hilcontact.plugin, _core.simulate_python): a pass-through
reproduces `none`, the 30-line PIC of examples/compensators reproduces the Rust `pic`, and bad
plug-ins stop with one line naming the class and the tick, nothing written."""

from __future__ import annotations

import math
import textwrap
from pathlib import Path

import numpy as np
import pytest

import hilcontact as hc
from hilcontact.plugin import PluginError, load_compensator

from test_cli import assert_one_error_line, invoke

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "compensators"
PASS_THROUGH = f"{EXAMPLES / 'pass_through.py'}:PassThrough"
PIC = f"{EXAMPLES / 'pic.py'}:PythonPic"


class DictPassThrough(hc.Compensator):
    """Returns a plain dict of lists (any 3-sequence is accepted)."""

    def step(self, inp):
        return {"applied_force": list(inp.measured_force), "applied_moment": tuple(inp.measured_moment)}


def _same_metrics(a: dict, b: dict) -> None:
    a, b = dict(a), dict(b)
    a.pop("compensator"), b.pop("compensator")
    assert a.keys() == b.keys()

    def close(x, y, where):
        if isinstance(x, dict):
            assert x.keys() == y.keys(), where
            for key in x:
                close(x[key], y[key], f"{where}.{key}")
        elif isinstance(x, list):
            assert len(x) == len(y), where
            for i, (u, v) in enumerate(zip(x, y)):
                close(u, v, f"{where}[{i}]")
        elif isinstance(x, float) and isinstance(y, float):
            assert (math.isnan(x) and math.isnan(y)) or abs(x - y) <= 1e-12 * max(1.0, abs(y)), (where, x, y)
        else:
            assert x == y, (where, x, y)

    close(a, b, "metrics")


@pytest.mark.parametrize("preset", sorted(hc.presets()))
@pytest.mark.parametrize("entry", [PASS_THROUGH, DictPassThrough], ids=["file", "class"])
def test_python_pass_through_reproduces_none_on_every_preset(core, preset, entry):
    scenario = hc.load_scenario(preset, {"compensator.kind": "none"})
    rust = hc.simulate(scenario)
    py = hc.simulate(scenario, compensator=entry)
    assert py.metrics["compensator"].startswith("py:")
    _same_metrics(py.metrics, rust.metrics)
    assert list(py.timeseries.columns) == list(rust.timeseries.columns)
    assert len(py.timeseries) == len(rust.timeseries)
    scale = np.maximum(1.0, np.abs(rust.timeseries.to_numpy()))
    assert np.all(np.abs(py.timeseries.to_numpy() - rust.timeseries.to_numpy()) <= 1e-12 * scale)


def test_pass_through_is_exact_with_a_rotated_sensor(core):
    """Frames: the step sees the sensor frame, the core works in t; with a sensor turned 90°
    about z the Python pass-through still equals `none` (to rounding of the two rotations)."""
    q = [math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)]
    scenario = hc.load_scenario("paper-table1", {"facility.sensor_orientation": q, "facility.robot_delay": 0.0,
                                                 "simulation.duration": 1.0})
    rust, py = hc.simulate(scenario), hc.simulate(scenario, compensator=PASS_THROUGH)
    assert np.allclose(py.timeseries["applied_force_y"], rust.timeseries["applied_force_y"], rtol=1e-9, atol=1e-9)
    assert np.abs(rust.timeseries["applied_force_y"]).max() > 10.0  # the contact is along t's x: sensor y


class Recorder(hc.Compensator):
    """Records what it sees: the measurement in the sensor frame, the context."""

    def reset(self, context):
        super().reset(context)
        self.seen = []

    def step(self, inp):
        self.seen.append((inp.tick, inp.time, inp.measured_force.copy()))
        return {"applied_force": inp.measured_force, "applied_moment": inp.measured_moment}


def test_context_and_input_are_the_run_s(core):
    scenario = hc.load_scenario("paper-exp-1.93hz", {"simulation.duration": 0.5})
    from hilcontact.plugin import make_adapter

    adapter = make_adapter(Recorder, scenario)
    result = core.simulate_python(scenario.to_json(), adapter, "rec")
    c = adapter.compensator.context
    assert c.period == 0.001 and c.sensor_delay_ticks == 5 and math.isclose(c.sensor_delay, 0.005)
    assert np.allclose(c.sensor_origin, [0.0, 0.0, -0.15]) and np.allclose(c.sensor_rotation, np.eye(3))
    assert math.isclose(c.reduced_mass, 600 * 4000 / 4600, rel_tol=1e-12)
    assert c.scenario is scenario
    seen = adapter.compensator.seen
    assert [s[0] for s in seen] == list(range(len(seen))) and len(seen) == len(result["timeseries"]["time"])
    assert np.allclose([s[1] for s in seen], result["timeseries"]["time"], rtol=0, atol=1e-12)
    measured = np.column_stack([result["timeseries"][f"measured_force_{a}"] for a in "xyz"])
    assert np.array_equal(np.array([s[2] for s in seen]), measured)


# ---- the 30-line PIC ---------------------------------------------------------------------

@pytest.mark.parametrize("preset,delay", [("paper-table1", 0.004), ("paper-table1", 0.01), ("paper-table1", 0.02),
                                          ("paper-exp-1.93hz", None), ("paper-exp-2.64hz", None),
                                          ("oblique-6dof", None)])
def test_python_pic_matches_rust_pic_per_collision(core, preset, delay):
    overrides = {"compensator.kind": "pic"}
    if delay is not None:
        overrides["facility.robot_delay"] = delay
    scenario = hc.load_scenario(preset, overrides)
    rust = hc.simulate(scenario).collision_table()
    py = hc.simulate(scenario, compensator=PIC).collision_table()
    assert len(py) == len(rust) >= 2
    for column in ("cov", "cof", "peak_force", "rebound_speed"):
        a, b = py[column].to_numpy(), rust[column].to_numpy()
        ok = np.isnan(a) & np.isnan(b) | (np.abs(a - b) <= 0.01 * np.abs(b))
        assert ok.all(), (column, a, b)


def test_pic_example_is_about_30_lines():
    code = [line for line in (EXAMPLES / "pic.py").read_text().splitlines()
            if line.strip() and not line.lstrip().startswith("#")]
    assert len(code) <= 45, len(code)


# ---- scenario: compensator.kind = "python" ----------------------------------------------

def test_scenario_kind_python_round_trips_and_runs(core, tmp_path):
    scenario = hc.load_scenario("paper-table1", {"compensator.kind": "python", "compensator.entry": PASS_THROUGH,
                                                 "simulation.duration": 1.0})
    assert scenario.python_entry == PASS_THROUGH
    assert scenario.to_dict()["compensator"] == {"kind": "python", "entry": PASS_THROUGH}
    assert '"kind": "none"' in scenario.to_json()
    again = hc.Scenario.from_toml(scenario.to_toml())
    assert again.python_entry == PASS_THROUGH and again.to_dict() == scenario.to_dict()
    run = hc.simulate(scenario)
    assert run.metrics["compensator"] == "py:PassThrough"
    none = hc.simulate(hc.load_scenario("paper-table1", {"simulation.duration": 1.0}))
    assert run.metrics["collisions"] == none.metrics["collisions"]


@pytest.mark.parametrize("overrides,fragment", [
    ({"compensator.kind": "python"}, "compensator.entry: expected path/to/file.py:ClassName"),
    ({"compensator.kind": "python", "compensator.entry": "x:Y", "compensator.alpha": 1},
     "compensator.alpha: unknown key for kind = 'python'"),
])
def test_scenario_kind_python_bad_tables(overrides, fragment):
    with pytest.raises(hc.ScenarioError, match=fragment.replace(".", r"\.").replace("(", r"\(")):
        hc.load_scenario("paper-table1", overrides)


# ---- bad plug-ins: one line, exit 2, nothing written ---------------------------------------

BAD_CODE = {
    "raises": ("Raises", "def step(self, inp):\n    if inp.tick == 7:\n        raise ValueError('boom')\n"
               "    return {'applied_force': inp.measured_force, 'applied_moment': inp.measured_moment}",
               ["Raises.step at tick 7", "ValueError: boom"]),
    "nan": ("Nan", "def step(self, inp):\n    return {'applied_force': [float('nan'), 0, 0], 'applied_moment': [0, 0, 0]}",
            ["Nan.step at tick 0", "non-finite applied_force"]),
    "shape": ("Shape", "def step(self, inp):\n    return {'applied_force': [0, 0], 'applied_moment': [0, 0, 0]}",
              ["Shape.step at tick 0", "applied_force of shape (2,), expected 3 numbers"]),
    "missing": ("Missing", "def step(self, inp):\n    return {'applied_force': [0, 0, 0]}",
                ["Missing.step at tick 0", "returned no applied_moment"]),
    "slow": ("Slow", "def step(self, inp):\n    import time\n    if inp.tick == 3:\n        time.sleep(1.0)\n"
             "    return {'applied_force': inp.measured_force, 'applied_moment': inp.measured_moment}",
             ["Slow.step at tick 3", "above the limit of 0.5 s"]),
}


def _plugin_file(tmp_path: Path, cls: str, body: str) -> str:
    path = tmp_path / "bad.py"
    path.write_text("import hilcontact as hc\n\nclass " + cls + "(hc.Compensator):\n" + textwrap.indent(body, "    ") + "\n")
    return f"{path}:{cls}"


@pytest.mark.parametrize("case", sorted(BAD_CODE))
def test_bad_plugin_stops_with_one_line_and_writes_nothing(core, tmp_path, case):
    cls, body, fragments = BAD_CODE[case]
    entry = _plugin_file(tmp_path, cls, body)
    out = tmp_path / "out"
    result = invoke("run", "paper-table1", "--compensator", entry, "--out", str(out), cwd=tmp_path)
    assert_one_error_line(result, *fragments)
    assert not out.exists()


def test_step_limit_option(core, tmp_path):
    cls, body, _ = BAD_CODE["slow"]
    entry = _plugin_file(tmp_path, cls, body.replace("1.0", "0.3"))
    result = invoke("run", "paper-table1", "--compensator", entry, "--step-limit", "0.1", "--out", str(tmp_path / "o"))
    assert_one_error_line(result, "Slow.step at tick 3", "above the limit of 0.1 s")


@pytest.mark.parametrize("entry,fragment", [
    ("nowhere/missing.py:X", "compensator nowhere/missing.py: no such file"),
    ("no_such_module_xyz:X", "compensator no_such_module_xyz: no such module"),
    (f"{EXAMPLES / 'pic.py'}:Nope", "has no class Nope; it has PythonPic"),
    ("math:pi", "not a subclass of hilcontact.Compensator"),
    ("justaname", "expected path/to/file.py:ClassName or module:ClassName"),
])
def test_bad_entries(core, tmp_path, entry, fragment):
    with pytest.raises(PluginError, match=None) as info:
        load_compensator(entry)
    assert fragment in str(info.value) and "\n" not in str(info.value)
    result = invoke("run", "paper-table1", "--compensator", entry, "--out", str(tmp_path / "o"))
    assert_one_error_line(result, fragment)
    assert not (tmp_path / "o").exists()


def test_run_command_with_a_python_compensator_saves_the_run(core, tmp_path):
    out = tmp_path / "run"
    result = invoke("run", "paper-table1", "--set", "simulation.duration=1", "--compensator", PASS_THROUGH,
                    "--no-plots", "--out", str(out))
    assert result.exit_code == 0, result.output
    loaded = hc.Run.load(out)
    assert loaded.metrics["compensator"] == "py:PassThrough"
    assert loaded.scenario.python_entry == PASS_THROUGH  # scenario.toml names what ran
    assert 'kind = "python"' in (out / "scenario.toml").read_text()


# ---- replay ------------------------------------------------------------------------------

def test_replay_with_a_python_compensator(core, tmp_path):
    """A recorded `pic` run replayed through the Python PIC gives what the run applied; the
    pass-through replays the measured wrench."""
    run_dir = tmp_path / "run"
    result = invoke("run", "paper-table1", "--set", "compensator.kind=pic", "--set", "simulation.duration=2",
                    "--no-plots", "--out", str(run_dir))
    assert result.exit_code == 0, result.output
    out = tmp_path / "replay"
    result = invoke("replay", str(run_dir), "--compensator", PIC, "--out", str(out))
    assert result.exit_code == 0, result.output
    import json

    summary = json.loads((out / "summary.json").read_text())
    assert summary["compensator"] == PIC
    assert summary["max_relative_difference_to_recorded"] < 1e-6
    table = __import__("pandas").read_parquet(out / "replay.parquet")
    recorded = hc.Run.load(run_dir).timeseries
    assert np.allclose(table["stiffness_estimate"], recorded["stiffness_estimate"], rtol=1e-6, equal_nan=True)
    shipped = tmp_path / "shipped"
    assert invoke("replay", str(run_dir), "--compensator", "pic", "--out", str(shipped)).exit_code == 0
    assert 'kind = "python"' in (out / "scenario.toml").read_text()
    result = invoke("replay", str(run_dir), "--compensator", PASS_THROUGH, "--out", str(tmp_path / "pt"))
    assert result.exit_code == 0, result.output
    table = __import__("pandas").read_parquet(tmp_path / "pt" / "replay.parquet")
    assert np.array_equal(table["applied_force_x"], recorded["measured_force_x"])


class Interrupted(hc.Compensator):
    def step(self, inp):
        if inp.tick == 5:
            raise KeyboardInterrupt
        return {"applied_force": inp.measured_force, "applied_moment": inp.measured_moment}


class BadReset(hc.Compensator):
    def reset(self, context):
        raise RuntimeError("no context for me")

    def step(self, inp):  # pragma: no cover - never reached
        return {}


def test_ctrl_c_in_a_step_is_not_a_plugin_error(core):
    with pytest.raises(KeyboardInterrupt):
        hc.simulate("paper-table1", compensator=Interrupted)


def test_reset_raising_is_one_line(core):
    with pytest.raises(PluginError, match=r"^compensator BadReset\.reset raised RuntimeError: no context for me$"):
        hc.simulate("paper-table1", compensator=BadReset)


def test_compare_with_a_python_compensator(core, tmp_path):
    out = tmp_path / "cmp"
    result = invoke("compare", "paper-table1", "--set", "simulation.duration=2", "--compensators", "pic",
                    "--compensator", PIC, "--no-plots", "--out", str(out))
    assert result.exit_code == 0, result.output
    assert (out / "pic" / "metrics.json").is_file() and (out / "py:PythonPic" / "metrics.json").is_file()
    assert "py:PythonPic" in (out / "comparison.md").read_text()
    loaded = hc.Comparison.load(out)
    assert loaded.kinds == ["pic", "py:PythonPic"]
    a, b = (loaded.runs[k].collision_table() for k in loaded.kinds)
    assert np.allclose(a["cov"], b["cov"], rtol=0.01)
    result = invoke("compare", "paper-table1", "--compensator", "nowhere.py:X", "--out", str(tmp_path / "o"))
    assert_one_error_line(result, "no such file")
    assert not (tmp_path / "o").exists()


def test_sweep_with_a_python_compensator(core, tmp_path):
    """A sweep's rows of the Python pass-through are `none`'s (but the name and wall time),
    and the folder resumes as any sweep's."""
    out = tmp_path / "sweep"
    result = invoke("sweep", "paper-table1", "--set", "simulation.duration=1.5", "--grid",
                    "facility.robot_delay=0.004,0.01", "--compensators", "none", "--compensator", PASS_THROUGH,
                    "--out", str(out))
    assert result.exit_code == 0, result.output
    rows = hc.load_results(out)
    assert sorted(set(rows["compensator"])) == ["none", "py:PassThrough"]
    drop = ["run_key", "compensator", "wall_time"]
    none = rows[rows["compensator"] == "none"].drop(columns=drop).reset_index(drop=True)
    py = rows[rows["compensator"] == "py:PassThrough"].drop(columns=drop).reset_index(drop=True)
    __import__("pandas").testing.assert_frame_equal(py, none)
    again = invoke("sweep", "paper-table1", "--set", "simulation.duration=1.5", "--grid",
                   "facility.robot_delay=0.004,0.01", "--compensators", "none", "--compensator", PASS_THROUGH,
                   "--out", str(out), "--resume")
    assert again.exit_code == 0, again.output
    assert len(hc.load_results(out)) == 4
