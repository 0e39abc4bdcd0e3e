"""Figures of a run (matplotlib, Agg canvas; no pyplot global state is touched).

- contact_velocity: rod-tip velocity (mm/s), HIL solid vs ideal reference dashed, with the
  collision intervals shaded (the paper's velocity figures).
- contact_force: contact force magnitude (N), HIL vs reference (the paper's Figs 6/9/11).
- energy: energy of the virtual relative motion (J), HIL vs reference (the paper's Fig 10),
  and the compensator's observed energy (dotted) when it has an energy observer.
- identification (only when the compensator estimates them): stiffness (N/mm) and damping
  (N s/mm) estimates vs the scenario's true values.

Runs whose motion is not 1-D (:func:`moves_in_1d`: the ideal reference rotates, or its rod tip
moves off one line) also get:

- contact_rotation: the servicer's angular velocity relative to the target (mrad/s, t frame)
  above the moment on the frame about the sensor origin (N m, t frame; HIL: the applied
  moment, reference: the true contact's), HIL solid vs reference dashed, per axis.
- tip_tracking: the rod tip's distance to the wall of the first collision along its normal
  (mm): commanded (virtual) vs actual (robot), over the run and zoomed on the first
  collision, where the robot's delay shows.

Runs with a contact episode whose motion is not 1-D or whose contact has friction
(:func:`shows_episodes`) also get:

- contact_points: where the hardware touched, per episode: the rod tip while in contact (HIL:
  the actual, robot tip; reference: the ideal tip) in three orthogonal projections of the
  ``t`` frame (mm), over the walls' outlines (each wall cut at the contact points' mean depth).
- contact_normal_tangential: the normal part ``|F − F_t|`` of the physical contact force above
  its tangential (friction) part ``|F_t|`` (N), HIL solid vs reference dashed.

Comparison figures (several compensators on one scenario, one panel each, shared axes):
compare_velocity, compare_force, compare_energy, compare_identification (the compensators
that identify the contact), compare_cov_cof (grouped bars, like the paper's Fig. 8d) and, when
the motion is not 1-D, compare_velocity_error (velocity and angular velocity errors per
collision, grouped bars).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .native import core
from .processes import in_two_processes
from .registry import COMPENSATORS

if TYPE_CHECKING:
    from .scenario import Scenario

__all__ = ["RunData", "comparison_figures", "make_figures", "moves_in_1d", "shows_episodes"]


class RunData(Protocol):
    """What the figures draw: a run's resolved scenario, metrics, time series and ideal
    reference (SI units), its status and compensator. A :class:`hilcontact.Run` is one."""

    scenario: Scenario
    metrics: dict[str, Any]
    timeseries: pd.DataFrame
    reference: pd.DataFrame

    @property
    def status(self) -> str: ...

    @property
    def compensator(self) -> str: ...


_COLORS = {"x": "tab:blue", "y": "tab:orange", "z": "tab:green"}


#: Statuses of runs that ran to their end (their values set the axes' limits).
_RAN_THROUGH = ("ok", "unfaithful")
#: Title colour of a panel per run status (others: red).
_STATUS_COLOURS = {"ok": "black", "unfaithful": "darkorange"}


def save_figures(figures: Mapping[str, Figure], directory: str | os.PathLike[str], dpi: int) -> None:
    """Save each figure as ``<name>.png`` in ``directory`` (created if needed)."""
    folder = Path(directory)
    folder.mkdir(parents=True, exist_ok=True)
    for name, figure in figures.items():
        figure.savefig(folder / f"{name}.png", dpi=dpi)


def _margins(figure: Figure, *, left: float, right: float, top: float, bottom: float,
             hspace: float = 0.2, wspace: float = 0.2) -> None:
    """Fixed margins, in inches (``hspace``/``wspace``: fractions of an axis, as matplotlib's):
    no layout engine, whose two extra passes per figure took half the drawing time."""
    width, height = figure.get_size_inches()
    figure.subplots_adjust(left=left / width, right=1.0 - right / width, top=1.0 - top / height,
                           bottom=bottom / height, hspace=hspace, wspace=wspace)


def _figure(rows: int = 1) -> tuple[Figure, list[Axes]]:
    """A run figure: ``rows`` axes one above the other, each titled on two lines and with its
    legend outside on the right."""
    figure = Figure(figsize=(10.0, 4.8 if rows == 1 else 7.0))
    FigureCanvasAgg(figure)
    axes = [figure.add_subplot(rows, 1, i + 1) for i in range(rows)]
    _margins(figure, left=0.85, right=2.3, top=0.62, bottom=0.55, hspace=0.45)
    return figure, axes


def _header(run: RunData) -> str:
    delay_ms = run.scenario.facility.robot_delay * 1e3
    status = "" if run.status == "ok" else f" | {run.status.upper()}"
    return f"{run.scenario.name} | compensator: {run.compensator} | robot delay {delay_ms:g} ms{status}"


def _finish(ax: Axes, title: str, run: RunData, ylabel: str) -> None:
    ax.set_title(f"{title}\n{_header(run)}", fontsize=11)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.4)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=9, frameon=False)


def _shade_collisions(ax: Axes, run: RunData) -> None:
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


def _mark_divergence(ax: Axes, run: RunData) -> None:
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


def velocity_figure(run: RunData) -> Figure:
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


def force_figure(run: RunData) -> Figure:
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


def has_values(frame: pd.DataFrame, name: str) -> bool:
    """Whether ``frame`` has the (optional) column ``name`` with at least one finite value."""
    return name in frame and bool(np.isfinite(frame[name].to_numpy(dtype=np.float64)).any())


def energy_figure(run: RunData) -> Figure:
    figure, (ax,) = _figure()
    if "energy" in run.timeseries:
        ax.plot(run.timeseries["time"], run.timeseries["energy"], color="tab:blue", lw=1.4, label="energy HIL")
    if "energy" in run.reference:
        ax.plot(run.reference["time"], run.reference["energy"], color="black", lw=1.2, ls="--", label="energy ideal reference")
    if has_values(run.timeseries, "observed_energy"):
        ax.plot(
            run.timeseries["time"], run.timeseries["observed_energy"], color="tab:purple", lw=1.2, ls=":",
            label="observed energy (compensator)",
        )
    _shade_collisions(ax, run)
    _mark_divergence(ax, run)
    _finish(ax, "Energy of the virtual relative motion", run, "energy (J)")
    return figure


def identification_figure(run: RunData) -> Figure:
    """Identified stiffness (N/mm) and damping (N s/mm) against the true contact values."""
    figure, (ax_k, ax_c) = _figure(rows=2)
    ts = run.timeseries
    contact = run.scenario.contact
    if "stiffness_estimate" in ts:
        ax_k.plot(ts["time"], ts["stiffness_estimate"] * 1e-3, color="tab:blue", lw=1.4, label="estimate k̂")
    ax_k.axhline(contact.stiffness * 1e-3, color="black", lw=1.2, ls="--", label="true k")
    _shade_collisions(ax_k, run)
    _finish(ax_k, "Identified contact stiffness", run, "stiffness (N/mm)")
    if "damping_estimate" in ts:
        ax_c.plot(ts["time"], ts["damping_estimate"] * 1e-3, color="tab:orange", lw=1.4, label="estimate ĉ")
    ax_c.axhline(contact.damping * 1e-3, color="black", lw=1.2, ls="--", label="true c")
    _shade_collisions(ax_c, run)
    ax_c.set_xlabel("time (s)")
    ax_c.set_ylabel("damping (N·s/mm)")
    ax_c.set_title("Identified contact damping", fontsize=11)
    ax_c.grid(True, alpha=0.4)
    ax_c.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=9, frameon=False)
    # axes that show the convergence, not the initial guess (converged_range)
    for ax, column, true in ((ax_k, "stiffness_estimate", contact.stiffness), (ax_c, "damping_estimate", contact.damping)):
        limits = converged_range(run, column, true)
        if limits is not None:
            ax.set_ylim(limits[0] * 1e-3, limits[1] * 1e-3)
    return figure


# --------------------------------------------------------------------------------------
# 6-DOF figures of a run
# --------------------------------------------------------------------------------------

#: Points per line above which the 6-DOF figures draw a min/max envelope of the samples
#: instead (an axis is well under 1200 pixels wide at the saved resolution).
MAX_POINTS = 2400
#: Reference angular velocity (rad/s) above which a run rotates (the metrics' threshold).
_ROTATION_THRESHOLD = 1e-6
#: Off-axis share of the reference tip velocity above which a run is not 1-D.
_OFF_AXIS_FRACTION = 0.01


def thin(time: np.ndarray, values: np.ndarray, limit: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """At most about ``limit`` (default :data:`MAX_POINTS`) samples of a series for drawing:
    the first and last samples and the smallest and largest of each of ``limit // 2`` equal
    slices, in time order, so peaks survive. Every point returned is a sample of the series.
    Series with non-finite values and short ones are returned whole."""
    limit = MAX_POINTS if limit is None else limit
    time, values = np.asarray(time), np.asarray(values)
    n = values.size
    if n <= limit or not np.isfinite(values).all():
        return time, values
    buckets = max(limit // 2, 1)
    size = math.ceil(n / buckets)
    padded = np.concatenate([values, np.full(buckets * size - n, values[-1])]).reshape(buckets, size)
    base = np.arange(buckets) * size
    keep = np.concatenate([[0, n - 1], base + padded.argmin(axis=1), base + padded.argmax(axis=1)])
    keep = np.unique(np.minimum(keep, n - 1))
    return time[keep], values[keep]


def _plot(ax: Axes, time: np.ndarray, values: np.ndarray, **style: object) -> None:
    t, y = thin(np.asarray(time), np.asarray(values))
    ax.plot(t, y, **style)


def moves_in_1d(run: RunData) -> bool:
    """Whether the run's motion is 1-D, decided from its ideal reference (the same for every
    compensator): no relative angular velocity above 1e-6 rad/s and a rod-tip velocity along
    one line (its second singular value below 1 % of the first). A run without a reference
    counts as 1-D."""
    ref = run.reference
    omega = _magnitude(ref, "angular_velocity")
    if omega is not None and _peak(omega) > _ROTATION_THRESHOLD:
        return False
    parts = [_column(ref, f"tip_velocity_{axis}") for axis in "xyz"]
    if any(p is None for p in parts) or len(ref) == 0:
        return True
    velocity = np.column_stack(parts)  # type: ignore[arg-type]
    velocity = velocity[np.isfinite(velocity).all(axis=1)]
    if velocity.size == 0:
        return True
    singular = np.linalg.svd(velocity, compute_uv=False)
    return bool(singular[0] == 0.0 or singular[1] <= _OFF_AXIS_FRACTION * singular[0])


def _frames(run: RunData, sensor_vectors: np.ndarray | None = None,
            points: list[np.ndarray] | None = None) -> dict[str, Any]:
    """The core's frame maths for the run's scenario (``hilcontact._core.frames``): the sensor
    vectors turned into ``t``, the walls' unit normals, the points' signed distances to each wall."""
    def rows(values: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(values, dtype=np.float64)

    return dict(core().frames(
        run.scenario.to_json(),
        None if sensor_vectors is None else rows(sensor_vectors),
        [rows(p) for p in points or []],
    ))


def applied_moment_in_t(run: RunData) -> np.ndarray | None:
    """The moment applied to the virtual dynamics (on the frame, about the sensor origin),
    turned from the sensor frame into ``t``: rows of (x, y, z), N m; None without the columns."""
    moment = _vectors(run.timeseries, "applied_moment")
    if moment is None:
        return None
    return np.asarray(_frames(run, sensor_vectors=moment)["in_t"])


def _vector_panel(
    ax: Axes,
    time: np.ndarray,
    hil: np.ndarray | None,
    ref_time: np.ndarray,
    ideal: np.ndarray | None,
    symbol: str,
    hil_label: str = "HIL",
) -> None:
    """Per axis: HIL solid, reference dashed, for the axes whose peak passes 1 % of the largest
    (x always). ``hil``/``ideal``: rows of (x, y, z)."""
    peaks = {
        axis: max(_peak(None if hil is None else hil[:, i]), _peak(None if ideal is None else ideal[:, i]))
        for i, axis in enumerate("xyz")
    }
    largest = max(peaks.values())
    for i, axis in enumerate("xyz"):
        if axis != "x" and not peaks[axis] > 0.01 * largest:
            continue
        if hil is not None:
            _plot(ax, time, hil[:, i], color=_COLORS[axis], lw=1.4, label=f"{symbol}{axis} {hil_label}")
        if ideal is not None:
            _plot(ax, ref_time, ideal[:, i], color=_COLORS[axis], lw=1.2, ls="--", label=f"{symbol}{axis} ideal reference")


def _vectors(frame: pd.DataFrame, name: str) -> np.ndarray | None:
    parts = [_column(frame, f"{name}_{axis}") for axis in "xyz"]
    return None if any(p is None for p in parts) else np.column_stack(parts)  # type: ignore[arg-type]


def rotation_figure(run: RunData) -> Figure:
    """Relative angular velocity (mrad/s) above the moment on the frame (N m), t frame, per axis."""
    figure, (ax_w, ax_m) = _figure(rows=2)
    ax_m.sharex(ax_w)
    ts, ref = run.timeseries, run.reference
    omega, omega_ref = _vectors(ts, "angular_velocity"), _vectors(ref, "angular_velocity")
    _vector_panel(
        ax_w, ts["time"].to_numpy(), None if omega is None else omega * 1e3,
        ref["time"].to_numpy(), None if omega_ref is None else omega_ref * 1e3, "ω",
    )
    _vector_panel(
        ax_m, ts["time"].to_numpy(), applied_moment_in_t(run), ref["time"].to_numpy(),
        _vectors(ref, "contact_moment"), "M", hil_label="HIL (applied)",
    )
    _finish_stacked(
        run, (ax_w, "Servicer angular velocity relative to the target (t frame)", "angular velocity (mrad/s)"),
        (ax_m, "Contact moment on the frame about the sensor origin (t frame)", "moment (N·m)"),
    )
    return figure


def _finish_stacked(run: RunData, top: tuple[Axes, str, str], bottom: tuple[Axes, str, str]) -> None:
    """Finish two panels stacked on one time axis, each given as (axes, title, y label): both
    get the collisions shaded, a divergence marked and ``_finish``'s title and labels; the
    run's header stays on the upper title only and the upper panel's time labels are hidden."""
    for ax, title, ylabel in (top, bottom):
        _shade_collisions(ax, run)
        _mark_divergence(ax, run)
        _finish(ax, title, run, ylabel)
    ax_top, ax_bottom = top[0], bottom[0]
    ax_bottom.set_title(ax_bottom.get_title().split("\n")[0], fontsize=11)
    ax_top.set_xlabel("")
    ax_top.tick_params(axis="x", labelbottom=False)


def _tracked_wall(run: RunData) -> int:
    """The index of the wall of the first HIL collision (the one whose normal is closest to the
    contact force at its peak), else of the wall nearest to the rod tip at the start."""
    ts = run.timeseries
    tip = _vectors(ts, "tip_position")
    start = tip[:1] if tip is not None and len(tip) else np.zeros((1, 3))
    frames = _frames(run, points=[start])
    force = _vectors(ts, "contact_force")
    collision = _first_collision(run)
    if collision is not None and force is not None:
        time = ts["time"].to_numpy()
        inside = (time >= collision[0]) & (time <= collision[1])
        if inside.any():
            during = force[inside]
            peak = during[np.argmax(np.linalg.norm(during, axis=1))]
            if np.linalg.norm(peak) > 0:
                return int(np.argmax(frames["normals"] @ (peak / np.linalg.norm(peak))))
    return int(np.argmin(frames["distances"][0][:, 0]))


def _first_collision(run: RunData) -> tuple[float, float] | None:
    """(start, end) of the first HIL collision (end of run if it does not end), or None."""
    for collision in run.metrics.get("collisions") or []:
        start = collision.get("start")
        if start is None:
            continue
        end = collision.get("end")
        if end is None:
            end = float(run.timeseries["time"].iloc[-1]) if len(run.timeseries) else start
        return float(start), float(end)
    return None


def wall_distance(run: RunData, column: str) -> np.ndarray | None:
    """The rod tip's signed distance to the tracked wall along its normal (m; < 0: inside),
    from ``<column>_x/y/z`` of the timeseries (tip_position or actual_tip_position)."""
    tip = _vectors(run.timeseries, column)
    if tip is None:
        return None
    return np.asarray(_frames(run, points=[tip])["distances"][0][_tracked_wall(run)])


def tracking_figure(run: RunData) -> Figure:
    """Commanded vs actual rod tip, distance to the wall of the first collision (mm): the
    whole run, then a zoom on the first collision with the command shifted by the robot delay."""
    collision = _first_collision(run)
    figure, axes = _figure(rows=2 if collision is not None else 1)
    ts = run.timeseries
    time = ts["time"].to_numpy()
    index = _tracked_wall(run)
    wall = run.scenario.walls[index]
    name = getattr(wall, "name", None) or f"walls[{index}]"
    commanded, actual = wall_distance(run, "tip_position"), wall_distance(run, "actual_tip_position")
    delay = run.scenario.facility.robot_delay

    def draw(ax: Axes, window: slice, zoom: bool) -> None:
        if commanded is not None:
            _plot(ax, time[window], commanded[window] * 1e3, color="tab:blue", lw=1.4, label="commanded (virtual)")
        if actual is not None:
            _plot(ax, time[window], actual[window] * 1e3, color="tab:red", lw=1.4, label="actual (robot)")
        if zoom and commanded is not None and delay > 0:
            _plot(
                ax, time[window] + delay, commanded[window] * 1e3, color="black", lw=1.2, ls=":", zorder=3,
                label=f"commanded, {delay * 1e3:g} ms later",
            )
        ax.axhline(0.0, color="black", lw=1.0, ls="--", label="wall surface")
        _shade_collisions(ax, run)
        _mark_divergence(ax, run)

    ylabel = "distance to wall (mm)"
    draw(axes[0], slice(None), zoom=False)
    _finish(axes[0], f"Rod tip, commanded vs actual: distance to wall '{name}' along its normal", run, ylabel)
    if collision is not None:
        start, end = collision
        pad = max(0.3 * (end - start), 2.0 * delay, 5.0 * run.scenario.simulation.period)
        lo, hi = start - pad - delay, end + pad
        window = slice(int(np.searchsorted(time, lo)), int(np.searchsorted(time, hi, side="right")))
        ax = axes[1]
        draw(ax, window, zoom=True)
        ax.set_xlim(lo, hi)
        shown = [s[window] for s in (commanded, actual) if s is not None]
        if shown and all(s.size for s in shown):
            bottom = min(float(s.min()) for s in shown) * 1e3
            top = max(float(s.max()) for s in shown) * 1e3
            margin = 0.1 * max(top - bottom, 1e-6)
            ax.set_ylim(bottom - margin, top + margin)
        _finish(ax, "First collision (zoom)", run, ylabel)
        ax.set_title("First collision (zoom); dotted: the command shifted by the robot delay", fontsize=11)
    return figure


def _friction_parts(frame: pd.DataFrame) -> np.ndarray | None:
    """The tangential (friction) part of the contact force, rows of (x, y, z), N; None when the
    table has no ``friction_force`` columns."""
    return _vectors(frame, "friction_force")


def tangential_force(run: RunData, frame: pd.DataFrame, tip_column: str) -> np.ndarray | None:
    """The tangential (friction) part of ``frame``'s contact force, rows of (x, y, z), N: its
    ``friction_force`` columns, or without them the force less its projection on the normals
    of the walls the tip (``tip_column``) is inside of (exact on one wall; in a corner a
    wall's friction along another wall's normal counts as normal). None without the force."""
    recorded = _friction_parts(frame)
    force = _vectors(frame, "contact_force")
    if recorded is not None or force is None:
        return recorded
    tip = _vectors(frame, tip_column)
    if tip is None or not len(tip):
        return np.zeros_like(force)
    frames = _frames(run, points=[tip])
    normals = np.asarray(frames["normals"])  # walls x 3
    inside = np.asarray(frames["distances"][0]) < 0.0  # walls x rows
    tangential = force.copy()
    for pattern in {tuple(column) for column in inside.T if column.any()}:
        rows = (inside.T == np.asarray(pattern)).all(axis=1)
        basis = normals[np.asarray(pattern)].T  # 3 x active walls
        coefficients, *_ = np.linalg.lstsq(basis, force[rows].T, rcond=None)
        tangential[rows] = force[rows] - (basis @ coefficients).T
    tangential[~inside.any(axis=0)] = 0.0
    return tangential


def has_friction(run: RunData) -> bool:
    """Whether the run's contact has friction: a friction coefficient in the scenario, or a
    non-zero friction force in the reference."""
    friction = getattr(getattr(run.scenario, "contact", None), "friction", None)
    coefficients = [getattr(friction, name, 0.0) or 0.0 for name in ("kinetic", "static",
                                                                      "kinetic_coefficient", "static_coefficient")]
    parts = _friction_parts(run.reference)
    return any(c > 0 for c in coefficients) or (parts is not None and _peak(parts.ravel()) > 0.0)


def shows_episodes(run: RunData) -> bool:
    """Whether a run gets the episode figures (contact_points, contact_normal_tangential): it
    has a HIL or reference collision, and its motion is not 1-D or its contact has friction."""
    collided = bool(run.metrics.get("collisions") or run.metrics.get("reference_collisions"))
    return collided and (not moves_in_1d(run) or has_friction(run))


def _episode_samples(time: np.ndarray, collisions: list[dict[str, Any]]) -> list[tuple[int, np.ndarray]]:
    """(collision number, mask of the samples in it) per collision with a start."""
    out = []
    end_of_run = float(time[-1]) if time.size else 0.0
    for c in collisions:
        start = c.get("start")
        if start is None:
            continue
        end = c.get("end")
        end = end_of_run if end is None else float(end)
        out.append((int(c.get("index", len(out) + 1)), (time >= float(start)) & (time <= end)))
    return out


#: The projections of the contact points figure: (horizontal, vertical, dropped) axes of `t`.
_PROJECTIONS = ((0, 1, 2), (0, 2, 1), (1, 2, 0))


def contact_points_figure(run: RunData) -> Figure:
    """Where the hardware touched, per episode: the rod tip while in contact (HIL: the actual,
    robot tip, dots in the episode's colour; reference: the ideal tip, crosses in the colour of
    the HIL episode matched to it, grey when lost), in the x–y, x–z and y–z projections of
    ``t`` (mm), over the walls' outlines (each wall's plane cut at the contact points' mean
    depth along the dropped axis)."""
    figure = Figure(figsize=(13.0, 4.8))
    FigureCanvasAgg(figure)
    axes = [figure.add_subplot(1, 3, i + 1) for i in range(3)]
    _margins(figure, left=0.75, right=2.3, top=0.95, bottom=0.55, wspace=0.35)
    ts, ref = run.timeseries, run.reference
    hil_tip, ref_tip = _vectors(ts, "actual_tip_position"), _vectors(ref, "tip_position")
    hil_eps = _episode_samples(ts["time"].to_numpy(), run.metrics.get("collisions") or [])
    ref_eps = _episode_samples(ref["time"].to_numpy(), run.metrics.get("reference_collisions") or [])
    partner = {c.get("reference"): c.get("index") for c in run.metrics.get("collisions") or []
               if c.get("reference") is not None}
    colours = [f"C{i}" for i in range(10)]
    drawn: list[np.ndarray] = []
    for a, b, _ in _PROJECTIONS:
        ax = axes[_PROJECTIONS.index((a, b, _))]
        if hil_tip is not None:
            for number, mask in hil_eps:
                points = hil_tip[mask] * 1e3
                if points.size:
                    ax.plot(points[:, a], points[:, b], ".", ms=3, color=colours[(number - 1) % 10],
                            label=f"HIL #{number} (robot tip)" if a == 0 and b == 1 else None)
                    drawn.append(points)
        if ref_tip is not None:
            for number, mask in ref_eps:
                points = ref_tip[mask] * 1e3
                if points.size:
                    hil = partner.get(number)
                    colour = "0.5" if hil is None else colours[(int(hil) - 1) % 10]
                    label = f"reference #{number}" + (" (lost)" if hil is None else "")
                    ax.plot(points[:, a], points[:, b], "x", ms=4, mew=0.8, color=colour,
                            label=label if a == 0 and b == 1 else None)
                    drawn.append(points)
    names = "xyz"
    if drawn:
        every = np.vstack(drawn)
        every = every[np.isfinite(every).all(axis=1)]
    else:
        every = np.zeros((0, 3))
    depths = _wall_depths(run, every)
    for ax, (a, b, c) in zip(axes, _PROJECTIONS):
        # the same scale on both axes (a square panel), the points in the middle
        lo, hi = (every.min(axis=0), every.max(axis=0)) if len(every) else (np.zeros(3), np.zeros(3))
        half = 0.5 * max(hi[a] - lo[a], hi[b] - lo[b]) * 1.4 + 2.0
        mid_a, mid_b = 0.5 * (lo[a] + hi[a]), 0.5 * (lo[b] + hi[b])
        ax.set_xlim(mid_a - half, mid_a + half)
        ax.set_ylim(mid_b - half, mid_b + half)
        ax.set_aspect("equal", adjustable="box")
        _draw_walls(ax, run, a, b, c, depths, first=(a, b) == (0, 1))
        ax.set_xlabel(f"{names[a]} (mm)")
        ax.set_ylabel(f"{names[b]} (mm)")
        ax.set_title(f"{names[a]}–{names[b]} projection", fontsize=10)
        ax.grid(True, alpha=0.4)
    figure.suptitle(f"Where the hardware touched: rod tip in contact, per episode (t frame; each wall cut "
                    f"through its contact points)\n{_header(run)}", fontsize=11)
    handles, labels = axes[0].get_legend_handles_labels()
    if handles:
        axes[2].legend(handles, labels, loc="upper left", bbox_to_anchor=(1.03, 1.0), fontsize=8, frameon=False)
    return figure


_WALL_STYLES = ("-", "--", "-.", ":")


def _walls(run: RunData) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(name, point in mm, unit normal) of each of the scenario's walls."""
    out = []
    for i, wall in enumerate(getattr(run.scenario, "walls", None) or []):
        normal = np.asarray(wall.normal, dtype=np.float64)
        norm = float(np.linalg.norm(normal))
        if norm > 0.0:
            name = getattr(wall, "name", None) or f"walls[{i}]"
            out.append((name, np.asarray(wall.point, dtype=np.float64) * 1e3, normal / norm))
    return out


def _wall_depths(run: RunData, points: np.ndarray) -> list[np.ndarray]:
    """Per wall, the point (mm) its outlines are cut through: the mean of the contact points
    nearest to it (of all of them when none is), else the wall's own point."""
    walls = _walls(run)
    if not len(points) or not walls:
        return [point for _, point, _ in walls]
    distance = np.abs(np.stack([(points - point) @ n for _, point, n in walls]))  # walls x points
    nearest = distance.argmin(axis=0)
    return [points[nearest == i].mean(axis=0) if (nearest == i).any() else points.mean(axis=0)
            for i in range(len(walls))]


def _draw_walls(ax: Axes, run: RunData, a: int, b: int, c: int, depths: list[np.ndarray], first: bool) -> None:
    """Each wall's outline in the a–b projection: its plane cut at ``c`` = its depth (the
    ``c`` of ``depths``, mm); a wall parallel to the projection is not drawn."""
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    for i, ((name, point, n), depth) in enumerate(zip(_walls(run), depths)):
        rest = n[c] * (depth[c] - point[c])
        if abs(n[b]) >= abs(n[a]) and abs(n[b]) > 1e-9:
            xs = np.array([x0, x1])
            ys = point[b] - (n[a] * (xs - point[a]) + rest) / n[b]
        elif abs(n[a]) > 1e-9:
            ys = np.array([y0, y1])
            xs = point[a] - (n[b] * (ys - point[b]) + rest) / n[a]
        else:
            continue
        ax.plot(xs, ys, color="0.3", lw=1.2, ls=_WALL_STYLES[i % len(_WALL_STYLES)], zorder=0,
                label=f"wall '{name}'" if first else None)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)


def normal_tangential_figure(run: RunData) -> Figure:
    """The normal part ``|F − F_t|`` of the physical contact force (top) and its tangential,
    friction part ``|F_t|`` (bottom), N, HIL solid vs reference dashed, collisions shaded."""
    figure, (ax_n, ax_t) = _figure(rows=2)
    ax_t.sharex(ax_n)
    for frame, label, style in ((run.timeseries, "HIL", {"color": "tab:blue", "lw": 1.4}),
                                (run.reference, "ideal reference", {"color": "black", "lw": 1.2, "ls": "--"})):
        force = _vectors(frame, "contact_force")
        if force is None:
            continue
        tip_column = "actual_tip_position" if frame is run.timeseries else "tip_position"
        tangential = tangential_force(run, frame, tip_column)
        if tangential is None:
            tangential = np.zeros_like(force)
        time = frame["time"].to_numpy()
        _plot(ax_n, time, np.linalg.norm(force - tangential, axis=1), label=f"|F_n| {label}", **style)
        _plot(ax_t, time, np.linalg.norm(tangential, axis=1), label=f"|F_t| {label}", **style)
    _finish_stacked(
        run, (ax_n, "Contact force: normal part |F − F_t|", "normal force (N)"),
        (ax_t, "Tangential (friction) part |F_t|", "tangential force (N)"),
    )
    return figure


def make_figures(run: RunData) -> dict[str, Figure]:
    """All figures of a run, by file stem: contact_velocity, contact_force, energy, then
    identification (when the compensator estimates the contact), contact_rotation and
    tip_tracking when the motion is not 1-D, and contact_points and
    contact_normal_tangential when :func:`shows_episodes`."""
    figures = {
        "contact_velocity": velocity_figure(run),
        "contact_force": force_figure(run),
        "energy": energy_figure(run),
    }
    if "stiffness_estimate" in run.timeseries or "damping_estimate" in run.timeseries:
        figures["identification"] = identification_figure(run)
    if not moves_in_1d(run):
        figures["contact_rotation"] = rotation_figure(run)
        figures["tip_tracking"] = tracking_figure(run)
    if shows_episodes(run):
        figures["contact_points"] = contact_points_figure(run)
        figures["contact_normal_tangential"] = normal_tangential_figure(run)
    return figures


# --------------------------------------------------------------------------------------
# Comparison figures
# --------------------------------------------------------------------------------------

_KIND_COLORS = {kind: info.colour for kind, info in COMPENSATORS.items()}
_EXTRA_COLORS = ("tab:pink", "tab:olive", "tab:cyan", "tab:gray")


def _kind_color(kind: str, index: int) -> str:
    return _KIND_COLORS.get(kind, _EXTRA_COLORS[index % len(_EXTRA_COLORS)])


def _comparison_header(runs: Mapping[str, RunData]) -> str:
    run = next(iter(runs.values()))
    f = run.scenario.facility
    return f"{run.scenario.name} | robot delay {f.robot_delay * 1e3:g} ms, sensor delay {f.sensor_delay * 1e3:g} ms"


#: Height of one line of a figure title (12 pt) and of a panel title (11 pt), inches.
_SUPTITLE_LINE = 0.22
_PANEL_TITLE = 0.34


def _suptitle(figure: Figure, text: str) -> None:
    """The figure's title, its top 0.1 in below the figure's top (its lines fit the margin
    :func:`_top_margin` leaves)."""
    height = figure.get_size_inches()[1]
    title = figure.suptitle(text, fontsize=12, y=1.0 - 0.1 / height, va="top")
    # a narrow figure (one panel) gets a smaller font rather than a title wider than itself
    width = title.get_window_extent(figure.canvas.get_renderer()).width
    room = 0.92 * figure.get_size_inches()[0] * figure.dpi
    if width > room:
        title.set_fontsize(max(12.0 * room / width, 7.0))


def _top_margin(title_lines: int) -> float:
    """Top margin (in) that holds a figure title of ``title_lines`` lines above the first
    row's panel titles, without overlap."""
    return 0.1 + _SUPTITLE_LINE * title_lines + 0.12 + _PANEL_TITLE


def _grid(count: int, rows_per_panel: int = 1, title_lines: int = 2,
          height_ratios: list[float] | None = None, between: float = 0.55) -> tuple[Figure, list[list[Axes]]]:
    """A figure with ``count`` panels (at most 3 per row), each ``rows_per_panel`` axes tall
    (relative heights ``height_ratios``); the same row of every panel shares x and y. The top
    margin holds a title of ``title_lines`` lines and the panel titles, the space between
    panel rows (``between``, in) a panel title, or with tick labels above it 0.9 in (nothing
    overlaps at any count). Returns the axes per panel."""
    columns = min(3, max(count, 1))
    panel_rows = math.ceil(count / columns)
    rows = panel_rows * rows_per_panel
    ratios = list(height_ratios or [1.0] * rows_per_panel) * panel_rows
    axis_height, inside = 2.7, 0.45  # inches: an axis, the space between the axes of a panel
    top, bottom = _top_margin(title_lines), 0.5
    heights: list[float] = []
    for r in range(rows):
        heights.append(axis_height * ratios[r])
        if r < rows - 1:
            heights.append(between if (r + 1) % rows_per_panel == 0 else inside)
    height = top + bottom + sum(heights)
    width = 5.0 * columns + 0.6
    figure = Figure(figsize=(width, height))
    FigureCanvasAgg(figure)
    spec = figure.add_gridspec(len(heights), columns, height_ratios=heights, hspace=0.0, wspace=0.14,
                               left=0.75 / width, right=1.0 - 0.2 / width, top=1.0 - top / height,
                               bottom=bottom / height)
    grid = [[figure.add_subplot(spec[2 * r, c]) for c in range(columns)] for r in range(rows)]
    for r in range(rows_per_panel):  # share x and y between the same row of every panel
        first = grid[r][0]
        for pr in range(panel_rows):
            for c in range(columns):
                ax = grid[pr * rows_per_panel + r][c]
                if ax is not first:
                    ax.sharex(first)
                    ax.sharey(first)
    panels = []
    for i in range(panel_rows * columns):
        pr, c = divmod(i, columns)
        axes = [grid[pr * rows_per_panel + r][c] for r in range(rows_per_panel)]
        if i < count:
            panels.append(axes)
        else:
            for ax in axes:
                ax.set_visible(False)
    return figure, panels


def _tidy_labels(panels: list[list[Axes]], every_row: tuple[int, ...] = ()) -> None:
    """Shared axes: time tick labels and label only under the lowest panel of each column
    (and under every panel for the rows in ``every_row``, e.g. a zoom row with its own time
    window), the y label only on the first column."""
    columns = min(3, max(len(panels), 1))
    for i, axes in enumerate(panels):
        lowest = i + columns >= len(panels)
        for r, ax in enumerate(axes):
            bottom = lowest and r == len(axes) - 1
            ax.tick_params(axis="x", labelbottom=bottom or r in every_row)
            if not bottom:
                ax.set_xlabel("")
            if i % columns:
                ax.set_ylabel("")


def _clip_to_ok_runs(
    panels: list[list[Axes]], runs: Mapping[str, RunData], ranges: list[tuple[float, float]], row: int = 0
) -> None:
    """Share y limits fitted to the runs that stayed ok (and their references) when a diverged
    run would otherwise flatten every panel; its panel's title then says it is clipped."""
    ok = [r for (kind, run), r in zip(runs.items(), ranges) if run.status in _RAN_THROUGH and math.isfinite(r[0])]
    if not ok:
        return
    lo, hi = min(r[0] for r in ok), max(r[1] for r in ok)
    span = max(hi - lo, 1e-12)
    allover = [r for r in ranges if math.isfinite(r[0])]
    full_lo, full_hi = min(r[0] for r in allover), max(r[1] for r in allover)
    if full_hi - full_lo <= 2.0 * span:
        return  # nothing far outside: let matplotlib fit everything
    pad = 0.1 * span
    panels[0][row].set_ylim(lo - pad, hi + pad)
    for axes, r in zip(panels, ranges):
        if math.isfinite(r[0]) and (r[0] < lo - pad or r[1] > hi + pad):
            ax = axes[row]
            ax.set_title(ax.get_title() + " (clipped)")


def _series_range(*series: np.ndarray | None) -> tuple[float, float]:
    values = [s[np.isfinite(s)] for s in series if s is not None]
    values = [v for v in values if v.size]
    if not values:
        return (math.nan, math.nan)
    return (float(min(v.min() for v in values)), float(max(v.max() for v in values)))


def _panel_title(kind: str, run: RunData) -> str:
    """A comparison panel's title: the compensator and its verdict (``ok``, ``OK FROM #3``,
    ``UNFAITHFUL``, ``DIVERGED at 1.23 s``)."""
    if run.status == "ok":
        return f"{kind}: ok"
    if run.status == "unfaithful":
        from .verdict import _judge

        start = _judge(run)[0]  # type: ignore[arg-type]
        return f"{kind}: OK FROM #{start}" if start is not None else f"{kind}: UNFAITHFUL"
    at = run.metrics.get("diverged_at")
    when = f" at {at:.2f} s" if isinstance(at, (int, float)) else ""
    return f"{kind}: {run.status.upper()}{when}"


def zoom_window(runs: Mapping[str, RunData]) -> tuple[float, float, int] | None:
    """The time window (s) of the comparison figures' zoom and the collision it shows: the
    ideal reference's second collision (its first when it has one only), widened by half its
    length and by the robot delay, so that the delayed HIL response shows. None without a
    reference collision."""
    run = next(iter(runs.values()))
    collisions = [c for c in run.metrics.get("reference_collisions") or [] if c.get("start") is not None]
    if not collisions:
        return None
    chosen = collisions[1] if len(collisions) > 1 else collisions[0]
    start = float(chosen["start"])
    end = float(chosen["end"]) if chosen.get("end") is not None else start + 0.2
    delay = max(r.scenario.facility.robot_delay for r in runs.values())
    pad = max(0.5 * (end - start), 2.0 * delay, 0.02)
    return start - pad - delay, end + pad + delay, int(chosen.get("index") or collisions.index(chosen) + 1)


def _in_window(time: np.ndarray, window: tuple[float, float]) -> slice:
    return slice(int(np.searchsorted(time, window[0])), int(np.searchsorted(time, window[1], side="right")))


def _time_panels(
    runs: Mapping[str, RunData],
    title: str,
    ylabel: str,
    hil: Callable[[pd.DataFrame], np.ndarray | None],
    extra: Callable[[Axes, RunData], np.ndarray | None] | None = None,
) -> Figure:
    """One panel per compensator: the whole run above, a zoom on one collision below
    (:func:`zoom_window`), HIL against the ideal reference."""
    zoom = zoom_window(runs)
    figure, panels = _grid(len(runs), rows_per_panel=2 if zoom else 1, title_lines=3,
                           height_ratios=[1.0, 0.75] if zoom else None, between=0.9 if zoom else 0.55)
    ranges, zoom_ranges = [], []
    for i, ((kind, run), axes) in enumerate(zip(runs.items(), panels)):
        ax = axes[0]
        color = _kind_color(kind, i)
        values = hil(run.timeseries)
        ideal = hil(run.reference)
        if ideal is not None:
            _plot(ax, run.reference["time"], ideal, color="black", lw=1.0, ls="--", label="ideal reference")
        if values is not None:
            _plot(ax, run.timeseries["time"], values, color=color, lw=1.3, label="HIL")
        more = extra(ax, run) if extra is not None else None
        ranges.append(_series_range(values, ideal, more))
        _shade_collisions(ax, run)
        _mark_divergence(ax, run)
        ax.set_title(_panel_title(kind, run), fontsize=11, color=_STATUS_COLOURS.get(run.status, "tab:red"))
        ax.grid(True, alpha=0.4)
        ax.set_ylabel(ylabel)
        ax.set_xlabel("time (s)")
        if i == 0:
            ax.legend(loc="best", fontsize=8)
        if zoom:
            lo, hi, number = zoom
            ax.axvspan(lo, hi, color="tab:blue", alpha=0.07, lw=0)
            zx = axes[1]
            zx.set_label("zoom")  # tells the zoom axes from the whole-run ones
            t, tr = run.timeseries["time"].to_numpy(), run.reference["time"].to_numpy()
            w, wr = _in_window(t, (lo, hi)), _in_window(tr, (lo, hi))
            if ideal is not None:
                zx.plot(tr[wr], ideal[wr], color="black", lw=1.0, ls="--")
            if values is not None:
                zx.plot(t[w], values[w], color=color, lw=1.3)
            zoom_ranges.append(_series_range(None if values is None else values[w], None if ideal is None else ideal[wr]))
            _shade_collisions(zx, run)
            zx.set_xlim(lo, hi)
            zx.grid(True, alpha=0.4)
            zx.set_ylabel(ylabel)
            zx.text(0.01, 0.97, f"collision {number}", transform=zx.transAxes, va="top", fontsize=8)
            zx.set_xlabel("time (s)")
    _clip_to_ok_runs(panels, runs, ranges)
    if zoom:
        _clip_to_ok_runs(panels, runs, zoom_ranges, row=1)
    _tidy_labels(panels, every_row=(0, 1) if zoom else ())
    zoomed = f"; below: collision {zoom[2]} (shaded above)" if zoom else ""
    _suptitle(figure, f"{title}\n{_comparison_header(runs)}\nsolid: HIL, dashed: ideal reference{zoomed}")
    return figure


def compare_velocity_figure(runs: Mapping[str, RunData]) -> Figure:
    def velocity(frame: pd.DataFrame) -> np.ndarray | None:
        values = _column(frame, "tip_velocity_x")
        return None if values is None else values * 1e3

    return _time_panels(runs, "Rod-tip relative velocity along x", "velocity x (mm/s)", velocity)


def compare_force_figure(runs: Mapping[str, RunData]) -> Figure:
    return _time_panels(
        runs, "Contact force magnitude", "|contact force| (N)", lambda frame: _magnitude(frame, "contact_force")
    )


def compare_energy_figure(runs: Mapping[str, RunData]) -> Figure:
    def observed(ax: Axes, run: RunData) -> np.ndarray | None:
        if not has_values(run.timeseries, "observed_energy"):
            return None
        values = run.timeseries["observed_energy"].to_numpy()
        ax.plot(run.timeseries["time"], values, color="0.25", lw=1.0, ls=":", label="observed energy")
        ax.legend(loc="best", fontsize=8)
        return values

    return _time_panels(runs, "Energy of the virtual relative motion", "energy (J)", lambda f: _column(f, "energy"), observed)


def identifies(run: RunData) -> bool:
    """Whether the run has contact estimates (stiffness or damping) with values."""
    return has_values(run.timeseries, "stiffness_estimate") or has_values(run.timeseries, "damping_estimate")


def compare_identification_figure(runs: Mapping[str, RunData]) -> Figure | None:
    """k̂ (N/mm) and ĉ (N s/mm) against the true values, one column per compensator that
    identifies; None if none does."""
    chosen = {kind: run for kind, run in runs.items() if identifies(run)}
    if not chosen:
        return None
    figure, panels = _grid(len(chosen), rows_per_panel=2, title_lines=3)
    index = {kind: i for i, kind in enumerate(runs)}
    for (kind, run), (ax_k, ax_c) in zip(chosen.items(), panels):
        ts, contact = run.timeseries, run.scenario.contact
        color = _kind_color(kind, index[kind])
        if "stiffness_estimate" in ts:
            ax_k.plot(ts["time"], ts["stiffness_estimate"] * 1e-3, color=color, lw=1.3, label="k̂")
        ax_k.axhline(contact.stiffness * 1e-3, color="black", lw=1.0, ls="--", label="true k")
        if "damping_estimate" in ts:
            ax_c.plot(ts["time"], ts["damping_estimate"] * 1e-3, color=color, lw=1.3, label="ĉ")
        ax_c.axhline(contact.damping * 1e-3, color="black", lw=1.0, ls="--", label="true c")
        for ax in (ax_k, ax_c):
            _shade_collisions(ax, run)
            _mark_divergence(ax, run)
            ax.grid(True, alpha=0.4)
            ax.legend(loc="best", fontsize=8)
        ax_k.set_title(_panel_title(kind, run), fontsize=11, color=_STATUS_COLOURS.get(run.status, "tab:red"))
        ax_k.set_ylabel("stiffness (N/mm)")
        ax_c.set_ylabel("damping (N·s/mm)")
        ax_c.set_xlabel("time (s)")
    # shared y limits that show the convergence: the estimates after each run's first
    # collision and the true values, not the initial guess
    for row, column, true, scale in ((0, "stiffness_estimate", "stiffness", 1e-3), (1, "damping_estimate", "damping", 1e-3)):
        limits = [converged_range(run, column, getattr(run.scenario.contact, true)) for run in chosen.values()]
        limits = [lim for lim in limits if lim is not None]
        if limits:
            lo, hi = min(lim[0] for lim in limits) * scale, max(lim[1] for lim in limits) * scale
            panels[0][row].set_ylim(lo, hi)
    _tidy_labels(panels)
    run = next(iter(runs.values()))
    _suptitle(
        figure,
        f"Identified contact stiffness and damping\n{run.scenario.name} | robot delay "
        f"{run.scenario.facility.robot_delay * 1e3:g} ms | dashed: true value\naxes fitted to the estimates "
        "after the first collision",
    )
    return figure


def converged_range(run: RunData, column: str, true: float) -> tuple[float, float] | None:
    """y limits (SI units) for an estimate ``column`` that show its convergence: the 0.5 and
    99.5 percentiles of its values after the run's first HIL collision, and the true value,
    widened by 10 % of their span (at least 2 % of the true value). None without such values."""
    ts = run.timeseries
    first = _first_collision(run)
    if column not in ts or first is None:
        return None
    values = ts[column].to_numpy(dtype=np.float64)[ts["time"].to_numpy() > first[1]]
    values = values[np.isfinite(values)]
    if not values.size:
        return None
    lo, hi = np.percentile(values, [0.5, 99.5])
    lo, hi = min(float(lo), true), max(float(hi), true)
    pad = max(0.1 * (hi - lo), 0.02 * abs(true), 1e-12)
    return lo - pad, hi + pad


def _finite_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _collision_count(runs: Mapping[str, RunData], keys: tuple[str, ...]) -> int:
    """Collisions up to the last one with a value for one of ``keys`` (later ones have no
    ideal counterpart); at least 1."""
    return max(
        (
            i + 1
            for run in runs.values()
            for i, c in enumerate(run.metrics.get("collisions") or [])
            if any(_finite_number(c.get(key)) for key in keys)
        ),
        default=1,
    )


def _collision_bars(
    ax: Axes, runs: Mapping[str, RunData], key: str, label: str, count: int, line: float | None, scale: float = 1.0,
    tolerances: tuple[float, ...] = (),
) -> None:
    """Grouped bars of ``metrics["collisions"][i][key] * scale`` per collision, one colour per
    compensator, a dashed line at ``line`` and dotted red lines at ``tolerances`` (the
    scenario's limits). When a diverged run's bars dwarf the others, the axis is cut and those
    bars are labelled with their value."""
    kinds = list(runs)
    numbers = np.arange(1, count + 1)
    width = 0.8 / max(len(kinds), 1)
    values = {}
    for kind, run in runs.items():
        row = np.full(count, np.nan)
        for i, c in enumerate((run.metrics.get("collisions") or [])[:count]):
            if _finite_number(c.get(key)):
                row[i] = float(c[key]) * scale
        values[kind] = row
    ok_values = [v for kind, v in values.items() if runs[kind].status in _RAN_THROUGH]
    finite_ok = np.concatenate([v[np.isfinite(v)] for v in ok_values]) if ok_values else np.array([])
    finite_all = np.concatenate([v[np.isfinite(v)] for v in values.values()]) if values else np.array([])
    top = float(finite_all.max()) if finite_all.size else 1.0
    floor = 1.0 if line is None else line
    cap = None
    if finite_ok.size and top > 2.0 * max(float(finite_ok.max()), floor):
        cap = max(1.5 * floor, 1.25 * float(finite_ok.max()))
    for i, kind in enumerate(kinds):
        heights = values[kind]
        x = numbers - 0.4 + width * (i + 0.5)
        shown = heights if cap is None else np.minimum(heights, cap)
        ax.bar(x, shown, width=width * 0.95, color=_kind_color(kind, i), label=kind)
        if cap is not None:
            for xi, h in zip(x, heights):
                if np.isfinite(h) and h > cap:
                    ax.text(xi, cap, f"{h:.2f}", ha="center", va="bottom", fontsize=7, rotation=90)
    if line is not None:
        ax.axhline(line, color="black", lw=1.0, ls="--")
    for limit in tolerances:
        ax.axhline(limit, color="tab:red", lw=1.2, ls=":")
    if tolerances:  # the highest limit named at the right (a band's two lines are too close for two)
        ax.annotate(f"{max(tolerances):g}", (1.0, max(tolerances)), xycoords=("axes fraction", "data"),
                    xytext=(3, 3), textcoords="offset points", va="bottom", fontsize=8, color="tab:red")
    if cap is not None:
        ax.set_ylim(0.0, cap * 1.15)
        label += " (cut; bars above labelled)"
    ax.set_ylabel(label)
    ax.grid(True, axis="y", alpha=0.4)


def _bars_figure(
    runs: Mapping[str, RunData], rows: list[tuple[str, str, float | None, float, tuple[float, ...]]], title: str,
    height: float = 7.0,
) -> Figure:
    """One axis of grouped bars per ``(key, label, line, scale, tolerances)``, collisions across;
    ``height`` in inches."""
    figure = Figure(figsize=(11.0, height))
    FigureCanvasAgg(figure)
    axes = figure.subplots(len(rows), 1, sharex=True, squeeze=False)[:, 0]
    _margins(figure, left=0.8, right=1.9, top=_top_margin(2) - _PANEL_TITLE, bottom=0.55, hspace=0.08)
    count = _collision_count(runs, tuple(row[0] for row in rows))
    for ax, (key, label, line, scale, tolerances) in zip(axes, rows):
        _collision_bars(ax, runs, key, label, count, line, scale, tolerances)
    axes[0].legend(loc="upper left", bbox_to_anchor=(1.03, 1.0), fontsize=9, frameon=False, title="compensator")
    axes[-1].set_xlabel("collision")
    axes[-1].set_xticks(np.arange(1, count + 1))
    run = next(iter(runs.values())) if runs else None
    if run is not None:
        _suptitle(figure, f"{title}\n{run.scenario.name} | robot delay {run.scenario.facility.robot_delay * 1e3:g} ms")
    return figure


def compare_cov_cof_figure(runs: Mapping[str, RunData]) -> Figure:
    """Grouped bars of CoV and CoF per collision, one colour per compensator, a line at 1.
    When a diverged run's bars dwarf the others, the axis is cut and those bars are
    labelled with their value."""
    tol = next(iter(runs.values())).scenario.metrics
    return _bars_figure(
        runs,
        [("cov", "CoV", 1.0, 1.0, (1.0 - tol.cov_tolerance, 1.0 + tol.cov_tolerance)),
         ("cof", "CoF", 1.0, 1.0, (tol.max_cof,))],
        f"CoV and CoF per collision (1 = ideal; dotted red: the tolerances |CoV − 1| ≤ {tol.cov_tolerance:g}, "
        f"CoF ≤ {tol.max_cof:g})",
    )


def compare_velocity_error_figure(runs: Mapping[str, RunData]) -> Figure:
    """Grouped bars of the rebound velocity error and angular velocity error per collision
    (%), one colour per compensator; a dashed line at the scenario's velocity tolerance. With
    friction (:func:`has_friction`) also the rebound direction error (degrees) and the
    tangential impulse error (%, dashed: its tolerance)."""
    run = next(iter(runs.values()))
    tolerance = 100.0 * float(run.scenario.metrics.max_velocity_error)
    rows: list[tuple[str, str, float | None, float, tuple[float, ...]]] = [
        ("velocity_error", "velocity error (%)", tolerance, 100.0, ()),
        ("angular_velocity_error", "angular velocity error (%)", None, 100.0, ()),
    ]
    title = ("Rebound velocity errors per collision: |v − v_ref|/|v_ref|, |ω − ω_ref|/|ω_ref| "
             f"(0 = ideal; dashed: tolerance {tolerance:g} %)")
    if any(has_friction(r) for r in runs.values()):
        impulse = 100.0 * float(run.scenario.metrics.max_tangential_impulse_error)
        rows += [
            ("direction_error", "direction error (°)", None, 1.0, ()),
            ("tangential_impulse_error", "J_t error (%)", impulse, 100.0, ()),
        ]
        title = ("Rebound velocity, angular velocity and direction errors, tangential impulse error per "
                 f"collision (0 = ideal; dashed: tolerances {tolerance:g} %, {impulse:g} %)")
    return _bars_figure(runs, rows, title, height=3.5 * len(rows))


def compare_measured_applied_figure(runs: Mapping[str, RunData]) -> Figure | None:
    """The paper's Figs. 16 and 18: per compensator, the measured force (the sensor's, delayed
    and noisy) against the force the compensator applied to the virtual dynamics, and the
    ideal reference's contact force, |F| (N), zoomed on one collision (:func:`zoom_window`):
    `pida`'s applied force leads the measured one. None without a reference collision."""
    zoom = zoom_window(runs)
    if zoom is None:
        return None
    lo, hi, number = zoom
    figure, panels = _grid(len(runs), title_lines=3)
    ranges = []
    for i, ((kind, run), (ax,)) in enumerate(zip(runs.items(), panels)):
        ts, ref = run.timeseries, run.reference
        t, tr = ts["time"].to_numpy(), ref["time"].to_numpy()
        w, wr = _in_window(t, (lo, hi)), _in_window(tr, (lo, hi))
        measured, applied = _magnitude(ts, "measured_force"), _magnitude(ts, "applied_force")
        ideal = _magnitude(ref, "contact_force")
        if ideal is not None:
            ax.plot(tr[wr], ideal[wr], color="black", lw=1.0, ls="--", label="ideal reference")
        if measured is not None:
            ax.plot(t[w], measured[w], color="0.45", lw=1.1, label="measured")
        if applied is not None:
            ax.plot(t[w], applied[w], color=_kind_color(kind, i), lw=1.5, label="applied (compensated)")
        ranges.append(_series_range(*(None if v is None else v[w] for v in (measured, applied)),
                                    None if ideal is None else ideal[wr]))
        _shade_collisions(ax, run)
        ax.set_xlim(lo, hi)
        ax.set_title(_panel_title(kind, run), fontsize=11, color=_STATUS_COLOURS.get(run.status, "tab:red"))
        ax.grid(True, alpha=0.4)
        ax.set_ylabel("|force| (N)")
        ax.set_xlabel("time (s)")
        if i == 0:
            ax.legend(loc="best", fontsize=8)
    _clip_to_ok_runs(panels, runs, ranges)
    _tidy_labels(panels, every_row=(0,))
    _suptitle(figure, f"Measured and applied force, collision {number} (the paper's Figs. 16, 18)\n"
                      f"{_comparison_header(runs)}\nmeasured: the sensor's; applied: given to the virtual "
                      "dynamics; dashed: ideal reference")
    return figure


def comparison_figure_makers(runs: Mapping[str, RunData]) -> dict[str, Callable[[], Figure | None]]:
    """Each comparison figure's maker by file stem (a maker may return None: no such figure
    for these runs)."""
    makers: dict[str, Callable[[], Figure | None]] = {
        "compare_velocity": lambda: compare_velocity_figure(runs),
        "compare_force": lambda: compare_force_figure(runs),
        "compare_energy": lambda: compare_energy_figure(runs),
        "compare_identification": lambda: compare_identification_figure(runs),
        "compare_cov_cof": lambda: compare_cov_cof_figure(runs),
        "compare_measured_applied": lambda: compare_measured_applied_figure(runs),
    }
    if not all(moves_in_1d(run) for run in runs.values()):
        makers["compare_velocity_error"] = lambda: compare_velocity_error_figure(runs)
    return makers


def comparison_figures(runs: Mapping[str, RunData]) -> dict[str, Figure]:
    """The comparison figures by file stem (compare_identification only if a compensator
    identifies the contact, compare_velocity_error only if the motion is not 1-D)."""
    figures = {name: make() for name, make in comparison_figure_makers(runs).items()}
    return {name: figure for name, figure in figures.items() if figure is not None}


def draw_in_two_processes(makers: Mapping[str, Callable[[], Figure | None]], directory: str | os.PathLike[str],
                          dpi: int) -> list[str]:
    """Make and save the figures (``<name>.png`` in ``directory``), half of them in a forked
    child process when the machine has two cores or more (:func:`hilcontact.processes.in_two_processes`):
    drawing is most of a comparison's time and matplotlib draws on one core. A figure is never
    lost to a failing child. Returns the names saved, in the makers' order."""
    folder = Path(directory)
    folder.mkdir(parents=True, exist_ok=True)

    def draw(subset: list[str]) -> list[str]:
        saved = []
        for name in subset:
            figure = makers[name]()
            if figure is not None:
                figure.savefig(folder / f"{name}.png", dpi=dpi)
                saved.append(name)
        return saved

    return in_two_processes(list(makers), draw, lambda name: (folder / f"{name}.png").is_file())


# --------------------------------------------------------------------------------------
# Comparisons over robot delays: (a), (b), … one panel per delay
# --------------------------------------------------------------------------------------

_PANEL_LETTERS = "abcdefghijklmnopqrstuvwxyz"


def _overlay_figure(runs_by_delay: Mapping[float, Mapping[str, RunData]], title: str, ylabel: str,
                    series: Callable[[pd.DataFrame], np.ndarray | None]) -> Figure:
    """One panel per delay, (a), (b), …: every compensator's HIL curve (its colour) over the
    ideal reference (dashed), as the paper's Figs. 9 and 11; y fitted to the runs that ran to
    the end (a diverged one leaves the panel, its end marked in the legend)."""
    count = len(runs_by_delay)
    figure = Figure(figsize=(5.5 * count + 2.4, 4.8))
    FigureCanvasAgg(figure)
    axes = figure.subplots(1, count, sharey=True, squeeze=False)[0]
    _margins(figure, left=0.8, right=2.4, top=_top_margin(2), bottom=0.55, wspace=0.08)
    ranges = []
    for letter, ax, (delay, runs) in zip(_PANEL_LETTERS, axes, runs_by_delay.items()):
        first = next(iter(runs.values()))
        ideal = series(first.reference)
        if ideal is not None:
            _plot(ax, first.reference["time"], ideal, color="black", lw=1.1, ls="--", label="ideal reference", zorder=3)
            ranges.append(_series_range(ideal))
        for i, (kind, run) in enumerate(runs.items()):
            values = series(run.timeseries)
            if values is None:
                continue
            label = kind if run.status in _RAN_THROUGH else f"{kind} ({run.status})"
            _plot(ax, run.timeseries["time"], values, color=_kind_color(kind, i), lw=1.2, label=label)
            if run.status in _RAN_THROUGH:
                ranges.append(_series_range(values))
        ax.set_title(f"({letter}) robot delay {delay * 1e3:g} ms", fontsize=11)
        ax.set_xlabel("time (s)")
        ax.grid(True, alpha=0.4)
    axes[0].set_ylabel(ylabel)
    finite = [r for r in ranges if math.isfinite(r[0])]
    if finite:
        lo, hi = min(r[0] for r in finite), max(r[1] for r in finite)
        pad = 0.1 * max(hi - lo, 1e-12)
        axes[0].set_ylim(lo - pad, hi + pad)
    axes[-1].legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=9, frameon=False, title="compensator")
    first = next(iter(next(iter(runs_by_delay.values())).values()))
    _suptitle(figure, f"{title}\n{first.scenario.name} | sensor delay {first.scenario.facility.sensor_delay * 1e3:g} ms "
                      "| dashed: ideal reference")
    return figure


def _delay_bars_figure(runs_by_delay: Mapping[float, Mapping[str, RunData]]) -> Figure:
    """CoV (top) and CoF (bottom) per collision, grouped by compensator, one column per
    delay, (a), (b), …, with the tolerance lines."""
    count = len(runs_by_delay)
    figure = Figure(figsize=(5.5 * count + 2.4, 7.0))
    FigureCanvasAgg(figure)
    axes = figure.subplots(2, count, sharex="col", squeeze=False)  # own y per panel: each may be cut
    _margins(figure, left=0.8, right=2.4, top=_top_margin(2), bottom=0.55, hspace=0.08, wspace=0.15)
    tol = next(iter(next(iter(runs_by_delay.values())).values())).scenario.metrics
    for column, (letter, (delay, runs)) in enumerate(zip(_PANEL_LETTERS, runs_by_delay.items())):
        collisions = _collision_count(runs, ("cov", "cof"))
        _collision_bars(axes[0][column], runs, "cov", "CoV", collisions, 1.0, 1.0,
                        (1.0 - tol.cov_tolerance, 1.0 + tol.cov_tolerance))
        _collision_bars(axes[1][column], runs, "cof", "CoF", collisions, 1.0, 1.0, (tol.max_cof,))
        axes[0][column].set_title(f"({letter}) robot delay {delay * 1e3:g} ms", fontsize=11)
        axes[1][column].set_xlabel("collision")
        axes[1][column].set_xticks(np.arange(1, collisions + 1))
        if column:
            axes[0][column].set_ylabel("")
            axes[1][column].set_ylabel("")
    axes[0][-1].legend(*axes[0][0].get_legend_handles_labels(), loc="upper left", bbox_to_anchor=(1.02, 1.0),
                       fontsize=9, frameon=False, title="compensator")
    first = next(iter(next(iter(runs_by_delay.values())).values()))
    _suptitle(figure, f"CoV and CoF per collision (1 = ideal; dotted red: |CoV − 1| ≤ {tol.cov_tolerance:g}, "
                      f"CoF ≤ {tol.max_cof:g})\n{first.scenario.name}")
    return figure


def delay_figures(runs_by_delay: Mapping[float, Mapping[str, RunData]]) -> dict[str, Figure]:
    """The figures of a comparison over robot delays (file stems as
    :data:`hilcontact.comparison.DELAY_FIGURES`): one panel per delay, (a), (b), …"""

    def velocity(frame: pd.DataFrame) -> np.ndarray | None:
        values = _column(frame, "tip_velocity_x")
        return None if values is None else values * 1e3

    return {
        "compare_velocity": _overlay_figure(runs_by_delay, "Rod-tip relative velocity along x", "velocity x (mm/s)",
                                            velocity),
        "compare_force": _overlay_figure(runs_by_delay, "Contact force magnitude", "|contact force| (N)",
                                         lambda frame: _magnitude(frame, "contact_force")),
        "compare_cov_cof": _delay_bars_figure(runs_by_delay),
    }
