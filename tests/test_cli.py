"""The command line: presets, show, --set parsing, and bad input (exit 2, one line, no writes)."""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from click.testing import CliRunner

import hilcontact as hc
from hilcontact.cli import cli, parse_set_options


def invoke(*args: str, cwd: Path | None = None):
    runner = CliRunner()
    if cwd is None:
        return runner.invoke(cli, list(args), prog_name="hilcontact")
    old = os.getcwd()
    os.chdir(cwd)
    try:
        return runner.invoke(cli, list(args), prog_name="hilcontact")
    finally:
        os.chdir(old)


def assert_one_error_line(result, *fragments: str) -> str:
    assert result.exit_code == 2, (result.exit_code, result.output, result.stderr)
    assert "Traceback" not in result.output and "Traceback" not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("error: ")
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    assert result.stdout == ""
    return lines[0]


# ---- --set parsing ------------------------------------------------------------------------


def test_parse_set_options_values():
    parsed = parse_set_options(
        [
            "facility.robot_delay=0.02",
            "facility.seed=3",
            "facility.round_delays=true",
            "servicer.velocity=[0.01, 0, 0]",
            "compensator.kind=none",
            'description="quoted text"',
            "name = spaced name ",
            "walls[0].point=[1,2,3]",
            "facility.robot_delay=0.004",  # last one wins
        ]
    )
    assert parsed == {
        "facility.robot_delay": 0.004,
        "facility.seed": 3,
        "facility.round_delays": True,
        "servicer.velocity": [0.01, 0, 0],
        "compensator.kind": "none",
        "description": "quoted text",
        "name": "spaced name",
        "walls[0].point": [1, 2, 3],
    }
    assert type(parsed["facility.seed"]) is int


@pytest.mark.parametrize("item", ["facility.robot_delay", "=3", ""])
def test_parse_set_options_rejects_missing_key_or_equals(item):
    with pytest.raises(hc.ScenarioError, match="expected KEY=VALUE"):
        parse_set_options([item])


# ---- presets / show / version -------------------------------------------------------------


def test_presets_command_lists_every_preset():
    result = invoke("presets")
    assert result.exit_code == 0, result.output
    lines = result.stdout.strip().splitlines()
    listing = hc.presets()
    assert len(lines) == len(listing)
    for line, (name, description) in zip(lines, listing.items()):
        assert line.split()[0] == name
        assert line.endswith(description)


def test_show_prints_resolved_toml():
    result = invoke("show", "paper-table1", "--set", "facility.robot_delay=0.02", "--set", "metrics.contact_threshold=1")
    assert result.exit_code == 0, result.stderr
    data = tomllib.loads(result.stdout)
    expected = hc.load_scenario("paper-table1", {"facility.robot_delay": 0.02, "metrics.contact_threshold": 1})
    assert data == expected.to_dict()
    assert data["facility"]["robot_delay"] == 0.02
    assert data["servicer"]["inertia"] == [[98.0, 0.0, 0.0], [0.0, 98.0, 0.0], [0.0, 0.0, 98.0]]
    assert hc.Scenario.from_toml(result.stdout) == expected


def test_show_accepts_a_file(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(hc.load_scenario("paper-table1", {"name": "from-file"}).to_toml(), encoding="utf-8")
    result = invoke("show", str(path))
    assert result.exit_code == 0
    assert tomllib.loads(result.stdout)["name"] == "from-file"


def test_version():
    result = invoke("--version")
    assert result.exit_code == 0
    assert result.stdout.startswith(f"hilcontact {hc.__version__} (core ")


def test_help_lists_commands():
    result = invoke("--help")
    assert result.exit_code == 0
    for command in ("run", "compare", "presets", "show"):
        assert command in result.stdout


# ---- bad input ----------------------------------------------------------------------------

BAD_RUNS = [
    (["--set", "servicer.mass=-3"], ["servicer.mass", "between 0.001 and 1e7"]),
    (["--set", "servicer.mas=3"], ["servicer.mas", "unknown key", "allowed keys in [servicer]"]),
    (["--set", "simulation.duration=abc"], ["simulation.duration: expected a number, got 'abc'"]),
    (["--set", "simulation.period=0"], ["simulation.period", "between 1e-6 and 1"]),
    (["--set", "walls[1].normal=[0,0,0]"], ["walls[1].normal", "nonzero"]),
    (["--set", "facility.robot_delay=0.0125"], ["facility.robot_delay = 0.0125 s is not a whole number of periods",
                                                 "use 0.012 or 0.013"]),
    (["--set", "compensator.kind=magic"], ["compensator.kind", "'magic'", "'none'"]),
    (["--set", "nonsense"], ["--set 'nonsense': expected KEY=VALUE"]),
]


@pytest.mark.parametrize(("args", "fragments"), BAD_RUNS, ids=[a[-1] for a, _ in BAD_RUNS])
def test_run_rejects_bad_input_and_writes_nothing(tmp_path, args, fragments):
    out = tmp_path / "out"
    result = invoke("run", "paper-table1", *args, "--out", str(out), cwd=tmp_path)
    assert_one_error_line(result, *fragments)
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no runs/ folder, no temp folder


def test_run_rejected_keeps_existing_folder_untouched(tmp_path):
    out = tmp_path / "existing"
    out.mkdir()
    (out / "metrics.json").write_text("old results\n")
    (out / "notes.txt").write_text("keep me\n")
    before = {p.name: p.read_text() for p in out.iterdir()}
    result = invoke("run", "paper-table1", "--set", "servicer.mass=0", "--out", str(out))
    assert_one_error_line(result, "servicer.mass")
    assert {p.name: p.read_text() for p in out.iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["existing"]


def test_run_unknown_preset(tmp_path):
    result = invoke("run", "does-not-exist", cwd=tmp_path)
    assert_one_error_line(result, "unknown scenario 'does-not-exist'", "paper-table1")
    assert list(tmp_path.iterdir()) == []


def test_run_invalid_toml_file(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text('name = "x"\n\n[simulation\nduration = 1\n')
    result = invoke("run", str(path), "--out", str(tmp_path / "out"))
    assert_one_error_line(result, "bad.toml: invalid TOML", "line 3")
    assert not (tmp_path / "out").exists()


def test_run_file_missing_required_value(tmp_path):
    text = hc.load_scenario("paper-table1").to_toml().replace("mass = 300.0\n", "")
    path = tmp_path / "nomass.toml"
    path.write_text(text)
    out = tmp_path / "out"
    result = invoke("run", str(path), "--out", str(out))
    assert_one_error_line(result, "servicer.mass: missing required value (kg, 0.001 to 1e7)")
    assert not out.exists()


def test_run_out_is_a_file(tmp_path):
    target = tmp_path / "afile"
    target.write_text("x")
    result = invoke("run", "paper-table1", "--out", str(target))
    assert_one_error_line(result, "exists and is not a directory")
    assert target.read_text() == "x"


def test_show_rejects_bad_input():
    result = invoke("show", "paper-table1", "--set", "contact.model=hertz")
    assert_one_error_line(result, "contact.model: must be one of 'linear' or 'hunt-crossley', got 'hertz'")


def test_console_script_entry_point_reports_errors_without_traceback(tmp_path):
    """The real entry point (python -m hilcontact), not just click's test runner."""
    # the same hilcontact as this test process (installed, or a source tree on PYTHONPATH)
    package_root = str(Path(hc.__file__).resolve().parent.parent)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [package_root, os.environ.get("PYTHONPATH")])))
    proc = subprocess.run(
        [sys.executable, "-m", "hilcontact", "run", "paper-table1", "--set", "target.mass=0", "--out", "o"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2, proc.stderr
    assert proc.stdout == ""
    assert proc.stderr.strip().splitlines() == ["error: target.mass: must be between 0.001 and 1e7, got 0"]
    assert list(tmp_path.iterdir()) == []


def test_scenario_error_from_the_core_is_reported_like_bad_input(monkeypatch, tmp_path):
    """An invalid scenario that slips past Python validation is rejected by the core with a
    ScenarioError: same one-line report, exit code 2, nothing written."""

    class Core:
        @staticmethod
        def simulate(scenario_json: str):
            raise hc.ScenarioError("walls[0].normal: rejected by the core")

    monkeypatch.setattr("hilcontact.run._core", lambda: Core)
    out = tmp_path / "o"
    result = invoke("run", "paper-table1", "--out", str(out))
    assert_one_error_line(result, "error: walls[0].normal: rejected by the core")
    assert list(tmp_path.iterdir()) == []
