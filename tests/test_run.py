"""Run results: saving (atomic), plots, collision table; integration through the real core."""

from __future__ import annotations

import dataclasses
import json
import math
import os
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner
from conftest import synthetic_run

import hilcontact as hc
from hilcontact.cli import cli
from hilcontact.output import MARKER
from hilcontact.plots import MAX_POINTS, moves_in_1d, thin
from hilcontact.run import (
    OPTIONAL_TIMESERIES_COLUMNS, PLOT_FILES, PLOT_FILES_6DOF, PLOT_FILES_EPISODES, REFERENCE_COLUMNS,
    TIMESERIES_COLUMNS,
)

DATA_FILES = {"timeseries.parquet", "reference.parquet", "metrics.json", "scenario.toml", MARKER}
PLOTS = {"contact_velocity.png", "contact_force.png", "energy.png"}
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def siblings(path: Path) -> list[str]:
    return sorted(p.name for p in path.parent.iterdir())


# ---- save / plots / table (synthetic data, no core needed) ---------------------------------


def test_save_writes_all_files(tmp_path, fake_run):
    out = tmp_path / "runs" / "paper"
    returned = fake_run.save(out)
    assert returned == out
    assert {p.name for p in out.iterdir()} == DATA_FILES | PLOTS
    for name in PLOTS:
        assert (out / name).read_bytes()[:8] == PNG_MAGIC
    assert json.loads((out / "metrics.json").read_text()) == fake_run.metrics
    assert (out / "metrics.json").read_text().startswith("{\n  ")  # indented
    assert hc.load_scenario(out / "scenario.toml") == fake_run.scenario
    table = pq.read_table(out / "timeseries.parquet")
    assert table.column_names == list(fake_run.timeseries.columns)
    pd.testing.assert_frame_equal(pd.read_parquet(out / "reference.parquet"), fake_run.reference)
    assert siblings(out) == ["paper"]  # no temporary folders left behind


def test_save_without_plots(tmp_path, fake_run):
    out = tmp_path / "noplots"
    fake_run.save(out, plots=False)
    assert {p.name for p in out.iterdir()} == DATA_FILES


def test_save_replaces_existing_folder_completely(tmp_path, fake_run):
    out = tmp_path / "run"
    fake_run.save(out, plots=False)  # a folder hilcontact wrote: replaced completely
    (out / "metrics.json").write_text("old")
    fake_run.save(out, plots=False)
    assert json.loads((out / "metrics.json").read_text())["status"] == "ok"
    (out / "stale.txt").write_text("old")  # a file hilcontact did not write: overwrite=True (issue 25)
    with pytest.raises(hc.output.OutputError, match="stale.txt"):
        fake_run.save(out, plots=False)
    assert (out / "stale.txt").read_text() == "old"
    (out / "metrics.json").write_text("old")
    fake_run.save(out, plots=False, overwrite=True)
    assert {p.name for p in out.iterdir()} == DATA_FILES
    assert json.loads((out / "metrics.json").read_text())["status"] == "ok"
    assert siblings(out) == ["run"]


def test_failed_save_leaves_existing_folder_untouched(tmp_path, fake_run, monkeypatch):
    out = tmp_path / "run"
    out.mkdir()
    (out / "metrics.json").write_text("old")

    def boom(self, *args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(hc.Scenario, "to_toml", boom)  # fails after the parquet files are written
    with pytest.raises(hc.HilContactError, match="No space left on device"):
        fake_run.save(out, overwrite=True)
    assert [p.name for p in out.iterdir()] == ["metrics.json"]
    assert (out / "metrics.json").read_text() == "old"
    assert siblings(out) == ["run"]


def test_failed_save_creates_nothing(tmp_path, fake_run, monkeypatch):
    monkeypatch.setattr(pd.DataFrame, "to_parquet", lambda *a, **k: (_ for _ in ()).throw(OSError("nope")))
    with pytest.raises(hc.HilContactError, match="nope"):
        fake_run.save(tmp_path / "new")
    assert list(tmp_path.iterdir()) == []


def test_save_refuses_a_file(tmp_path, fake_run):
    target = tmp_path / "file"
    target.write_text("x")
    with pytest.raises(hc.HilContactError, match="not a directory"):
        fake_run.save(target)
    assert target.read_text() == "x"


def test_collision_table(fake_run):
    table = fake_run.collision_table()
    assert list(table.index) == [1, 2]
    assert table.index.name == "collision"
    assert list(table.columns) == [
        "complete", "start", "end", "peak_force", "rebound_speed", "cov", "cof", "velocity_error",
        "angular_velocity_error", "impulse_ratio", "angular_impulse_ratio", "reference",
        "reference_peak_force", "reference_rebound_speed",
        # the contact episode's
        "normal_impulse", "tangential_impulse", "peak_moment",
        "rebound_velocity_x", "rebound_velocity_y", "rebound_velocity_z",
        "rebound_angular_velocity_x", "rebound_angular_velocity_y", "rebound_angular_velocity_z",
        "direction_error", "normal_impulse_error", "tangential_impulse_error", "peak_moment_ratio",
        "reference_normal_impulse", "reference_tangential_impulse", "reference_peak_moment",
        "reference_rebound_velocity_x", "reference_rebound_velocity_y", "reference_rebound_velocity_z",
        # how the compensator handled it (model-mediated's report; "-" without one)
        "rendering",
        # against the collision's local (restarted) reference (none in this run's metrics)
        "local_start", "local_velocity_error", "local_cof", "local_tangential_impulse_error",
        "local_normal_impulse_error",
    ]
    assert list(table["rendering"]) == ["-", "-"]
    assert table["local_velocity_error"].isna().all()
    assert table.loc[1, "cov"] == 1.25 and table.loc[1, "reference_rebound_speed"] == 0.02
    assert table.loc[1, "reference"] == 1 and table.loc[1, "velocity_error"] == 0.25
    assert math.isnan(table.loc[2, "reference"])
    assert math.isnan(table.loc[2, "cof"]) and math.isnan(table.loc[2, "reference_peak_force"])


def _lines(figure):
    return [line for ax in figure.axes for line in ax.get_lines() if not line.get_label().startswith("_")]


def test_plots_are_labelled(tmp_path, fake_run):
    figures = fake_run.plot()
    assert list(figures) == ["contact_velocity", "contact_force", "energy"]
    for name, figure in figures.items():
        ax = figure.axes[0]
        assert "paper-table1" in ax.get_title() and "none" in ax.get_title() and "10 ms" in ax.get_title()
        assert ax.get_xlabel() == "time (s)"
        assert ax.get_legend() is not None
        assert any(line.get_visible() for line in ax.get_xgridlines())
    assert figures["contact_velocity"].axes[0].get_ylabel() == "velocity (mm/s)"
    assert figures["contact_force"].axes[0].get_ylabel() == "contact force (N)"
    assert figures["energy"].axes[0].get_ylabel() == "energy (J)"
    # x only (y is zero): HIL solid + reference dashed, in mm/s
    lines = _lines(figures["contact_velocity"])
    assert [line.get_label() for line in lines] == ["vx HIL", "vx ideal reference"]
    assert lines[0].get_linestyle() == "-" and lines[1].get_linestyle() == "--"
    assert np.max(lines[0].get_ydata()) == pytest.approx(20.0)
    # collisions shaded
    assert len(figures["contact_velocity"].axes[0].patches) == 2
    fake_run.plot(tmp_path)
    assert {p.name for p in tmp_path.iterdir()} == PLOTS


def test_velocity_plot_adds_significant_components():
    figures = synthetic_run(lateral=0.5).plot()
    labels = [line.get_label() for line in _lines(figures["contact_velocity"])]
    assert labels == ["vx HIL", "vx ideal reference", "vy HIL", "vy ideal reference"]
    figures = synthetic_run(lateral=0.005).plot()  # below 1 % of the largest: left out
    assert len(_lines(figures["contact_velocity"])) == 2


def test_identification_plot_when_estimates_exist(tmp_path):
    run = synthetic_run(estimates=True)
    figures = run.plot()
    assert "identification" in figures
    ax_k, ax_c = figures["identification"].axes
    assert ax_k.get_ylabel() == "stiffness (N/mm)" and ax_c.get_ylabel() == "damping (N\u00b7s/mm)"
    k_lines = {line.get_label(): line for line in ax_k.get_lines()}
    assert k_lines["estimate k\u0302"].get_ydata()[0] == pytest.approx(170.0)  # 170000 N/m
    assert k_lines["true k"].get_ydata()[0] == pytest.approx(176.275)  # 176275 N/m
    c_lines = {line.get_label(): line for line in ax_c.get_lines()}
    assert c_lines["estimate c\u0302"].get_ydata()[0] == pytest.approx(1e-3)  # 1 N s/m
    assert c_lines["true c"].get_ydata()[0] == 0.0
    run.save(tmp_path / "id")
    assert (tmp_path / "id" / "identification.png").read_bytes()[:8] == PNG_MAGIC


def test_observed_energy_is_plotted_only_when_it_has_values():
    run = synthetic_run()
    run.timeseries["observed_energy"] = np.nan
    labels = [line.get_label() for line in _lines(run.plot()["energy"])]
    assert labels == ["energy HIL", "energy ideal reference"]
    run.timeseries["observed_energy"] = np.where(run.timeseries["time"] > 0.5, 0.02, np.nan)
    lines = {line.get_label(): line for line in _lines(run.plot()["energy"])}
    assert lines["observed energy (compensator)"].get_linestyle() == ":"
    assert np.nanmax(lines["observed energy (compensator)"].get_ydata()) == 0.02


def test_optional_columns_keep_their_order(monkeypatch):
    import hilcontact.run as run_module

    class FakeCore:
        @staticmethod
        def simulate(_json):
            n = 3
            columns = {name: [0.0] * n for name in ["observed_energy", "damping_estimate", "stiffness_estimate"]}
            columns.update({name: [0.0] * n for name in reversed(TIMESERIES_COLUMNS)})
            reference = {name: [0.0] * n for name in REFERENCE_COLUMNS}

            class Tables:  # `_core.Tables`: the tables made when asked
                timeseries = staticmethod(lambda: columns)
                reference = staticmethod(lambda: reference)

            return {"tables": Tables, "metrics": json.dumps({"status": "ok"})}

    monkeypatch.setattr(run_module, "_core", lambda: FakeCore)
    run = hc.simulate(hc.load_scenario("paper-table1"))
    assert list(run.timeseries.columns) == TIMESERIES_COLUMNS + OPTIONAL_TIMESERIES_COLUMNS


# ---- integration through the real core ----------------------------------------------------
#
# paper-table1 uses the pass-through compensator ("none") with 10 ms of robot delay: every
# collision rebounds ~1.47x faster than the one before (negative damping k*tau of the delayed
# spring: exp(pi*omega*tau/2) = 1.48 at 4 Hz), so the energy passes 100x its initial value in
# the 6th collision (~2.8 s) and the run is reported as diverged. Without delay the HIL loop
# reproduces the ideal reference: status ok, five collisions, CoV = CoF = 1.


@pytest.fixture(scope="session")
def undelayed_run(core) -> hc.Run:
    return hc.simulate(hc.load_scenario("paper-table1", {"facility.robot_delay": 0.0}))


def check_frames(run: hc.Run) -> None:
    assert set(TIMESERIES_COLUMNS) <= set(run.timeseries.columns)
    assert set(REFERENCE_COLUMNS) <= set(run.reference.columns)
    for frame in (run.timeseries, run.reference):
        assert all(frame[c].dtype == np.float64 for c in frame.columns)
        time = frame["time"].to_numpy()
        assert time[0] == 0.0
        assert np.allclose(np.diff(time), run.scenario.simulation.period, rtol=1e-9)
    # the ideal reference always covers the whole duration
    assert run.reference["time"].iloc[-1] == pytest.approx(run.scenario.simulation.duration, abs=1e-9)
    # both start from the scenario's state: 20 mm/s along x, rod tip 5 mm from the front wall
    for frame in (run.timeseries, run.reference):
        assert frame["tip_velocity_x"].iloc[0] == pytest.approx(0.02, rel=1e-12)
        assert frame["tip_position_x"].iloc[0] == pytest.approx(0.005, abs=1e-12)
    initial = 0.5 * (300.0 * 4000.0 / 4300.0) * 0.02**2  # 1/2 m_e v^2
    assert run.metrics["energy"]["initial"] == pytest.approx(initial, rel=1e-9)
    assert run.timeseries["energy"].iloc[0] == pytest.approx(initial, rel=1e-9)


def test_paper_table1_without_delay_matches_reference(undelayed_run):
    run = undelayed_run
    check_frames(run)
    m = run.metrics
    assert m["scenario"] == "paper-table1" and m["compensator"] == "none"
    assert m["status"] == "ok" and run.status == "ok"
    assert m["diverged_at"] is None and m["reason"] is None
    assert m["identification"] is None
    assert len(run.timeseries) == len(run.reference) == 5501
    assert [c["index"] for c in m["collisions"]] == [1, 2, 3, 4, 5]
    assert len(m["reference_collisions"]) == 5
    table = run.collision_table()
    assert table["cov"].to_numpy() == pytest.approx(1.0, abs=1e-3)
    assert table["cof"].to_numpy() == pytest.approx(1.0, abs=1e-3)
    assert table["reference_rebound_speed"].to_numpy() == pytest.approx(0.02, rel=1e-6)
    assert (table["end"] > table["start"]).all()
    assert m["energy"]["final"] == pytest.approx(m["energy"]["reference_final"], rel=1e-3)


def test_paper_table1_via_api_diverges_without_compensation(paper_run):
    run = paper_run
    check_frames(run)
    assert run.scenario.compensator.kind == "none" and run.scenario.facility.robot_delay == 0.01
    m = run.metrics
    assert m["status"] == "diverged" and run.status == "diverged"
    assert 2.0 < m["diverged_at"] < 3.5
    assert "divergence" in m["reason"]
    assert m["energy"]["max"] > 100 * m["energy"]["initial"]
    # the HIL series stops where it diverged
    assert run.timeseries["time"].iloc[-1] == pytest.approx(m["diverged_at"], abs=1e-9)
    table = run.collision_table()
    assert len(table) >= 5
    first5 = table.loc[1:5]
    assert first5["cov"].notna().all() and first5["cof"].notna().all()
    assert first5["cov"].iloc[0] == pytest.approx(1.48, abs=0.03)
    assert (first5["cov"].diff().dropna() > 0).all()  # each rebound faster than the last
    assert (first5["peak_force"] > first5["reference_peak_force"]).all()


def test_paper_table1_save_and_reproduce(paper_run, tmp_path):
    out = paper_run.save(tmp_path / "paper")
    assert {p.name for p in out.iterdir()} == DATA_FILES | PLOTS
    columns = pq.read_table(out / "timeseries.parquet").column_names
    assert set(TIMESERIES_COLUMNS) <= set(columns)
    assert set(REFERENCE_COLUMNS) <= set(pq.read_table(out / "reference.parquet").column_names)
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics == paper_run.metrics
    again = hc.simulate(hc.load_scenario(out / "scenario.toml"))
    assert again.metrics == paper_run.metrics  # the saved scenario reproduces the run
    pd.testing.assert_frame_equal(again.timeseries, paper_run.timeseries)
    pd.testing.assert_frame_equal(pd.read_parquet(out / "reference.parquet"), paper_run.reference)


def test_simulate_accepts_a_preset_name(paper_run):
    run = hc.simulate("paper-table1")
    assert run.scenario == hc.load_scenario("paper-table1")
    assert run.metrics == paper_run.metrics


def test_core_version(core):
    assert isinstance(core.version(), str) and core.version()


def test_core_rejects_invalid_json_with_scenario_error(core):
    with pytest.raises(hc.ScenarioError):
        core.simulate('{"name": "x"}')


def test_core_validates_what_slips_past_python(core):
    scenario = hc.load_scenario("paper-table1")
    scenario.facility.robot_delay = 0.0125  # assignment is not validated: only the core sees it
    with pytest.raises(hc.ScenarioError, match="facility.robot_delay"):
        hc.simulate(scenario)


def test_cli_run_paper_table1(core, tmp_path):
    out = tmp_path / "cli-run"
    result = CliRunner().invoke(cli, ["run", "paper-table1", "--out", str(out)], prog_name="hilcontact")
    assert result.exit_code == 0, (result.output, result.stderr)
    assert {p.name for p in out.iterdir()} == DATA_FILES | PLOTS
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["status"] == "diverged"
    stdout = result.stdout.replace("\n", " ")
    assert f"status: diverged at {metrics['diverged_at']:.3f} s" in stdout
    assert str(out) in result.stdout.replace("\n", "")
    for collision in metrics["collisions"]:  # one table row per collision, with its CoV
        if collision["cov"] is not None:
            assert f"{collision['cov']:.3f}" in result.stdout


def test_cli_run_ok_with_set(core, tmp_path):
    out = tmp_path / "ok"
    result = CliRunner().invoke(
        cli, ["run", "paper-table1", "--set", "facility.robot_delay=0", "--out", str(out)], prog_name="hilcontact"
    )
    assert result.exit_code == 0, (result.output, result.stderr)
    assert "status: ok" in result.stdout
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["status"] == "ok" and len(metrics["collisions"]) == 5
    assert hc.load_scenario(out / "scenario.toml").facility.robot_delay == 0.0
    rows = [line for line in result.stdout.splitlines() if line.startswith("│")]
    assert len(rows) == 5


def test_cli_run_no_plots_default_folder(core, tmp_path):
    old = os.getcwd()
    os.chdir(tmp_path)
    try:
        result = CliRunner().invoke(
            cli, ["run", "paper-table1", "--no-plots", "--set", "simulation.duration=1.0"], prog_name="hilcontact"
        )
    finally:
        os.chdir(old)
    assert result.exit_code == 0, (result.output, result.stderr)
    out = tmp_path / "runs" / "paper-table1"
    assert {p.name for p in out.iterdir()} == DATA_FILES
    assert hc.load_scenario(out / "scenario.toml").simulation.duration == 1.0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["runs"]


@pytest.mark.parametrize("name", sorted(hc.presets()))
def test_every_preset_simulates_consistently(core, name):
    run = hc.simulate(name)
    assert set(TIMESERIES_COLUMNS) <= set(run.timeseries.columns)
    assert set(REFERENCE_COLUMNS) <= set(run.reference.columns)
    m = run.metrics
    assert m["scenario"] == name and m["compensator"] == run.scenario.compensator.kind
    assert m["status"] in ("ok", "unfaithful", "diverged")
    if m["status"] == "ok":
        assert m["diverged_at"] is None and m["reason"] is None and m["violations"] == []
        assert len(run.timeseries) == len(run.reference)
    elif m["status"] == "unfaithful":
        assert m["diverged_at"] is None and m["violations"]
        assert m["reason"].startswith("unfaithful: " + m["violations"][0])
        assert len(run.timeseries) == len(run.reference)
    else:
        assert m["diverged_at"] > 0 and isinstance(m["reason"], str) and m["reason"]
        assert run.timeseries["time"].iloc[-1] == pytest.approx(m["diverged_at"], abs=1e-9)
    assert not run.timeseries.isna().any().any() and not run.reference.isna().any().any()
    for key in ("collisions", "reference_collisions"):
        assert [c["index"] for c in m[key]] == list(range(1, len(m[key]) + 1))
        assert all(c["end"] > c["start"] for c in m[key])
    assert m["collisions"] and m["reference_collisions"]
    assert set(m["energy"]) == {"initial", "final", "reference_final", "reference_friction_work", "max"}
    frictional = run.scenario.contact.friction.kinetic > 0.0
    assert (m["energy"]["reference_friction_work"] > 0.0) == frictional  # friction works only where there is some
    json.dumps(m, allow_nan=False)  # plain JSON: no NaN or infinity


# ---- 6-DOF figures ---------------------------------------------------------------------------

SIX_DOF_PLOTS = {"contact_rotation.png", "tip_tracking.png"}


def _labelled(ax):
    return {line.get_label(): line for line in ax.get_lines() if not line.get_label().startswith("_")}


def test_plot_files_constants():
    assert set(PLOT_FILES) == PLOTS and set(PLOT_FILES_6DOF) == SIX_DOF_PLOTS


def test_moves_in_1d_from_the_reference():
    assert moves_in_1d(synthetic_run())
    assert moves_in_1d(synthetic_run(lateral=0.5))  # only the HIL leaves the line: still 1-D
    assert not moves_in_1d(synthetic_run(spin=1e-3))
    run = synthetic_run()
    run.reference["tip_velocity_y"] = 0.5 * run.reference["tip_velocity_x"] + 0.001
    assert not moves_in_1d(run)
    run.reference["tip_velocity_y"] = 0.005 * run.reference["tip_velocity_x"]  # below 1 %
    assert moves_in_1d(run)


def test_thin_keeps_samples_and_peaks():
    t = np.arange(100_000) * 1e-4
    y = np.sin(t)
    y[12_345], y[67_890] = 5.0, -7.0
    tt, yy = thin(t, y, limit=1000)
    assert len(yy) <= 1002 and tt[0] == t[0] and tt[-1] == t[-1]
    assert np.all(np.diff(tt) > 0)
    index = np.round(tt / 1e-4).astype(int)
    assert np.array_equal(yy, y[index])  # samples of the series, nothing interpolated
    assert yy.max() == 5.0 and yy.min() == -7.0
    short_t, short_y = thin(t[:500], y[:500], limit=1000)
    assert np.array_equal(short_y, y[:500])
    y[3] = np.nan  # not thinned: NaN gaps must stay where they are
    assert len(thin(t, y, limit=1000)[1]) == len(y)


def test_synthetic_6dof_run_gets_the_figures(tmp_path):
    run = synthetic_run(spin=2e-3)
    figures = run.plot()
    assert list(figures) == ["contact_velocity", "contact_force", "energy", "contact_rotation", "tip_tracking",
                             "contact_points", "contact_normal_tangential"]
    ax_w, ax_m = figures["contact_rotation"].axes
    assert "paper-table1" in ax_w.get_title() and "10 ms" in ax_w.get_title()
    assert ax_w.get_ylabel() == "angular velocity (mrad/s)" and ax_m.get_ylabel() == "moment (N\u00b7m)"
    assert ax_m.get_xlabel() == "time (s)" and ax_w.get_legend() is not None and ax_m.get_legend() is not None
    omega = _labelled(ax_w)
    assert np.allclose(omega["\u03c9z HIL"].get_ydata(), 2.0) and omega["\u03c9z ideal reference"].get_linestyle() == "--"
    assert len(ax_w.patches) == len(ax_m.patches) == 2  # collisions shaded
    run.save(tmp_path / "six")
    assert {p.name for p in (tmp_path / "six").iterdir()} == DATA_FILES | PLOTS | SIX_DOF_PLOTS | set(PLOT_FILES_EPISODES)
    long = synthetic_run(spin=2e-3)  # a long run is drawn thinned
    t = np.arange(20_001) * 1e-3
    long.timeseries = pd.DataFrame({c: np.interp(t, long.timeseries["time"], long.timeseries[c]) for c in long.timeseries})
    long.timeseries["time"] = t
    long.timeseries["applied_moment_y"] = np.sin(t)
    moment = _labelled(long.plot()["contact_rotation"].axes[1])["My HIL (applied)"]
    assert len(moment.get_xdata()) <= 2402 and np.max(moment.get_ydata()) == np.max(np.sin(t))


@pytest.fixture(scope="session")
def oblique_run(core) -> hc.Run:
    """oblique-6dof (10 ms robot delay, `none`), cut after its first collision."""
    return hc.simulate(hc.load_scenario("oblique-6dof", {"simulation.duration": 1.0}))


def test_paper_table1_is_1d_and_keeps_its_figures(paper_run):
    assert moves_in_1d(paper_run)
    assert list(paper_run.plot()) == ["contact_velocity", "contact_force", "energy"]


def test_oblique_6dof_rotation_figure(oblique_run):
    run = oblique_run
    assert not moves_in_1d(run) and len(run.timeseries) <= MAX_POINTS  # drawn whole
    figures = run.plot()
    assert list(figures) == ["contact_velocity", "contact_force", "energy", "contact_rotation", "tip_tracking",
                             "contact_points", "contact_normal_tangential"]
    ax_w, ax_m = figures["contact_rotation"].axes
    assert "oblique-6dof" in ax_w.get_title()
    ts, ref = run.timeseries, run.reference
    omega, moment = _labelled(ax_w), _labelled(ax_m)
    for axis in "xyz":  # every axis rotates and carries a moment in this case
        assert np.array_equal(omega[f"\u03c9{axis} HIL"].get_xdata(), ts["time"])
        assert np.array_equal(omega[f"\u03c9{axis} HIL"].get_ydata(), ts[f"angular_velocity_{axis}"] * 1e3)
        assert np.array_equal(omega[f"\u03c9{axis} ideal reference"].get_ydata(), ref[f"angular_velocity_{axis}"] * 1e3)
        # identity sensor orientation: the applied moment is already in t
        assert np.allclose(moment[f"M{axis} HIL (applied)"].get_ydata(), ts[f"applied_moment_{axis}"], rtol=0, atol=1e-12)
        assert np.array_equal(moment[f"M{axis} ideal reference"].get_ydata(), ref[f"contact_moment_{axis}"])
    assert len(ax_w.patches) == len(ax_m.patches) == len(run.metrics["collisions"]) >= 1


def test_rotation_figure_turns_the_applied_moment_into_t(oblique_run):
    # the sensor turned 90 deg about z: sensor x is t's y, sensor y is t's -x
    turned = dataclasses.replace(
        oblique_run, scenario=hc.load_scenario("oblique-6dof", {"facility.sensor_orientation": [0.5**0.5, 0, 0, 0.5**0.5]})
    )
    moment = _labelled(turned.plot()["contact_rotation"].axes[1])
    ts = oblique_run.timeseries
    assert np.allclose(moment["Mx HIL (applied)"].get_ydata(), -ts["applied_moment_y"], atol=1e-9)
    assert np.allclose(moment["My HIL (applied)"].get_ydata(), ts["applied_moment_x"], atol=1e-9)
    assert np.allclose(moment["Mz HIL (applied)"].get_ydata(), ts["applied_moment_z"], atol=1e-9)


def test_without_delay_the_hil_moment_follows_the_reference(core):
    run = hc.simulate(hc.load_scenario("oblique-6dof", {"simulation.duration": 0.6, "facility.robot_delay": 0.0}))
    moment = _labelled(run.plot()["contact_rotation"].axes[1])
    for axis in "xyz":  # same sign convention and frame as the reference's contact moment
        hil = moment[f"M{axis} HIL (applied)"].get_ydata()
        ideal = moment[f"M{axis} ideal reference"].get_ydata()
        peak = np.abs(ideal).max()
        assert peak > 0.5  # N m: a real moment about every axis
        assert np.abs(hil - ideal).max() < 0.1 * peak


def test_oblique_6dof_tip_tracking_shows_the_delay(oblique_run, tmp_path):
    run = oblique_run
    ax_run, ax_zoom = run.plot()["tip_tracking"].axes
    assert "front-oblique" in ax_run.get_title() and "oblique-6dof" in ax_run.get_title()
    assert ax_run.get_ylabel() == ax_zoom.get_ylabel() == "distance to wall (mm)"
    wall = run.scenario.walls[0]
    normal = np.asarray(wall.normal) / np.linalg.norm(wall.normal)
    ts = run.timeseries
    commanded = (ts[["tip_position_x", "tip_position_y", "tip_position_z"]].to_numpy() - wall.point) @ normal
    actual = (ts[["actual_tip_position_x", "actual_tip_position_y", "actual_tip_position_z"]].to_numpy() - wall.point) @ normal
    lines = _labelled(ax_run)
    assert set(lines) == {"commanded (virtual)", "actual (robot)", "wall surface"}
    assert np.allclose(lines["commanded (virtual)"].get_ydata(), commanded * 1e3, rtol=0, atol=1e-9)
    assert np.allclose(lines["actual (robot)"].get_ydata(), actual * 1e3, rtol=0, atol=1e-9)
    # the zoom frames the first collision, and the actual tip reaches the wall one robot delay
    # (10 ms) after the command
    first = run.metrics["collisions"][0]
    lo, hi = ax_zoom.get_xlim()
    assert lo < first["start"] - 0.010 and hi > first["end"]
    zoom = _labelled(ax_zoom)
    assert set(zoom) == {"commanded (virtual)", "actual (robot)", "commanded, 10 ms later", "wall surface"}
    t_zoom = zoom["commanded (virtual)"].get_xdata()
    assert lo <= t_zoom[0] and t_zoom[-1] <= hi + 1e-9
    time = ts["time"].to_numpy()
    crossing = lambda d: time[np.argmax(d < 0)]  # noqa: E731
    assert crossing(actual) - crossing(commanded) == pytest.approx(0.010, abs=2e-3)
    assert crossing(actual) == pytest.approx(first["start"], abs=2e-3)
    out = run.save(tmp_path / "oblique")
    assert {p.name for p in out.iterdir()} == DATA_FILES | PLOTS | SIX_DOF_PLOTS | set(PLOT_FILES_EPISODES)
    for name in SIX_DOF_PLOTS:
        assert (out / name).read_bytes()[:8] == PNG_MAGIC
