"""`compare --delays`: a comparison per robot delay, figures with (a), (b), … panels."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from click.testing import CliRunner

import hilcontact as hc
from hilcontact.cli import cli
from hilcontact.comparison import DELAY_FIGURES, compare_over_delays, parse_delays

SHORT = {"simulation.duration": 1.5}


def invoke(*args: str, cwd: Path | None = None):
    old = os.getcwd()
    if cwd is not None:
        os.chdir(cwd)
    try:
        return CliRunner().invoke(cli, list(args), prog_name="hilcontact")
    finally:
        os.chdir(old)


def test_parse_delays():
    assert parse_delays("0.01, 0.02,0.01") == [0.01, 0.02]
    for bad, fragment in (("x", "not a number"), ("-0.01", "between 0 and 60"), (" , ", "no delay given"),
                          ("nan", "between 0 and 60"), (",".join(str(i / 100) for i in range(9)), "at most 8")):
        with pytest.raises(hc.ScenarioError, match=fragment):
            parse_delays(bad)


def test_one_comparison_per_delay_and_panels_per_delay(core):
    result = compare_over_delays("paper-table1", [0.01, 0.02], "none,pida", SHORT)
    assert list(result.comparisons) == [0.01, 0.02]
    for delay, comparison in result.comparisons.items():
        assert list(comparison.runs) == ["none", "pida"]
        assert all(run.scenario.facility.robot_delay == delay for run in comparison.runs.values())
    figures = result.plot()
    assert list(figures) == list(DELAY_FIGURES)
    velocity = [ax for ax in figures["compare_velocity"].axes if ax.get_visible()]
    assert [ax.get_title() for ax in velocity] == ["(a) robot delay 10 ms", "(b) robot delay 20 ms"]
    bars = figures["compare_cov_cof"].axes
    assert [ax.get_title() for ax in bars[:2]] == ["(a) robot delay 10 ms", "(b) robot delay 20 ms"]
    report = result.to_markdown()
    assert report.index("## (a) robot delay 10 ms") < report.index("## (b) robot delay 20 ms")
    for comparison in result.comparisons.values():
        assert comparison.recommendation.replace("|", "\\|") in report  # pipes escaped in Markdown


def test_cli_compare_delays(core, tmp_path):
    out = tmp_path / "cmp"
    result = invoke("compare", "paper-table1", "--delays", "0.01,0.02", "--compensators", "none,pida",
                    "--set", "simulation.duration=1.5", "--out", str(out))
    assert result.exit_code == 0, (result.output, result.stderr)
    names = {p.name for p in out.iterdir()}
    assert {"10ms", "20ms", "comparison.md", "compare_velocity.png", "compare_force.png", "compare_cov_cof.png"} <= names
    for label in ("10ms", "20ms"):
        assert (out / label / "comparison.md").is_file() and (out / label / "pida" / "metrics.json").is_file()
    assert result.stdout.count("recommendation:") == 2
    assert "robot delay 10 ms" in result.stdout and "robot delay 20 ms" in result.stdout


@pytest.mark.parametrize(("args", "fragment"), [
    (["--delays", "0.01,abc"], "--delays: 'abc' is not a number"),
    (["--delays", "0.01", "--set", "facility.robot_delay=0.02"], "set the delays with --delays"),
    (["--delays", "0.0105"], "facility.robot_delay"),
])
def test_cli_compare_delays_rejects_bad_input_and_writes_nothing(tmp_path, args, fragment):
    result = invoke("compare", "paper-table1", *args, "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert result.exit_code == 2, (result.output, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and fragment in lines[0], result.stderr
    assert list(tmp_path.iterdir()) == []
