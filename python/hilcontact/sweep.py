"""Parameter sweeps: a scenario run over a grid of values, compensators and noise seeds, in
parallel (Rust threads, or a Dask cluster), one summary row per run.

A sweep's folder holds:

- ``sweep.json``: what was asked (the resolved base scenario, the grid, compensators, seeds);
  ``--resume`` checks it so that a folder never mixes two different sweeps;
- ``results.parquet``: one row per finished run (see :data:`RESULT_COLUMNS`);
- ``parts/``: while the sweep runs, finished rows in small Parquet files, each written
  atomically; they are merged into ``results.parquet`` at the end or on interruption, so an
  interrupted sweep keeps every finished row and ``--resume`` skips them. A part that cannot
  be read (truncated, not Parquet, without the result columns) is skipped and reported, renamed
  ``*.unreadable``, and its runs are run again by ``--resume``; an unreadable ``sweep.json`` or
  ``results.parquet`` is one line of error naming the file.

Before anything runs, a sweep whose estimated memory or time is above its limits
(:class:`~hilcontact.limits.Limits`) is refused, as is a grid of more than
:data:`MAX_GRID_VALUES` values per key or :data:`MAX_SEEDS` seeds.

Time series are never kept: a run is reduced to its summary in the core
(``_core.simulate_batch``), so memory does not grow with the number of runs beyond one small
row each.
"""

from __future__ import annotations

import itertools
import json
import math
import os
import sys
import time
import tomllib
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa

from .comparison import comparison_scenarios, parse_kinds
from .errors import ArgumentError, HilContactError, ScenarioError
from .errors import describe as _shown
from .limits import (
    SWEEP_BYTES_PER_RUN,
    SWEEP_SECONDS_PER_RUN,
    Estimate,
    Limits,
    check_estimate,
    cores,
    describe,
    run_estimate,
)
from .output import OutputError, mark_folder, marker_kind, remove_stale, staging_name
from .native import core as _core
from .scenario import Scenario, load_scenario

__all__ = [
    "RESULT_COLUMNS",
    "GridAxis",
    "SweepPlan",
    "contact_frequency",
    "load_results",
    "parse_grid",
    "plan_sweep",
    "run_plan",
    "sweep",
]

RESULTS_FILE = "results.parquet"
SPEC_FILE = "sweep.json"
PARTS_DIR = "parts"

#: Most values of one ``--grid`` key.
MAX_GRID_VALUES = 100_000
#: Most noise seeds per grid point (``--seeds``).
MAX_SEEDS = 100_000
#: Most Rust threads of a local sweep (``threads``, ``--threads``).
MAX_THREADS = 1024
#: Most runs per core call or Dask task (``chunk_size``).
MAX_CHUNK_SIZE = 1_000_000

#: Columns of a result row, after the swept keys (one column per ``--grid`` key, named by the
#: key), in this order. ``run_key`` identifies the run (grid values, compensator, seed) for
#: ``--resume``; ``point`` numbers the grid point (from 0); ``robot_delay`` (s) and
#: ``contact_frequency`` (Hz, ``sqrt(k/μ)/2π`` of a linear contact, NaN for Hunt-Crossley) are
#: there even when not swept. Then ``status`` ("ok", "unfaithful" or "diverged": the core's
#: verdict with the scenario's ``[metrics]`` tolerances) and the core's summary columns
#: (``_core.summary_columns()``: name, unit, meaning; see docs/model.md, "Metrics").
RESULT_COLUMNS = [
    "run_key",
    "point",
    "compensator",
    "seed",
    "robot_delay",
    "contact_frequency",
    "status",
    *(name for name, _, _ in _core().summary_columns()),
]

#: Columns that count (stored as integers).
_COUNT_COLUMNS = ("collisions", "reference_collisions", "lost_collisions", "extra_collisions")

_CORE_COLUMNS = RESULT_COLUMNS[6:]


# ---- the grid -----------------------------------------------------------------------------


@dataclass(frozen=True)
class GridAxis:
    """One swept key and its values."""

    key: str
    values: tuple[Any, ...]


def _tidy(value: float) -> float:
    """A float from a range, rounded to 12 significant digits (``0.026``, not
    ``0.026000000000000002``), so that delays stay whole control periods."""
    return float(f"{value:.12g}")


def _toml_value(text: str, key: str = "") -> Any:
    try:
        return tomllib.loads("v = " + text)["v"]
    except tomllib.TOMLDecodeError:
        return text
    except RecursionError:
        raise ScenarioError(f"--grid {key} value {text[:40]!r}...: nested too deeply") from None
    except ValueError:  # an integer above Python's limit on digits
        raise ScenarioError(
            f"--grid {key}: a number of more than {sys.get_int_max_str_digits()} digits; give a number such as 0.02"
        ) from None


def parse_grid(spec: str) -> GridAxis:
    """Parse ``KEY=START:STOP:COUNT`` (COUNT values, both ends included) or ``KEY=A,B,C``
    (a list; each item a TOML value or a plain string) or ``KEY=VALUE``.

    Raises ScenarioError naming the key for a malformed spec.
    """
    if not isinstance(spec, str):
        raise ScenarioError(f"--grid {spec!r}: expected KEY=START:STOP:COUNT or KEY=A,B,C")
    key, sep, body = spec.partition("=")
    key, body = key.strip(), body.strip()
    if not sep or not key or not body:
        raise ScenarioError(
            f"--grid {spec!r}: expected KEY=START:STOP:COUNT or KEY=A,B,C, "
            "e.g. --grid facility.robot_delay=0.002:0.06:30"
        )
    if ":" in body:
        parts = [p.strip() for p in body.split(":")]
        if len(parts) != 3:
            raise ScenarioError(f"--grid {key}: range {body!r} must be START:STOP:COUNT, e.g. 0.002:0.06:30")
        try:
            start, stop = float(parts[0]), float(parts[1])
        except ValueError:
            raise ScenarioError(f"--grid {key}: range {body!r}: START and STOP must be numbers") from None
        try:
            count = int(parts[2])
        except ValueError:
            raise ScenarioError(f"--grid {key}: range {body!r}: COUNT must be a whole number") from None
        if not (math.isfinite(start) and math.isfinite(stop)):
            raise ScenarioError(f"--grid {key}: range {body!r}: START and STOP must be finite")
        if count < 1 or count > MAX_GRID_VALUES:
            raise ScenarioError(f"--grid {key}: range {body!r}: COUNT must be 1 to {MAX_GRID_VALUES}")
        if count == 1 and start != stop:
            raise ScenarioError(f"--grid {key}: range {body!r}: one value needs START == STOP")
        values: tuple[Any, ...] = tuple(_tidy(v) for v in np.linspace(start, stop, count))
    else:
        items = [item.strip() for item in body.split(",")]
        if len(items) > MAX_GRID_VALUES:
            raise ScenarioError(f"--grid {key}: {len(items)} values; at most {MAX_GRID_VALUES} per key")
        if any(not item for item in items):
            raise ScenarioError(f"--grid {key}: list {body!r} has an empty item")
        values = tuple(_toml_value(item, key) for item in items)
    if len(set(map(repr, values))) != len(values):
        raise ScenarioError(f"--grid {key}: {body!r} repeats a value")
    return GridAxis(key=key, values=values)


def _axes(grid: Mapping[str, Any] | Iterable[str | GridAxis] | None) -> list[GridAxis]:
    """Grid axes from specs (``"key=..."``), GridAxis objects or a mapping key -> spec body
    (``"0.002:0.06:30"``) or list of values."""
    if grid is None:
        return []
    axes: list[GridAxis] = []
    if isinstance(grid, Mapping):
        for key, body in grid.items():
            if not isinstance(key, str):
                raise ArgumentError(f"grid: keys are dotted scenario keys (strings), got {_shown(key)}")
            if isinstance(body, str):
                axes.append(parse_grid(f"{key}={body}"))
            elif isinstance(body, Mapping):
                raise ArgumentError(f"grid: {key}: expected a spec 'START:STOP:COUNT' or a list of values, got a mapping")
            elif isinstance(body, Iterable):
                axes.append(GridAxis(key=key, values=tuple(body)))
            else:
                axes.append(GridAxis(key=key, values=(body,)))
    elif isinstance(grid, (str, bytes)) or not isinstance(grid, Iterable):
        raise ArgumentError(
            "grid: expected a list of specs ['KEY=START:STOP:COUNT', ...] or a mapping "
            f"{{KEY: 'START:STOP:COUNT' or [values]}}, got {_shown(grid)}"
        )
    else:
        for item in grid:
            axes.append(item if isinstance(item, GridAxis) else parse_grid(item))
    for axis in axes:
        if len(axis.values) > MAX_GRID_VALUES:
            raise ScenarioError(f"--grid {axis.key}: {len(axis.values)} values; at most {MAX_GRID_VALUES} per key")
        try:
            shown = [repr(v) for v in axis.values]
        except ValueError:  # an integer above Python's limit on digits
            raise ScenarioError(f"--grid {axis.key}: a number of more than {sys.get_int_max_str_digits()} digits") from None
        if len(set(shown)) != len(shown):
            repeated = next(v for v in axis.values if shown.count(repr(v)) > 1)
            raise ScenarioError(f"--grid {axis.key}: repeats the value {_shown(repeated)}; give each value once")
    keys = [a.key for a in axes]
    for key in keys:
        if keys.count(key) > 1:
            raise ScenarioError(f"--grid {key}: given more than once")
        if key.replace(" ", "") in ("compensator.kind", "facility.seed"):
            raise ScenarioError(
                f"--grid {key}: choose compensators with --compensators and seeds with --seeds"
            )
    for axis in axes:
        if not axis.values:
            raise ScenarioError(f"--grid {axis.key}: no values")
    return axes


def contact_frequency(scenario: Scenario) -> float:
    """Undamped contact frequency of a linear contact, Hz: ``sqrt(k/μ) / 2π`` with the reduced
    mass ``μ = m_s m_t / (m_s + m_t)``; NaN for a Hunt-Crossley contact (from the core)."""
    return float(_core().contact_frequency(scenario.to_json()))


# ---- the plan -----------------------------------------------------------------------------


@dataclass
class SweepPlan:
    """Every run of a sweep, validated before anything runs.

    Attributes:
        base: the resolved base scenario (``--set`` applied), as a dict.
        axes: the swept keys and their values.
        compensators: the compensator kinds.
        seeds: the noise seeds (``facility.seed`` values).
        scenarios: (grid point, compensator) -> resolved scenario dict (seed not yet set).
        points: the grid points (key -> value), numbered from 0.
    """

    base: dict[str, Any]
    axes: list[GridAxis]
    compensators: list[str]
    seeds: list[int]
    scenarios: dict[tuple[int, str], dict[str, Any]]
    points: list[dict[str, Any]]
    frequencies: dict[int, float]
    #: (grid point, compensator) -> its scenario's JSON without ``facility`` (which carries the
    #: seed), made once: the whole scenario's JSON per run was most of the Python per run.
    _json_without_facility: dict[tuple[int, str], str] = field(default_factory=dict, repr=False, compare=False)

    @property
    def size(self) -> int:
        """Number of runs."""
        return len(self.points) * len(self.compensators) * len(self.seeds)

    def spec(self) -> dict[str, Any]:
        """What ``sweep.json`` records."""
        return {
            "scenario": self.base,
            "grid": [[axis.key, list(axis.values)] for axis in self.axes],
            "compensators": self.compensators,
            "seeds": self.seeds,
        }

    def runs(self) -> Iterator[tuple[str, int, str, int]]:
        """``(run_key, point, compensator, seed)`` of every run, grid point by grid point."""
        for point, values in enumerate(self.points):
            for kind in self.compensators:
                for seed in self.seeds:
                    yield run_key(values, kind, seed), point, kind, seed

    def scenario_json(self, point: int, kind: str, seed: int) -> str:
        """The resolved scenario of one run, as JSON for the core."""
        data = self.scenarios[(point, kind)]
        rest = self._json_without_facility.get((point, kind))
        if rest is None:
            rest = json.dumps({key: value for key, value in data.items() if key != "facility"})
            self._json_without_facility[(point, kind)] = rest
        facility = json.dumps(dict(data["facility"], seed=seed))
        # the same object as {**data, "facility": ...}, the facility last
        return f'{{"facility": {facility}}}' if rest == "{}" else f'{rest[:-1]}, "facility": {facility}}}'


def run_key(values: Mapping[str, Any], kind: str, seed: int) -> str:
    """The identity of a run: its grid values, compensator and seed (stable text)."""
    return json.dumps({"grid": dict(values), "compensator": kind, "seed": seed}, sort_keys=True)


def check_threads(threads: Any) -> int | None:
    """``threads`` checked: None (one per core) or a whole number from 1 to
    :data:`MAX_THREADS`; else :class:`~hilcontact.errors.ArgumentError`."""
    if threads is None:
        return None
    if isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or not 1 <= threads <= MAX_THREADS:
        raise ArgumentError(
            f"threads: expected a whole number from 1 to {MAX_THREADS} (None: one per core), got {_shown(threads)}"
        )
    return int(threads)


def check_run_arguments(out: Any, resume: Any, dask: Any, chunk_size: Any, progress: Any,
                         flush_seconds: Any) -> None:
    """The arguments of :func:`run_plan` (and :func:`sweep`) checked before anything runs or is
    written; :class:`~hilcontact.errors.ArgumentError` naming the first bad one."""
    if out is not None and not isinstance(out, (str, os.PathLike)):
        raise ArgumentError(f"out: expected a folder path or None, got {_shown(out)}")
    if out is not None and (not isinstance(os.fspath(out), str) or "\x00" in os.fspath(out)):
        raise ArgumentError(f"out: expected a folder path (text without NUL characters), got {_shown(out)}")
    if not isinstance(resume, bool):
        raise ArgumentError(f"resume: expected True or False, got {_shown(resume)}")
    if chunk_size is not None and (
        isinstance(chunk_size, bool) or not isinstance(chunk_size, (int, np.integer))
        or not 1 <= chunk_size <= MAX_CHUNK_SIZE
    ):
        raise ArgumentError(
            f"chunk_size: expected a whole number from 1 to {MAX_CHUNK_SIZE} (None: the default), got {_shown(chunk_size)}"
        )
    if progress is not None and not callable(progress):
        raise ArgumentError(f"progress: expected a function (done, total) or None, got {_shown(progress)}")
    if isinstance(flush_seconds, bool) or not isinstance(flush_seconds, (int, float)) or not (
        math.isfinite(flush_seconds) and flush_seconds >= 0
    ):
        raise ArgumentError(f"flush_seconds: expected a finite number of seconds >= 0, got {_shown(flush_seconds)}")
    if dask is None:
        return
    if isinstance(dask, str):
        if not dask.strip():
            raise ArgumentError("dask: expected 'local', a scheduler address (tcp://host:8786) or a Client, got ''")
        try:
            import dask.distributed  # noqa: F401
        except ImportError:
            raise ArgumentError(
                "dask: needs dask.distributed, which is not installed: pip install 'hilcontact[dask]'"
            ) from None
    elif not callable(getattr(dask, "submit", None)):
        raise ArgumentError(
            f"dask: expected 'local', a scheduler address (tcp://host:8786) or a dask.distributed.Client, got {_shown(dask)}"
        )


def _sweep_estimate(runs: int, per_run: Estimate, threads: int | None) -> Estimate:
    """A sweep's estimate: its runs' time plus their validation, and the memory of the runs
    that run at once (one per thread) plus what the plan keeps per run."""
    parallel = min(runs, threads or cores())
    return Estimate(
        memory=parallel * per_run.memory + runs * SWEEP_BYTES_PER_RUN,
        time=runs * (per_run.time + SWEEP_SECONDS_PER_RUN),
    )


def plan_sweep(
    scenario: Any,
    grid: Mapping[str, Any] | Iterable[str | GridAxis] | None = None,
    compensators: str | Iterable[str] | None = None,
    seeds: int = 1,
    overrides: Mapping[str, Any] | None = None,
    *,
    limits: Limits | None = None,
    threads: int | None = None,
    python: Sequence[Any] = (),
) -> SweepPlan:
    """Resolve and validate every run of a sweep (see :func:`sweep` for the arguments;
    ``python``: compensators written in Python, ``FILE.py:Class`` entries, run as ``py:<Class>``).

    Raises ScenarioError naming the key and value for a bad grid, a bad override or a grid
    point that is not a valid scenario, and for a sweep whose estimated memory or time is
    above ``limits`` (checked before the grid is built: first with the base scenario's
    runs, then with each swept key's most demanding value).
    """
    if isinstance(seeds, bool) or not isinstance(seeds, int) or not 1 <= seeds <= MAX_SEEDS:
        raise ArgumentError(f"--seeds: expected a whole number from 1 to {MAX_SEEDS}, got {_shown(seeds)}")
    threads = check_threads(threads)
    if limits is not None and not isinstance(limits, Limits):
        raise ArgumentError(f"limits: expected a hilcontact.limits.Limits or None, got {_shown(limits)}")
    axes = _axes(grid)
    kinds = [] if python and compensators is None else parse_kinds(compensators)
    if python:
        from .plugin import compensator_name

        kinds += [compensator_name(entry) for entry in python]
    base_scenario = load_scenario(scenario, overrides)
    base = base_scenario.to_dict()
    runs = math.prod(len(axis.values) for axis in axes) * len(kinds) * seeds
    shape = " x ".join([*(f"{len(a.values)} {a.key}" for a in axes), f"{len(kinds)} compensator(s)", f"{seeds} seed(s)"])
    per_run = run_estimate(base_scenario, saved=False)
    what = f"the sweep of {runs} runs ({shape}; each {describe(base_scenario)})"
    check_estimate(_sweep_estimate(runs, per_run, threads), limits, what)
    # each value alone first, so that a bad value is reported with its key; the most
    # demanding value of each key scales the estimate
    memory_factor = time_factor = 1.0
    # a one-key grid's points are its values: each is built here once, as the grid below
    # would build it (loading is most of the plan's time), and its estimate read from it; a
    # value that does not build is loaded alone, so that the error is the same as without
    shipped = [k for k in kinds if not k.startswith("py:")]
    reusable = len(axes) == 1 and not python and bool(shipped) and not axes[0].key.startswith("compensator.")
    built: dict[int, dict[str, Any]] = {}
    for axis in axes:
        worst = Estimate(0.0, 0.0)
        for i, value in enumerate(axis.values):
            scenario_alone = None
            if reusable:
                try:
                    built[i] = comparison_scenarios(base, shipped, {axis.key: value})
                    scenario_alone = next(iter(built[i].values()))
                except ScenarioError:
                    pass
            if scenario_alone is None:
                try:
                    scenario_alone = load_scenario(base, {axis.key: value})
                except ScenarioError as exc:
                    raise ScenarioError(f"--grid {axis.key}={value!r}: {exc}") from None
            alone = run_estimate(scenario_alone, saved=False)
            worst = Estimate(max(worst.memory, alone.memory), max(worst.time, alone.time))
        memory_factor *= worst.memory / per_run.memory
        time_factor *= worst.time / per_run.time
    if memory_factor > 1.0 or time_factor > 1.0:
        scaled = per_run.scaled(max(memory_factor, 1.0), max(time_factor, 1.0))
        what = f"the sweep of {runs} runs ({shape}; at its most demanding grid values)"
        check_estimate(_sweep_estimate(runs, scaled, threads), limits, what)
    points = [dict(zip([a.key for a in axes], combo)) for combo in itertools.product(*[a.values for a in axes])]
    scenarios: dict[tuple[int, str], dict[str, Any]] = {}
    frequencies: dict[int, float] = {}
    for point, values in enumerate(points):
        try:
            resolved = built.get(point) or (comparison_scenarios(base, shipped, values) if shipped else {})
            if python:
                from .plugin import with_python_compensators

                resolved = with_python_compensators(resolved or {"": load_scenario(base, values)}, python)
                resolved.pop("", None)
        except ScenarioError as exc:
            shown = ", ".join(f"{k}={v!r}" for k, v in values.items())
            raise ScenarioError(f"--grid point {shown}: {exc}") from None
        for kind, s in resolved.items():
            if s.facility.kind == "mujoco":  # a Python engine: the core's batch cannot run it
                raise ScenarioError("facility.kind: a sweep cannot run the mujoco facility yet (its engine is Python, docs/mujoco.md): use hilcontact run or compare")
            scenarios[(point, kind)] = s.to_dict()
        frequencies[point] = contact_frequency(next(iter(resolved.values())))
    first_seed = int(base["facility"].get("seed", 1))
    return SweepPlan(
        base=base,
        axes=axes,
        compensators=kinds,
        seeds=[first_seed + i for i in range(seeds)],
        scenarios=scenarios,
        points=points,
        frequencies=frequencies,
    )


# ---- results on disk ----------------------------------------------------------------------


def _write_parquet_atomically(frame: pd.DataFrame, path: Path) -> None:
    staging = path.with_name(staging_name(path.name))
    try:
        frame.to_parquet(staging, engine="pyarrow", index=False)
        os.replace(staging, path)
    finally:
        if staging.exists():
            staging.unlink()


#: Columns without which a file of rows is not a sweep's.
_KEY_COLUMNS = ("run_key", "point", "compensator", "seed", "status")


def _read_rows(path: Path) -> pd.DataFrame | str:
    """The rows of a results or part file, or why they cannot be read."""
    try:
        frame = pd.read_parquet(path, engine="pyarrow")
    except (OSError, ValueError, pa.ArrowException) as exc:
        return " ".join(str(exc).split()) or type(exc).__name__
    missing = [c for c in _KEY_COLUMNS if c not in frame.columns]
    if missing:
        return f"no {missing[0]!r} column"
    return frame


def _parts(folder: Path) -> list[Path]:
    return sorted((folder / PARTS_DIR).glob("part-*.parquet")) if (folder / PARTS_DIR).is_dir() else []


def unreadable_parts(directory: str | os.PathLike[str]) -> list[tuple[Path, str]]:
    """The part files of a sweep folder that cannot be read, with the reason."""
    out = []
    for part in _parts(Path(directory)):
        rows = _read_rows(part)
        if isinstance(rows, str):
            out.append((part, rows))
    return out


def load_results(directory: str | os.PathLike[str]) -> pd.DataFrame:
    """Every finished row of a sweep folder (``results.parquet`` and the unmerged parts that
    can be read; an unreadable part is left out, its runs are not finished). Raises
    :class:`~hilcontact.output.OutputError` (one line) if ``results.parquet`` cannot be read."""
    folder = Path(directory)
    frames = []
    if (folder / RESULTS_FILE).is_file():
        rows = _read_rows(folder / RESULTS_FILE)
        if isinstance(rows, str):
            raise OutputError(
                f"{folder / RESULTS_FILE}: cannot be read ({rows[:200]}); move it away (its runs are then "
                "run again by --resume) or choose another folder"
            )
        frames.append(rows)
    frames += [rows for rows in map(_read_rows, _parts(folder)) if not isinstance(rows, str)]
    if not frames:
        raise HilContactError(f"{folder}: no sweep results ({RESULTS_FILE}) here")
    frame = pd.concat(frames, ignore_index=True) if len(frames) > 1 else frames[0]
    return frame.drop_duplicates(subset="run_key", keep="first").reset_index(drop=True)


def _merge(folder: Path, order: Sequence[str]) -> pd.DataFrame | None:
    """Merge ``results.parquet`` and the readable parts into ``results.parquet`` (the plan's
    rows, in plan order), then remove those parts. Returns the merged rows (None if there
    are none)."""
    parts = [part for part in _parts(folder) if not isinstance(_read_rows(part), str)]
    if not parts and not (folder / RESULTS_FILE).is_file():
        return None
    frame = load_results(folder)
    rank = {key: i for i, key in enumerate(order)}
    frame = frame.assign(_rank=frame["run_key"].map(rank)).dropna(subset="_rank")
    frame = frame.sort_values("_rank", kind="stable").drop(columns="_rank").reset_index(drop=True)
    _write_parquet_atomically(frame, folder / RESULTS_FILE)
    for part in parts:
        part.unlink()
    return frame


# ---- running ------------------------------------------------------------------------------


#: Progress callback: (runs done, runs in total) — including those skipped by ``resume``.
Progress = Callable[[int, int], None]


def _run_chunk(scenarios: list[str], threads: int | None) -> dict[str, Any]:
    """Run a chunk of scenarios in the core (the task a Dask worker runs); those with a
    compensator written in Python (``"kind": "python"``) one by one in this process
    (:func:`hilcontact.plugin.run_summaries`)."""
    python = [i for i, text in enumerate(scenarios) if '"python"' in text and _is_python(text)]
    if not python:
        return dict(_core().simulate_batch(scenarios, threads))
    from .plugin import run_summaries

    shipped = [i for i in range(len(scenarios)) if i not in set(python)]
    parts = [(shipped, dict(_core().simulate_batch([scenarios[i] for i in shipped], threads)) if shipped else None),
             (python, run_summaries([scenarios[i] for i in python]))]
    columns: dict[str, Any] = {}
    for order, part in parts:
        if part is None:
            continue
        for name, values in part.items():
            column = columns.setdefault(name, [None] * len(scenarios))
            for i, value in zip(order, values):
                column[i] = value
    return columns


def _is_python(text: str) -> bool:
    return json.loads(text).get("compensator", {}).get("kind") == "python"


def _rows(plan: SweepPlan, chunk: list[tuple[str, int, str, int]], columns: Mapping[str, Any]) -> pd.DataFrame:
    data: dict[str, Any] = {
        "run_key": [r[0] for r in chunk],
        "point": np.array([r[1] for r in chunk], dtype=np.int64),
    }
    for axis in plan.axes:
        data[axis.key] = [plan.points[r[1]][axis.key] for r in chunk]
    data["compensator"] = [r[2] for r in chunk]
    data["seed"] = np.array([r[3] for r in chunk], dtype=np.int64)
    data["robot_delay"] = [float(plan.scenarios[(r[1], r[2])]["facility"]["robot_delay"]) for r in chunk]
    data["contact_frequency"] = [plan.frequencies[r[1]] for r in chunk]
    for name in _CORE_COLUMNS:
        values = columns[name]
        data[name] = list(values) if name == "status" else np.asarray(values, dtype=np.float64)
    frame = pd.DataFrame(data)
    for name in _COUNT_COLUMNS:
        frame[name] = frame[name].astype(np.int64)
    return frame


def _chunks(items: list[Any], size: int) -> Iterator[list[Any]]:
    for start in range(0, len(items), size):
        yield items[start : start + size]


def _has_results(folder: Path) -> bool:
    return (folder / RESULTS_FILE).is_file() or bool(_parts(folder))


def _recorded_spec(spec_path: Path) -> dict[str, Any]:
    """The sweep recorded in ``sweep.json``; OutputError (one line) if it cannot be read."""
    try:
        recorded = json.loads(spec_path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError) as exc:
        reason = getattr(exc, "strerror", None) or " ".join(str(exc).split()) or type(exc).__name__
        raise OutputError(
            f"--resume {spec_path.parent}: {SPEC_FILE} cannot be read ({reason}); choose another --out"
        ) from None
    if not isinstance(recorded, dict):
        raise OutputError(f"--resume {spec_path.parent}: {SPEC_FILE} does not describe a sweep; choose another --out")
    return recorded


def check_sweep_folder(folder: Path, plan: SweepPlan, resume: bool) -> list[str]:
    """Check, writing nothing, that ``folder`` can take this sweep: new, empty, or (with
    ``resume``) a folder of the same sweep whose ``sweep.json`` and ``results.parquet`` can be
    read. Returns notes for the user (the unreadable part files that will be skipped, their
    runs run again). Raises ScenarioError or OutputError (one line)."""
    spec_path = folder / SPEC_FILE
    if folder.exists() and not folder.is_dir():
        raise ScenarioError(f"--out {folder}: exists and is not a directory")
    has_results = _has_results(folder)
    kind = marker_kind(folder)
    is_sweep = kind == "sweep" or spec_path.is_file() or has_results
    if folder.is_dir() and not is_sweep and any(folder.iterdir()):
        what = f"a hilcontact {kind} folder" if kind else "files hilcontact did not write"
        raise OutputError(f"--out {folder}: holds {what}; a sweep needs a new or empty folder (or its own, with --resume)")
    if resume:
        if spec_path.is_file():
            recorded = _recorded_spec(spec_path)
            wanted = json.loads(json.dumps(plan.spec()))
            for field in ("scenario", "grid", "compensators", "seeds"):
                if recorded.get(field) != wanted.get(field):
                    raise ScenarioError(
                        f"--resume {folder}: the folder holds a sweep with other {field}; "
                        "resume it with the same scenario, --set, --grid, --compensators and --seeds, "
                        "or choose another --out"
                    )
        elif has_results:
            raise ScenarioError(f"--resume {folder}: results without {SPEC_FILE}; choose another --out")
        if (folder / RESULTS_FILE).is_file():
            load_results(folder)  # one line if results.parquet cannot be read
    elif has_results:
        raise ScenarioError(
            f"--out {folder}: already holds sweep results; add --resume to continue that sweep "
            "(its finished runs are skipped), or choose another --out"
        )
    return [
        f"{part}: cannot be read ({reason[:200]}); skipped (renamed {part.name}.unreadable), its runs are run again"
        for part, reason in unreadable_parts(folder)
    ]


def _prepare_folder(folder: Path, plan: SweepPlan, resume: bool) -> set[str]:
    """Check (:func:`check_sweep_folder`) and create the sweep folder; set unreadable parts
    aside (``*.unreadable``) and remove the temporary files of a sweep that was killed;
    returns the keys of the runs already done."""
    check_sweep_folder(folder, plan, resume)
    for part, _ in unreadable_parts(folder):
        os.replace(part, part.with_name(part.name + ".unreadable"))
    remove_stale(folder)
    remove_stale(folder / PARTS_DIR)
    has_results = _has_results(folder)
    spec_path = folder / SPEC_FILE
    (folder / PARTS_DIR).mkdir(parents=True, exist_ok=True)
    mark_folder(folder, "sweep")
    spec_path.write_text(json.dumps(plan.spec(), indent=1) + "\n", encoding="utf-8")
    if not has_results:
        return set()
    return set(load_results(folder)["run_key"])


def _dask_client(address: str) -> Any:
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise HilContactError(
            "--dask needs dask.distributed: pip install 'hilcontact[dask]' (or dask distributed)"
        ) from None
    if address == "local":
        cluster = LocalCluster(n_workers=os.cpu_count() or 1, threads_per_worker=1, dashboard_address=None)
        return Client(cluster)
    try:
        return Client(address, timeout="20s")
    except OSError as exc:
        raise HilContactError(f"--dask {address}: cannot reach the scheduler: {exc}") from None


def _close_dask_client(client: Any) -> None:
    """Closes a client made by :func:`_dask_client`, and its LocalCluster if it made one."""
    cluster = getattr(client, "cluster", None)
    client.close()
    if cluster is not None:
        cluster.close()


def _execute(
    plan: SweepPlan,
    pending: list[tuple[str, int, str, int]],
    emit: Callable[[pd.DataFrame], None],
    threads: int | None,
    chunk_size: int | None,
    dask: str | Any | None,
) -> None:
    """Run the pending runs chunk by chunk, locally or on Dask, handing each chunk's rows to
    ``emit`` as it finishes."""
    if dask is None:
        size = chunk_size or max(8, 16 * (threads or os.cpu_count() or 1))
        for chunk in _chunks(pending, size):
            columns = _run_chunk([plan.scenario_json(p, k, s) for _, p, k, s in chunk], threads)
            emit(_rows(plan, chunk, columns))
        return
    from dask.distributed import as_completed

    client = _dask_client(dask) if isinstance(dask, str) else dask
    try:
        size = chunk_size or 200
        window = 2 * max(1, sum(client.nthreads().values()))
        chunks = iter(_chunks(pending, size))
        running: dict[Any, list[tuple[str, int, str, int]]] = {}

        def submit() -> bool:
            chunk = next(chunks, None)
            if chunk is None:
                return False
            jsons = [plan.scenario_json(p, k, s) for _, p, k, s in chunk]
            running[client.submit(_run_chunk, jsons, 1, pure=False)] = chunk
            return True

        for _ in range(window):
            if not submit():
                break
        done = as_completed(list(running))
        for future in done:
            chunk = running.pop(future)
            emit(_rows(plan, chunk, future.result()))
            if submit():
                done.add(next(reversed(running)))
    finally:
        if isinstance(dask, str):
            _close_dask_client(client)


def sweep(
    scenario: Any,
    grid: Mapping[str, Any] | Iterable[str | GridAxis] | None = None,
    compensators: str | Iterable[str] | None = None,
    seeds: int = 1,
    out: str | os.PathLike[str] | None = None,
    *,
    python: Sequence[Any] = (),
    overrides: Mapping[str, Any] | None = None,
    resume: bool = False,
    dask: str | Any | None = None,
    threads: int | None = None,
    chunk_size: int | None = None,
    progress: Progress | None = None,
    flush_seconds: float = 5.0,
    limits: Limits | None = None,
) -> pd.DataFrame:
    """Run a scenario over a grid, compensators and seeds; one summary row per run.

    Args:
        scenario: preset name, TOML path, dict or :class:`Scenario` (the base).
        grid: the swept keys: specs ``["facility.robot_delay=0.002:0.06:30",
            "servicer.mass=100,300"]``, or a mapping ``{"facility.robot_delay": "0.002:0.06:30",
            "servicer.mass": [100, 300]}``. A range ``START:STOP:COUNT`` includes both ends.
        compensators: kinds (comma-separated or a list; default all, none when ``python`` is
            given).
        python: compensators written in Python (``FILE.py:Class`` entries; they run one at a
            time per process: threads do not speed them up, Dask workers do).
        seeds: noise seeds per grid point: ``facility.seed``, ``facility.seed + 1``, ...
        out: folder for ``results.parquet`` (kept up to date as runs finish); None keeps the
            rows in memory only.
        overrides: ``--set`` values applied to the base scenario.
        resume: skip the runs already in ``out`` (the same sweep, checked against
            ``sweep.json``).
        dask: None (local threads), ``"local"`` (a LocalCluster, one worker per core), a
            scheduler address (``"tcp://host:8786"``) or a ``dask.distributed.Client``.
        threads: Rust threads for a local sweep (default: one per core).
        chunk_size: runs per core call (local) or per Dask task (default 16 per thread, 200).
        progress: called with (runs done, total) after each chunk.
        flush_seconds: how often finished rows are written to ``out``.
        limits: refuse a sweep estimated above these (default :class:`Limits`).

    Returns the rows (see :data:`RESULT_COLUMNS`; one column per swept key after ``point``),
    in grid order. Identical inputs give identical rows (but for ``wall_time``), locally or
    on Dask. Raises ScenarioError for bad input before anything runs; on KeyboardInterrupt the
    finished rows are in ``out`` before the exception propagates.
    """
    check_run_arguments(out, resume, dask, chunk_size, progress, flush_seconds)
    return run_plan(
        plan_sweep(scenario, grid, compensators, seeds, overrides, limits=limits, threads=threads, python=python),
        out,
        resume=resume,
        dask=dask,
        threads=threads,
        chunk_size=chunk_size,
        progress=progress,
        flush_seconds=flush_seconds,
    )


def run_plan(
    plan: SweepPlan,
    out: str | os.PathLike[str] | None = None,
    *,
    resume: bool = False,
    dask: str | Any | None = None,
    threads: int | None = None,
    chunk_size: int | None = None,
    progress: Progress | None = None,
    flush_seconds: float = 5.0,
) -> pd.DataFrame:
    """Run a validated :class:`SweepPlan` (see :func:`sweep` for the arguments)."""
    _core()  # fail early if the extension is missing
    if not isinstance(plan, SweepPlan):
        raise ArgumentError(f"plan: expected a SweepPlan (from plan_sweep), got {_shown(plan)}")
    threads = check_threads(threads)
    check_run_arguments(out, resume, dask, chunk_size, progress, flush_seconds)
    everything = list(plan.runs())
    order = [r[0] for r in everything]
    folder = Path(out) if out is not None else None
    try:
        done: set[str] = _prepare_folder(folder, plan, resume) if folder is not None else set()
    except OSError as exc:
        raise OutputError(f"--out {folder}: cannot write {exc.filename or folder}: {exc.strerror or exc}") from None
    pending = [r for r in everything if r[0] not in done]
    finished = len(everything) - len(pending)
    kept: list[pd.DataFrame] = []  # rows when there is no folder
    buffer: list[pd.DataFrame] = []
    last_flush = time.monotonic()

    def flush() -> None:
        nonlocal last_flush
        if folder is not None and buffer:
            frame = pd.concat(buffer, ignore_index=True)
            _write_parquet_atomically(frame, folder / PARTS_DIR / f"part-{time.time_ns():020d}.parquet")
            buffer.clear()
        last_flush = time.monotonic()

    def emit(rows: pd.DataFrame) -> None:
        nonlocal finished
        finished += len(rows)
        (buffer if folder is not None else kept).append(rows)
        if folder is not None and time.monotonic() - last_flush >= flush_seconds:
            flush()
        if progress is not None:
            progress(finished, len(everything))

    if progress is not None:
        progress(finished, len(everything))
    try:
        try:
            _execute(plan, pending, emit, threads, chunk_size, dask)
        finally:
            if folder is not None:
                flush()
                _merge(folder, order)
    except OSError as exc:
        raise OutputError(f"--out {folder}: cannot write {exc.filename or folder}: {exc.strerror or exc}") from None
    if folder is not None:
        return load_results(folder)
    frame = pd.concat(kept, ignore_index=True) if kept else _rows(plan, [], {c: [] for c in _CORE_COLUMNS})
    return frame
