"""The comparison's answer: ranking, recommendation, the tolerance each unfaithful run broke;
and the stability map's seed fractions and cell rule."""

from __future__ import annotations

import json
import math
import random

import pandas as pd
import pytest
from conftest import synthetic_run

import hilcontact as hc
from hilcontact.comparison import ALL_KINDS, RANKING_RULE, Comparison, Violation
from hilcontact.stability import cell_rule, stability_map


def run_with(kind: str, collisions: list[tuple[float, float, float]], status: str | None = None,
             diverged_at: float | None = None, lost: int = 0, overrides: dict | None = None) -> hc.Run:
    """A synthetic run of ``kind`` whose collisions have these (CoV, CoF, velocity error);
    its status is the verdict of the default tolerances unless given."""
    run = synthetic_run()
    run.scenario = hc.load_scenario("paper-table1", {"compensator.kind": kind, **(overrides or {})})
    metrics = json.loads(json.dumps(run.metrics))
    metrics["compensator"] = kind
    metrics["collisions"] = [
        {"index": i, "start": i - 0.5, "end": i - 0.4, "peak_force": 100.0 * cof, "complete": True,
         "rebound_speed": 0.02 * cov, "reference": i, "cov": cov, "cof": cof, "velocity_error": error}
        for i, (cov, cof, error) in enumerate(collisions, start=1)
    ]
    metrics["lost_collisions"] = list(range(1, lost + 1))
    tol = run.scenario.metrics
    broken = any(abs(cov - 1) > tol.cov_tolerance or cof > tol.max_cof or error > tol.max_velocity_error
                 for i, (cov, cof, error) in enumerate(collisions, start=1) if i >= tol.judge_from) or lost > 0
    metrics["status"] = status or ("unfaithful" if broken else "ok")
    metrics["diverged_at"] = diverged_at
    run.metrics = metrics
    return run


GOOD = (1.01, 1.05, 0.01)


def test_ranking_and_recommendation_on_the_issue_case():
    # the issue's lab: model-mediated faithful from collision 3, pida's CoF 1.30 everywhere
    runs = {
        "none": run_with("none", [(2.8, 4.7, 1.8)], status="diverged", diverged_at=1.6),
        "pida": run_with("pida", [(1.0, 1.30, 0.01), (0.99, 1.30, 0.01), (0.98, 1.29, 0.02), (1.01, 1.30, 0.01)]),
        "dac": run_with("dac", [(1.01, 1.70, 0.03)] * 4),
        "model-mediated": run_with("model-mediated", [(1.0, 1.30, 0.01), (1.0, 1.30, 0.01), (1.0, 1.005, 0.001),
                                                      (1.0, 1.005, 0.002)]),
    }
    comparison = Comparison(runs)
    ranking = comparison.ranking
    assert [s.kind for s in ranking] == ["model-mediated", "pida", "dac", "none"]
    assert [s.rank for s in ranking] == [1, 2, 3, 4]
    mm, pida, dac, none = ranking
    assert mm.faithful_from == 3 and mm.verdict == "faithful from collision 3"
    # its worst margin from collision 3 on: CoF 1.005 / 1.2
    assert mm.margin == pytest.approx(1.005 / 1.2)
    assert pida.faithful_from is None and pida.verdict == "unfaithful"
    assert [(v.collision, v.metric) for v in pida.violations] == [(1, "CoF"), (2, "CoF"), (3, "CoF"), (4, "CoF")]
    assert pida.violations[0] == Violation(1, "CoF", 1.30, 1.2)
    assert pida.margin == pytest.approx(1.30 / 1.2)
    assert dac.margin == pytest.approx(1.70 / 1.2)
    assert none.verdict == "diverged at 1.600 s" and none.faithful_from is None
    line = comparison.recommendation
    assert line.startswith("use model-mediated: faithful from collision 3 on at 10 ms")
    assert "pida: collision 1: CoF 1.300 > 1.2 (+3 more)" in line
    # in the summary and the report too
    summary = comparison.summary
    assert summary.loc["pida", "rank"] == 2 and summary.loc["pida", "verdict"] == "unfaithful"
    assert summary.loc["pida", "violation"] == "collision 1: CoF 1.300 > 1.2"
    assert summary.loc["model-mediated", "violation"] == "collision 1: CoF 1.300 > 1.2"
    report = comparison.to_markdown()
    assert f"**Recommendation:** {line}." in report
    assert "| 2 | `pida` | unfaithful | 1.08 | collision 1: CoF 1.300 > 1.2 (+3 more) |" in report
    assert "| 4 | `none` | diverged at 1.600 s | 36.00 | diverged at 1.600 s |" in report  # |CoV - 1| 1.8 / 0.05
    assert report.index("## Ranking") < report.index("## Summary")


def test_a_faithful_run_wins_and_the_runner_up_is_named():
    runs = {
        "pic": run_with("pic", [(1.04, 1.04, 0.04), (1.08, 1.08, 0.08)]),  # unfaithful at #2 (|CoV-1| 0.08)
        "pida": run_with("pida", [(1.02, 1.10, 0.02)] * 3),
        "dac": run_with("dac", [(1.01, 1.15, 0.01)] * 3),
    }
    comparison = Comparison(runs)
    assert [s.kind for s in comparison.ranking] == ["pida", "dac", "pic"]  # margins 0.4 < 0.958 (CoF 1.15/1.2)
    pida = comparison.ranking[0]
    assert pida.verdict == "faithful" and pida.faithful_from == 1 and pida.violations == () and pida.reason == ""
    assert pida.margin == pytest.approx(max(0.02 / 0.05, 1.10 / 1.2, 0.02 / 0.05))
    line = comparison.recommendation
    assert line.startswith("use pida: faithful on every collision at 10 ms (worst margin 0.92")
    assert "; next: dac (faithful, worst margin 0.96)" in line
    pic = comparison.ranking[2]
    assert [str(v) for v in pic.violations] == ["collision 2: |CoV − 1| 0.080 > 0.05",
                                                "collision 2: velocity error 8.00 % > 5 %"]


def test_nothing_faithful_says_so_and_names_the_closest():
    runs = {"pic": run_with("pic", [(1.2, 1.1, 0.2)] * 3), "dac": run_with("dac", [(1.0, 1.3, 0.0)] * 3)}
    line = Comparison(runs).recommendation
    assert line == "no compensator is faithful at 10 ms; closest: dac (collision 1: CoF 1.300 > 1.2 (+2 more))"


def test_lost_collisions_are_never_faithful_and_judge_from_is_respected():
    lost = run_with("pida", [GOOD] * 3, lost=1)
    judged = run_with("model-mediated", [(1.0, 1.5, 0.0), (1.0, 1.5, 0.0), GOOD],
                      overrides={"metrics.judge_from": 3})
    comparison = Comparison({"pida": lost, "model-mediated": judged})
    mm, pida = comparison.ranking
    assert mm.verdict == "faithful" and mm.faithful_from == 3 and mm.violations == ()
    assert comparison.recommendation.startswith("use model-mediated: faithful on every collision from 3 on")
    assert pida.faithful_from is None and pida.violations == (Violation(None, "lost collisions", 1, 0),)
    assert str(pida.violations[0]) == "lost collisions 1 > 0"


def test_ranking_rule_holds_on_random_comparisons():
    """Over random runs: a permutation; faithful (from any collision) before never faithful
    before stopped; within a group by faithful_from then margin; every violation breaks its
    limit and every judged value over a limit is a violation."""
    rng = random.Random(26)
    kinds = list(ALL_KINDS)
    for _ in range(60):
        runs = {}
        for kind in rng.sample(kinds, rng.randint(1, len(kinds))):
            collisions = [(rng.uniform(0.9, 1.1), rng.uniform(0.9, 1.3), rng.uniform(0.0, 0.08))
                          for _ in range(rng.randint(0, 5))]
            stopped = rng.random() < 0.2
            runs[kind] = run_with(kind, collisions, status="diverged" if stopped else None,
                                  diverged_at=rng.uniform(0.5, 5.0) if stopped else None)
        ranking = Comparison(runs).ranking
        assert sorted(s.kind for s in ranking) == sorted(runs)
        assert [s.rank for s in ranking] == list(range(1, len(runs) + 1))

        def group(s):
            if runs[s.kind].status == "diverged":
                return 2
            return 0 if s.faithful_from is not None else 1

        groups = [group(s) for s in ranking]
        assert groups == sorted(groups)
        for a, b in zip(ranking, ranking[1:]):
            if group(a) == group(b) == 0:
                assert (a.faithful_from, a.margin) <= (b.faithful_from, b.margin)
            if group(a) == group(b) == 1 and math.isfinite(b.margin):
                assert a.margin <= b.margin
            if group(a) == group(b) == 2:
                assert runs[a.kind].metrics["diverged_at"] >= runs[b.kind].metrics["diverged_at"]
        for s in ranking:
            over = [(c["index"], name)
                    for c in runs[s.kind].metrics["collisions"]
                    for name, value, limit in (("|CoV − 1|", abs(c["cov"] - 1), 0.05), ("CoF", c["cof"], 1.2),
                                               ("velocity error (%)", c["velocity_error"], 0.05))
                    if value > limit]
            assert [(v.collision, v.metric) for v in s.violations] == over
            assert all(v.value > v.limit for v in s.violations)
            if s.faithful_from is not None:
                assert all(v.collision < s.faithful_from for v in s.violations)
                assert runs[s.kind].status != "ok" or s.faithful_from == 1


def test_ranking_rule_is_stated_once():
    assert "worst margin" in RANKING_RULE and "faithful" in RANKING_RULE
    assert RANKING_RULE in Comparison({"pida": run_with("pida", [GOOD])}).to_markdown()


def test_violations_agree_with_the_cores_verdict(core):
    """The Python violations are the core's (same collisions, same metrics), on real runs."""
    comparison = hc.compare("paper-table1", "pic,dac,pida,tdpa-impedance",
                            {"facility.robot_delay": 0.02, "simulation.duration": 3.0})
    names = {"|CoV − 1|": "|CoV - 1|", "CoF": "CoF", "velocity error (%)": "rebound velocity error"}
    for standing in comparison.ranking:
        run = comparison.runs[standing.kind]
        core_lines = run.metrics.get("violations") or []
        assert len(core_lines) == len(standing.violations), (standing.kind, core_lines)
        for line, violation in zip(core_lines, standing.violations):
            assert line.startswith(f"collision {violation.collision}: {names[violation.metric]}"), (line, violation)
        assert (run.status == "ok") == (standing.verdict == "faithful")


# ---- stability map: seed fractions and the cell rule -------------------------------------------


def _seeded_rows(outcomes: dict[float, list[bool]]) -> pd.DataFrame:
    """One compensator at 4 Hz; per delay, the faithful outcome of each seed."""
    rows = []
    for delay, seeds in outcomes.items():
        for seed, ok in enumerate(seeds, start=1):
            rows.append({"run_key": f"{delay}-{seed}", "compensator": "pida", "seed": seed, "robot_delay": delay,
                         "contact_frequency": 4.0, "worst_cov": 1.0 if ok else 1.05002, "worst_cof": 1.1,
                         "status": "ok" if ok else "unfaithful"})
    return pd.DataFrame(rows)


def test_stability_map_tolerates_one_failing_seed_of_three_by_default():
    # the issue's case: one of three seeds just over at 10 ms, every seed faithful at 20-40 ms
    rows = _seeded_rows({0.01: [True, False, True], 0.02: [True] * 3, 0.03: [True] * 3, 0.04: [False, False, True]})
    result = stability_map(rows)
    cells = result.cells.set_index("robot_delay")
    assert list(cells["faithful_runs"]) == [2, 3, 3, 1]
    assert list(cells["faithful_fraction"]) == pytest.approx([2 / 3, 1.0, 1.0, 1 / 3])
    assert list(cells["faithful"]) == [True, True, True, False]
    assert result.max_faithful_delay().loc[4.0, "pida"] == 0.03
    assert result.rule == cell_rule(1) and "but at most 1" in result.rule
    strict = stability_map(rows, tolerate=0)
    assert list(strict.cells["faithful"]) == [False, True, True, False]
    assert math.isnan(strict.max_faithful_delay().loc[4.0, "pida"])
    assert strict.rule == "a cell is faithful when every run in it is"


@pytest.mark.parametrize(("seeds", "tolerate", "faithful"), [
    ([True, False], 1, False),        # one of two: not fewer than half
    ([False], 1, False),
    ([True, True, True, False, False], 2, True),
    ([True, True, False, False], 2, False),
    ([True, True, True, False, False], 1, False),
])
def test_cell_rule(seeds, tolerate, faithful):
    result = stability_map(_seeded_rows({0.01: seeds}), tolerate=tolerate)
    assert bool(result.cells["faithful"].iloc[0]) is faithful
    assert result.cells["faithful_fraction"].iloc[0] == pytest.approx(sum(seeds) / len(seeds))


def test_stability_map_rejects_a_bad_tolerate():
    with pytest.raises(hc.HilContactError, match="tolerate: expected an integer >= 0, got -1"):
        stability_map(_seeded_rows({0.01: [True]}), tolerate=-1)
