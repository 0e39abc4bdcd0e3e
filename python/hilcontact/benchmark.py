"""``hil-bench-1``: a fixed, versioned benchmark that scores every compensator the same way.

The suite is one table, :data:`CASES` (built from the presets with overrides, seeds fixed):
the paper's cases and experiments, oblique 6-DOF, Hunt-Crossley and damped contacts, servo lag,
and a grid of robot delays (10 to 150 ms) × contact frequencies (1, 2, 4, 8 Hz), each grid cell in
three variants (a clean loop; sensor noise with a sensor delay; servo lag). Each case runs with
each compensator; what is kept of a run is its sweep row (the core's ``RunSummary``: CoV, CoF,
rebound-vector error, energy ratio, lost and extra collisions) and its verdict (``ok`` against
the scenario's ``[metrics]`` tolerances, their defaults for every case). A compensator's score
is the fraction of cases it passes. docs/benchmark.md says why.

A benchmark folder holds ``benchmark.json`` (suite, compensators, cases), ``cases/<compensator>/
<case>.json`` (one file per finished run, written atomically as it finishes: an interrupted
benchmark resumes where it stopped, and gives the same table), and, once complete,
``results.csv`` (every run), ``summary.csv`` and ``summary.md`` (one row per compensator) and
``pass_fraction.png`` (pass fraction over delay × contact frequency).
"""

from __future__ import annotations

import fnmatch
import json
import math
import os
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from .errors import HilContactError, ScenarioError
from .native import VERSION
from .native import core as _core
from .output import OutputError
from .scenario import load_scenario

__all__ = [
    "CASES",
    "SUITE",
    "BenchCase",
    "compare_folders",
    "load_benchmark",
    "run_benchmark",
    "select_cases",
    "summary_table",
]

#: The suite's name and version: any change of :data:`CASES` (or of what a case keeps) is a
#: new version.
SUITE = "hil-bench-1"

#: Robot delays of the grid, s (the paper's 10 ms to what a robot over a slow link reaches).
GRID_DELAYS = (0.010, 0.020, 0.030, 0.040, 0.060, 0.080, 0.100, 0.150)
#: Contact frequencies of the grid, Hz (the paper's 4 Hz, softer and stiffer contacts), set
#: through ``contact.stiffness`` (the frequency goes with √k: ``_core.contact_frequency``).
GRID_FREQUENCIES = (1.0, 2.0, 4.0, 8.0)
#: The grid cell's variants: overrides on top of the delay and the stiffness.
GRID_VARIANTS: dict[str, dict[str, Any]] = {
    "clean": {},
    "noisy": {"facility.sensor_noise": 0.3, "facility.torque_noise": 0.03, "facility.sensor_delay": 0.002},
    "servo": {"facility.servo_frequency": 20.0, "facility.servo_damping": 0.7},
}

#: The preset the grid is built on.
GRID_BASE = "paper-table1"


@dataclass(frozen=True)
class BenchCase:
    """One case of the suite: a preset with overrides (the compensator set by the benchmark)."""

    name: str
    """Case name (unique; file names and tables use it)."""
    preset: str
    """The preset it starts from."""
    overrides: dict[str, Any] = field(default_factory=dict)
    """``--set`` overrides on the preset."""
    group: str = "named"
    """``named`` or ``grid`` (the grid's cells make the figure)."""
    delay: float = math.nan
    """Robot delay, s (grid cases)."""
    frequency: float = math.nan
    """Contact frequency, Hz (grid cases)."""

    def scenario(self, compensator: str | None = None) -> Any:
        """The case's resolved scenario, with the shipped compensator ``compensator``
        (default: the preset's)."""
        overrides = dict(self.overrides)
        if compensator is not None:
            overrides["compensator.kind"] = compensator
        return load_scenario(self.preset, overrides)


def _named_cases() -> list[BenchCase]:
    hunt_crossley = {"contact.model": "hunt-crossley", "contact.stiffness": 6.2e6, "contact.exponent": 1.5}
    rows: list[tuple[str, str, dict[str, Any]]] = [
        ("paper-4ms", "paper-table1", {"facility.robot_delay": 0.004}),
        ("paper-10ms", "paper-table1", {}),
        ("paper-20ms", "paper-table1", {"facility.robot_delay": 0.020}),
        ("paper-exp-1.93hz", "paper-exp-1.93hz", {}),
        ("paper-exp-2.64hz", "paper-exp-2.64hz", {}),
        ("oblique-6dof", "oblique-6dof", {}),
        ("oblique-6dof-40ms", "oblique-6dof", {"facility.robot_delay": 0.040}),
        ("hunt-crossley", "paper-table1", hunt_crossley),
        ("hunt-crossley-damped", "paper-table1", {**hunt_crossley, "contact.damping": 3.1e7}),
        ("damped", "paper-table1", {"contact.damping": 500.0}),
        ("noise-sensor-delay", "paper-table1",
         {"facility.sensor_noise": 0.5, "facility.torque_noise": 0.05, "facility.sensor_delay": 0.005}),
        ("servo-lag", "paper-table1", {"facility.servo_frequency": 15.0, "facility.servo_damping": 0.7}),
    ]
    return [BenchCase(name, preset, overrides) for name, preset, overrides in rows]


def _grid_cases() -> list[BenchCase]:
    base = load_scenario(GRID_BASE)
    f0 = float(_core().contact_frequency(base.to_json()))
    k0 = float(base.contact.stiffness)
    cases = []
    for delay in GRID_DELAYS:
        for frequency in GRID_FREQUENCIES:
            stiffness = round(k0 * (frequency / f0) ** 2, 3)
            for variant, extra in GRID_VARIANTS.items():
                cases.append(BenchCase(
                    name=f"grid-{round(delay * 1000):03d}ms-{frequency:g}hz-{variant}",
                    preset=GRID_BASE,
                    overrides={"facility.robot_delay": delay, "contact.stiffness": stiffness, **extra},
                    group="grid",
                    delay=delay,
                    frequency=frequency,
                ))
    return cases


CASES: list[BenchCase] = _named_cases() + _grid_cases()
"""Every case of :data:`SUITE`, in order: the one definition of the suite."""


def select_cases(patterns: str | Iterable[str] | None) -> list[BenchCase]:
    """The cases whose names match one of the comma-separated shell patterns
    (``"paper-*,grid-010ms-*"``; None: all). Raises ScenarioError when a pattern matches none."""
    if patterns is None:
        return list(CASES)
    items = [p.strip() for p in (patterns.split(",") if isinstance(patterns, str) else patterns) if p.strip()]
    if not items:
        raise ScenarioError("--cases: no pattern given")
    for pattern in items:
        if not any(fnmatch.fnmatchcase(c.name, pattern) for c in CASES):
            raise ScenarioError(f"--cases {pattern}: matches no case of {SUITE} (e.g. paper-10ms, grid-*-4hz-clean)")
    return [c for c in CASES if any(fnmatch.fnmatchcase(c.name, p) for p in items)]


# ---- the columns ---------------------------------------------------------------------------

def _summary_names() -> list[str]:
    return [name for name, _, _ in _core().summary_columns() if name != "wall_time"]


#: What a case keeps of a run, after ``compensator`` and ``case``: the verdict and the core's
#: sweep row (``_core.summary_columns()``, the one definition of these metrics).
KEPT_COLUMNS = ["status", "passed", *_summary_names()]

#: The summary's columns per compensator (means over the cases that have the value).
SUMMARY_COLUMNS = [
    "compensator", "cases", "passed", "pass_fraction", "diverged", "mean_cov", "worst_cov",
    "mean_cof", "worst_cof", "worst_velocity_error", "energy_ratio", "lost_collisions",
    "extra_collisions",
]


# ---- running -------------------------------------------------------------------------------

def _safe(name: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-._" else "_" for ch in name)


def _write_json_atomically(path: Path, data: Any) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(data, indent=1, allow_nan=True) + "\n", encoding="utf-8")
    os.replace(tmp, path)


@dataclass(frozen=True)
class Entrant:
    """A compensator in the benchmark: a shipped kind or a Python entry."""

    name: str
    """Its name in tables (the kind, or ``py:Class``)."""
    kind: str | None = None
    """The shipped kind, or None."""
    entry: Any = None
    """The Python entry (``path.py:Class``, ``module:Class`` or a class), or None."""


def entrants(kinds: str | Iterable[str] | None, python: Sequence[Any] = ()) -> list[Entrant]:
    """The compensators to score: shipped ``kinds`` (comma-separated or a list; default all when
    no Python entry is given, none when ``kinds`` is ``""``) and Python ``entries``."""
    from .comparison import parse_kinds
    from .plugin import compensator_name

    chosen = [] if (kinds is None and python) or kinds == "" else parse_kinds(kinds)
    out = [Entrant(kind, kind=kind) for kind in chosen]
    for entry in python:
        out.append(Entrant(compensator_name(entry), entry=entry))
    names = [e.name for e in out]
    if len(set(names)) != len(names):
        raise ScenarioError(f"compensators: a name is given twice ({', '.join(names)})")
    return out


def _spec(cases: Sequence[BenchCase], who: Sequence[Entrant]) -> dict[str, Any]:
    return {
        "suite": SUITE,
        "cases": [c.name for c in cases],
        "compensators": [e.name for e in who],
        "entries": {e.name: e.entry for e in who if isinstance(e.entry, str)},
    }


def _prepare(folder: Path, spec: dict[str, Any], resume: bool) -> None:
    meta = folder / "benchmark.json"
    if folder.exists() and not folder.is_dir():
        raise OutputError(f"--out {folder}: is a file")
    if folder.is_dir() and any(folder.iterdir()):
        if not meta.is_file():
            raise OutputError(f"--out {folder}: holds files that are not a benchmark's; choose another folder")
        if not resume:
            raise OutputError(f"--out {folder}: holds a benchmark; add --resume to continue it, or choose another folder")
        try:
            recorded = json.loads(meta.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise OutputError(f"{meta}: unreadable ({exc})") from None
        for key in ("suite", "cases", "compensators"):
            if recorded.get(key) != spec[key]:
                raise OutputError(
                    f"--out {folder}: a benchmark with other {key} ({recorded.get(key)!r:.80}); "
                    "resume it with the same --cases and compensators, or choose another folder"
                )
        return
    _write_json_atomically(meta, {**spec, "hilcontact": VERSION})


def _case_path(folder: Path, compensator: str, case: str) -> Path:
    return folder / "cases" / _safe(compensator) / f"{_safe(case)}.json"


def _row(compensator: str, case: BenchCase, summary: dict[str, Any], wall_time: float) -> dict[str, Any]:
    row: dict[str, Any] = {"compensator": compensator, "case": case.name, "status": str(summary["status"])}
    row["passed"] = row["status"] == "ok"
    for name in _summary_names():
        row[name] = float(summary[name])
    row["wall_time"] = float(wall_time)
    return row


def _run_shipped(jobs: list[tuple[Entrant, BenchCase]], threads: int | None) -> list[dict[str, Any]]:
    jsons = [case.scenario(who.kind).to_json() for who, case in jobs]
    columns = _core().simulate_batch(jsons, threads)
    rows = []
    for i, (who, case) in enumerate(jobs):
        summary = {name: columns[name][i] for name in _summary_names()}
        summary["status"] = columns["status"][i]
        rows.append(_row(who.name, case, summary, float(columns["wall_time"][i])))
    return rows


def _run_python(who: Entrant, case: BenchCase, step_limit: float | None) -> dict[str, Any]:
    import time

    from .plugin import STEP_LIMIT, make_adapter

    scenario = case.scenario()
    adapter = make_adapter(who.entry, scenario, STEP_LIMIT if step_limit is None else step_limit)
    start = time.perf_counter()
    result = _core().simulate_python(scenario.to_json(), adapter, who.name)
    return _row(who.name, case, dict(result["summary"]), time.perf_counter() - start)


def run_benchmark(
    out: str | os.PathLike[str],
    kinds: str | Iterable[str] | None = None,
    python: Sequence[Any] = (),
    cases: str | Iterable[str] | None = None,
    *,
    resume: bool = False,
    threads: int | None = None,
    step_limit: float | None = None,
    plots: bool = True,
    progress: Callable[[int, int], None] | None = None,
    dask: str | Any | None = None,
) -> pd.DataFrame:
    """Run :data:`SUITE` (or the ``cases`` matching its patterns) with the shipped ``kinds`` and
    the Python compensators ``python`` into the folder ``out``; returns the summary (one row
    per compensator, :data:`SUMMARY_COLUMNS`).

    Shipped compensators run in chunks on the core's thread pool (``simulate_batch``,
    ``threads`` Rust threads, default one per core); Python ones one case at a time in this
    process (their steps hold the GIL). Each finished run is written at once; ``resume``
    continues a benchmark in ``out`` (same cases and compensators), skipping its finished runs.
    On KeyboardInterrupt the finished runs stay in ``out``. Raises ScenarioError for bad input
    and OutputError for a folder that cannot be used, both before anything runs.

    ``dask``: run on Dask instead (``"local"``: a LocalCluster, one single-threaded worker per
    core; a scheduler address; or a ``dask.distributed.Client``): tasks of a few shipped runs,
    or one Python run, each worker a process (Python compensators then run in parallel).
    """
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int) or threads < 1):
        raise ScenarioError(f"threads: expected a whole number >= 1, got {threads!r}")
    chosen = select_cases(cases)
    who = entrants(kinds, python)
    for case in chosen:  # validate every case before anything runs
        case.scenario()
    folder = Path(out)
    spec = _spec(chosen, who)
    try:
        _prepare(folder, spec, resume)
    except OSError as exc:
        raise OutputError(f"--out {folder}: cannot write: {exc.strerror or exc}") from None
    jobs = [(w, c) for w in who for c in chosen]
    pending = [(w, c) for w, c in jobs if not _case_path(folder, w.name, c.name).is_file()]
    done = len(jobs) - len(pending)
    if progress is not None:
        progress(done, len(jobs))

    def save(row: dict[str, Any]) -> None:
        nonlocal done
        _write_json_atomically(_case_path(folder, row["compensator"], row["case"]), row)
        done += 1
        if progress is not None:
            progress(done, len(jobs))

    if dask is not None:
        _run_on_dask(dask, pending, step_limit, save)
    else:
        shipped = [(w, c) for w, c in pending if w.kind is not None]
        size = 2 * (threads or os.cpu_count() or 1)
        for start in range(0, len(shipped), size):
            for row in _run_shipped(shipped[start:start + size], threads):
                save(row)
        for w, c in pending:
            if w.kind is None:
                save(_run_python(w, c, step_limit))
    results = load_benchmark(folder)
    summary = summary_table(results)
    _write_tables(folder, results, summary)
    if plots:
        plot_pass_fraction(results, folder / "pass_fraction.png")
    return summary


def _run_task(jobs: list[tuple[Entrant, BenchCase]], step_limit: float | None) -> list[dict[str, Any]]:
    """The rows of some runs (the task a Dask worker runs)."""
    shipped = [(w, c) for w, c in jobs if w.kind is not None]
    rows = _run_shipped(shipped, 1) if shipped else []
    return rows + [_run_python(w, c, step_limit) for w, c in jobs if w.kind is None]


def _run_on_dask(dask: str | Any, pending: list[tuple[Entrant, BenchCase]], step_limit: float | None,
                 save: Callable[[dict[str, Any]], None]) -> None:
    from dask.distributed import as_completed

    from .sweep import _close_dask_client, _dask_client

    client = _dask_client(dask) if isinstance(dask, str) else dask
    try:
        shipped = [(w, c) for w, c in pending if w.kind is not None]
        tasks = [shipped[i:i + 8] for i in range(0, len(shipped), 8)]
        tasks += [[(w, c)] for w, c in pending if w.kind is None]
        futures = [client.submit(_run_task, task, step_limit, pure=False) for task in tasks]
        for future in as_completed(futures):
            for row in future.result():
                save(row)
    finally:
        if isinstance(dask, str):
            _close_dask_client(client)


# ---- reading and tables --------------------------------------------------------------------

def load_benchmark(directory: str | os.PathLike[str]) -> pd.DataFrame:
    """Every finished run of a benchmark folder, one row each (``compensator``, ``case``,
    :data:`KEPT_COLUMNS`, ``wall_time``, and the case's ``group``, ``delay``, ``frequency``),
    in the order of ``benchmark.json``. Raises HilContactError for a folder that is not one."""
    folder = Path(directory)
    meta = folder / "benchmark.json"
    if not meta.is_file():
        raise ScenarioError(f"{folder}: not a benchmark folder (no benchmark.json)")
    try:
        spec = json.loads(meta.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ScenarioError(f"{meta}: unreadable ({exc})") from None
    by_name = {c.name: c for c in CASES}
    rows = []
    for compensator in spec.get("compensators", []):
        for name in spec.get("cases", []):
            path = _case_path(folder, compensator, name)
            if not path.is_file():
                continue
            try:
                row = json.loads(path.read_text(encoding="utf-8"))
            except (OSError, ValueError) as exc:
                raise HilContactError(f"{path}: unreadable ({exc})") from None
            case = by_name.get(name)
            row["group"] = case.group if case else "unknown"
            row["delay"] = case.delay if case else math.nan
            row["frequency"] = case.frequency if case else math.nan
            rows.append(row)
    columns = ["compensator", "case", *KEPT_COLUMNS, "wall_time", "group", "delay", "frequency"]
    return pd.DataFrame(rows, columns=columns)


def summary_table(results: pd.DataFrame) -> pd.DataFrame:
    """One row per compensator (:data:`SUMMARY_COLUMNS`): cases run, passed, pass fraction,
    diverged runs, and the means (worst: the maxima) over the cases of the core's columns
    (NaN-skipping: a diverged run has no CoV); lost and extra collisions summed."""
    rows = []
    for compensator, runs in results.groupby("compensator", sort=False):
        n = len(runs)
        passed = int(runs["passed"].sum())
        rows.append({
            "compensator": compensator,
            "cases": n,
            "passed": passed,
            "pass_fraction": passed / n if n else math.nan,
            "diverged": int((runs["status"] == "diverged").sum()),
            "mean_cov": runs["mean_cov"].mean(),
            "worst_cov": _worst_cov(runs["worst_cov"]),
            "mean_cof": runs["mean_cof"].mean(),
            "worst_cof": runs["worst_cof"].max(),
            "worst_velocity_error": runs["worst_velocity_error"].max(),
            "energy_ratio": runs["energy_ratio"].mean(),
            "lost_collisions": int(runs["lost_collisions"].fillna(0).sum()),
            "extra_collisions": int(runs["extra_collisions"].fillna(0).sum()),
        })
    return pd.DataFrame(rows, columns=SUMMARY_COLUMNS)


def _worst_cov(values: pd.Series) -> float:
    """The case CoV farthest from 1."""
    values = values.dropna()
    if values.empty:
        return math.nan
    return float(values.loc[(values - 1.0).abs().idxmax()])


def _cell(value: Any) -> str:
    if isinstance(value, float):
        return "–" if math.isnan(value) else f"{value:.3g}"
    return str(value)


def to_markdown(summary: pd.DataFrame) -> str:
    """The summary as a Markdown table (the one in docs/benchmark.md)."""
    head = "| " + " | ".join(summary.columns) + " |"
    rule = "|" + "|".join("---" for _ in summary.columns) + "|"
    body = ["| " + " | ".join(_cell(v) for v in row) + " |" for row in summary.itertuples(index=False)]
    return "\n".join([head, rule, *body]) + "\n"


def _write_tables(folder: Path, results: pd.DataFrame, summary: pd.DataFrame) -> None:
    def write(name: str, text: str) -> None:
        tmp = folder / f".{name}.tmp"
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, folder / name)

    write("results.csv", results.to_csv(index=False))
    write("summary.csv", summary.to_csv(index=False))
    write("summary.md", f"# {SUITE}\n\n" + to_markdown(summary))


def pass_grid(results: pd.DataFrame) -> pd.DataFrame:
    """Pass fraction per compensator, robot delay and contact frequency (grid cases: the
    fraction of the cell's variants that passed)."""
    grid = results[results["group"] == "grid"]
    return (grid.groupby(["compensator", "delay", "frequency"], sort=False)["passed"].mean()
            .rename("pass_fraction").reset_index())


def plot_pass_fraction(results: pd.DataFrame, path: str | os.PathLike[str] | None = None) -> Any:
    """The figure: pass fraction over robot delay × contact frequency, one panel per
    compensator (grid cases); saved to ``path`` when given. Returns the Figure."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    cells = pass_grid(results)
    names = list(dict.fromkeys(cells["compensator"])) or ["(none)"]
    fig, axes = plt.subplots(1, len(names), figsize=(1.9 * len(names) + 1.4, 2.8), squeeze=False, sharey=True,
                             layout="constrained")
    image = None
    for ax, name in zip(axes[0], names):
        mine = cells[cells["compensator"] == name]
        table = np.full((len(GRID_FREQUENCIES), len(GRID_DELAYS)), np.nan)
        for row in mine.itertuples(index=False):
            if row.delay in GRID_DELAYS and row.frequency in GRID_FREQUENCIES:
                table[GRID_FREQUENCIES.index(row.frequency), GRID_DELAYS.index(row.delay)] = row.pass_fraction
        image = ax.imshow(table, origin="lower", vmin=0.0, vmax=1.0, cmap="RdYlGn", aspect="auto")
        ax.set_title(name, fontsize=9)
        ax.set_xticks(range(len(GRID_DELAYS)), [f"{d * 1000:g}" for d in GRID_DELAYS], fontsize=6, rotation=90)
        ax.set_yticks(range(len(GRID_FREQUENCIES)), [f"{f:g}" for f in GRID_FREQUENCIES], fontsize=7)
        ax.set_xlabel("robot delay, ms", fontsize=8)
    axes[0][0].set_ylabel("contact frequency, Hz", fontsize=8)
    if image is not None:
        fig.colorbar(image, ax=list(axes[0]), label="pass fraction", fraction=0.03, pad=0.01)
    fig.suptitle(f"{SUITE}: pass fraction (clean, noisy, servo-lag variants)", fontsize=9)
    if path is not None:
        fig.savefig(path, dpi=110)
        plt.close(fig)
    return fig


def compare_folders(a: str | os.PathLike[str], b: str | os.PathLike[str]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Two benchmark folders side by side: their summaries stacked (a ``folder`` column first)
    and, per case, each compensator's status in each (columns ``case``, then
    ``<compensator> (<folder>)``). Raises ScenarioError when either is not a benchmark folder
    or their suites differ."""
    folders = [Path(a), Path(b)]
    suites = []
    for folder in folders:
        meta = folder / "benchmark.json"
        if not meta.is_file():
            raise ScenarioError(f"{folder}: not a benchmark folder (no benchmark.json)")
        suites.append(json.loads(meta.read_text(encoding="utf-8")).get("suite"))
    if suites[0] != suites[1]:
        raise ScenarioError(f"--compare: {folders[0]} is {suites[0]}, {folders[1]} is {suites[1]}")
    summaries, statuses = [], []
    for folder in folders:
        results = load_benchmark(folder)
        summary = summary_table(results)
        summary.insert(0, "folder", folder.name or str(folder))
        summaries.append(summary)
        wide = results.pivot(index="case", columns="compensator", values="status")
        wide.columns = [f"{c} ({folder.name or folder})" for c in wide.columns]
        statuses.append(wide)
    cases = pd.concat(statuses, axis=1).reset_index()
    order = {c.name: i for i, c in enumerate(CASES)}
    cases = cases.sort_values("case", key=lambda s: s.map(lambda n: order.get(n, len(order)))).reset_index(drop=True)
    return pd.concat(summaries, ignore_index=True), cases
