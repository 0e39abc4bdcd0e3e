"""Several compensators on one scenario: the runs, a table per collision, a summary, figures.

    import hilcontact as hc
    comparison = hc.compare("paper-table1", overrides={"facility.robot_delay": 0.02})
    comparison.summary          # one row per compensator
    comparison.table            # one row per compensator and collision
    comparison.save("runs/paper-table1-compare")

Every compensator runs the same scenario, loaded with the overrides and
``compensator.kind = <kind>``. A compensator parameter set by an override
(``compensator.alpha_max``) goes to the compensators that have it; one that no compared
compensator has is an error.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pandas as pd

from .errors import ArgumentError, HilContactError, ScenarioError, describe
from .registry import KINDS
from .output import write_atomically
from .run import Run, simulate
from .verdict import RENDERING_LABELS, Violation, _finite, _judge, _ratio, rendering_label  # noqa: F401  (Violation, RENDERING_LABELS are part of this module's API)
from .scenario import COMPENSATOR_MODELS, Scenario, _check_overrides, _override_steps, _read_source, load_scenario

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "ALL_KINDS",
    "COMPARISON_FIGURES",
    "RANKING_RULE",
    "Comparison",
    "DelayComparison",
    "Standing",
    "Violation",
    "compare",
    "compare_over_delays",
    "comparison_scenarios",
    "parse_kinds",
    "run_comparison",
]

#: Every compensator kind, in the order of the tables and figures.
ALL_KINDS: tuple[str, ...] = KINDS

#: Figures of a comparison (file stems); ``compare_identification`` only when a compared
#: compensator identifies the contact, ``compare_measured_applied`` only when the ideal
#: reference has a collision, ``compare_velocity_error`` only when the motion is not 1-D.
COMPARISON_FIGURES = (
    "compare_velocity",
    "compare_force",
    "compare_energy",
    "compare_identification",
    "compare_cov_cof",
    "compare_measured_applied",
    "compare_velocity_error",
)

#: Per-collision columns of :attr:`Comparison.table`: ``(column, metrics.json key, scale)``
#: (the collision's value times the scale; docs/model.md "Metrics").
PER_COLLISION_COLUMNS: tuple[tuple[str, str, float], ...] = (
    ("cov", "cov", 1.0),
    ("cof", "cof", 1.0),
    ("peak_force_N", "peak_force", 1.0),
    ("rebound_speed_mm_s", "rebound_speed", 1e3),
    ("velocity_error_pct", "velocity_error", 100.0),
    ("direction_error_deg", "direction_error", 1.0),
    ("tangential_impulse_error_pct", "tangential_impulse_error", 100.0),
    ("normal_impulse_error_pct", "normal_impulse_error", 100.0),
    ("tangential_impulse_Ns", "tangential_impulse", 1.0),
    ("normal_impulse_Ns", "normal_impulse", 1.0),
)

#: Columns of :attr:`Comparison.table` (and of ``comparison.csv``).
TABLE_COLUMNS = [
    "compensator",
    "collision",
    *[column for column, _, _ in PER_COLLISION_COLUMNS],
    "rendering",
    "status",
    "worst_cov_error",
    "worst_cof",
    "mean_cov",
    "stiffness_error_pct",
    "damping_error_Ns_mm",
]

#: Columns of :attr:`Comparison.summary` (index: compensator).
SUMMARY_COLUMNS = [
    "status",
    "diverged_at",
    "collisions",
    "cov",
    "mean_cov",
    "worst_cov_error",
    "worst_cof",
    "stiffness_error_pct",
    "damping_error_Ns_mm",
    "worst_velocity_error_pct",
    "worst_direction_error_deg",
    "worst_tangential_impulse_error_pct",
    "lost_collisions",
    "extra_collisions",
    "rank",
    "verdict",
    "violation",
]


def parse_kinds(kinds: str | Iterable[str] | None, argument: str = "compensators") -> list[str]:
    """Compensator kinds from a comma-separated string or a list (None: all of them), checked,
    duplicates removed, in the given order; ``argument`` names them in the error
    (:class:`~hilcontact.errors.ArgumentError` for a wrong type, ScenarioError for an unknown
    kind)."""
    if kinds is None:
        return list(ALL_KINDS)
    allowed = ", ".join(ALL_KINDS)
    if isinstance(kinds, (bytes, Mapping)) or not isinstance(kinds, (str, Iterable)):
        raise ArgumentError(
            f"{argument}: expected compensator kinds (a list, or a comma-separated string), got {describe(kinds)}; "
            f"allowed: {allowed}"
        )
    items = kinds.split(",") if isinstance(kinds, str) else list(kinds)
    out: list[str] = []
    for item in items:
        if not isinstance(item, str):
            raise ArgumentError(f"{argument}: expected compensator kinds, got {describe(item)}; allowed: {allowed}")
        kind = item.strip()
        if not kind:
            continue  # "none,pida," or spaces
        if kind not in COMPENSATOR_MODELS:
            raise ScenarioError(f"{argument}: unknown compensator {describe(kind)}; allowed: {allowed}")
        if kind not in out:
            out.append(kind)
    if not out:
        raise ScenarioError(f"{argument}: none given; allowed: {allowed}")
    return out


def comparison_scenarios(
    scenario_source: Any,
    kinds: str | Iterable[str] | None = None,
    overrides: Mapping[str, Any] | None = None,
    *,
    argument: str = "compensators",
) -> dict[str, Scenario]:
    """The resolved scenario of each compensator (validated before anything runs).

    Raises ScenarioError for a bad scenario, override or kind (``argument`` names the kinds in
    the message), and for an override of ``compensator.kind`` (the kinds are the ``kinds``
    argument).
    """
    _check_overrides(overrides)
    chosen = parse_kinds(kinds, argument)
    user = dict(overrides or {})
    parameters: dict[str, str] = {}  # override key -> compensator parameter it sets
    for key in user:
        steps = _override_steps(key)
        if steps == ["compensator", "kind"]:
            raise ScenarioError(
                "compensator.kind: a comparison runs every chosen compensator; choose them with "
                "--compensators (kinds=...) instead of overriding compensator.kind"
            )
        if len(steps) == 2 and steps[0] == "compensator" and isinstance(steps[1], str):
            parameters[key] = steps[1]
    owned = {name for kind in chosen for name in COMPENSATOR_MODELS[kind].model_fields}
    raw = _read_source(scenario_source)
    scenarios: dict[str, Scenario] = {}
    for kind in chosen:
        fields = COMPENSATOR_MODELS[kind].model_fields
        # a parameter that some compared kind has goes only to those; an unknown one is kept
        # everywhere, so that validation reports it
        mine = {
            key: value
            for key, value in user.items()
            if key not in parameters or parameters[key] in fields or parameters[key] not in owned
        }
        scenarios[kind] = load_scenario(raw, {**mine, "compensator.kind": kind})
    return scenarios


#: How :attr:`Comparison.ranking` orders the compensators (quoted by docs/choosing.md).
RANKING_RULE = (
    "Compensators that ran to the end come first, those that diverged or stopped last (the "
    "later the stop, the better). Among those that ran to the end: first the ones faithful "
    "from an earlier collision (every collision from it on within the scenario's [metrics] "
    "tolerances: |CoV − 1|, CoF, rebound velocity error, tangential impulse error; judged from `judge_from`; none lost "
    "or extra beyond those allowed; at least one compared collision from it on), then the ones "
    "never faithful; ties go to the smaller worst margin, the largest of |CoV − 1| / "
    "cov_tolerance, CoF / max_cof, velocity error / max_velocity_error and tangential impulse "
    "error / max_tangential_impulse_error over the collisions judged (from the faithful one on, "
    "or all of them). The rebound direction error needs no tolerance of its own: a direction "
    "off by θ ≤ 90° has a velocity error ≥ sin θ, so max_velocity_error 0.05 bounds it to "
    "2.87°."
)


@dataclass(frozen=True)
class Standing:
    """A compensator's place in :attr:`Comparison.ranking` (:data:`RANKING_RULE`).

    Attributes:
        kind: the compensator.
        rank: 1 for the best.
        faithful_from: the first collision (1-based) from which every collision keeps the
            tolerances (None: never; a run that diverged is never faithful).
        margin: the worst margin (largest value / limit over the collisions judged; > 1 breaks
            a tolerance), NaN without a compared collision.
        violations: every tolerance broken, per collision, in order (collisions before
            ``[metrics] judge_from`` are not judged).
        verdict: one phrase: ``faithful``, ``faithful from collision 3``, ``unfaithful``,
            ``diverged at 1.234 s``.
    """

    kind: str
    rank: int
    faithful_from: int | None
    margin: float
    violations: tuple[Violation, ...]
    verdict: str

    @property
    def reason(self) -> str:
        """Why it is not faithful (on every collision): its worst violation and how many more,
        or its stop; empty when faithful."""
        return _why_not(self) if self.verdict != "faithful" else ""


def _nan(value: Any) -> float:
    if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value):
        return float(value)
    return math.nan


@dataclass
class Comparison:
    """The result of :func:`compare`: one :class:`Run` per compensator, same scenario.

    Attributes:
        runs: compensator kind -> run, in the compared order.

    The answer: :attr:`ranking` (a :class:`Standing` per compensator, best first, by
    :data:`RANKING_RULE`: rank, verdict, faithful_from, margin, every :class:`Violation`),
    :attr:`recommendation` (one line), and :attr:`summary` (with rank, verdict and the worst
    violation per compensator); :attr:`table` per collision.
    """

    runs: dict[str, Run]

    def __post_init__(self) -> None:
        if not self.runs:
            raise HilContactError("a comparison needs at least one run")

    @classmethod
    def load(cls, directory: str | os.PathLike[str]) -> Comparison:
        """A comparison from the folder :meth:`save` wrote: one run folder per compensator
        (``<kind>/``), in the order of :data:`ALL_KINDS`. Raises ScenarioError naming the folder
        when it holds no run folder."""
        folder = Path(directory)
        if not folder.is_dir():
            raise ScenarioError(f"{folder}: not a folder")
        runs = {kind: Run.load(folder / kind) for kind in ALL_KINDS if (folder / kind / "metrics.json").is_file()}
        runs.update({p.name: Run.load(p) for p in sorted(folder.glob("py:*")) if (p / "metrics.json").is_file()})
        if not runs:
            raise ScenarioError(f"{folder}: not a comparison folder (no <compensator>/metrics.json)")
        return cls(runs)

    @property
    def scenario(self) -> Scenario:
        """The scenario of the first run (they differ only in ``[compensator]``)."""
        return next(iter(self.runs.values())).scenario

    @property
    def kinds(self) -> list[str]:
        return list(self.runs)

    # ---- tables ------------------------------------------------------------------------

    def _stats(self, run: Run) -> dict[str, Any]:
        collisions = run.metrics.get("collisions") or []
        summary = run.metrics.get("summary") or {}  # the core's one definition of worst/mean
        identification = run.metrics.get("identification") or {}
        at = run.metrics.get("diverged_at")
        return {
            "status": run.status,
            "diverged_at": _nan(at),
            "collisions": len(collisions),
            "cov": [_nan(c.get("cov")) for c in collisions],
            "mean_cov": _nan(summary.get("mean_cov")),
            "worst_cov_error": abs(_nan(summary.get("worst_cov")) - 1.0),
            "worst_cof": _nan(summary.get("worst_cof")),
            "stiffness_error_pct": _nan(identification.get("stiffness_error")) * 100.0,
            "damping_error_Ns_mm": _nan(identification.get("damping_error")) * 1e-3,
            "worst_velocity_error_pct": _nan(summary.get("worst_velocity_error")) * 100.0,
            "worst_direction_error_deg": _nan(summary.get("worst_direction_error")),
            "worst_tangential_impulse_error_pct": _nan(summary.get("worst_tangential_impulse_error")) * 100.0,
            "lost_collisions": len(run.metrics.get("lost_collisions") or []),
            "extra_collisions": len(run.metrics.get("extra_collisions") or []),
        }

    @property
    def ranking(self) -> list[Standing]:
        """The compensators from best to worst by :data:`RANKING_RULE`, each with why: the
        collision it is faithful from, its worst margin and every tolerance it broke."""
        judged = []
        for order, (kind, run) in enumerate(self.runs.items()):
            start, margin, violations = _judge(run)
            stopped = run.status not in ("ok", "unfaithful")
            at = _nan(run.metrics.get("diverged_at"))
            if stopped:
                key: tuple[Any, ...] = (2, -at if math.isfinite(at) else 0.0, order)
                verdict = f"{run.status} at {at:.3f} s" if math.isfinite(at) else run.status
            elif start is not None:
                key = (0, start, margin, order)
                verdict = "faithful" if run.status == "ok" else f"faithful from collision {start}"
            else:
                key = (1, margin if math.isfinite(margin) else math.inf, order)
                verdict = "unfaithful" if violations else "no compared collision"
            judged.append((key, kind, start, margin, violations, verdict))
        judged.sort(key=lambda item: item[0])
        return [Standing(kind, rank, start, margin, tuple(violations), verdict)
                for rank, (_, kind, start, margin, violations, verdict) in enumerate(judged, 1)]

    @property
    def recommendation(self) -> str:
        """One line: the compensator to use (the first of :attr:`ranking`) and why, and why
        not the next one; or that none is faithful, and the closest."""
        ranking = self.ranking
        delay = f"{self.scenario.facility.robot_delay * 1e3:g} ms"
        best = ranking[0]
        if best.faithful_from is None:
            line = f"no compensator is faithful at {delay}; closest: {best.kind} ({_why_not(best)})"
        elif best.verdict == "faithful":
            judged = self.runs[best.kind].scenario.metrics.judge_from
            where = "every collision" if judged == 1 else f"every collision from {judged} on"
            line = f"use {best.kind}: faithful on {where} at {delay} (worst margin {best.margin:.2f} of the tolerances)"
        else:
            line = (f"use {best.kind}: faithful from collision {best.faithful_from} on at {delay} "
                    f"(before: {_worst(best.violations)})")
        if len(ranking) > 1 and best.faithful_from is not None:
            runner = ranking[1]
            if runner.faithful_from is None:
                line += f"; {runner.kind}: {_why_not(runner)}"
            else:
                line += f"; next: {runner.kind} ({runner.verdict}, worst margin {runner.margin:.2f})"
        return line

    @property
    def summary(self) -> pd.DataFrame:
        """One row per compensator (index ``compensator``), in the compared order: status,
        diverged_at (s, NaN if ok), collisions (count), cov (list, one per collision),
        mean_cov, worst_cov_error (largest |CoV - 1|), worst_cof (the CoF farthest from 1),
        stiffness_error_pct (%), damping_error_Ns_mm (N s/mm), worst_velocity_error_pct (%),
        worst_direction_error_deg (the largest rebound direction error, degrees),
        worst_tangential_impulse_error_pct (%), lost_collisions and extra_collisions (counts); then from :attr:`ranking`: rank (1:
        best), verdict (``faithful``, ``faithful from collision 3``, ``unfaithful``,
        ``diverged at 1.234 s``) and violation (the worst tolerance broken: collision,
        metric, value > limit; empty if none). NaN where the run has no such value."""
        standings = {s.kind: s for s in self.ranking}
        rows = [
            {"compensator": kind, **self._stats(run), "rank": standings[kind].rank,
             "verdict": standings[kind].verdict, "violation": _worst(standings[kind].violations)}
            for kind, run in self.runs.items()
        ]
        frame = pd.DataFrame(rows, columns=["compensator", *SUMMARY_COLUMNS])
        return frame.set_index("compensator")

    @property
    def table(self) -> pd.DataFrame:
        """One row per compensator and collision (a compensator without collisions gets one
        row with an empty collision number): compensator, collision, the collision's values of
        :data:`PER_COLLISION_COLUMNS` (cov, cof, peak_force_N, rebound_speed_mm_s,
        velocity_error_pct, direction_error_deg, tangential_impulse_error_pct,
        normal_impulse_error_pct, tangential_impulse_Ns, normal_impulse_Ns), rendering (how the
        collision was handled: :func:`rendering_label`) and the compensator's summary values (status, worst_cov_error, worst_cof, mean_cov,
        stiffness_error_pct, damping_error_Ns_mm)."""
        rows = []
        first_per_run = TABLE_COLUMNS.index("rendering") + 1
        for kind, run in self.runs.items():
            stats = self._stats(run)
            per_run = {key: stats[key] for key in TABLE_COLUMNS[first_per_run:]}
            collisions = run.metrics.get("collisions") or [{}]
            for collision in collisions:
                rows.append(
                    {
                        "compensator": kind,
                        "collision": collision.get("index"),
                        **{column: _nan(collision.get(key)) * scale for column, key, scale in PER_COLLISION_COLUMNS},
                        "rendering": rendering_label(collision.get("rendering")),
                        **per_run,
                    }
                )
        frame = pd.DataFrame(rows, columns=TABLE_COLUMNS)
        frame["collision"] = frame["collision"].astype("Int64")
        return frame

    def to_csv(self) -> str:
        """:attr:`table` as CSV, ``-`` for missing values."""
        return self.table.to_csv(index=False, na_rep="-")

    def to_markdown(self, figures: Iterable[str] = ()) -> str:
        """The report: a summary table, the per-collision table, then links to ``figures``
        (file names)."""
        s = self.scenario
        f = s.facility
        contact = s.contact
        lines = [
            f"# Compensator comparison: {s.name}",
            "",
            f"Robot delay {f.robot_delay * 1e3:g} ms, sensor delay {f.sensor_delay * 1e3:g} ms, "
            f"force noise {f.sensor_noise:g} N; true contact ({contact.model}) stiffness "
            f"{contact.stiffness * 1e-3:g} N/mm, damping {contact.damping * 1e-3:g} N·s/mm.",
            "CoV and CoF are the rebound speed and the peak force of each collision divided by "
            "those of the ideal reference (1 is perfect). `-`: no value.",
            "",
            "## Ranking",
            "",
            f"**Recommendation:** {_escape(self.recommendation)}.",
            "",
            "| rank | compensator | verdict | worst margin | tolerances broken (worst; all in metrics.json) |",
            "|--:|---|---|--:|---|",
            *[
                f"| {s.rank} | `{s.kind}` | {s.verdict} | {_cell(s.margin, '.2f')} | {_escape(s.reason) or '-'} |"
                for s in self.ranking
            ],
            "",
            "Worst margin: the largest value / limit of |CoV − 1|, CoF, velocity error and tangential "
            "impulse error over the collisions judged (1 = at a tolerance). " + RANKING_RULE,
            "",
            "## Summary",
            "",
            "| compensator | status | CoV per collision | mean CoV | worst \\|CoV − 1\\| | worst CoF "
            "| worst velocity error (%) | worst direction error (°) | worst J_t error (%) "
            "| lost, extra | k error (%) | c error (N·s/mm) |",
            "|---|---|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|",
        ]
        for kind, row in self.summary.iterrows():
            status = str(row["status"])
            if math.isfinite(row["diverged_at"]):
                status += f" at {row['diverged_at']:.3f} s"
            covs = ", ".join(_cell(v, ".3f") for v in row["cov"]) or "-"
            lines.append(
                f"| `{kind}` | {status} | {covs} | {_cell(row['mean_cov'], '.3f')} "
                f"| {_cell(row['worst_cov_error'], '.3f')} | {_cell(row['worst_cof'], '.3f')} "
                f"| {_cell(row['worst_velocity_error_pct'], '.2f')} "
                f"| {_cell(row['worst_direction_error_deg'], '.2f')} "
                f"| {_cell(row['worst_tangential_impulse_error_pct'], '.2f')} "
                f"| {row['lost_collisions']}, {row['extra_collisions']} "
                f"| {_cell(row['stiffness_error_pct'], '.3g')} | {_cell(row['damping_error_Ns_mm'], '.3g')} |"
            )
        lines += [
            "",
            "## Per collision",
            "",
            "| compensator | # | CoV | CoF | peak force (N) | rebound speed (mm/s) | velocity error (%) "
            "| direction error (°) | J_t error (%) | J_n error (%) | J_t (N·s) | J_n (N·s) | rendered by |",
            "|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|---|",
        ]
        for _, row in self.table.iterrows():
            number = "-" if pd.isna(row["collision"]) else str(int(row["collision"]))
            lines.append(
                f"| `{row['compensator']}` | {number} | {_cell(row['cov'], '.3f')} | {_cell(row['cof'], '.3f')} "
                f"| {_cell(row['peak_force_N'], '.1f')} | {_cell(row['rebound_speed_mm_s'], '.2f')} "
                f"| {_cell(row['velocity_error_pct'], '.2f')} | {_cell(row['direction_error_deg'], '.2f')} "
                f"| {_cell(row['tangential_impulse_error_pct'], '.2f')} | {_cell(row['normal_impulse_error_pct'], '.2f')} "
                f"| {_cell(row['tangential_impulse_Ns'], '.4g')} | {_cell(row['normal_impulse_Ns'], '.4g')} "
                f"| {row['rendering']} |"
            )
        figures = list(figures)
        if figures:
            lines += ["", "## Figures", ""]
            for name in figures:
                lines += [f"![{Path(name).stem}]({name})", ""]
            lines.pop()
        lines.append("")
        return "\n".join(lines)

    # ---- figures and files -------------------------------------------------------------

    def plot(self, directory: str | os.PathLike[str] | None = None) -> dict[str, Figure]:
        """The comparison figures (name -> matplotlib Figure, see :data:`COMPARISON_FIGURES`);
        saved as ``<name>.png`` in ``directory`` if given."""
        from .plots import comparison_figures, save_figures

        figures = comparison_figures(self.runs)
        if directory is not None:
            save_figures(figures, directory, dpi=110)
        return figures

    def save_figures(self, directory: str | os.PathLike[str]) -> list[str]:
        """Make and save the comparison figures as ``<name>.png`` in ``directory`` (on two
        cores when there are: :func:`hilcontact.plots.draw_in_two_processes`); returns the
        names saved. Faster than :meth:`plot` with a directory, which also returns the
        figures."""
        from .plots import comparison_figure_makers, draw_in_two_processes

        return draw_in_two_processes(comparison_figure_makers(self.runs), directory, dpi=110)

    def save(self, directory: str | os.PathLike[str], plots: bool = True, overwrite: bool = False,
             run_plots: bool = False) -> Path:
        """Write the comparison to ``directory``, atomically (a temporary sibling folder that
        then replaces ``directory``; only a new or empty folder, or one hilcontact wrote,
        unless ``overwrite``: :mod:`hilcontact.output`).

        Contents: ``<kind>/`` (a run folder per compensator, as :meth:`Run.save`, with its
        figures only if ``run_plots``: ``hilcontact plot DIR/<kind>`` draws them later),
        ``comparison.md``, ``comparison.csv`` and, unless ``plots=False``,
        ``compare_*.png``. Returns the folder's path.
        """
        def write(folder: Path) -> None:
            for kind, run in self.runs.items():
                run.save(folder / kind, plots=plots and run_plots)
            names = [f"{name}.png" for name in self.save_figures(folder)] if plots else []
            (folder / "comparison.csv").write_text(self.to_csv(), encoding="utf-8")
            (folder / "comparison.md").write_text(self.to_markdown(names), encoding="utf-8")

        return write_atomically(directory, write, "comparison", overwrite)


def _escape(text: str) -> str:
    """Text for a Markdown table cell (pipes escaped)."""
    return text.replace("|", "\\|")


def _worst(violations: Iterable[Violation]) -> str:
    """The collision's violation farthest over its limit (a lost or extra collision count
    only when no collision broke a tolerance), as text (empty if none)."""
    worst = max(violations, key=lambda v: (v.collision is not None, _ratio(v.value, v.limit)), default=None)
    return "" if worst is None else str(worst)


def _why_not(standing: Standing) -> str:
    """Why a compensator is not faithful: its worst violation (and how many more), or its stop."""
    if standing.violations and standing.verdict.startswith(("unfaithful", "faithful")):
        more = len(standing.violations) - 1
        return _worst(standing.violations) + (f" (+{more} more)" if more else "")
    return standing.verdict


def _cell(value: Any, fmt: str) -> str:
    if value is None:
        return "-"
    try:
        number = float(value)
    except (TypeError, ValueError):
        return "-"
    return format(number, fmt) if math.isfinite(number) else "-"


def compare(
    scenario_source: Any,
    kinds: str | Iterable[str] | None = None,
    overrides: Mapping[str, Any] | None = None,
    *,
    progress: Callable[[str, int, int], None] | None = None,
) -> Comparison:
    """Simulate one scenario with several compensators.

    ``scenario_source``: a preset name, a TOML path, a raw dict or a Scenario. ``kinds``: the
    compensators (a list or a comma-separated string; default: all of :data:`ALL_KINDS`).
    ``overrides``: dotted keys as in :func:`load_scenario`, applied to every run.
    ``progress(kind, index, total)`` is called before each run. Every scenario is validated
    before the first run; raises ScenarioError for bad input. A diverging run is a result,
    not an error.
    """
    if progress is not None and not callable(progress):
        raise ArgumentError(f"progress: expected a function (kind, index, total) or None, got {describe(progress)}")
    return run_comparison(comparison_scenarios(scenario_source, kinds, overrides, argument="kinds"), progress=progress)


def run_comparison(
    scenarios: Mapping[str, Scenario], *, progress: Callable[[str, int, int], None] | None = None
) -> Comparison:
    """Simulate resolved scenarios (kind -> Scenario, e.g. from :func:`comparison_scenarios`)."""
    if not isinstance(scenarios, Mapping) or not all(isinstance(s, Scenario) for s in scenarios.values()):
        raise ArgumentError(f"scenarios: expected a mapping kind -> Scenario, got {describe(scenarios)}")
    runs: dict[str, Run] = {}
    for index, (kind, scenario) in enumerate(scenarios.items()):
        if progress is not None:
            progress(kind, index, len(scenarios))
        runs[kind] = simulate(scenario)
    return Comparison(runs=runs)


def delay_label(delay: float) -> str:
    """A robot delay (s) as a folder name and label: ``10ms``."""
    return f"{delay * 1e3:g}ms"


#: Figures of a comparison over robot delays (file stems): one panel per delay, (a), (b), …
DELAY_FIGURES = ("compare_velocity", "compare_force", "compare_cov_cof")


@dataclass
class DelayComparison:
    """The result of :func:`compare_over_delays`: one :class:`Comparison` per robot delay.

    Attributes:
        comparisons: robot delay (s) -> comparison, in the given order.
    """

    comparisons: dict[float, Comparison]

    def to_markdown(self, figures: Iterable[str] = ()) -> str:
        """The report: per delay, its recommendation and ranking (the full tables in each
        delay's folder), then links to ``figures``."""
        first = next(iter(self.comparisons.values()))
        lines = [f"# Compensator comparison over robot delays: {first.scenario.name}", ""]
        for panel, (delay, comparison) in zip("abcdefghijklmnopqrstuvwxyz", self.comparisons.items()):
            lines += [f"## ({panel}) robot delay {delay * 1e3:g} ms", "",
                      f"**Recommendation:** {_escape(comparison.recommendation)}.", "",
                      "| rank | compensator | verdict | worst margin | tolerances broken |", "|--:|---|---|--:|---|"]
            lines += [f"| {s.rank} | `{s.kind}` | {s.verdict} | {_cell(s.margin, '.2f')} | {_escape(s.reason) or '-'} |"
                      for s in comparison.ranking]
            lines += ["", f"Tables and figures: [{delay_label(delay)}/comparison.md]({delay_label(delay)}/comparison.md)", ""]
        figures = list(figures)
        if figures:
            lines += ["## Figures", ""]
            for name in figures:
                lines += [f"![{Path(name).stem}]({name})", ""]
        lines.append("Ranking rule: " + RANKING_RULE)
        lines.append("")
        return "\n".join(lines)

    def plot(self) -> dict[str, Figure]:
        """The figures over delays (:data:`DELAY_FIGURES`), one panel per delay."""
        from .plots import delay_figures

        return delay_figures({delay: c.runs for delay, c in self.comparisons.items()})

    def save(self, directory: str | os.PathLike[str], plots: bool = True, overwrite: bool = False,
             run_plots: bool = False) -> Path:
        """Write ``<delay>ms/`` (a comparison folder per delay, as :meth:`Comparison.save`),
        ``comparison.md`` and, unless ``plots=False``, the figures over delays, atomically."""
        from .plots import save_figures

        def write(folder: Path) -> None:
            for delay, comparison in self.comparisons.items():
                comparison.save(folder / delay_label(delay), plots=plots, run_plots=run_plots)
            names = []
            if plots:
                figures = self.plot()
                save_figures(figures, folder, dpi=110)
                names = [f"{name}.png" for name in figures]
            (folder / "comparison.md").write_text(self.to_markdown(names), encoding="utf-8")

        return write_atomically(directory, write, "comparison-delays", overwrite)


def parse_delays(text: str) -> list[float]:
    """Robot delays (s) from ``"0.01,0.02"``: finite, >= 0, at most 8, duplicates removed.
    Raises ScenarioError with one line."""
    out: list[float] = []
    for item in text.split(","):
        item = item.strip()
        if not item:
            continue
        try:
            value = float(item)
        except ValueError:
            raise ScenarioError(f"--delays: {item!r} is not a number (seconds, e.g. 0.01,0.02)") from None
        if not (math.isfinite(value) and 0.0 <= value <= 60.0):
            raise ScenarioError(f"--delays: {item!r} must be between 0 and 60 s")
        if value not in out:
            out.append(value)
    if not out:
        raise ScenarioError("--delays: no delay given (seconds, e.g. 0.01,0.02)")
    if len(out) > 8:
        raise ScenarioError(f"--delays: at most 8 delays, got {len(out)}")
    return out


def delay_scenarios(
    scenario_source: Any, delays: Iterable[float], kinds: str | Iterable[str] | None = None,
    overrides: Mapping[str, Any] | None = None,
) -> dict[float, dict[str, Scenario]]:
    """The resolved scenarios per robot delay and compensator (all validated first);
    ``overrides`` may not set ``facility.robot_delay``."""
    user = dict(overrides or {})
    if any(_override_steps(key) == ["facility", "robot_delay"] for key in user):
        raise ScenarioError("facility.robot_delay: set the delays with --delays, not --set")
    return {delay: comparison_scenarios(scenario_source, kinds, {**user, "facility.robot_delay": delay})
            for delay in delays}


def compare_over_delays(
    scenario_source: Any,
    delays: Iterable[float],
    kinds: str | Iterable[str] | None = None,
    overrides: Mapping[str, Any] | None = None,
    *,
    progress: Callable[[str, int, int], None] | None = None,
) -> DelayComparison:
    """:func:`compare` at each robot delay (s); every scenario is validated before the first
    run. ``progress(label, index, total)`` before each run."""
    return run_over_delays(delay_scenarios(scenario_source, delays, kinds, overrides), progress=progress)


def run_over_delays(
    scenarios: Mapping[float, Mapping[str, Scenario]], *, progress: Callable[[str, int, int], None] | None = None
) -> DelayComparison:
    """Simulate resolved scenarios per delay (from :func:`delay_scenarios`)."""
    total = sum(len(per) for per in scenarios.values())
    done = 0
    out: dict[float, Comparison] = {}
    for delay, per in scenarios.items():
        runs: dict[str, Run] = {}
        for kind, scenario in per.items():
            if progress is not None:
                progress(f"{kind}, {delay * 1e3:g} ms", done, total)
            runs[kind] = simulate(scenario)
            done += 1
        out[delay] = Comparison(runs=runs)
    return DelayComparison(out)
