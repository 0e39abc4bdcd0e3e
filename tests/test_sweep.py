"""Sweeps: grid syntax, runs, resume after an interruption, determinism (local threads and a
Dask LocalCluster), stability maps and the CLI."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

import hilcontact as hc
from hilcontact.cli import cli
from hilcontact.errors import ScenarioError
from hilcontact.stability import MAP_FILES, stability_map
from hilcontact.sweep import RESULT_COLUMNS, contact_frequency, load_results, parse_grid, plan_sweep

SHORT = {"simulation.duration": 2.0}  # two collisions: enough for CoV and CoF, quick


# ---- grid syntax --------------------------------------------------------------------------


def test_range_includes_both_ends_and_is_tidy():
    axis = parse_grid("facility.robot_delay=0.002:0.06:30")
    assert axis.key == "facility.robot_delay"
    assert len(axis.values) == 30
    assert axis.values[0] == 0.002 and axis.values[-1] == 0.06
    assert axis.values[12] == 0.026  # not 0.026000000000000002
    assert np.allclose(np.diff(axis.values), 0.002)


def test_list_and_single_values_are_toml_values():
    assert parse_grid("servicer.mass=100,300, 600,1200").values == (100, 300, 600, 1200)
    assert parse_grid("compensator.delay_mode=align,lead").values == ("align", "lead")
    assert parse_grid("facility.sensor_noise=0.2").values == (0.2,)
    assert parse_grid("contact.stiffness=1e5:1e5:1").values == (1e5,)


@pytest.mark.parametrize(
    ("spec", "fragment"),
    [
        ("facility.robot_delay", "expected KEY=START:STOP:COUNT"),
        ("=0:1:3", "expected KEY=START:STOP:COUNT"),
        ("facility.robot_delay=", "expected KEY=START:STOP:COUNT"),
        ("facility.robot_delay=0:1", "--grid facility.robot_delay: range '0:1' must be START:STOP:COUNT"),
        ("facility.robot_delay=0:x:3", "--grid facility.robot_delay: range '0:x:3': START and STOP must be numbers"),
        ("facility.robot_delay=0:1:2.5", "--grid facility.robot_delay: range '0:1:2.5': COUNT must be a whole number"),
        ("facility.robot_delay=0:1:0", "--grid facility.robot_delay: range '0:1:0': COUNT must be 1 to 100000"),
        ("facility.robot_delay=0:1:1", "one value needs START == STOP"),
        ("facility.robot_delay=0:inf:3", "must be finite"),
        ("servicer.mass=100,,300", "--grid servicer.mass: list '100,,300' has an empty item"),
        ("servicer.mass=100,100", "--grid servicer.mass: '100,100' repeats a value"),
    ],
)
def test_bad_grid_specs_name_the_key(spec, fragment):
    with pytest.raises(ScenarioError) as info:
        parse_grid(spec)
    assert fragment in str(info.value)


def test_bad_keys_and_values_are_reported_before_running(core):
    with pytest.raises(ScenarioError, match=r"--grid facility\.robot_dealy=0\.01: .*robot_dealy"):
        plan_sweep("paper-table1", ["facility.robot_dealy=0.01,0.02"], "pida")
    with pytest.raises(ScenarioError, match=r"--grid servicer\.mass=-5: servicer\.mass"):
        plan_sweep("paper-table1", ["servicer.mass=300,-5"], "pida")
    with pytest.raises(ScenarioError, match=r"--grid facility\.robot_delay=0\.0105: .*whole"):
        plan_sweep("paper-table1", ["facility.robot_delay=0.01,0.0105"], "pida")
    with pytest.raises(ScenarioError, match="--grid facility.seed: choose compensators with --compensators and seeds with --seeds"):
        plan_sweep("paper-table1", ["facility.seed=1,2"], "pida")
    with pytest.raises(ScenarioError, match="--grid servicer.mass: given more than once"):
        plan_sweep("paper-table1", ["servicer.mass=1,2", "servicer.mass=3"], "pida")
    with pytest.raises(ScenarioError, match="unknown compensator 'pidaa'"):
        plan_sweep("paper-table1", ["servicer.mass=300"], "pidaa")
    with pytest.raises(ScenarioError, match="--seeds"):
        plan_sweep("paper-table1", ["servicer.mass=300"], "pida", seeds=0)


def test_plan_is_the_product_of_axes_compensators_and_seeds(core):
    plan = plan_sweep(
        "paper-table1",
        {"facility.robot_delay": "0.01:0.03:3", "servicer.mass": [300, 600]},
        "none,pida",
        seeds=2,
    )
    assert plan.size == 3 * 2 * 2 * 2 == len(list(plan.runs()))
    assert plan.seeds == [1, 2]
    runs = list(plan.runs())
    assert len({r[0] for r in runs}) == plan.size  # unique run keys
    # the JSON handed to the core carries the point's values, the compensator and the seed
    key, point, kind, seed = runs[-1]
    data = json.loads(plan.scenario_json(point, kind, seed))
    assert data["facility"]["robot_delay"] == 0.03 and data["servicer"]["mass"] == 600
    assert data["compensator"]["kind"] == kind == "pida" and data["facility"]["seed"] == seed == 2


def test_contact_frequency_of_table1_is_4_hz():
    s = hc.load_scenario("paper-table1")
    assert contact_frequency(s) == pytest.approx(4.0, rel=1e-3)  # the paper's 4 Hz
    hunt = hc.load_scenario("paper-table1", {"contact.model": "hunt-crossley", "contact.exponent": 1.5})
    assert math.isnan(contact_frequency(hunt))


# ---- running ------------------------------------------------------------------------------


def _without_time(frame: pd.DataFrame) -> pd.DataFrame:
    return frame.drop(columns="wall_time").reset_index(drop=True)


def test_rows_summarise_each_run_as_a_simulation_does(core, tmp_path):
    grid = {"facility.robot_delay": [0.004, 0.02]}
    rows = hc.sweep("paper-table1", grid, "none,pida", seeds=1, out=tmp_path / "s", overrides=SHORT)
    assert list(rows.columns) == [*RESULT_COLUMNS[:2], "facility.robot_delay", *RESULT_COLUMNS[2:]]
    assert len(rows) == 4
    assert (tmp_path / "s" / "results.parquet").is_file() and (tmp_path / "s" / "sweep.json").is_file()
    assert not list((tmp_path / "s" / "parts").glob("*.parquet"))  # merged
    for _, row in rows.iterrows():
        run = hc.simulate(
            hc.load_scenario(
                "paper-table1",
                {**SHORT, "facility.robot_delay": row["facility.robot_delay"], "compensator.kind": row["compensator"]},
            )
        )
        summary = run.metrics["summary"]
        assert row["status"] == run.status
        assert row["collisions"] == summary["collisions"] == len(run.metrics["collisions"])
        for name in ("worst_cov", "mean_cov", "worst_cof", "mean_cof"):
            assert row[name] == pytest.approx(summary[name], rel=1e-12), name
        covs = [c["cov"] for c in run.metrics["collisions"] if c["cov"] is not None]
        assert row["worst_cov"] == max(covs, key=lambda v: abs(v - 1))
        assert row["robot_delay"] == row["facility.robot_delay"]
        assert row["contact_frequency"] == pytest.approx(4.0, rel=1e-3)
        assert row["wall_time"] > 0
    pida = rows[rows["compensator"] == "pida"]
    none = rows[rows["compensator"] == "none"]
    assert (abs(pida["worst_cov"] - 1) < 0.01).all() and pida["stiffness_error"].notna().all()
    assert (none["worst_cov"] > 1.05).all() and none["stiffness_error"].isna().all()


def test_same_seeds_same_rows_other_seeds_other_rows(core):
    args = dict(grid={"facility.robot_delay": [0.02]}, compensators="pida", overrides={**SHORT, "facility.sensor_noise": 0.3})
    first = hc.sweep("paper-table1", seeds=3, **args)
    again = hc.sweep("paper-table1", seeds=3, threads=1, **args)
    pd.testing.assert_frame_equal(_without_time(first), _without_time(again))
    assert list(first["seed"]) == [1, 2, 3]
    assert first["worst_cof"].nunique() == 3  # the noise differs from seed to seed


def test_interrupted_sweep_keeps_finished_rows_and_resume_skips_them(core, tmp_path):
    out = tmp_path / "sweep"
    args = dict(grid=["facility.robot_delay=0.004:0.02:5"], compensators="none,pida", seeds=2, overrides=SHORT)
    calls = []

    def stop_after_two_chunks(done, total):
        calls.append(done)
        if len(calls) == 3:  # the initial call, then two chunks of 4
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        hc.sweep("paper-table1", out=out, chunk_size=4, progress=stop_after_two_chunks, **args)
    saved = load_results(out)
    assert len(saved) == 8 and saved["run_key"].is_unique

    # without --resume the folder is protected
    with pytest.raises(ScenarioError, match="--resume"):
        hc.sweep("paper-table1", out=out, **args)
    # another sweep cannot be resumed into it
    with pytest.raises(ScenarioError, match="other seeds"):
        hc.sweep("paper-table1", out=out, resume=True, **{**args, "seeds": 3})

    progress = []
    rows = hc.sweep("paper-table1", out=out, resume=True, progress=lambda d, t: progress.append((d, t)), **args)
    assert progress[0] == (8, 20)  # the finished runs are counted, not run again
    assert progress[-1] == (20, 20)
    assert len(rows) == 20 and rows["run_key"].is_unique
    fresh = hc.sweep("paper-table1", **args)
    pd.testing.assert_frame_equal(_without_time(rows), _without_time(fresh))


def test_dask_local_cluster_gives_the_same_rows(core, tmp_path):
    pytest.importorskip("dask.distributed")
    from dask.distributed import Client, LocalCluster

    args = dict(
        grid={"facility.robot_delay": [0.01, 0.03], "servicer.mass": [300, 600]},
        compensators="none,dac,pida",
        seeds=2,
        overrides={**SHORT, "facility.sensor_noise": 0.2},
    )
    local = hc.sweep("paper-table1", **args)
    with LocalCluster(n_workers=2, threads_per_worker=1, dashboard_address=None) as cluster, Client(cluster) as client:
        remote = hc.sweep("paper-table1", dask=client, chunk_size=5, out=tmp_path / "d", **args)
    assert len(remote) == 24
    pd.testing.assert_frame_equal(_without_time(local), _without_time(remote))


# ---- stability maps -----------------------------------------------------------------------


def _synthetic_rows() -> pd.DataFrame:
    """Two frequencies x three delays x two seeds; faithful where it is written so."""
    rows = []
    # (frequency, delay) -> (worst_cov, worst_cof) of seed 1 and of seed 2
    table = {
        (4.0, 0.01): [(1.01, 1.05), (0.99, 1.10)],
        (4.0, 0.02): [(1.04, 1.19), (1.06, 1.10)],  # seed 2: |CoV-1| = 6 %: not faithful
        (4.0, 0.03): [(1.00, 1.10), (1.00, 1.10)],  # faithful again, but past a gap
        (8.0, 0.01): [(1.00, 1.25), (1.00, 1.00)],  # CoF 1.25: not faithful
        (8.0, 0.02): [(1.00, 1.00), (1.00, 1.00)],
        (8.0, 0.03): [(1.00, 1.00), (1.00, 1.00)],
    }
    for (freq, delay), seeds in table.items():
        for seed, (cov, cof) in enumerate(seeds, start=1):
            rows.append(
                {"run_key": f"{freq}-{delay}-{seed}", "compensator": "pida", "seed": seed, "robot_delay": delay,
                 "contact_frequency": freq, "worst_cov": cov, "worst_cof": cof,
                 # the core's verdict with the default tolerances
                 "status": "ok" if abs(cov - 1) <= 0.05 and cof <= 1.2 else "unfaithful"}
            )
            rows.append(
                {"run_key": f"n-{freq}-{delay}-{seed}", "compensator": "none", "seed": seed, "robot_delay": delay,
                 "contact_frequency": freq, "status": "ok" if delay < 0.02 else "diverged",
                 "worst_cov": 1.0 if delay < 0.02 else math.nan, "worst_cof": 1.0}
            )
    return pd.DataFrame(rows)


def test_stability_map_cells_and_maximal_faithful_delay():
    result = stability_map(_synthetic_rows())
    cells = result.cells.set_index(["compensator", "contact_frequency", "robot_delay"])
    assert cells.loc[("pida", 4.0, 0.01), "faithful"]
    assert not cells.loc[("pida", 4.0, 0.02), "faithful"]
    assert cells.loc[("pida", 4.0, 0.02), "worst_cov"] == 1.06  # the seed farthest from 1
    assert cells.loc[("pida", 4.0, 0.02), "worst_cof"] == 1.19
    assert cells.loc[("pida", 4.0, 0.02), "runs"] == 2
    assert cells.loc[("none", 4.0, 0.03), "diverged"] == 2
    best = result.max_faithful_delay()
    assert best.loc[4.0, "pida"] == 0.01  # the faithful cell at 30 ms lies past a gap
    assert math.isnan(best.loc[8.0, "pida"])  # the smallest delay already fails
    assert best.loc[4.0, "none"] == 0.01
    stricter = stability_map(_synthetic_rows(), cov_tolerance=0.005)
    assert math.isnan(stricter.max_faithful_delay().loc[4.0, "pida"])


def test_stability_map_cli_on_a_real_sweep(core, tmp_path):
    out = tmp_path / "s1"
    runner = CliRunner()
    result = runner.invoke(
        cli,
        ["sweep", "paper-table1", "--grid", "facility.robot_delay=0.004:0.024:3", "--grid", "servicer.mass=300,1200",
         "--compensators", "none,pida", "--set", "simulation.duration=2", "--out", str(out)],
    )
    assert result.exit_code == 0, result.output
    assert "12 runs" in result.output
    rows = pd.read_parquet(out / "results.parquet")
    assert len(rows) == 12 and set(rows["compensator"]) == {"none", "pida"}
    result = runner.invoke(cli, ["stability-map", str(out), "--out", str(tmp_path / "map")])
    assert result.exit_code == 0, result.output
    for name in MAP_FILES:
        assert (tmp_path / "map" / name).stat().st_size > 0, name
    best = pd.read_csv(tmp_path / "map" / "max_faithful_delay.csv", index_col=0)
    assert list(best.columns) == ["none", "pida"]
    assert len(best) == 2  # two masses: two contact frequencies
    assert best["pida"].notna().all() and best["none"].isna().all()
    assert "maximal faithful robot delay" in result.output


def test_sweep_cli_errors_exit_2_and_write_nothing(core, tmp_path):
    runner = CliRunner()
    out = tmp_path / "bad"
    result = runner.invoke(cli, ["sweep", "paper-table1", "--grid", "servicer.mass=1:2", "--out", str(out)])
    assert result.exit_code == 2
    assert "error: --grid servicer.mass: range '1:2' must be START:STOP:COUNT" in result.output
    assert not out.exists()
    result = runner.invoke(cli, ["stability-map", str(tmp_path / "nowhere")])
    assert result.exit_code == 2 and "not a sweep folder" in result.output


def test_sweep_cli_on_a_local_dask_cluster_matches_threads(core, tmp_path):
    pytest.importorskip("dask.distributed")
    runner = CliRunner()
    common = ["sweep", "paper-table1", "--grid", "facility.robot_delay=0.01,0.02", "--compensators", "none,pida",
              "--seeds", "2", "--set", "simulation.duration=2", "--set", "facility.sensor_noise=0.2"]
    result = runner.invoke(cli, [*common, "--out", str(tmp_path / "threads")])
    assert result.exit_code == 0, result.output
    result = runner.invoke(cli, [*common, "--out", str(tmp_path / "dask"), "--dask", "local"])
    assert result.exit_code == 0, result.output
    threads = pd.read_parquet(tmp_path / "threads" / "results.parquet")
    dask = pd.read_parquet(tmp_path / "dask" / "results.parquet")
    assert len(dask) == 8
    pd.testing.assert_frame_equal(_without_time(threads), _without_time(dask))
