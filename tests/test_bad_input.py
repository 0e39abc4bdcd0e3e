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
from collections.abc import Mapping
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


# ---- the last round's leftovers (issue 25, item 10) ----------------------------------------

DIGITS = "1" * 5000  # above Python's limit on the digits of an integer (4300)


def test_a_5000_digit_number_is_one_line_naming_the_key(tmp_path):
    result = invoke("run", "paper-table1", "--set", f"facility.robot_delay={DIGITS}", "--out", "o", cwd=tmp_path)
    assert_one_error_line(result, "--set facility.robot_delay", "more than 4300 digits")
    path = tmp_path / "long.toml"
    path.write_text(hc.load_scenario("paper-table1").to_toml().replace("robot_delay = 0.01", f"robot_delay = {DIGITS}"))
    assert f"robot_delay = {DIGITS}" in path.read_text()
    result = invoke("run", str(path), "--out", "o", cwd=tmp_path)
    assert_one_error_line(result, "long.toml", "facility.robot_delay", "more than 4300 digits")
    result = invoke("sweep", "paper-table1", "--grid", f"facility.robot_delay=0.01,{DIGITS}", "--out", "s", cwd=tmp_path)
    assert_one_error_line(result, "--grid facility.robot_delay", "more than 4300 digits")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["long.toml"]
    # from the API: a Python integer of 5000 digits is a value like any other, named by its key
    with pytest.raises(hc.ScenarioError, match=r"^facility\.robot_delay: .*digits"):
        hc.load_scenario("paper-table1", {"facility.robot_delay": 10**4999})


@pytest.mark.parametrize("key", ["facility.force_resolution", "facility.torque_resolution"])
def test_a_tiny_quantisation_step_is_refused_and_0_or_a_real_step_runs(tmp_path, key):
    for value in ("1e-308", "5e-324", "1e-10"):
        result = invoke("run", "paper-table1", "--set", f"{key}={value}", *SHORT, "--out", "o", cwd=tmp_path)
        assert_one_error_line(result, key, "must be 0 (none) or >= 1e-9")
        with pytest.raises(hc.ScenarioError, match="must be 0 \\(none\\) or >= 1e-9"):
            hc.load_scenario("paper-table1", {key: float(value)})
    assert list(tmp_path.iterdir()) == []
    # the core refuses it too (a scenario that bypasses Python's models)
    data = hc.load_scenario("paper-table1").to_dict()
    section, name = key.split(".")
    data[section][name] = 1e-308
    with pytest.raises(hc.ScenarioError) as info:
        hc.native.core().resolve_scenario(json.dumps(data))
    assert [m for k, m in info.value.issues if k == key][0].startswith("must be 0 (none) or >= 1e-9, got 1e-308")
    for value in (0.0, 1e-9, 0.5):
        run = hc.simulate(hc.load_scenario("paper-table1", {key: value, "simulation.duration": 0.3}))
        assert run.timeseries.notna().all().all() and run.status in ("ok", "unfaithful", "diverged")


def _bare(tmp_path: Path) -> list[str]:
    return sorted(p.name for p in tmp_path.iterdir())


QUICK = {"simulation.duration": 0.3}


@pytest.mark.parametrize(
    ("call", "name"),
    [
        (lambda out: hc.sweep("paper-table1", ["servicer.mass=300"], "none", out=out, threads="x", overrides=QUICK), "threads"),
        (lambda out: hc.sweep("paper-table1", ["servicer.mass=300"], "none", out=out, threads=100000, overrides=QUICK), "threads"),
        (lambda out: hc.sweep("paper-table1", ["servicer.mass=300"], "none", out=out, threads=0, overrides=QUICK), "threads"),
        (lambda out: hc.sweep("paper-table1", ["servicer.mass=300"], "none", out=out, overrides=["simulation.duration=0.3"]), "overrides"),
        (lambda out: hc.sweep("paper-table1", {"facility.robot_delay": [0.01, 0.01]}, "none", out=out, overrides=QUICK), "--grid facility.robot_delay"),
        (lambda out: hc.sweep("paper-table1", ["servicer.mass=300"], "none", out=out, chunk_size=-1, overrides=QUICK), "chunk_size"),
        (lambda out: hc.sweep("paper-table1", ["servicer.mass=300"], "none", out=out, chunk_size=2.5, overrides=QUICK), "chunk_size"),
        (lambda out: hc.sweep("paper-table1", 5, "none", out=out, overrides=QUICK), "grid"),
        (lambda out: hc.sweep("paper-table1", ["servicer.mass=300"], 5, out=out, overrides=QUICK), "compensators"),
        (lambda out: hc.sweep("paper-table1", ["servicer.mass=300"], "none", out=out, progress=3, overrides=QUICK), "progress"),
        (lambda out: hc.sweep("paper-table1", ["servicer.mass=300"], "none", out=out, flush_seconds=float("nan"), overrides=QUICK), "flush_seconds"),
        (lambda out: hc.sweep("paper-table1", ["servicer.mass=300"], "none", out=out, dask=7, overrides=QUICK), "dask"),
        (lambda out: hc.compare("paper-table1", 5, QUICK), "kinds"),
        (lambda out: hc.compare("paper-table1", "none", ["simulation.duration=0.3"]), "overrides"),
        (lambda out: hc.compare(5, "none", QUICK), "scenario"),
        (lambda out: hc.load_scenario("paper-table1", [("simulation.duration", 0.3)]), "overrides"),
        (lambda out: hc.simulate("paper-table1", outputs=["mcap"]), "outputs"),
        (lambda out: hc.stability_map(out), "results"),
        (lambda out: hc.stability_map(pd.DataFrame()), "results"),
        (lambda out: hc.stability_map(pd.DataFrame(columns=hc.sweep.__globals__["RESULT_COLUMNS"])), "results"),
        (lambda out: hc.stability_map(5), "results"),
        (lambda out: hc.stability_map(_ROWS(), cov_tolerance="x"), "cov_tolerance"),
        (lambda out: hc.stability_map(_ROWS(), cof_limit=-1), "cof_limit"),
    ],
    ids=["threads x", "threads 100000", "threads 0", "overrides list", "grid repeats", "chunk_size -1",
         "chunk_size 2.5", "grid 5", "compensators 5", "progress 3", "flush nan", "dask 7", "compare kinds 5",
         "compare overrides list", "compare scenario 5", "load overrides list", "outputs list", "map of a missing folder",
         "map of an empty frame", "map of no rows", "map of 5", "cov_tolerance x", "cof_limit -1"],
)
def test_bad_api_arguments_raise_the_package_s_value_error_naming_them(tmp_path, call, name):
    out = tmp_path / "out"
    with pytest.raises(hc.HilContactError) as info:
        call(out)
    assert isinstance(info.value, ValueError), type(info.value)
    message = str(info.value)
    assert message.startswith(name) and "\n" not in message, message
    assert _bare(tmp_path) == []  # nothing written


def _ROWS() -> pd.DataFrame:
    from test_sweep import _synthetic_rows

    return _synthetic_rows()


def test_dask_without_dask_installed_is_the_package_s_error(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "dask", None)  # import dask -> ImportError
    monkeypatch.setitem(sys.modules, "dask.distributed", None)
    with pytest.raises(hc.errors.ArgumentError, match="^dask: needs dask.distributed"):
        hc.sweep("paper-table1", ["servicer.mass=300"], "none", out=tmp_path / "s", dask="local", overrides=QUICK)
    assert _bare(tmp_path) == []
    result = invoke("sweep", "paper-table1", "--grid", "servicer.mass=300", "--compensators", "none",
                    "--dask", "local", "--out", "s", cwd=tmp_path)
    assert_one_error_line(result, "dask: needs dask.distributed", "pip install")
    assert _bare(tmp_path) == []


def test_stability_map_cli_on_a_missing_or_empty_folder_is_one_line(tmp_path):
    assert_one_error_line(invoke("stability-map", str(tmp_path / "nope")), "nope")
    (tmp_path / "empty").mkdir()
    assert_one_error_line(invoke("stability-map", str(tmp_path / "empty")), "no sweep results")
    assert _bare(tmp_path) == ["empty"] and list((tmp_path / "empty").iterdir()) == []


# ---- property: any argument of the Python API works or is the package's error naming it -----

hypothesis_api = pytest.importorskip("hypothesis")
st_api = hypothesis_api.strategies

#: Values of any type an argument might be given by mistake.
ANY_VALUE = (
    st_api.sampled_from([None, True, False, 0, -1, 1, 2, 5, 2**70, 10**5000, 0.5, -0.5, float("nan"),
                         float("inf"), 1e-308, "", "x", "none", "none,pida", "pida,", "local", "0.01,0.02",
                         [], [0.01, 0.01], ["none"], ["servicer.mass=300"], [1, "a"], {}, {"a": 1},
                         {"servicer.mass": [300, 300]}, (300,), b"none", object(), print, pd.DataFrame()])
    | st_api.integers(min_value=-(2**40), max_value=2**40)
    | st_api.floats(allow_nan=True, allow_infinity=True)
    | st_api.text(max_size=8)
)

#: Each function's arguments: the baseline (a valid call) and the names an error may name for
#: a bad value of each argument (the argument, or the scenario keys it carries).
API_CALLS = {
    "simulate": ({"scenario": "paper-table1", "mcap": None, "overwrite": False, "outputs": None},
                 {"scenario": ("scenario", "unknown scenario", "preset"), "mcap": ("mcap",), "overwrite": ("overwrite",),
                  "outputs": ("outputs", "options", "mcap")}),
    "compare": ({"scenario_source": "paper-table1", "kinds": "none", "overrides": None, "progress": None},
                {"scenario_source": ("scenario", "unknown scenario", "preset"), "kinds": ("kinds",),
                 "overrides": ("overrides", "invalid override key"), "progress": ("progress",)}),
    "sweep": ({"scenario": "paper-table1", "grid": ["servicer.mass=300"], "compensators": "none", "seeds": 1,
               "out": None, "threads": None, "chunk_size": None, "dask": None, "progress": None, "resume": False,
               "flush_seconds": 5.0},
              {"scenario": ("scenario", "unknown scenario", "preset"), "grid": ("grid", "--grid"),
               "compensators": ("compensators",), "seeds": ("--seeds",), "out": ("out", "--out"),
               "threads": ("threads",), "chunk_size": ("chunk_size",), "dask": ("dask",), "progress": ("progress",),
               "resume": ("resume",), "flush_seconds": ("flush_seconds",)}),
    "stability_map": ({"results": "ROWS", "cov_tolerance": None, "cof_limit": None},
                      {"results": ("results",), "cov_tolerance": ("cov_tolerance",), "cof_limit": ("cof_limit",)}),
}


@hypothesis_api.settings(max_examples=150, derandomize=True, database=None, deadline=None,
                         suppress_health_check=list(hypothesis_api.HealthCheck))
@hypothesis_api.given(data=st_api.data())
def test_any_argument_of_the_api_works_or_is_the_package_s_error_naming_it(core, tmp_path_factory, data):
    function = data.draw(st_api.sampled_from(sorted(API_CALLS)), label="function")
    baseline, names = API_CALLS[function]
    argument = data.draw(st_api.sampled_from(sorted(names)), label="argument")
    value = data.draw(ANY_VALUE, label="value")
    if argument == "dask" and isinstance(value, str):
        value = None  # an address would connect (or start a cluster): tested on its own
    kwargs = dict(baseline)
    if function == "stability_map":
        kwargs["results"] = _ROWS()
    folder = tmp_path_factory.mktemp("api")
    kwargs[argument] = value
    if argument in ("out", "mcap") and isinstance(value, str):
        kwargs[argument] = str(folder / ("p" + value.replace("/", "_")))  # always inside the test's folder
    if function == "simulate":
        call = lambda: hc.simulate(hc.load_scenario("paper-table1", QUICK) if kwargs["scenario"] == "paper-table1" else kwargs["scenario"],  # noqa: E731
                                   **{k: v for k, v in kwargs.items() if k != "scenario"})
    elif function == "compare":
        if kwargs["overrides"] is None:
            kwargs["overrides"] = QUICK
        call = lambda: hc.compare(**kwargs)  # noqa: E731
    elif function == "sweep":
        kwargs["overrides"] = QUICK
        call = lambda: hc.sweep(**kwargs)  # noqa: E731
    else:
        call = lambda: hc.stability_map(**kwargs)  # noqa: E731
    try:
        call()
    except hc.HilContactError as exc:
        assert isinstance(exc, ValueError), (function, argument, value, type(exc), exc)
        message = str(exc)
        assert "\n" not in message
        if isinstance(value, Mapping) and argument in ("scenario", "scenario_source"):
            hypothesis_api.event("refused (raw scenario data: its keys are named)")
            return
        acceptable = names[argument] + (tuple(map(str, value)) if isinstance(value, Mapping) else ())
        assert any(name in message for name in acceptable), (function, argument, value, message)
        hypothesis_api.event("refused")
        return
    hypothesis_api.event("worked")


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
