"""Comparing compensators: scenarios per kind, tables, report, figures, atomic save, CLI.

The synthetic tests need no core. The integration tests run every compensator through the
real core and check the structure only (the fidelity numbers are tested with the core).
"""

from __future__ import annotations

import io
import json
import math
import os
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner
from conftest import synthetic_run

import hilcontact as hc
from hilcontact.cli import cli
from hilcontact.output import MARKER, OutputError
from hilcontact.comparison import (
    ALL_KINDS,
    SUMMARY_COLUMNS,
    TABLE_COLUMNS,
    Comparison,
    comparison_scenarios,
    parse_kinds,
)
from hilcontact.run import OPTIONAL_TIMESERIES_COLUMNS, REFERENCE_COLUMNS, TIMESERIES_COLUMNS

KINDS = ["none", "pic", "dac", "pida", "tdpa-impedance", "tdpa-admittance", "model-mediated"]
IDENTIFYING = {"pic", "dac", "pida", "model-mediated"}
RUN_FILES = {"timeseries.parquet", "reference.parquet", "metrics.json", "scenario.toml", MARKER}
RUN_PLOTS = {"contact_velocity.png", "contact_force.png", "energy.png"}
COMPARE_PLOTS = {
    "compare_velocity.png",
    "compare_force.png",
    "compare_energy.png",
    "compare_identification.png",
    "compare_cov_cof.png",
    "compare_measured_applied.png",
}
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def invoke(*args: str, cwd: Path | None = None):
    old = os.getcwd()
    if cwd is not None:
        os.chdir(cwd)
    try:
        return CliRunner().invoke(cli, list(args), prog_name="hilcontact")
    finally:
        os.chdir(old)


# ---- kinds and scenarios (no core) ----------------------------------------------------------


def test_all_kinds_in_order():
    assert list(ALL_KINDS) == KINDS


def test_parse_kinds():
    assert parse_kinds(None) == KINDS
    assert parse_kinds("pida, none,pida") == ["pida", "none"]
    assert parse_kinds(["tdpa-admittance", "pic"]) == ["tdpa-admittance", "pic"]
    with pytest.raises(hc.ScenarioError, match="unknown compensator 'pdia'; allowed: none, pic, dac, pida"):
        parse_kinds("none,pdia")
    with pytest.raises(hc.ScenarioError, match="none given"):
        parse_kinds(" , ")


def test_comparison_scenarios_differ_only_in_the_compensator():
    scenarios = comparison_scenarios("paper-table1", overrides={"facility.robot_delay": 0.02})
    assert list(scenarios) == KINDS
    dumps = []
    for kind, scenario in scenarios.items():
        assert scenario.compensator.kind == kind
        assert scenario.facility.robot_delay == 0.02
        data = scenario.to_dict()
        data.pop("compensator")
        dumps.append(data)
    assert all(d == dumps[0] for d in dumps)


def test_compensator_parameter_overrides_go_to_the_kinds_that_have_them():
    scenarios = comparison_scenarios(
        "paper-table1",
        "none,pic,tdpa-impedance,tdpa-admittance",
        {"compensator.forgetting": 0.9, "compensator.beta_max": 2e-5, "compensator.alpha_max": 50.0},
    )
    assert scenarios["none"].to_dict()["compensator"] == {"kind": "none"}
    assert scenarios["pic"].compensator.forgetting == 0.9 and scenarios["pic"].compensator.alpha_max == 50.0
    for kind in ("tdpa-impedance", "tdpa-admittance"):
        assert scenarios[kind].compensator.beta_max == 2e-5 and scenarios[kind].compensator.alpha_max == 50.0
    # a parameter no compared kind has is an error, not silently dropped
    with pytest.raises(hc.ScenarioError, match=r"^compensator\.forgetting: unknown key"):
        comparison_scenarios("paper-table1", "none,tdpa-impedance", {"compensator.forgetting": 0.9})
    with pytest.raises(hc.ScenarioError, match=r"^compensator\.alpha_mx: unknown key"):
        comparison_scenarios("paper-table1", "pida", {"compensator.alpha_mx": 1.0})


def test_comparison_rejects_a_kind_override_and_bad_input():
    with pytest.raises(hc.ScenarioError, match=r"^compensator\.kind: .*--compensators"):
        comparison_scenarios("paper-table1", None, {"compensator.kind": "pida"})
    with pytest.raises(hc.ScenarioError, match=r"^servicer\.mass: must be between 0\.001"):
        comparison_scenarios("paper-table1", None, {"servicer.mass": -1.0})


def test_compare_validates_everything_before_running(monkeypatch):
    calls = []
    monkeypatch.setattr("hilcontact.comparison.simulate", lambda scenario: calls.append(scenario))
    with pytest.raises(hc.ScenarioError, match="compensator.noise_std: must be > 0 and <= 1e6"):
        hc.compare("paper-table1", overrides={"compensator.noise_std": 0.0})
    assert calls == []


# ---- tables, report, figures, save (synthetic runs, no core) -------------------------------


def fake_comparison(kinds=("none", "pic", "pida", "tdpa-impedance")) -> Comparison:
    runs = {}
    for kind in kinds:
        run = synthetic_run(estimates=kind in IDENTIFYING)
        run.metrics = json.loads(json.dumps(run.metrics))
        run.metrics["compensator"] = kind
        run.scenario = hc.load_scenario("paper-table1", {"compensator.kind": kind})
        if kind == "none":
            run.metrics.update(status="diverged", diverged_at=0.9, reason="energy divergence")
            run.metrics["collisions"][0]["cov"] = 3.0
            run.metrics["collisions"].append(
                {"index": 3, "start": 0.8, "end": 0.85, "peak_force": 400.0, "rebound_speed": 0.05,
                 "cov": 4.0, "cof": 0.5}
            )
            run.metrics["summary"] = {"collisions": 3, "mean_cov": 3.5, "worst_cov": 4.0, "mean_cof": 0.85, "worst_cof": 0.5}
        if kind == "pida":
            run.metrics["identification"] = {"stiffness_error": 0.0043, "damping_error": 320.0, "samples": 10}
            run.timeseries["observed_energy"] = np.where(run.timeseries["time"] > 0.5, 0.01, np.nan)
        if kind == "tdpa-impedance":
            run.timeseries["observed_energy"] = np.nan  # present but never observed
        runs[kind] = run
    return Comparison(runs=runs)


def test_summary_one_row_per_compensator():
    comparison = fake_comparison()
    summary = comparison.summary
    assert list(summary.index) == ["none", "pic", "pida", "tdpa-impedance"]
    assert summary.index.name == "compensator"
    assert list(summary.columns) == SUMMARY_COLUMNS
    none = summary.loc["none"]
    assert none["status"] == "diverged" and none["diverged_at"] == 0.9 and none["collisions"] == 3
    assert none["cov"][0] == 3.0 and math.isnan(none["cov"][1]) and none["cov"][2] == 4.0
    assert none["mean_cov"] == pytest.approx(3.5)
    assert none["worst_cov_error"] == pytest.approx(3.0)
    assert none["worst_cof"] == pytest.approx(0.5)  # the farthest from 1: |0.5-1| > |1.2-1|
    assert math.isnan(none["stiffness_error_pct"]) and math.isnan(none["damping_error_Ns_mm"])
    pida = summary.loc["pida"]
    assert pida["status"] == "ok" and math.isnan(pida["diverged_at"])
    assert pida["stiffness_error_pct"] == pytest.approx(0.43)
    assert pida["damping_error_Ns_mm"] == pytest.approx(0.32)
    assert pida["worst_cof"] == pytest.approx(1.2) and pida["worst_cov_error"] == pytest.approx(0.25)


def test_table_one_row_per_compensator_and_collision():
    comparison = fake_comparison()
    table = comparison.table
    assert list(table.columns) == TABLE_COLUMNS
    assert len(table) == 3 + 2 + 2 + 2
    assert list(table["compensator"]) == ["none"] * 3 + ["pic"] * 2 + ["pida"] * 2 + ["tdpa-impedance"] * 2
    assert list(table.loc[table["compensator"] == "none", "collision"]) == [1, 2, 3]
    first = table.iloc[0]
    assert first["cov"] == 3.0 and first["cof"] == 1.2 and first["peak_force_N"] == 120.0
    assert first["rebound_speed_mm_s"] == pytest.approx(25.0)
    assert first["status"] == "diverged" and first["worst_cov_error"] == pytest.approx(3.0)
    pida = table[table["compensator"] == "pida"]
    assert np.allclose(pida["stiffness_error_pct"], 0.43)
    assert table.loc[table["compensator"] == "pic", "stiffness_error_pct"].isna().all()


def test_compensator_without_collisions_still_gets_a_row():
    comparison = fake_comparison(("none", "pida"))
    comparison.runs["pida"].metrics["collisions"] = []
    table = comparison.table
    row = table[table["compensator"] == "pida"]
    assert len(row) == 1 and pd.isna(row["collision"].iloc[0]) and math.isnan(row["cov"].iloc[0])
    assert comparison.summary.loc["pida", "collisions"] == 0
    assert "| `pida` | - | - | - | - | - |" in comparison.to_markdown()


def test_csv_marks_missing_values_with_a_dash():
    comparison = fake_comparison()
    text = comparison.to_csv()
    lines = text.splitlines()
    assert lines[0] == ",".join(TABLE_COLUMNS)
    assert len(lines) == 1 + len(comparison.table)
    frame = pd.read_csv(io.StringIO(text), na_values="-")
    assert list(frame["compensator"]) == list(comparison.table["compensator"])
    assert frame.loc[1, "cov"] != frame.loc[1, "cov"]  # NaN: collision 2 has no CoV
    assert lines[2].split(",")[2] == "-"
    assert frame.loc[frame["compensator"] == "pida", "damping_error_Ns_mm"].iloc[0] == pytest.approx(0.32)


def test_markdown_report():
    comparison = fake_comparison()
    text = comparison.to_markdown(["compare_velocity.png"])
    assert text.startswith("# Compensator comparison: paper-table1\n")
    assert "Robot delay 10 ms" in text
    summary_at, detail_at = text.index("## Summary"), text.index("## Per collision")
    assert summary_at < detail_at < text.index("## Figures")
    summary = text[summary_at:detail_at]
    rows = [line for line in summary.splitlines() if line.startswith("| `")]
    assert [row.split("|")[1].strip() for row in rows] == ["`none`", "`pic`", "`pida`", "`tdpa-impedance`"]
    assert "| `none` | diverged at 0.900 s | 3.000, -, 4.000 |" in summary
    assert "| 0.43 | 0.32 |" in rows[2]  # k error %, c error N·s/mm
    assert rows[1].endswith("| - | - |")
    assert "worst \\|CoV − 1\\|" in summary  # pipes escaped inside the table
    header = next(line for line in summary.splitlines() if line.startswith("| compensator"))
    for row in rows:  # every row has as many cells as the header
        assert row.count("|") == header.count("|") - header.count("\\|") == 13  # 12 columns
    detail = text[detail_at:]
    assert len([line for line in detail.splitlines() if line.startswith("| `")]) == len(comparison.table)
    assert "| `none` | 1 | 3.000 | 1.200 | 120.0 | 25.00 |" in detail
    assert "![compare_velocity](compare_velocity.png)" in text
    assert "## Figures" not in comparison.to_markdown()


def test_comparison_figures():
    comparison = fake_comparison()
    figures = comparison.plot()
    assert list(figures) == [
        "compare_velocity", "compare_force", "compare_energy", "compare_identification", "compare_cov_cof",
        "compare_measured_applied",
    ]
    velocity = figures["compare_velocity"]
    panels = [ax for ax in velocity.axes if ax.get_visible() and ax.get_label() != "zoom"]
    assert len(panels) == 4
    # below each panel, a zoom on one collision of the reference (the synthetic one has one)
    zooms = [ax for ax in velocity.axes if ax.get_visible() and ax.get_label() == "zoom"]
    assert len(zooms) == 4 and len({ax.get_xlim() for ax in zooms}) == 1
    start, end = 0.1, 0.2  # its reference collision
    lo, hi = zooms[0].get_xlim()
    assert lo < start < end < hi and hi - lo < 0.5
    assert [ax.get_title().split(":")[0] for ax in panels] == ["none", "pic", "pida", "tdpa-impedance"]
    assert "DIVERGED" in panels[0].get_title() and panels[1].get_title() == "pic: ok"
    assert len({ax.get_ylim() for ax in panels}) == 1  # shared axes
    assert len({ax.get_xlim() for ax in panels}) == 1
    for ax in panels:  # HIL solid, reference dashed, in mm/s
        styles = {line.get_label(): line.get_linestyle() for line in ax.get_lines()}
        assert styles["HIL"] == "-" and styles["ideal reference"] == "--"
    pic_hil = [line for line in panels[1].get_lines() if line.get_label() == "HIL"][0]
    assert np.nanmax(pic_hil.get_ydata()) == pytest.approx(20.0)
    # observed energy only where it has values
    energy = [ax for ax in figures["compare_energy"].axes if ax.get_visible() and ax.get_label() != "zoom"]
    observed = [[line for line in ax.get_lines() if line.get_label() == "observed energy"] for ax in energy]
    assert [len(lines) for lines in observed] == [0, 0, 1, 0]
    assert observed[2][0].get_linestyle() == ":"
    # identification: pic and pida, k̂ in N/mm and ĉ in N·s/mm against the true values
    ident = [ax for ax in figures["compare_identification"].axes if ax.get_visible()]
    assert len(ident) == 4
    titles = [ax.get_title() for ax in ident if ax.get_title()]
    assert titles == ["pic: ok", "pida: ok"]
    k_lines = {line.get_label(): line for line in ident[0].get_lines()}
    assert np.nanmax(k_lines["k\u0302"].get_ydata()) == pytest.approx(170.0)
    assert k_lines["true k"].get_ydata()[0] == pytest.approx(176.275)
    assert ident[0].get_ylabel() == "stiffness (N/mm)" and ident[2].get_ylabel() == "damping (N\u00b7s/mm)"
    c_lines = {line.get_label(): line for line in ident[2].get_lines()}
    assert np.nanmax(c_lines["c\u0302"].get_ydata()) == pytest.approx(1e-3)  # 1 N·s/m
    # CoV/CoF bars: one bar per compensator and collision (3 collisions), a line at 1
    cov_ax, cof_ax = figures["compare_cov_cof"].axes[:2]
    assert len(cov_ax.patches) == 4 * 3
    assert any(list(line.get_ydata()) == [1.0, 1.0] for line in cov_ax.get_lines())
    assert cov_ax.get_ylabel().startswith("CoV") and cof_ax.get_ylabel().startswith("CoF")
    legend = [text.get_text() for text in cov_ax.get_legend().get_texts()]
    assert legend == ["none", "pic", "pida", "tdpa-impedance"]


def test_identification_figure_only_when_a_kind_identifies():
    figures = fake_comparison(("none", "tdpa-impedance")).plot()
    assert "compare_identification" not in figures
    assert set(figures) == {"compare_velocity", "compare_force", "compare_energy", "compare_cov_cof",
                            "compare_measured_applied"}


@pytest.mark.parametrize("run_plots", [False, True])
def test_save_writes_runs_report_and_figures(tmp_path, run_plots):
    comparison = fake_comparison()
    out = comparison.save(tmp_path / "cmp", run_plots=run_plots)
    assert out == tmp_path / "cmp"
    names = {p.name for p in out.iterdir()}
    assert names == {"none", "pic", "pida", "tdpa-impedance", "comparison.md", "comparison.csv", MARKER} | COMPARE_PLOTS
    for kind, run in comparison.runs.items():
        files = {p.name for p in (out / kind).iterdir()}
        plots = RUN_PLOTS | ({"identification.png"} if kind in IDENTIFYING else set())
        assert files == RUN_FILES | (plots if run_plots else set())
        assert json.loads((out / kind / "metrics.json").read_text()) == run.metrics
        assert hc.load_scenario(out / kind / "scenario.toml").compensator.kind == kind
    for name in COMPARE_PLOTS:
        assert (out / name).read_bytes()[:8] == PNG_MAGIC
    assert (out / "comparison.csv").read_text() == comparison.to_csv()
    report = (out / "comparison.md").read_text()
    for name in COMPARE_PLOTS:
        assert f"({name})" in report
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cmp"]  # no temporary folders


def test_save_without_plots_and_replacing_an_old_folder(tmp_path):
    out = tmp_path / "cmp"
    comparison = fake_comparison(("none", "pida"))
    comparison.save(out, plots=False)  # a folder hilcontact wrote: replaced completely
    comparison.save(out, plots=False)
    (out / "stale.txt").write_text("old")  # a file hilcontact did not write: overwrite=True (issue 25)
    with pytest.raises(OutputError, match="stale.txt"):
        comparison.save(out, plots=False)
    assert (out / "stale.txt").read_text() == "old"
    comparison.save(out, plots=False, overwrite=True)
    assert {p.name for p in out.iterdir()} == {"none", "pida", "comparison.md", "comparison.csv", MARKER}
    assert {p.name for p in (out / "pida").iterdir()} == RUN_FILES
    assert "## Figures" not in (out / "comparison.md").read_text()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cmp"]


def test_failed_save_leaves_the_old_folder_untouched(tmp_path, monkeypatch):
    out = tmp_path / "cmp"
    out.mkdir()
    (out / "comparison.md").write_text("old")
    comparison = fake_comparison(("none", "pida"))

    def boom(self, *args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(Comparison, "to_markdown", boom)  # after the runs and the CSV
    with pytest.raises(hc.HilContactError, match="disk full"):
        comparison.save(out, plots=False, overwrite=True)
    assert [p.name for p in out.iterdir()] == ["comparison.md"]
    assert (out / "comparison.md").read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cmp"]


def test_save_refuses_a_file(tmp_path):
    target = tmp_path / "file"
    target.write_text("x")
    with pytest.raises(hc.HilContactError, match="not a directory"):
        fake_comparison(("none",)).save(target)
    assert target.read_text() == "x"


def test_empty_comparison_is_an_error():
    with pytest.raises(hc.HilContactError):
        Comparison(runs={})


# ---- integration through the real core -----------------------------------------------------


@pytest.fixture(scope="session")
def paper_comparison(core) -> Comparison:
    """paper-table1 (10 ms robot delay) with every compensator."""
    return hc.compare("paper-table1")


def test_compare_runs_every_compensator(paper_comparison):
    comparison = paper_comparison
    assert list(comparison.runs) == KINDS
    assert comparison.scenario.name == "paper-table1"
    for kind, run in comparison.runs.items():
        assert run.scenario.compensator.kind == kind
        assert run.metrics["compensator"] == kind
        assert run.metrics["status"] in ("ok", "unfaithful", "diverged")
        assert set(TIMESERIES_COLUMNS) <= set(run.timeseries.columns)
        assert set(REFERENCE_COLUMNS) <= set(run.reference.columns)
        extra = set(run.timeseries.columns) - set(TIMESERIES_COLUMNS)
        assert extra <= set(OPTIONAL_TIMESERIES_COLUMNS), extra
        assert all(run.timeseries[c].dtype == np.float64 for c in run.timeseries.columns)
        identifies = kind in IDENTIFYING
        assert ("stiffness_estimate" in run.timeseries) is identifies
        assert ("damping_estimate" in run.timeseries) is identifies
        assert (run.metrics["identification"] is not None) is identifies
        json.dumps(run.metrics, allow_nan=False)
    assert "observed_energy" not in comparison.runs["none"].timeseries
    # the same ideal reference for every compensator
    reference = comparison.runs["none"].reference
    for run in comparison.runs.values():
        pd.testing.assert_frame_equal(run.reference, reference)


def test_compare_tables_through_the_core(paper_comparison):
    comparison = paper_comparison
    summary = comparison.summary
    assert list(summary.index) == KINDS
    assert summary.loc["none", "status"] == "diverged"  # 10 ms, no compensation
    assert 2.0 < summary.loc["none", "diverged_at"] < 3.5
    table = comparison.table
    expected_rows = sum(max(len(run.metrics["collisions"]), 1) for run in comparison.runs.values())
    assert len(table) == expected_rows
    for kind, run in comparison.runs.items():
        rows = table[table["compensator"] == kind]
        assert list(rows["collision"]) == [c["index"] for c in run.metrics["collisions"]]
        assert summary.loc[kind, "collisions"] == len(run.metrics["collisions"])
        assert (rows["status"] == run.status).all()
        covs = [c["cov"] for c in run.metrics["collisions"] if c["cov"] is not None]
        if covs:
            assert summary.loc[kind, "mean_cov"] == pytest.approx(float(np.mean(covs)))
            assert summary.loc[kind, "worst_cov_error"] == pytest.approx(max(abs(c - 1) for c in covs))
        if kind in IDENTIFYING:
            identification = run.metrics["identification"]
            assert summary.loc[kind, "stiffness_error_pct"] == pytest.approx(100 * identification["stiffness_error"])
            assert summary.loc[kind, "damping_error_Ns_mm"] == pytest.approx(identification["damping_error"] / 1e3)
        else:
            assert math.isnan(summary.loc[kind, "stiffness_error_pct"])


def test_compare_save_through_the_core(paper_comparison, tmp_path):
    out = paper_comparison.save(tmp_path / "paper-table1-compare", run_plots=True)
    assert {p.name for p in out.iterdir()} == set(KINDS) | {"comparison.md", "comparison.csv", MARKER} | COMPARE_PLOTS
    for kind in KINDS:
        files = {p.name for p in (out / kind).iterdir()}
        assert RUN_FILES | RUN_PLOTS <= files
        assert ("identification.png" in files) is (kind in IDENTIFYING)
        assert hc.load_scenario(out / kind / "scenario.toml") == paper_comparison.runs[kind].scenario
    frame = pd.read_csv(out / "comparison.csv", na_values="-")
    assert list(frame.columns) == TABLE_COLUMNS
    assert set(frame["compensator"]) == set(KINDS)
    assert len(frame) == len(paper_comparison.table)
    report = (out / "comparison.md").read_text()
    for kind in KINDS:
        assert f"| `{kind}` |" in report


def test_cli_compare(core, tmp_path):
    out = tmp_path / "cmp"
    result = invoke("compare", "paper-table1", "--compensators", "none,pida", "--no-plots", "--out", str(out))
    assert result.exit_code == 0, (result.output, result.stderr)
    assert {p.name for p in out.iterdir()} == {"none", "pida", "comparison.md", "comparison.csv", MARKER}
    assert {p.name for p in (out / "pida").iterdir()} == RUN_FILES
    metrics = json.loads((out / "none" / "metrics.json").read_text())
    assert metrics["status"] == "diverged"
    stdout = result.stdout
    rows = [line for line in stdout.splitlines() if line.startswith("│") and line.split("│")[1].strip()]
    assert [row.split("│")[1].strip() for row in rows] == ["none", "pida"]
    assert "diverged" in rows[0]
    assert f"{metrics['collisions'][0]['cov']:.2f}" in rows[0]
    assert str(out) in stdout.replace("\n", "")
    frame = pd.read_csv(out / "comparison.csv", na_values="-")
    assert list(frame["compensator"].unique()) == ["none", "pida"]


def test_cli_compare_default_folder_and_sets(core, tmp_path):
    result = invoke(
        "compare", "paper-table1", "--compensators", "pic", "--set", "facility.robot_delay=0.004",
        "--set", "simulation.duration=1.0", "--set", "compensator.alpha_max=1000", "--no-plots", cwd=tmp_path,
    )
    assert result.exit_code == 0, (result.output, result.stderr)
    out = tmp_path / "runs" / "paper-table1-compare"
    assert {p.name for p in out.iterdir()} == {"pic", "comparison.md", "comparison.csv", MARKER}
    scenario = hc.load_scenario(out / "pic" / "scenario.toml")
    assert scenario.facility.robot_delay == 0.004 and scenario.simulation.duration == 1.0
    assert scenario.compensator.kind == "pic" and scenario.compensator.alpha_max == 1000.0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["runs"]
    assert sorted(p.name for p in (tmp_path / "runs").iterdir()) == ["paper-table1-compare"]


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["--compensators", "none,magic"], "compensators: unknown compensator 'magic'"),
        (["--set", "compensator.kind=pida"], "compensator.kind: "),
        (["--set", "servicer.mass=0"], "servicer.mass: must be between 0.001 and 1e7"),
        (["--set", "compensator.forgetting=2"], "compensator.forgetting: must be between 0 and 1 (exclusive), got 2"),
    ],
)
def test_cli_compare_rejects_bad_input_and_writes_nothing(tmp_path, args, fragment):
    result = invoke("compare", "paper-table1", *args, "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert result.exit_code == 2, (result.output, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and fragment in lines[0], result.stderr
    assert result.stdout == ""
    assert list(tmp_path.iterdir()) == []


def test_cli_help_lists_compare():
    result = invoke("--help")
    assert result.exit_code == 0 and "compare" in result.stdout
    result = invoke("compare", "--help")
    assert result.exit_code == 0
    assert "--compensators" in result.stdout and "none,pic,dac,pida,tdpa-impedance" in result.stdout


# ---- 6-DOF comparisons -----------------------------------------------------------------------


def test_velocity_error_figure_only_for_6dof_comparisons():
    assert "compare_velocity_error" not in fake_comparison().plot()  # 1-D: unchanged
    comparison = fake_comparison(("none", "pic", "pida"))
    errors = {"none": (0.5, 0.4), "pic": (0.02, 0.03), "pida": (0.04, None)}
    for kind, run in comparison.runs.items():
        run.reference["angular_velocity_z"] = 1e-3  # the reference rotates: 6-DOF
        run.metrics["collisions"][0]["velocity_error"], run.metrics["collisions"][0]["angular_velocity_error"] = errors[kind]
        run.metrics["collisions"][1]["velocity_error"] = None
    figures = comparison.plot()
    assert list(figures)[-1] == "compare_velocity_error"
    v_ax, w_ax = figures["compare_velocity_error"].axes[:2]
    assert v_ax.get_ylabel().startswith("velocity error (%)") and w_ax.get_ylabel().startswith("angular velocity error (%)")
    # collision 1 only (the last with a value), one bar per compensator, in %
    heights = [bar.get_height() for bar in v_ax.patches]
    assert len(heights) == 3 and heights[1] == pytest.approx(2.0) and heights[2] == pytest.approx(4.0)
    assert heights[0] < 50.0 and "(cut" in v_ax.get_ylabel()  # the diverged run's bar is cut
    w_heights = [bar.get_height() for bar in w_ax.patches]
    assert w_heights[1] == pytest.approx(3.0) and math.isnan(w_heights[2])
    assert any(list(line.get_ydata()) == [5.0, 5.0] for line in v_ax.get_lines())  # max_velocity_error
    legend = [text.get_text() for text in v_ax.get_legend().get_texts()]
    assert legend == ["none", "pic", "pida"]


def test_compare_oblique_6dof_through_the_core(core, tmp_path):
    comparison = hc.compare("oblique-6dof", "none,pic", {"simulation.duration": 1.0})
    out = comparison.save(tmp_path / "oblique", run_plots=True)
    assert {p.name for p in out.iterdir()} >= COMPARE_PLOTS | {"compare_velocity_error.png"}
    for kind in ("none", "pic"):
        files = {p.name for p in (out / kind).iterdir()}
        assert RUN_PLOTS | {"contact_rotation.png", "tip_tracking.png"} <= files
    v_ax = comparison.plot()["compare_velocity_error"].axes[0]
    expected = [100 * run.metrics["collisions"][0]["velocity_error"] for run in comparison.runs.values()]
    assert [bar.get_height() for bar in v_ax.patches[:2]] == pytest.approx(expected)
    assert "(compare_velocity_error.png)" in (out / "comparison.md").read_text()


def test_a_saved_comparison_loads_back_equal(tmp_path):
    comparison = fake_comparison()
    comparison.save(tmp_path / "cmp", plots=False)
    loaded = Comparison.load(tmp_path / "cmp")
    assert loaded.kinds == comparison.kinds
    for kind, run in comparison.runs.items():
        back = loaded.runs[kind]
        assert back.metrics == run.metrics and back.scenario == run.scenario
        pd.testing.assert_frame_equal(back.timeseries, run.timeseries)
        pd.testing.assert_frame_equal(back.reference, run.reference)
    assert loaded.to_csv() == comparison.to_csv()
    with pytest.raises(hc.ScenarioError, match="not a comparison folder"):
        Comparison.load(tmp_path)


def test_cli_plot_draws_a_comparison_and_a_run_folder_later(core, tmp_path):
    out = tmp_path / "cmp"
    assert invoke("compare", "paper-table1", "--compensators", "none,pida", "--no-plots", "--out", str(out)).exit_code == 0
    result = invoke("plot", str(out / "pida"))
    assert result.exit_code == 0, (result.output, result.stderr)
    assert {p.name for p in (out / "pida").iterdir()} == RUN_FILES | RUN_PLOTS | {"identification.png"}
    assert {p.name for p in out.iterdir() if p.suffix == ".png"} == set()
    result = invoke("plot", str(out))
    assert result.exit_code == 0, (result.output, result.stderr)
    assert {p.name for p in out.iterdir() if p.suffix == ".png"} == COMPARE_PLOTS
    assert {p.name for p in (out / "none").iterdir()} == RUN_FILES | RUN_PLOTS
    for png in out.rglob("*.png"):
        assert png.read_bytes()[:8] == PNG_MAGIC
    assert result.stdout.strip() == f"drew {len(COMPARE_PLOTS) + 2 * len(RUN_PLOTS) + 1} figures in {out}/"


@pytest.mark.parametrize(
    ("setup", "fragment"),
    [
        (lambda d: None, "no such folder"),
        (lambda d: d.mkdir(), "not written by hilcontact"),
        (lambda d: (d.mkdir(), (d / MARKER).write_text('{"kind": "sweep"}')), "a sweep folder"),
        (lambda d: (d.mkdir(), (d / MARKER).write_text('{"kind": "run"}'), (d / "metrics.json").write_text("{}")),
         "not a run folder (missing timeseries.parquet"),
        (lambda d: (d.mkdir(), (d / MARKER).write_text('{"kind": "comparison"}')), "not a comparison folder"),
    ],
)
def test_cli_plot_refuses_what_it_cannot_draw_in_one_line(tmp_path, setup, fragment):
    folder = tmp_path / "x"
    setup(folder)
    before = sorted(p.name for p in folder.iterdir()) if folder.is_dir() else None
    result = invoke("plot", str(folder))
    assert result.exit_code == 2, (result.output, result.stderr)
    assert fragment in result.stderr and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert (sorted(p.name for p in folder.iterdir()) if folder.is_dir() else None) == before


def test_figures_drawn_in_two_processes_survive_a_failing_child(tmp_path, monkeypatch):
    from matplotlib.figure import Figure

    from hilcontact.plots import draw_in_two_processes

    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    parent = os.getpid()

    def maker(name: str, fail_in_child: bool = False):
        def make():
            if fail_in_child and os.getpid() != parent:
                raise RuntimeError("the child fails")
            figure = Figure(figsize=(2, 2))
            figure.add_subplot().plot([0, 1], [0, 1])
            return figure
        return make

    makers = {"a": maker("a"), "b": maker("b", fail_in_child=True), "c": maker("c"), "none": lambda: None, "e": maker("e")}
    saved = draw_in_two_processes(makers, tmp_path, dpi=50)
    assert saved == ["a", "b", "c", "e"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.png", "b.png", "c.png", "e.png"]
    for png in tmp_path.iterdir():
        assert png.read_bytes()[:8] == PNG_MAGIC
