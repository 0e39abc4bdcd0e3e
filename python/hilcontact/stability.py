"""Stability maps of a sweep: where, in (contact frequency, robot delay), each compensator
keeps the loop faithful.

A run is *faithful* when the core's verdict says so (status ``ok``: it ran to the end and
every collision kept the scenario's ``[metrics]`` tolerances: |CoV − 1|, CoF, rebound
velocity error, no lost or extra collision; docs/model.md, "Metrics") and it had at least
one compared collision; the map may be stricter still in the worst CoV and CoF of every
collision (``cov_tolerance``, ``cof_limit``; by default none: the verdict alone, by the
scenario's tolerances, |CoV − 1| ≤ 5 %, CoF ≤ 1.2 unless set, from ``[metrics] judge_from``
on). A cell (compensator, contact frequency, robot delay)
holds every seed and every value of any other swept key; its *faithful fraction* is the share
of its runs that are faithful. A cell counts as faithful by :func:`cell_rule` (default: all
its runs but at most one, and the failing ones fewer than half: with 3 seeds, 2 of 3 pass;
with 1 or 2, all must; ``tolerate=0``: every run).
The *maximal faithful delay* of a compensator at a frequency is the largest swept delay up to
which every cell, from the smallest delay on, is faithful (NaN if the smallest is not).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from .errors import ArgumentError, HilContactError, describe
from .sweep import RESULTS_FILE, load_results

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["DEFAULT_TOLERATE", "StabilityMap", "cell_rule", "faithful", "stability_map"]

#: Failing runs a faithful cell may hold by default (while they stay fewer than half of it).
DEFAULT_TOLERATE = 1

#: Files written by :meth:`StabilityMap.save`.
MAP_FILES = ("stability_map.png", "worst_cov.png", "worst_cof.png", "max_faithful_delay.csv", "cells.csv")


def faithful(rows: pd.DataFrame, cov_tolerance: float | None = None, cof_limit: float | None = None) -> pd.Series:
    """Whether each run (row of a sweep) is faithful (see the module doc)."""
    ok = rows["status"] == "ok"
    if cov_tolerance is not None:
        ok &= (rows["worst_cov"].astype(float) - 1.0).abs() <= cov_tolerance
    if cof_limit is not None:
        ok &= rows["worst_cof"].astype(float) <= cof_limit
    return ok


def cell_rule(tolerate: int) -> str:
    """The rule that makes a cell faithful, in words (figures, tables, docs)."""
    if tolerate == 0:
        return "a cell is faithful when every run in it is"
    return (f"a cell is faithful when all its runs but at most {tolerate} are, the failing ones "
            "fewer than half")


def cell_faithful(faithful_runs: np.ndarray, runs: np.ndarray, tolerate: int) -> np.ndarray:
    """Whether cells with ``faithful_runs`` of ``runs`` faithful pass :func:`cell_rule`."""
    failing = np.asarray(runs) - np.asarray(faithful_runs)
    return (failing <= tolerate) & (2 * failing < np.asarray(runs))


@dataclass
class StabilityMap:
    """Per compensator and (contact frequency, robot delay) cell: faithful or not, and the
    worst CoV and CoF over the cell's runs.

    Attributes:
        cells: one row per (compensator, contact_frequency, robot_delay): runs,
            faithful_runs, faithful_fraction (faithful_runs / runs), faithful (bool, by
            :func:`cell_rule`), worst_cov (the CoV farthest from 1), worst_cof (largest),
            diverged (runs).
        cov_tolerance, cof_limit: the run criterion; tolerate: the cell rule's failing runs.
    """

    cells: pd.DataFrame
    cov_tolerance: float | None
    cof_limit: float | None
    tolerate: int = DEFAULT_TOLERATE

    @property
    def rule(self) -> str:
        """The cell rule in words (:func:`cell_rule`)."""
        return cell_rule(self.tolerate)

    @property
    def compensators(self) -> list[str]:
        return list(dict.fromkeys(self.cells["compensator"]))

    def max_faithful_delay(self) -> pd.DataFrame:
        """Rows: contact frequency (Hz); columns: compensators; values: the maximal faithful
        robot delay (s), NaN where even the smallest swept delay is not faithful."""
        out: dict[str, dict[float, float]] = {}
        for (kind, freq), group in self.cells.groupby(["compensator", "contact_frequency"], sort=False):
            best = math.nan
            for _, cell in group.sort_values("robot_delay").iterrows():
                if not cell["faithful"]:
                    break
                best = float(cell["robot_delay"])
            out.setdefault(str(kind), {})[float(freq)] = best
        frame = pd.DataFrame(out)
        frame.index.name = "contact_frequency"
        return frame.sort_index()[self.compensators]

    def figures(self) -> dict[str, Figure]:
        """``stability_map`` (faithful cells per compensator), ``worst_cov`` (|CoV − 1| heat
        maps) and ``worst_cof`` (CoF heat maps): one panel per compensator, robot delay (ms)
        across, contact frequency (Hz) up."""
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.colors import ListedColormap, LogNorm
        from matplotlib.figure import Figure

        kinds = self.compensators
        delays = np.sort(self.cells["robot_delay"].unique())
        freqs = np.sort(self.cells["contact_frequency"].unique())

        def grid(kind: str, column: str) -> np.ndarray:
            cells = self.cells[self.cells["compensator"] == kind]
            table = cells.pivot_table(index="contact_frequency", columns="robot_delay", values=column, aggfunc="first")
            return table.reindex(index=freqs, columns=delays).to_numpy(dtype=float)

        def edges(values: np.ndarray) -> np.ndarray:
            if len(values) == 1:
                return np.array([values[0] - 0.5, values[0] + 0.5]) if values[0] else np.array([-0.5, 0.5])
            mids = (values[1:] + values[:-1]) / 2
            return np.concatenate([[values[0] - (mids[0] - values[0])], mids, [values[-1] + (values[-1] - mids[-1])]])

        x, y = edges(delays * 1e3), edges(freqs)
        criterion = criterion_text(self.cov_tolerance, self.cof_limit)

        def panels(title: str) -> tuple[Figure, list[Any]]:
            cols = min(len(kinds), 3)
            rows = math.ceil(len(kinds) / cols)
            figure = Figure(figsize=(4.2 * cols + 1.0, 3.4 * rows + 0.6), layout="constrained")
            FigureCanvasAgg(figure)
            axes = [figure.add_subplot(rows, cols, i + 1) for i in range(len(kinds))]
            figure.suptitle(title)
            for ax, kind in zip(axes, kinds):
                ax.set_title(kind)
                ax.set_xlabel("robot delay (ms)")
                ax.set_ylabel("contact frequency (Hz)")
            return figure, axes

        figures: dict[str, Figure] = {}
        figure, axes = panels(f"Faithful runs per cell (a run is faithful with {criterion}; green: all, orange: some, "
                              f"red: none);\n✓: {self.rule}")
        colours = ListedColormap(["#d9534f", "#f0ad4e", "#5cb85c"])
        for ax, kind in zip(axes, kinds):
            fraction, ok = grid(kind, "faithful_fraction"), grid(kind, "faithful")
            good, runs = grid(kind, "faithful_runs"), grid(kind, "runs")
            # red: none faithful, orange: some, green: all
            shade = np.where(np.isfinite(fraction), np.where(fraction >= 1.0, 2.0, np.where(fraction > 0.0, 1.0, 0.0)), np.nan)
            ax.pcolormesh(x, y, np.ma.masked_invalid(shade), cmap=colours, vmin=0, vmax=2, edgecolors="white", linewidth=0.3)
            # every cell's count when they fit (12 delays), else only the mixed (orange) ones
            every = len(delays) <= 12
            if len(freqs) <= 40:
                for i, freq in enumerate(freqs):
                    for j, delay in enumerate(delays):
                        if np.isfinite(runs[i, j]) and (every or 0 < good[i, j] < runs[i, j]):
                            mark = " ✓" if ok[i, j] == 1.0 else ""
                            ax.text(delay * 1e3, freq, f"{int(good[i, j])}/{int(runs[i, j])}{mark}", ha="center",
                                    va="center", fontsize=7 if every else 5, color="black")
        figures["stability_map"] = figure

        figure, axes = panels("Worst |CoV − 1| per cell (log scale)")
        for ax, kind in zip(axes, kinds):
            error = np.abs(grid(kind, "worst_cov") - 1.0)
            mesh = ax.pcolormesh(x, y, np.ma.masked_invalid(np.clip(error, 1e-4, None)), cmap="viridis",
                                 norm=LogNorm(vmin=1e-4, vmax=max(1.0, float(np.nanmax(error)) if np.isfinite(error).any() else 1.0)))
            if min(error.shape) > 1 and np.isfinite(error).any():
                ax.contour(delays * 1e3, freqs, error, levels=[self.cov_tolerance if self.cov_tolerance is not None else 0.05], colors="white", linewidths=1.0)
            figure.colorbar(mesh, ax=ax)
        figures["worst_cov"] = figure

        figure, axes = panels("Worst CoF per cell")
        for ax, kind in zip(axes, kinds):
            cof = grid(kind, "worst_cof")
            mesh = ax.pcolormesh(x, y, np.ma.masked_invalid(cof), cmap="magma", vmin=1.0,
                                 vmax=max((self.cof_limit or 1.2) * 1.5, float(np.nanmax(cof)) if np.isfinite(cof).any() else 2.0))
            figure.colorbar(mesh, ax=ax)
        figures["worst_cof"] = figure
        return figures

    def save(self, directory: str | os.PathLike[str]) -> Path:
        """Write the figures (PNG), ``max_faithful_delay.csv`` and ``cells.csv`` into
        ``directory``; returns it."""
        from .plots import save_figures

        folder = Path(directory)
        folder.mkdir(parents=True, exist_ok=True)
        save_figures(self.figures(), folder, dpi=110)
        self.max_faithful_delay().to_csv(folder / "max_faithful_delay.csv")
        self.cells.to_csv(folder / "cells.csv", index=False)
        return folder


def criterion_text(cov_tolerance: float | None, cof_limit: float | None) -> str:
    """What makes a run faithful on the map, for titles."""
    extra = []
    if cov_tolerance is not None:
        extra.append(f"|CoV−1| ≤ {cov_tolerance:g}")
    if cof_limit is not None:
        extra.append(f"CoF ≤ {cof_limit:g}")
    return "status ok" + (" and " + ", ".join(extra) + " on every collision" if extra else "")


#: The columns of a sweep's rows a map reads.
_NEEDED = ("run_key", "compensator", "status", "robot_delay", "contact_frequency", "worst_cov", "worst_cof")


def _rows_of(results: Any) -> pd.DataFrame:
    """A sweep's rows from a DataFrame or a sweep folder, checked (see :func:`stability_map`)."""
    if isinstance(results, pd.DataFrame):
        rows = results
    elif isinstance(results, (str, os.PathLike)):
        folder = Path(results)
        if not folder.is_dir():
            raise ArgumentError(f"results: {folder}: no such folder (expected a sweep folder or its rows)")
        try:
            rows = load_results(folder)
        except ArgumentError:
            raise
        except HilContactError as exc:
            if isinstance(exc, ValueError):
                raise
            raise ArgumentError(f"results: {folder}: no sweep results ({RESULTS_FILE}) here") from None
    else:
        raise ArgumentError(f"results: expected a sweep's rows (a DataFrame) or a sweep folder, got {describe(results)}")
    missing = [name for name in _NEEDED if name not in rows.columns]
    if missing:
        raise ArgumentError(f"results: not a sweep's rows (missing columns {', '.join(missing)})")
    if rows.empty:
        raise ArgumentError("results: the sweep has no finished runs")
    return rows


def stability_map(
    results: pd.DataFrame | str | os.PathLike[str], cov_tolerance: float | None = None, cof_limit: float | None = None,
    tolerate: int = DEFAULT_TOLERATE,
) -> StabilityMap:
    """The stability map of a sweep's rows (a DataFrame from :func:`hilcontact.sweep` or a
    sweep folder). ``cov_tolerance``, ``cof_limit``: None or a finite number > 0;
    ``tolerate``: failing runs a faithful cell may hold (:func:`cell_rule`).

    Raises :class:`~hilcontact.errors.ArgumentError` (a ValueError) naming the argument for a
    missing folder, a folder without sweep results, rows without a sweep's columns, no
    finished run, or a bad tolerance."""
    for name, value in (("cov_tolerance", cov_tolerance), ("cof_limit", cof_limit)):
        if value is not None and (
            isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating))
            or not (math.isfinite(value) and value > 0)
        ):
            raise ArgumentError(f"{name}: expected a finite number > 0 or None, got {describe(value)}")
    if isinstance(tolerate, bool) or not isinstance(tolerate, (int, np.integer)) or tolerate < 0:
        raise ArgumentError(f"tolerate: expected an integer >= 0, got {describe(tolerate)}")
    rows = _rows_of(results)
    usable = rows[np.isfinite(rows["contact_frequency"].astype(float))]
    if usable.empty:
        raise HilContactError(
            "stability map: no run has a contact frequency (only linear contacts have one; "
            "Hunt-Crossley sweeps cannot be mapped)"
        )
    usable = usable.assign(
        faithful=faithful(usable, cov_tolerance, cof_limit),
        cov_error=(usable["worst_cov"].astype(float) - 1.0).abs(),
        diverged=usable["status"] == "diverged",
    )
    keys = ["compensator", "contact_frequency", "robot_delay"]
    grouped = usable.groupby(keys, sort=False)
    cells = grouped.agg(
        runs=("run_key", "size"), faithful_runs=("faithful", "sum"), worst_cof=("worst_cof", "max"),
        diverged=("diverged", "sum"),
    )
    cells["faithful_runs"] = cells["faithful_runs"].astype(np.int64)
    cells["faithful_fraction"] = cells["faithful_runs"] / cells["runs"]
    cells["faithful"] = cell_faithful(cells["faithful_runs"].to_numpy(), cells["runs"].to_numpy(), int(tolerate))
    # the worst CoV of a cell: the run's CoV farthest from 1 (NaN if any run has none)
    worst = usable.loc[usable["cov_error"].fillna(np.inf).groupby([usable[k] for k in keys], sort=False).idxmax()]
    cells["worst_cov"] = worst.set_index(keys)["worst_cov"]
    cells = cells.reset_index()[["compensator", "contact_frequency", "robot_delay", "runs", "faithful_runs",
                                 "faithful_fraction", "faithful", "worst_cov", "worst_cof", "diverged"]]
    cells["diverged"] = cells["diverged"].astype(np.int64)
    return StabilityMap(cells=cells, cov_tolerance=cov_tolerance, cof_limit=cof_limit, tolerate=int(tolerate))
