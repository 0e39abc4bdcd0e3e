"""Bad input, as a user would give it (issue "Bad input"): every bad scenario value, override,
grid, option and sweep folder gets one ``error: ...`` line naming the key or option and what
is allowed, exit code 2, and nothing is written; a run killed mid-way leaves no temporary
folder behind."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

import hilcontact as hc
from hilcontact.output import MARKER, write_atomically
from hilcontact.registry import KINDS
from test_cli import assert_one_error_line, invoke

SHORT = ("--set", "simulation.duration=0.3", "--no-plots")
TWO_70 = str(2**70)

# (--set value, fragments of the one error line)
BAD_VALUES = [
    ('name="a\\u0000b"', ["name:", "control characters"]),
    ('name="' + "n" * 300 + '"', ["name:", "at most 100 characters", "got 300"]),
    ('name="a/b"', ["name:", "'/'"]),
    ("facility.robot_delay=1e308", ["facility.robot_delay", "between 0 and 60", "1e+308"]),
    ("facility.robot_delay=1e300", ["facility.robot_delay", "between 0 and 60"]),
    (f"facility.robot_delay={TWO_70}", ["facility.robot_delay", "between 0 and 60"]),
    ("facility.robot_delay=1e-320", ["facility.robot_delay = 1e-320 s is not a whole number of periods", "use 0 or 0.001"]),
    ("facility.robot_delay=1e-308", ["facility.robot_delay = 1e-308 s is not a whole number of periods"]),
    ("facility.robot_delay=6", ["facility.robot_delay = 6 s is longer than the run", "simulation.duration"]),
    (f"facility.sensor_delay={TWO_70}", ["facility.sensor_delay", "between 0 and 60"]),
    ("simulation.duration=1e308", ["simulation.duration", "<= 86400"]),
    (f"simulation.duration={TWO_70}", ["simulation.duration", "<= 86400"]),
    ("simulation.duration=nan", ["simulation.duration", "finite"]),
    ("simulation.period=1e-308", ["simulation.period", "between 1e-6 and 1"]),
    ("simulation.period=1e-7", ["simulation.period", "between 1e-6 and 1"]),
    ("simulation.reference_substeps=1000000000", ["simulation.reference_substeps", "between 1 and 1000"]),
    ("simulation.reference_substeps=4294967296", ["simulation.reference_substeps", "between 1 and 1000"]),
    ("simulation.plant_substeps=4294967296", ["simulation.plant_substeps", "between 1 and 1000"]),
    (f"facility.seed={TWO_70}", ["facility.seed", "between 0 and 18446744073709551615"]),
    ("rod.tip=[1e308, 0, 0]", ["rod.tip", "|x| <= 1000"]),
    ("servicer.position=[0, 2e3, 0]", ["servicer.position", "|x| <= 1000"]),
    ("walls[0].normal=[1e300, 1e300, 0]", ["walls[0].normal", "|x| <= 1e6"]),
    ("contact.stiffness=1e308", ["contact.stiffness", "<= 1e11"]),
    (f"contact.stiffness={TWO_70}", ["contact.stiffness", "<= 1e11"]),
    ("contact.stiffness=1e11", ["contact.stiffness", "contact frequency", "reference_substeps"]),
    ("servicer.mass=1e-9", ["servicer.mass", "between 0.001 and 1e7"]),
    ("servicer.inertia=[1e-300, 1, 1]", ["servicer.inertia", ">= 1e-6"]),
    ("target.inertia=[[1e12, 0, 0], [0, 1, 0], [0, 0, 1]]", ["target.inertia", "|x| <= 1e10"]),
    ("simulation.duration=" + "[" * 3000 + "]" * 3000, ["--set simulation.duration", "nested too deeply"]),
    ("simulation.duration={a={b={c=1}}}", ["simulation.duration: expected a number"]),
]


@pytest.mark.parametrize(("value", "fragments"), BAD_VALUES, ids=lambda v: str(v)[:40])
def test_bad_values_are_one_line_naming_the_key_and_nothing_is_written(tmp_path, value, fragments):
    result = invoke("run", "paper-table1", "--set", value, "--out", str(tmp_path / "out"), *SHORT[2:], cwd=tmp_path)
    assert_one_error_line(result, *fragments)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "text",
    [
        "name = 'x'\nv = " + "[" * 5000 + "]" * 5000 + "\n",
        "name = 'x'\nv = " + "{a = " * 5000 + "1" + "}" * 5000 + "\n",
    ],
    ids=["arrays", "tables"],
)
def test_deeply_nested_toml_is_one_line(tmp_path, text):
    path = tmp_path / "deep.toml"
    path.write_text(text)
    result = invoke("run", str(path), "--out", str(tmp_path / "out"))
    assert_one_error_line(result, "deep.toml", "invalid TOML", "nested too deeply")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["deep.toml"]


# ---- estimates above the limits are refused before anything runs -------------------------


def test_a_run_above_the_memory_limit_is_refused_with_the_estimate_and_the_limit(tmp_path):
    start = time.monotonic()
    result = invoke("run", "paper-table1", "--set", "simulation.duration=5500", "--out", str(tmp_path / "o"))
    assert_one_error_line(result, "simulation.duration = 5500 s", "5.5 GB", "limit of 2 GB", "--max-memory")
    assert time.monotonic() - start < 20 and list(tmp_path.iterdir()) == []
    result = invoke("compare", "paper-table1", "--set", "simulation.duration=1000", "--out", str(tmp_path / "o"))
    assert_one_error_line(result, f"{len(KINDS)} runs of simulation.duration = 1000 s", "--max-memory")
    result = invoke("run", "paper-table1", *SHORT, "--max-time", "0.001", "--out", str(tmp_path / "o"))
    assert_one_error_line(result, "takes about", "limit of 0.001 s", "--max-time")
    # the option raises the limit
    result = invoke("run", "paper-table1", *SHORT, "--max-memory", "0.5", "--out", str(tmp_path / "o"))
    assert result.exit_code == 0, result.stderr


@pytest.mark.parametrize(
    ("grid", "fragments"),
    [
        (["servicer.mass=1:2:10000", "contact.stiffness=1e5:2e5:10000"], ["sweep of 100000000 runs", "2 TB of memory", "above the limit"]),
        (["servicer.mass=1:2:100000000"], ["--grid servicer.mass", "COUNT must be 1 to 100000"]),
        (["simulation.duration=1e308"], ["--grid simulation.duration=1e+308", "<= 86400"]),
        (["simulation.duration=1,3000"], ["at its most demanding grid values", "--max-memory"]),
    ],
    ids=["1e8 points", "1e8 values", "duration 1e308", "one long duration"],
)
def test_a_sweep_above_the_limits_is_refused_at_once(tmp_path, grid, fragments):
    out = tmp_path / "s"
    args = [a for g in grid for a in ("--grid", g)]
    start = time.monotonic()
    result = invoke("sweep", "paper-table1", *args, "--compensators", "none", "--threads", "2", "--out", str(out))
    assert_one_error_line(result, *fragments)
    assert time.monotonic() - start < 30
    assert not out.exists()


def test_too_many_seeds_are_refused(tmp_path):
    result = invoke("sweep", "paper-table1", "--seeds", "1000000000", "--out", str(tmp_path / "s"))
    assert_one_error_line(result, "--seeds", "1 to 100000")


# ---- options ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("args", "fragments"),
    [
        (["facility", "paper-table1", "--duration", "nan"], ["--duration", "finite number > 0", "'nan'"]),
        (["facility", "paper-table1", "--duration", "-1"], ["--duration", "finite number > 0", "'-1'"]),
        (["facility", "paper-table1", "--silence-robot-after", "inf"], ["--silence-robot-after"]),
        (["check", "paper-table1", "--duration", "1e308"], ["--duration", "<= 3600"]),
        (["hil", "paper-table1", "--connect-timeout", "1e308"], ["--connect-timeout", "<= 3600"]),
        (["hil", "paper-table1", "--egm-rotation", "0,0,0,0"], ["egm_rotation", "non-zero quaternion"]),
        (["hil", "paper-table1", "--sensor", "999.1.1.1"], ["sensor host", "999.1.1.1", "IPv4"]),
        (["hil", "paper-table1", "--robot", "1.2.3.256"], ["robot_host", "1.2.3.256"]),
        (["hil", "paper-table1", "--force-limit", "nan"], ["--force-limit", "finite"]),
        (["hil", "paper-table1", "--egm-port", "70000"], ["--egm-port", "70000", "0<=x<=65535"]),
        (["hil", "paper-table1", "--set", "simulation.duration=5500"], ["5500 s", "--max-memory"]),
        (["sweep", "paper-table1", "--threads", "1000000000", "--out", "x"], ["--threads", "1<=x<=1024"]),
        (["run", "paper-table1", "--bogus"], ["No such option", "--bogus"]),
        (["sweep", "paper-table1", "--seeds", "abc", "--out", "x"], ["--seeds", "abc"]),
        (["run", "paper-table1", "--max-memory", "0"], ["--max-memory", "finite number > 0"]),
        (["stability-map", "x", "--cof-limit", "nan"], ["--cof-limit"]),
    ],
    ids=lambda v: " ".join(v)[:50] if isinstance(v, list) else None,
)
def test_bad_options_are_one_line_before_any_socket_is_opened(tmp_path, args, fragments):
    start = time.monotonic()
    result = invoke(*args, cwd=tmp_path)
    assert_one_error_line(result, *fragments)
    assert time.monotonic() - start < 15  # no connection was tried (the default timeout is 5 s)
    assert list(tmp_path.iterdir()) == []


# ---- disk errors ------------------------------------------------------------------------


def test_a_full_disk_while_saving_is_one_line_naming_the_file(tmp_path, monkeypatch):
    import errno

    def full(self, folder, plots):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(folder / "timeseries.parquet"))

    monkeypatch.setattr(hc.Run, "_write", full)
    result = invoke("run", "paper-table1", *SHORT, "--out", str(tmp_path / "o"))
    assert_one_error_line(result, "timeseries.parquet", os.strerror(errno.ENOSPC))
    assert list(tmp_path.iterdir()) == []


# ---- a corrupt sweep folder -------------------------------------------------------------

SWEEP = ("sweep", "paper-table1", "--grid", "facility.robot_delay=0.002,0.004", "--compensators", "none",
         "--set", "simulation.duration=0.3")


@pytest.fixture
def sweep_folder(core, tmp_path) -> Path:
    out = tmp_path / "s"
    result = invoke(*SWEEP, "--out", str(out))
    assert result.exit_code == 0, result.stderr
    return out


@pytest.mark.parametrize(
    ("damage", "fragments"),
    [
        (lambda out: (out / "results.parquet").write_bytes((out / "results.parquet").read_bytes()[:100]),
         ["results.parquet: cannot be read", "move it away"]),
        (lambda out: (out / "sweep.json").write_text(""), ["sweep.json cannot be read"]),
        (lambda out: (out / "sweep.json").write_text("\x00garbage{"), ["sweep.json cannot be read"]),
        (lambda out: (out / "sweep.json").write_text("[1, 2]"), ["sweep.json does not describe a sweep"]),
    ],
    ids=["truncated results", "empty sweep.json", "garbage sweep.json", "a list"],
)
def test_a_corrupt_sweep_folder_is_one_line_on_resume(sweep_folder, damage, fragments):
    damage(sweep_folder)
    before = {p.name: p.read_bytes() for p in sweep_folder.iterdir() if p.is_file()}
    result = invoke(*SWEEP, "--out", str(sweep_folder), "--resume")
    assert_one_error_line(result, *fragments)
    assert {p.name: p.read_bytes() for p in sweep_folder.iterdir() if p.is_file()} == before


def test_an_unreadable_part_is_skipped_reported_and_its_runs_rerun(sweep_folder):
    rows = pd.read_parquet(sweep_folder / "results.parquet")
    rows.iloc[:1].to_parquet(sweep_folder / "results.parquet", index=False)
    part = sweep_folder / "parts" / "part-00000000000000000001.parquet"
    rows.iloc[1:].to_parquet(part, index=False)
    part.write_bytes(part.read_bytes()[:-20])  # truncated
    junk = sweep_folder / "parts" / "part-00000000000000000002.parquet"
    junk.write_text("not parquet")
    result = invoke(*SWEEP, "--out", str(sweep_folder), "--resume")
    assert result.exit_code == 0, result.stderr
    notes = [line for line in result.stderr.splitlines() if line.startswith("note: ")]
    assert len(notes) == 2 and all("cannot be read" in n and "run again" in n for n in notes), result.stderr
    again = pd.read_parquet(sweep_folder / "results.parquet")
    assert list(again["run_key"]) == list(rows["run_key"])  # the lost run was run again
    assert sorted(p.name for p in (sweep_folder / "parts").iterdir()) == [
        part.name + ".unreadable", junk.name + ".unreadable"
    ]


# ---- killed runs leave no temporary folders ----------------------------------------------


def _entries(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def test_a_killed_process_s_temporary_folders_are_removed_by_the_next_write(tmp_path):
    dead = 2**22 + 12345  # above Linux's pid_max default: no such process
    (tmp_path / f".out.tmp-{dead}-0123456789ab").mkdir()
    (tmp_path / f".out.tmp-{dead}-0123456789ab" / "timeseries.parquet").write_text("partial")
    (tmp_path / f".other.tmp-{dead}-0123456789ab").mkdir()  # another folder's: left alone
    (tmp_path / f".out.tmp-{os.getpid()}-0123456789ab").mkdir()  # a running process's: left alone
    write_atomically(tmp_path / "out", lambda folder: (folder / "a.txt").write_text("a"), "run")
    assert _entries(tmp_path) == sorted(
        [f".other.tmp-{dead}-0123456789ab", f".out.tmp-{os.getpid()}-0123456789ab", "out"]
    )
    # a swap cut short: the old folder is put back before the new one is written
    (tmp_path / "out").rename(tmp_path / f".out.old-{dead}-0123456789ab")
    write_atomically(tmp_path / "out", lambda folder: (folder / "b.txt").write_text("b"), "run")
    assert (tmp_path / "out" / "b.txt").is_file() and not list(tmp_path.glob(".out.old-*"))


def _cli(*args: str, cwd: Path) -> subprocess.Popen:
    package_root = str(Path(hc.__file__).resolve().parent.parent)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [package_root, os.environ.get("PYTHONPATH")])))
    return subprocess.Popen([sys.executable, "-m", "hilcontact", *args], cwd=cwd, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL], ids=["SIGTERM", "SIGKILL"])
def test_a_run_killed_while_writing_leaves_no_temporary_folder(core, tmp_path, sig):
    args = ("run", "paper-table1", "--set", "simulation.duration=2", "--out", "out")
    proc = _cli(*args, cwd=tmp_path)
    deadline = time.monotonic() + 120
    while not list(tmp_path.glob(".out.tmp-*")) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.005)
    if proc.poll() is not None:
        pytest.skip("the run finished before its staging folder was seen")
    proc.send_signal(sig)
    proc.wait(timeout=60)
    assert proc.returncode != 0
    if sig == signal.SIGTERM:
        assert "Traceback" not in proc.stderr.read()
        # removed on the way out (the complete folder if the signal came after the swap)
        assert _entries(tmp_path) in ([], ["out"])
        assert not (tmp_path / "out").exists() or (tmp_path / "out" / MARKER).is_file()
    else:
        assert _entries(tmp_path) != []  # nothing can run on SIGKILL: the next write tidies up
        again = _cli(*args, "--no-plots", cwd=tmp_path)
        assert again.wait(timeout=120) == 0, again.stderr.read()
        assert _entries(tmp_path) == ["out"]


# ---- property: any mutation of a preset is one clear line or a finite result --------------

hypothesis = pytest.importorskip("hypothesis")
st = hypothesis.strategies


def _leaves(data, prefix: str = "") -> list[str]:
    """The dotted keys of a resolved scenario: every table, value and list item."""
    keys = []
    if isinstance(data, dict):
        for key, value in data.items():
            path = f"{prefix}.{key}" if prefix else key
            keys.append(path)
            keys += _leaves(value, path)
    elif isinstance(data, list):
        for i, value in enumerate(data):
            keys += _leaves(value, f"{prefix}[{i}]")
    return keys


def _toml(value) -> str:
    """A value as the TOML text of a --set (NaN and ±inf as TOML writes them)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "nan" if value != value else "inf" if value == float("inf") else "-inf" if value == float("-inf") else repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {_toml(v)}" for k, v in value.items()) + "}"
    return str(value)


PRESETS = {name: hc.load_scenario(name).to_dict() for name in hc.presets()}
KEYS = sorted({k for data in PRESETS.values() for k in _leaves(data)} | {"bogus", "contact.bogus", "walls[5].point"})
NESTED: list = [1.0]
for _ in range(40):
    NESTED = [NESTED]
EXTREMES = [
    0, -1, 1, 3, 1e308, -1e308, 1e-308, 1e-320, 2**70, -(2**70), 2**32, 2**64, 1e300, 1e11, 1e-7, 5500,
    float("nan"), float("inf"), float("-inf"), "text", "", "n" * 300, "a\x00b", "a/b", "..", True, [],
    [1e308, 0, 0], [float("nan")] * 3, [0.0, 0.0, 0.0, 0.0], [1e-300, 1, 1], {"x": 1}, {"kind": "pida"}, NESTED,
]
VALUES = (
    st.sampled_from(EXTREMES)
    | st.floats(min_value=1e-3, max_value=10.0)  # often valid: those must run
    | st.integers(min_value=0, max_value=20)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.integers(min_value=-(2**80), max_value=2**80)
    | st.text(max_size=12)
    | st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=4)
)


@hypothesis.settings(
    max_examples=120,
    derandomize=True,
    database=None,
    deadline=None,
    suppress_health_check=list(hypothesis.HealthCheck),
)
@hypothesis.given(
    preset=st.sampled_from(sorted(PRESETS)),
    mutations=st.lists(st.tuples(st.sampled_from(KEYS), VALUES), min_size=1, max_size=3),
)
def test_any_mutation_of_a_preset_is_one_line_exit_2_or_a_finite_result(core, preset, mutations):
    sets = [a for key, value in mutations for a in ("--set", f"{key}={_toml(value)}")]
    result = invoke("show", preset, *sets)
    assert "Traceback" not in result.output + result.stderr
    if result.exit_code != 0:
        hypothesis.event("refused")
        assert_one_error_line(result)
        return
    hypothesis.event("valid")
    # valid: it runs to a finite result (on a short run: the mutated duration was validated)
    scenario = hc.Scenario.from_toml(result.stdout)
    f = scenario.facility
    duration = max(min(scenario.simulation.duration, 0.3), f.robot_delay, f.sensor_delay, scenario.simulation.period)
    run = hc.simulate(hc.load_scenario(scenario, {"simulation.duration": duration}))
    json.dumps(run.metrics, allow_nan=False)  # every number in metrics.json is finite
    assert run.status in ("ok", "unfaithful", "diverged")
    assert run.reference.notna().all().all() and (run.reference.abs() < float("inf")).all().all()
