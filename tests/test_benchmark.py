"""hil-bench-1 (hilcontact.benchmark, `hilcontact benchmark`): the suite's definition, a run
on a small subset, interruption and resume giving the same table, the comparison of two
folders, bad input."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pandas as pd
import pytest

import hilcontact as hc
from hilcontact import benchmark as bench
from hilcontact.output import OutputError

from test_cli import assert_one_error_line, invoke

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "compensators"
PASS_THROUGH = f"{EXAMPLES / 'pass_through.py'}:PassThrough"
SUBSET = "paper-10ms,oblique-6dof,grid-040ms-4hz-*"


def test_suite_is_one_table_of_unique_valid_cases(core):
    names = [c.name for c in bench.CASES]
    assert len(names) == len(set(names))
    assert bench.SUITE == "hil-bench-1"
    for case in bench.CASES:
        case.scenario()  # every case resolves
    grid = [c for c in bench.CASES if c.group == "grid"]
    assert {c.delay for c in grid} == set(bench.GRID_DELAYS)
    assert min(bench.GRID_DELAYS) == 0.010 and max(bench.GRID_DELAYS) == 0.150
    assert len(grid) == len(bench.GRID_DELAYS) * len(bench.GRID_FREQUENCIES) * len(bench.GRID_VARIANTS)
    for case in grid:  # the contact frequency is what the grid says (√(k/μ)/2π, from the core)
        s = case.scenario()
        assert math.isclose(core.contact_frequency(s.to_json()), case.frequency, rel_tol=1e-6)
        assert s.facility.robot_delay == case.delay
    kinds = {c.scenario().contact.model for c in bench.CASES}
    assert kinds == {"linear", "hunt-crossley"}
    assert any(c.scenario().facility.servo_frequency > 0 for c in bench.CASES)
    assert any(c.scenario().facility.sensor_noise > 0 and c.scenario().facility.sensor_delay > 0 for c in bench.CASES)


def test_select_cases():
    assert [c.name for c in bench.select_cases("paper-10ms")] == ["paper-10ms"]
    assert len(bench.select_cases("grid-*")) == len([c for c in bench.CASES if c.group == "grid"])
    with pytest.raises(hc.ScenarioError, match="--cases nothing-\\*: matches no case"):
        bench.select_cases("paper-10ms,nothing-*")


def _table(folder: Path) -> pd.DataFrame:
    return pd.read_csv(folder / "results.csv").drop(columns=["wall_time"])


def test_benchmark_runs_a_subset_and_its_rows_are_the_runs(core, tmp_path):
    out = tmp_path / "b"
    summary = bench.run_benchmark(out, "none,pida", cases=SUBSET, plots=True)
    results = bench.load_benchmark(out)
    assert len(results) == 2 * len(bench.select_cases(SUBSET))
    assert list(summary["compensator"]) == ["none", "pida"]
    for name in ("summary.md", "summary.csv", "results.csv", "pass_fraction.png"):
        assert (out / name).is_file()
    # a row is the run's verdict and sweep row: the same numbers as a run of its own
    row = results[(results["compensator"] == "pida") & (results["case"] == "paper-10ms")].iloc[0]
    run = hc.simulate(bench.select_cases("paper-10ms")[0].scenario("pida"))
    assert row["status"] == run.status and bool(row["passed"]) == (run.status == "ok")
    assert row["collisions"] == len(run.metrics["collisions"])
    worst = max(run.metrics["collisions"], key=lambda c: abs(c["cov"] - 1.0))["cov"]
    assert math.isclose(row["worst_cov"], worst, rel_tol=1e-12)
    # the pass fraction is the share of passed cases
    for r in summary.itertuples():
        mine = results[results["compensator"] == r.compensator]
        assert r.cases == len(mine) and r.passed == int(mine["passed"].sum())
        assert math.isclose(r.pass_fraction, mine["passed"].mean())


def test_interrupted_and_resumed_gives_the_same_table(core, tmp_path):
    whole = tmp_path / "whole"
    bench.run_benchmark(whole, "none,pic", cases=SUBSET, plots=False)
    part = tmp_path / "part"
    calls = []

    def interrupt(done, total):
        calls.append(done)
        if done >= 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        bench.run_benchmark(part, "none,pic", cases=SUBSET, plots=False, threads=1, progress=interrupt)
    finished = list((part / "cases").rglob("*.json"))
    assert 3 <= len(finished) < 2 * len(bench.select_cases(SUBSET))
    assert not (part / "results.csv").exists()
    # a resume without --resume is refused; with it, the finished runs are not run again
    with pytest.raises(OutputError, match="add --resume"):
        bench.run_benchmark(part, "none,pic", cases=SUBSET, plots=False)
    before = {p: p.stat().st_mtime_ns for p in finished}
    bench.run_benchmark(part, "none,pic", cases=SUBSET, plots=False, resume=True)
    assert all(p.stat().st_mtime_ns == t for p, t in before.items())
    pd.testing.assert_frame_equal(_table(part), _table(whole))
    assert (part / "summary.md").read_text() == (whole / "summary.md").read_text()
    # resuming with other compensators is refused
    with pytest.raises(OutputError, match="other compensators"):
        bench.run_benchmark(part, "none", cases=SUBSET, plots=False, resume=True)


def test_a_python_pass_through_scores_as_none(core, tmp_path):
    out = tmp_path / "py"
    bench.run_benchmark(out, "none", python=[PASS_THROUGH], cases="paper-10ms,grid-010ms-2hz-noisy", plots=False)
    results = bench.load_benchmark(out).drop(columns=["wall_time"])
    none = results[results["compensator"] == "none"].drop(columns=["compensator"]).reset_index(drop=True)
    py = results[results["compensator"] == "py:PassThrough"].drop(columns=["compensator"]).reset_index(drop=True)
    pd.testing.assert_frame_equal(py, none)


def test_cli_benchmark_and_compare(core, tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    result = invoke("benchmark", "--compensators", "none", "--cases", "paper-10ms", "--out", str(a), "--no-plots")
    assert result.exit_code == 0, result.output
    assert "| none | 1 |" in result.stdout
    result = invoke("benchmark", "--compensators", "pida", "--cases", "paper-10ms", "--out", str(b), "--no-plots")
    assert result.exit_code == 0, result.output
    result = invoke("benchmark", "--compare", str(a), str(b))
    assert result.exit_code == 0, result.output
    assert "| a | none |" in result.stdout and "| b | pida |" in result.stdout
    assert "none (a)" in result.stdout and "pida (b)" in result.stdout
    recorded = json.loads((a / "benchmark.json").read_text())
    assert recorded["suite"] == "hil-bench-1" and recorded["cases"] == ["paper-10ms"]


@pytest.mark.parametrize("args,fragment", [
    (["--cases", "nope"], "--cases nope: matches no case"),
    (["--compensators", "magic"], "unknown compensator 'magic'"),
    (["--compensator", "nowhere.py:X"], "no such file"),
])
def test_cli_benchmark_bad_input_writes_nothing(core, tmp_path, args, fragment):
    out = tmp_path / "o"
    result = invoke("benchmark", *args, "--out", str(out))
    assert_one_error_line(result, fragment)
    assert not out.exists()


def test_cli_benchmark_refuses_a_foreign_folder(core, tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    (out / "mine.txt").write_text("x")
    result = invoke("benchmark", "--cases", "paper-10ms", "--out", str(out))
    assert_one_error_line(result, "not a benchmark's")
    assert sorted(p.name for p in out.iterdir()) == ["mine.txt"]


def test_on_dask_gives_the_same_table(core, tmp_path):
    distributed = pytest.importorskip("dask.distributed")
    local = tmp_path / "local"
    bench.run_benchmark(local, "none,pida", python=[PASS_THROUGH], cases="paper-10ms,grid-010ms-2hz-*", plots=False)
    with distributed.Client(processes=False, n_workers=1, threads_per_worker=2, dashboard_address=None) as client:
        on_dask = tmp_path / "dask"
        bench.run_benchmark(on_dask, "none,pida", python=[PASS_THROUGH], cases="paper-10ms,grid-010ms-2hz-*",
                            plots=False, dask=client)
    pd.testing.assert_frame_equal(_table(on_dask), _table(local))
