"""Figures of ``hilcontact identify`` (matplotlib, Agg canvas; no pyplot global state):

- ``identification.png``: the identified stiffness k̂ (N/mm) and damping ĉ (N·s/mm) over time,
  in contact only, with the filter's ±1σ band; the axes span the collisions' identified values
  and their bands, not the initial guess, so that the convergence shows;
- ``force_penetration.png``: per collision, the measured force against the penetration
  ``d = (p − p_w)·ē`` (the tip ``τ_p`` earlier for ``align``), with the fitted law
  ``k̂·d + ĉ·ḋ`` at each sample and its elastic part ``k̂·d``.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

__all__ = ["MAX_COLLISION_PANELS", "force_penetration_figure", "identification_figure", "save_identification_figures"]

#: Most collisions drawn in ``force_penetration.png`` (the first ones).
MAX_COLLISION_PANELS = 12
_AXES = ("x", "y", "z")


def _span(values: np.ndarray, std: np.ndarray) -> tuple[float, float]:
    """Limits holding every value with its ±1σ band, padded by 10 % (and at least a hair)."""
    lo = float(np.nanmin(values - std))
    hi = float(np.nanmax(values + std))
    pad = max(0.1 * (hi - lo), 1e-3 * max(abs(lo), abs(hi)), 1e-9)
    return lo - pad, hi + pad


def identification_figure(ticks: pd.DataFrame, collisions: pd.DataFrame, title: str) -> Figure:
    """k̂ and ĉ over time (in contact; ±1σ band), each collision's final value marked. The
    y-axes span the estimates after each collision's first 20 % of ticks (the filter's
    start from the initial guess is cut off the axis), so that the convergence shows."""
    figure = Figure(figsize=(9, 6), layout="constrained")
    FigureCanvasAgg(figure)
    axes = figure.subplots(2, 1, sharex=True)
    time = ticks["time"].to_numpy(dtype=float)
    contact = ticks["in_contact"].to_numpy(dtype=float) > 0.5
    settled = np.zeros(len(time), dtype=bool)
    for _, c in collisions.iterrows():
        inside = np.flatnonzero((time >= c["start"]) & (time <= c["end"]))
        settled[inside[len(inside) // 5:]] = True
    for ax, (name, unit, scale, label) in zip(axes, [
        ("stiffness", "N/mm", 1e-3, "k̂"), ("damping", "N·s/mm", 1e-3, "ĉ"),
    ]):
        value = np.where(contact, ticks[f"{name}_estimate"].to_numpy(dtype=float) * scale, np.nan)
        std = np.where(contact, ticks[f"{name}_std"].to_numpy(dtype=float) * scale, np.nan)
        ax.fill_between(time, value - std, value + std, color="tab:blue", alpha=0.25, linewidth=0, label="±1σ")
        ax.plot(time, value, color="tab:blue", linewidth=1.0, label=f"{label} (in contact)")
        if len(collisions):
            ends = collisions["end"].to_numpy(dtype=float)
            final = collisions[name].to_numpy(dtype=float) * scale
            final_std = collisions[f"{name}_std"].to_numpy(dtype=float) * scale
            ax.errorbar(ends, final, yerr=final_std, fmt="o", color="tab:red", markersize=4, capsize=3,
                        label="per collision (±1σ)")
            mask = settled & np.isfinite(value)
            if mask.any():
                lo, hi = _span(np.concatenate([value[mask], final]), np.concatenate([std[mask], final_std]))
                ax.set_ylim(lo, hi)
        ax.set_ylabel(f"{label}, {unit}")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize="small")
    axes[-1].set_xlabel("time, s")
    figure.suptitle(title)
    return figure


def _collision_series(data: pd.DataFrame, c: pd.Series, lag: int) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                                              np.ndarray]:
    """A collision's penetration d (m), its rate ḋ (m/s), the measured force magnitude (N) and
    whether each tick had a new sensor record (a real-time run's ``sensor_age`` is 0)."""
    time = data["time"].to_numpy(dtype=float)
    first, last = int(np.searchsorted(time, c["start"])), int(np.searchsorted(time, c["end"]))
    k = np.arange(first, last + 1)
    fresh = (data["sensor_age"].to_numpy(dtype=float)[k] <= 0 if "sensor_age" in data.columns
             else np.ones(len(k), dtype=bool))
    j = np.maximum(k - lag, 0)
    n = np.array([c[f"normal_{a}"] for a in _AXES])
    point = np.array([c[f"point_{a}"] for a in _AXES])
    p = data[[f"actual_tip_position_{a}" for a in _AXES]].to_numpy(dtype=float)[j]
    v = data[[f"actual_tip_velocity_{a}" for a in _AXES]].to_numpy(dtype=float)[j]
    f = data[[f"measured_force_{a}" for a in _AXES]].to_numpy(dtype=float)[k]
    return -(p - point) @ n, -v @ n, np.linalg.norm(f, axis=1), fresh


def force_penetration_figure(data: pd.DataFrame, collisions: pd.DataFrame, lag: int, title: str) -> Figure:
    """Per collision (the first :data:`MAX_COLLISION_PANELS`): measured |F| against the
    penetration (mm), the fitted law k̂·d + ĉ·ḋ at each sample and its elastic part k̂·d."""
    shown = collisions.head(MAX_COLLISION_PANELS)
    n = max(len(shown), 1)
    cols = min(n, 4)
    rows = math.ceil(n / cols)
    figure = Figure(figsize=(3.2 * cols + 0.6, 2.8 * rows + 0.8), layout="constrained")
    FigureCanvasAgg(figure)
    grid = np.atleast_1d(figure.subplots(rows, cols, squeeze=False)).ravel()
    for ax in grid[len(shown):]:
        ax.set_visible(False)
    if len(shown) == 0:
        grid[0].set_visible(True)
        grid[0].text(0.5, 0.5, "no collision", ha="center", va="center", transform=grid[0].transAxes)
    for ax, (_, c) in zip(grid, shown.iterrows()):
        d, rate, force, fresh = _collision_series(data, c, lag)
        k_hat, c_hat = float(c["stiffness"]), float(c["damping"])
        if not fresh.all():
            # real time: a held record against the moving tip (not identified on)
            ax.plot(d[~fresh] * 1e3, force[~fresh], ".", markersize=2, color="0.75", label="held record")
            d, rate, force = d[fresh], rate[fresh], force[fresh]
        law = k_hat * d + c_hat * rate
        ax.plot(d * 1e3, force, ".", markersize=2, color="tab:blue", label="measured |F|")
        ax.plot(d * 1e3, law, "-", linewidth=1.0, color="tab:red", label="k̂·d + ĉ·ḋ")
        order = np.argsort(d)
        ax.plot(d[order] * 1e3, k_hat * d[order], ":", linewidth=1.0, color="black", label="k̂·d")
        if not fresh.all():
            ax.legend(loc="upper left", fontsize="x-small")
        ax.set_title(f"#{int(c['index'])}: k̂ {k_hat / 1e3:.4g} N/mm, ĉ {c_hat / 1e3:.3g} N·s/mm", fontsize="small")
        ax.set_xlabel("penetration d, mm")
        ax.set_ylabel("force, N")
        ax.grid(True, alpha=0.3)
    if len(shown):
        grid[0].legend(loc="upper left", fontsize="x-small")
    more = f" (first {len(shown)} of {len(collisions)} collisions)" if len(collisions) > len(shown) else ""
    figure.suptitle(title + more)
    return figure


def save_identification_figures(data: pd.DataFrame, ticks: pd.DataFrame, collisions: pd.DataFrame, lag: int,
                                source: str, folder: str | os.PathLike[str], dpi: int = 120) -> list[str]:
    """Writes identification.png and force_penetration.png into ``folder``; returns their names."""
    out = Path(folder)
    figures = {
        "identification": identification_figure(ticks, collisions, f"{source}: identified stiffness and damping"),
        "force_penetration": force_penetration_figure(data, collisions, lag, f"{source}: force against penetration"),
    }
    for name, figure in figures.items():
        figure.savefig(out / f"{name}.png", dpi=dpi)
    return [f"{name}.png" for name in figures]
