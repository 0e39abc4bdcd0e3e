"""Figures of a run (matplotlib, Agg canvas; no pyplot global state is touched).

- contact_velocity: rod-tip velocity (mm/s), HIL solid vs ideal reference dashed, with the
  collision intervals shaded (the paper's velocity figures).
- contact_force: contact force magnitude (N), HIL vs reference (the paper's Figs 6/9/11).
- energy: energy of the virtual relative motion (J), HIL vs reference (the paper's Fig 10).
- identification (only when the compensator estimates them): stiffness and damping
  estimates vs the scenario's true values.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

if TYPE_CHECKING:
    from .run import Run

__all__ = ["make_figures"]

_COLORS = {"x": "tab:blue", "y": "tab:orange", "z": "tab:green"}


def _figure(rows: int = 1) -> tuple[Figure, list[Axes]]:
    figure = Figure(figsize=(10.0, 4.8 if rows == 1 else 7.0), layout="constrained")
    FigureCanvasAgg(figure)
    axes = [figure.add_subplot(rows, 1, i + 1) for i in range(rows)]
    return figure, axes


def _header(run: Run) -> str:
    delay_ms = run.scenario.facility.robot_delay * 1e3
    status = "" if run.status == "ok" else f" | {run.status.upper()}"
    return f"{run.scenario.name} | compensator: {run.compensator} | robot delay {delay_ms:g} ms{status}"


def _finish(ax: Axes, title: str, run: Run, ylabel: str) -> None:
    ax.set_title(f"{title}\n{_header(run)}", fontsize=11)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.4)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=9, frameon=False)


def _shade_collisions(ax: Axes, run: Run) -> None:
    end_of_run = float(run.timeseries["time"].iloc[-1]) if len(run.timeseries) else 0.0
    for i, collision in enumerate(run.metrics.get("collisions") or []):
        start = collision.get("start")
        if start is None:
            continue
        end = collision.get("end")
        ax.axvspan(
            start,
            end_of_run if end is None else end,
            color="0.55",
            alpha=0.15,
            lw=0,
            label="collision (HIL)" if i == 0 else None,
        )


def _mark_divergence(ax: Axes, run: Run) -> None:
    at = run.metrics.get("diverged_at")
    if run.status != "ok" and at is not None:
        ax.axvline(at, color="tab:red", lw=1.0, ls=":", label=f"diverged at {at:.3f} s")


def _column(frame: pd.DataFrame, name: str) -> np.ndarray | None:
    return frame[name].to_numpy() if name in frame else None


def _peak(values: np.ndarray | None) -> float:
    if values is None or values.size == 0:
        return 0.0
    finite = np.abs(values[np.isfinite(values)])
    return float(finite.max()) if finite.size else 0.0


def velocity_figure(run: Run) -> Figure:
    figure, (ax,) = _figure()
    ts, ref = run.timeseries, run.reference
    peaks = {
        axis: max(_peak(_column(ts, f"tip_velocity_{axis}")), _peak(_column(ref, f"tip_velocity_{axis}")))
        for axis in "xyz"
    }
    largest = max(peaks.values())
    shown = [axis for axis in "xyz" if axis == "x" or peaks[axis] > 0.01 * largest]
    for axis in shown:
        hil = _column(ts, f"tip_velocity_{axis}")
        ideal = _column(ref, f"tip_velocity_{axis}")
        if hil is not None:
            ax.plot(ts["time"], hil * 1e3, color=_COLORS[axis], lw=1.4, label=f"v{axis} HIL")
        if ideal is not None:
            ax.plot(ref["time"], ideal * 1e3, color=_COLORS[axis], lw=1.2, ls="--", label=f"v{axis} ideal reference")
    _shade_collisions(ax, run)
    _mark_divergence(ax, run)
    _finish(ax, "Rod-tip relative velocity", run, "velocity (mm/s)")
    return figure


def _magnitude(frame: pd.DataFrame, name: str) -> np.ndarray | None:
    parts = [_column(frame, f"{name}_{axis}") for axis in "xyz"]
    if any(p is None for p in parts):
        return None
    return np.sqrt(sum(p * p for p in parts))  # type: ignore[operator]


def force_figure(run: Run) -> Figure:
    figure, (ax,) = _figure()
    hil = _magnitude(run.timeseries, "contact_force")
    ideal = _magnitude(run.reference, "contact_force")
    if hil is not None:
        ax.plot(run.timeseries["time"], hil, color="tab:blue", lw=1.4, label="|F| HIL")
    if ideal is not None:
        ax.plot(run.reference["time"], ideal, color="black", lw=1.2, ls="--", label="|F| ideal reference")
    _shade_collisions(ax, run)
    _mark_divergence(ax, run)
    _finish(ax, "Contact force magnitude", run, "contact force (N)")
    return figure


def energy_figure(run: Run) -> Figure:
    figure, (ax,) = _figure()
    if "energy" in run.timeseries:
        ax.plot(run.timeseries["time"], run.timeseries["energy"], color="tab:blue", lw=1.4, label="energy HIL")
    if "energy" in run.reference:
        ax.plot(run.reference["time"], run.reference["energy"], color="black", lw=1.2, ls="--", label="energy ideal reference")
    _shade_collisions(ax, run)
    _mark_divergence(ax, run)
    _finish(ax, "Energy of the virtual relative motion", run, "energy (J)")
    return figure


def identification_figure(run: Run) -> Figure:
    figure, (ax_k, ax_c) = _figure(rows=2)
    ts = run.timeseries
    contact = run.scenario.contact
    ax_k.plot(ts["time"], ts["stiffness_estimate"], color="tab:blue", lw=1.4, label="estimate")
    ax_k.axhline(contact.stiffness, color="black", lw=1.2, ls="--", label="true")
    _shade_collisions(ax_k, run)
    _finish(ax_k, "Identified contact stiffness", run, "stiffness (N/m)")
    if "damping_estimate" in ts:
        ax_c.plot(ts["time"], ts["damping_estimate"], color="tab:orange", lw=1.4, label="estimate")
    ax_c.axhline(contact.damping, color="black", lw=1.2, ls="--", label="true")
    _shade_collisions(ax_c, run)
    ax_c.set_xlabel("time (s)")
    ax_c.set_ylabel("damping (N s/m)")
    ax_c.set_title("Identified contact damping", fontsize=11)
    ax_c.grid(True, alpha=0.4)
    ax_c.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=9, frameon=False)
    return figure


def make_figures(run: Run) -> dict[str, Figure]:
    """All figures of a run, by file stem."""
    figures = {
        "contact_velocity": velocity_figure(run),
        "contact_force": force_figure(run),
        "energy": energy_figure(run),
    }
    if "stiffness_estimate" in run.timeseries:
        figures["identification"] = identification_figure(run)
    return figures
