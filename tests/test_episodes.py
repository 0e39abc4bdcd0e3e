"""Contact episodes (docs/model.md "Metrics"): the normal and tangential impulse, the rebound
vector and direction errors per collision in the Python API, the verdict, `compare`'s tables,
the `run` report and the episode figures."""

from __future__ import annotations

import math

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import synthetic_run

import hilcontact as hc
from hilcontact.cli import cli
from hilcontact.comparison import TABLE_COLUMNS, Comparison, Violation
from hilcontact.plots import shows_episodes
from hilcontact.run import PLOT_FILES_EPISODES

FRICTION = {"contact.friction.kinetic": 0.2}


@pytest.fixture(scope="module")
def rough(core) -> hc.Run:
    """oblique-6dof with kinetic friction 0.2 and no delay, cut after its first collisions."""
    return hc.simulate(hc.load_scenario("oblique-6dof", {**FRICTION, "facility.robot_delay": 0.0,
                                                          "simulation.duration": 3.0}))


def test_a_frictional_episode_without_delay_is_the_references(rough):
    table = rough.collision_table()
    assert len(table) >= 1 and table["complete"].all()
    assert (table["tangential_impulse"] > 0.0).all()
    assert (table["tangential_impulse"] <= 0.2 * table["normal_impulse"] * (1 + 1e-9)).all()  # Coulomb's cone
    assert (table["tangential_impulse_error"] < 5e-3).all()  # 0.015 %, 0.13 % measured
    assert (table["normal_impulse_error"] < 1e-3).all()
    assert (table["direction_error"] < 0.1).all()
    # 0.009 %, 0.135 % measured: the second is above issue 21's 0.1 % (the facility's physics)
    assert (table["velocity_error"] < 2e-3).all()
    assert np.allclose(table["tangential_impulse"], table["reference_tangential_impulse"], rtol=1e-3)
    # the rebound vector is a vector: its norm is the rebound speed
    vector = table[["rebound_velocity_x", "rebound_velocity_y", "rebound_velocity_z"]].to_numpy()
    assert np.allclose(np.linalg.norm(vector, axis=1), table["rebound_speed"], rtol=1e-12)
    assert rough.status == "ok", rough.metrics.get("violations")


def test_frictionless_errors_are_zero_not_nan(core):
    run = hc.simulate(hc.load_scenario("oblique-6dof", {"facility.robot_delay": 0.0, "simulation.duration": 3.0}))
    table = run.collision_table()
    assert (table["tangential_impulse"] == 0.0).all()
    assert (table["tangential_impulse_error"] == 0.0).all()
    assert run.metrics["summary"]["worst_tangential_impulse_error"] == 0.0


def test_the_verdict_judges_the_tangential_impulse_as_the_core_does():
    run = synthetic_run()
    run.metrics["collisions"][0].update(cov=1.0, cof=1.0, velocity_error=0.01, tangential_impulse_error=0.2)
    comparison = Comparison({"pida": run})
    (standing,) = comparison.ranking
    assert standing.violations == (Violation(1, "tangential impulse error (%)", 20.0, 10.0),)
    assert str(standing.violations[0]) == "collision 1: tangential impulse error 20.00 % > 10 %"
    assert standing.margin == pytest.approx(2.0)
    # within a looser tolerance of the scenario's [metrics]
    run.scenario = hc.load_scenario("paper-table1", {"metrics.max_tangential_impulse_error": 0.25})
    assert Comparison({"pida": run}).ranking[0].violations == ()


@pytest.mark.parametrize("delay", [0.01, 0.02])
def test_compare_reports_the_episode_errors_and_flags_them(core, delay):
    comparison = hc.compare("oblique-6dof", "none,pida",
                            {**FRICTION, "facility.robot_delay": delay, "simulation.duration": 3.0})
    table = comparison.table
    assert list(table.columns) == TABLE_COLUMNS
    for column in ("tangential_impulse_error_pct", "direction_error_deg", "velocity_error_pct"):
        assert column in TABLE_COLUMNS
    summary = comparison.summary
    for kind, run in comparison.runs.items():
        errors = [c["tangential_impulse_error"] for c in run.metrics["collisions"]
                  if c.get("tangential_impulse_error") is not None]
        rows = table[table["compensator"] == kind]
        got = rows["tangential_impulse_error_pct"].dropna().to_numpy()
        assert got == pytest.approx(100.0 * np.asarray(errors))
        worst = summary.loc[kind, "worst_tangential_impulse_error_pct"]
        assert (math.isnan(worst) and not errors) or worst == pytest.approx(100.0 * max(errors))
        # a run whose tangential impulse breaks the tolerance is never ok
        if any(e > run.scenario.metrics.max_tangential_impulse_error for e in errors):
            assert run.status != "ok"
            assert any("tangential impulse error" in v for v in run.metrics["violations"]) or run.status != "unfaithful"
    text = comparison.to_markdown()
    assert "J_t error (%)" in text and "direction error (°)" in text


def test_run_prints_the_episode_table(core, tmp_path):
    out = tmp_path / "run"
    result = CliRunner().invoke(cli, ["run", "oblique-6dof", "--set", "contact.friction.kinetic=0.2",
                                      "--set", "simulation.duration=2", "--out", str(out)], prog_name="hilcontact")
    assert result.exit_code == 0, result.output
    assert "contact episodes" in result.stdout and "J_t" in result.stdout
    files = {p.name for p in out.iterdir()}
    assert set(PLOT_FILES_EPISODES) <= files


def test_contact_points_are_the_tips_in_contact_over_the_walls(rough):
    assert shows_episodes(rough)
    figures = rough.plot()
    assert {"contact_points", "contact_normal_tangential"} <= set(figures)
    xy = figures["contact_points"].axes[0]
    lines = {line.get_label(): line for line in xy.get_lines()}
    first = rough.metrics["collisions"][0]
    ts = rough.timeseries
    inside = (ts["time"] >= first["start"]) & (ts["time"] <= first["end"])
    hil = lines["HIL #1 (robot tip)"]
    assert np.array_equal(hil.get_xdata(), ts["actual_tip_position_x"][inside] * 1e3)
    assert np.array_equal(hil.get_ydata(), ts["actual_tip_position_y"][inside] * 1e3)
    assert "reference #1" in lines
    walls = [label for label in lines if label.startswith("wall ")]
    assert walls  # the front wall's outline at least
    # the front wall's outline is its plane cut at one depth z between its contact points':
    # along the line n_x (x − x0) + n_y (y − y0) = −n_z (z − z0)
    front = rough.scenario.walls[0]
    line = lines["wall 'front-oblique'"]
    n = np.asarray(front.normal) / np.linalg.norm(front.normal)
    x, y = line.get_xdata(), line.get_ydata()
    along = n[0] * (x - front.point[0] * 1e3) + n[1] * (y - front.point[1] * 1e3)
    assert along[0] == pytest.approx(along[1], abs=1e-9)
    z = front.point[2] * 1e3 - along[0] / n[2]
    tips = ts[["actual_tip_position_z"]].to_numpy()[inside] * 1e3
    assert tips.min() - 1.0 <= z <= tips.max() + 40.0  # the mean depth of the points nearest to the wall
    normal_ax, tangential_ax = figures["contact_normal_tangential"].axes
    t_lines = {line.get_label(): line for line in tangential_ax.get_lines()}
    assert np.nanmax(t_lines["|F_t| HIL"].get_ydata()) > 0.0


def test_1d_frictionless_runs_get_no_episode_figures(core):
    run = hc.simulate(hc.load_scenario("paper-table1", {"simulation.duration": 1.5, "facility.robot_delay": 0.0}))
    assert not shows_episodes(run)
    rough_1d = hc.simulate(hc.load_scenario("paper-table1", {"simulation.duration": 1.5, **FRICTION}))
    assert shows_episodes(rough_1d)
