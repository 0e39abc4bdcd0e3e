"""Running a scenario through the native core, and the results of a run."""

from __future__ import annotations


import json
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from .errors import ArgumentError, ScenarioError, describe
from .native import core as _core
from .output import write_atomically
from .scenario import Scenario, load_scenario
from .verdict import rendering_label

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "COLUMN_UNITS",
    "OPTIONAL_TIMESERIES_COLUMNS", "PLOT_FILES_EPISODES", "REFERENCE_COLUMNS", "TIMESERIES_COLUMNS", "Run",
    "RunInterrupted", "simulate"]


def _table_columns() -> dict[str, list[tuple[str, str, str]]]:
    return _core().table_columns()


#: Every table column's unit (SI), from the core: ``{"tip_velocity_x": "m/s", ...}``.
COLUMN_UNITS: dict[str, str] = {
    name: unit for columns in _table_columns().values() for name, unit, _ in columns
}

#: Columns of ``Run.timeseries`` (the HIL loop) that every run has, in this order (from the
#: core); the optional ones (:data:`OPTIONAL_TIMESERIES_COLUMNS`) follow.
TIMESERIES_COLUMNS: list[str] = [
    name for name, _, only in _table_columns()["timeseries"] if only == "always"
]

#: Columns of ``Run.timeseries`` that only some compensators produce: ``stiffness_estimate``
#: (N/m) and ``damping_estimate`` (N s/m) for those that identify the contact (pic, dac,
#: pida; NaN before the first estimate), ``observed_energy`` (J) for those with an energy
#: observer (NaN where it does not observe). Code reading a run must not assume them.
OPTIONAL_TIMESERIES_COLUMNS: list[str] = [
    name for name, _, only in _table_columns()["timeseries"] if only != "always"
]

#: Columns of ``Run.reference`` (the ideal reference: true contact law, no delay).
REFERENCE_COLUMNS: list[str] = [name for name, _, _ in _table_columns()["reference"]]

#: Files written by :meth:`Run.save` (plots excluded).
DATA_FILES = ("timeseries.parquet", "reference.parquet", "metrics.json", "scenario.toml")
#: Plot files written by :meth:`Run.save` (``identification.png`` too when estimates exist,
#: and :data:`PLOT_FILES_6DOF` when the motion is not 1-D).
PLOT_FILES = ("contact_velocity.png", "contact_force.png", "energy.png")
#: Plot files that :meth:`Run.save` adds for a run whose motion is not 1-D (the reference
#: rotates or its rod tip leaves a line: :func:`hilcontact.plots.moves_in_1d`).
PLOT_FILES_6DOF = ("contact_rotation.png", "tip_tracking.png")
#: Plot files of the contact episodes that :meth:`Run.save` adds for a run with a collision
#: whose motion is not 1-D or whose contact has friction
#: (:func:`hilcontact.plots.shows_episodes`): where the hardware touched, and the normal and
#: tangential contact force.
PLOT_FILES_EPISODES = ("contact_points.png", "contact_normal_tangential.png")


def _frame(columns: dict[str, Any], order: list[str]) -> pd.DataFrame:
    data = {name: np.asarray(values, dtype=np.float64) for name, values in columns.items()}
    names = [c for c in order if c in data] + sorted(c for c in data if c not in order)
    # the core's arrays as the columns, not copied into one block (fresh from the core's thread,
    # the copy cost a run about 0.3 ms of CPU); the same values
    return pd.DataFrame({name: data[name] for name in names}, copy=False)


class _LazyFrame:
    """A table of the core, ``columns()`` (name -> array, made by the core when called), and
    its columns' order, made into the DataFrame :func:`_frame` makes of them when the run's
    table is first read: making the two tables and their frames cost ``hc.simulate`` of
    ``paper-table1`` about 1.3 ms of CPU, spent only by code that reads them."""

    __slots__ = ("columns", "order")

    def __init__(self, columns: Callable[[], dict[str, Any]], order: list[str]) -> None:
        self.columns, self.order = columns, order

    def frame(self) -> pd.DataFrame:
        return _frame(self.columns(), self.order)


def _lazy_table(name: str) -> property:
    """The ``Run`` attribute ``name``: a DataFrame, made from a :class:`_LazyFrame` on first
    read and kept."""
    slot = f"_{name}"

    def get(self: Any) -> pd.DataFrame:
        value = self.__dict__[slot]
        if isinstance(value, _LazyFrame):
            value = self.__dict__[slot] = value.frame()
        return value

    def set(self: Any, value: Any) -> None:
        self.__dict__[slot] = value

    return property(get, set, doc=f"The run's {name} (a DataFrame; made from the core's columns when first read).")


@dataclass
class Run:
    """The result of :func:`simulate`.

    Attributes:
        scenario: the resolved scenario that was simulated.
        metrics: collisions (CoV, CoF, peak force, rebound speed), status, energy, ...
            (see ``hilcontact._core.simulate``).
        timeseries: the HIL loop, one row per control period (SI units; from a simulation, made
            into a DataFrame when first read).
        reference: the ideal reference (true contact law, no delay).
        mcap: what the run's MCAP recording wrote, when it was recorded (``simulate(...,
            mcap=FILE)``, a real-time run with the ``mcap`` option): ``path``, ``messages``,
            ``chunks``, ``bytes``, ``write_errors``, ``error``, ``complete``; else None.
    """

    scenario: Scenario
    metrics: dict[str, Any]
    timeseries: pd.DataFrame
    reference: pd.DataFrame
    mcap: dict[str, Any] | None = None

    @property
    def status(self) -> str:
        """``"ok"`` or ``"diverged"``."""
        return str(self.metrics.get("status", "unknown"))

    @property
    def compensator(self) -> str:
        return str(self.metrics.get("compensator") or self.scenario.compensator.kind)

    def collision_table(self) -> pd.DataFrame:
        """The contact episodes: one row per HIL collision (index: collision number, from 1),
        with the ideal reference's collision it is matched to (see docs/model.md, "Metrics"):
        complete, start, end (s), peak_force (N), rebound_speed (m/s), cov, cof,
        velocity_error, angular_velocity_error (fractions), impulse_ratio,
        angular_impulse_ratio, reference (the matched reference collision's number, NaN if
        none), reference_peak_force (N), reference_rebound_speed (m/s); then the episode's
        contact: normal_impulse, tangential_impulse (N s), peak_moment (N m, about the sensor
        origin), rebound_velocity_x/_y/_z (m/s, `t`), rebound_angular_velocity_x/_y/_z
        (rad/s, `t`), direction_error (degrees), normal_impulse_error,
        tangential_impulse_error (fractions), peak_moment_ratio, reference_normal_impulse,
        reference_tangential_impulse (N s), reference_peak_moment (N m),
        reference_rebound_velocity_x/_y/_z (m/s); rendering (how the compensator handled the
        collision, :func:`~hilcontact.verdict.rendering_label`: ``model``, ``pida: no
        prior``, ``pida: prior contradicted``, ``pida: law unknown``; ``-`` for a compensator
        without a model); then the errors against the collision's local (restarted) reference
        (docs/model.md, "Metrics"; read, never judged): local_start (s), local_velocity_error,
        local_cof, local_tangential_impulse_error, local_normal_impulse_error (fractions;
        NaN for real-time runs and replays). NaN where there is no value."""
        reference = {c.get("index"): c for c in self.metrics.get("reference_collisions") or []}
        numbers = [
            "start", "end", "peak_force", "rebound_speed", "cov", "cof", "velocity_error",
            "angular_velocity_error", "impulse_ratio", "angular_impulse_ratio",
        ]
        episode = ["normal_impulse", "tangential_impulse", "peak_moment"]
        vectors = ["rebound_velocity", "rebound_angular_velocity"]
        errors = ["direction_error", "normal_impulse_error", "tangential_impulse_error", "peak_moment_ratio"]
        from_reference = ["normal_impulse", "tangential_impulse", "peak_moment"]
        local = [
            "local_start", "local_velocity_error", "local_cof", "local_tangential_impulse_error",
            "local_normal_impulse_error",
        ]
        axes = ("x", "y", "z")

        def spread(name: str, value: Any) -> dict[str, Any]:
            value = value if isinstance(value, (list, tuple)) and len(value) == 3 else (None,) * 3
            return {f"{name}_{axis}": v for axis, v in zip(axes, value)}

        rows = []
        for collision in self.metrics.get("collisions") or []:
            ref = reference.get(collision.get("reference"), {})
            row = {"collision": collision.get("index"), "complete": bool(collision.get("complete", True))}
            row.update({key: collision.get(key) for key in numbers})
            row["reference"] = collision.get("reference")
            row["reference_peak_force"] = ref.get("peak_force")
            row["reference_rebound_speed"] = ref.get("rebound_speed")
            row.update({key: collision.get(key) for key in episode})
            for name in vectors:
                row.update(spread(name, collision.get(name)))
            row.update({key: collision.get(key) for key in errors})
            row.update({f"reference_{key}": ref.get(key) for key in from_reference})
            row.update(spread("reference_rebound_velocity", ref.get("rebound_velocity")))
            row["rendering"] = rendering_label(collision.get("rendering"))
            row.update({key: collision.get(key) for key in local})
            rows.append(row)
        floats = [
            *numbers, "reference", "reference_peak_force", "reference_rebound_speed",
            *episode,
            *[f"{name}_{axis}" for name in vectors for axis in axes],
            *errors,
            *[f"reference_{key}" for key in from_reference],
            *[f"reference_rebound_velocity_{axis}" for axis in axes],
        ]
        columns = ["collision", "complete", *floats, "rendering", *local]
        table = pd.DataFrame(rows, columns=columns)
        table[floats + local] = table[floats + local].astype(np.float64)
        return table.set_index("collision")

    @classmethod
    def load(cls, directory: str | os.PathLike[str]) -> Run:
        """A run from the folder :meth:`save` wrote (its data files: :data:`DATA_FILES`).
        Raises :class:`~hilcontact.errors.ScenarioError` naming the folder and the missing or
        unreadable file."""
        folder = Path(directory)
        if not folder.is_dir():
            raise ScenarioError(f"{folder}: not a folder")
        missing = [name for name in DATA_FILES if not (folder / name).is_file()]
        if missing:
            raise ScenarioError(f"{folder}: not a run folder (missing {', '.join(missing)})")
        try:
            metrics = json.loads((folder / "metrics.json").read_text(encoding="utf-8"))
            timeseries = pd.read_parquet(folder / "timeseries.parquet")
            reference = pd.read_parquet(folder / "reference.parquet")
        except (OSError, ValueError) as exc:
            raise ScenarioError(f"{folder}: unreadable run data ({' '.join(str(exc).split())})") from None
        if not isinstance(metrics, dict):
            raise ScenarioError(f"{folder / 'metrics.json'}: expected a JSON object")
        scenario = load_scenario(folder / "scenario.toml")
        return cls(scenario=scenario, metrics=metrics, timeseries=timeseries, reference=reference)

    def plot(self, directory: str | os.PathLike[str] | None = None) -> dict[str, Figure]:
        """Make the figures (name -> matplotlib Figure); save them as ``<name>.png`` in
        ``directory`` if given. Names: contact_velocity, contact_force, energy,
        identification when the compensator estimates the contact stiffness or damping,
        contact_rotation and tip_tracking when the motion is not 1-D, and contact_points and
        contact_normal_tangential (:data:`PLOT_FILES_EPISODES`) for a run with a collision
        whose motion is not 1-D or whose contact has friction."""
        from .plots import make_figures, save_figures

        figures = make_figures(self)
        if directory is not None:
            save_figures(figures, directory, dpi=120)
        return figures

    def save(self, directory: str | os.PathLike[str], plots: bool = True, overwrite: bool = False) -> Path:
        """Write the run to ``directory``, atomically.

        Files: timeseries.parquet, reference.parquet, metrics.json, scenario.toml (resolved,
        reproduces the run) and, unless ``plots=False``, the PNG figures. Everything is
        written into a temporary sibling folder which then replaces ``directory``: an
        existing folder is never half-overwritten. Only a new or empty folder, or one that
        hilcontact wrote, is replaced (``overwrite=True`` replaces any other folder; see
        :mod:`hilcontact.output`); else :class:`~hilcontact.output.OutputError`. Returns the
        folder's path.
        """
        if not isinstance(directory, (str, os.PathLike)):
            raise ArgumentError(f"directory: expected a folder path, got {describe(directory)}")
        return write_atomically(directory, lambda folder: self._write(folder, plots), "run", overwrite)

    def _write(self, folder: Path, plots: bool) -> None:
        self.timeseries.to_parquet(folder / "timeseries.parquet", engine="pyarrow", index=False)
        self.reference.to_parquet(folder / "reference.parquet", engine="pyarrow", index=False)
        (folder / "metrics.json").write_text(json.dumps(self.metrics, indent=2) + "\n", encoding="utf-8")
        (folder / "scenario.toml").write_text(self.scenario.to_toml(), encoding="utf-8")
        if plots:
            self.plot(folder)


# the tables as properties (the dataclass's __init__, replace, repr and == go through them):
# `simulate` hands them over as columns, made into DataFrames when first read
Run.timeseries = _lazy_table("timeseries")  # type: ignore[assignment]
Run.reference = _lazy_table("reference")  # type: ignore[assignment]


class RunInterrupted(KeyboardInterrupt):
    """A Ctrl-C stopped :func:`simulate`: a ``KeyboardInterrupt`` (code that stops on one
    stops on it) carrying the run so far as :attr:`run`: status ``interrupted``, its tables
    and metrics up to the tick it stopped at (``metrics["stop"]["time"]``, s), the reference
    over the same span; or the whole run (its own status) when the Ctrl-C came after its last
    tick."""

    def __init__(self, run: Run) -> None:
        super().__init__()
        #: The run so far.
        self.run = run

    @property
    def time(self) -> float:
        """Run time of the last tick run, s."""
        return float(self.run.timeseries["time"].iloc[-1]) if len(self.run.timeseries) else 0.0


def simulate(
    scenario: Scenario | str | os.PathLike[str],
    mcap: str | os.PathLike[str] | None = None,
    overwrite: bool = False,
    outputs: dict[str, Any] | None = None,
    *,
    compensator: Any = None,
    step_limit: float | None = None,
) -> Run:
    """Simulate a scenario (a :class:`Scenario`, a preset name or a TOML path).

    ``mcap``: also write the run to this MCAP file (ROS 2 messages that Foxglove, Lichtblick and
    PlotJuggler open; the channels are in docs/realtime.md, "MCAP recordings"), with the same
    recorder as a real-time run; the file is created before the run, and an existing one is
    refused (RealtimeOptionError) unless ``overwrite``. ``Run.mcap`` then says what was written.

    ``outputs``: more outputs to write the run to, each under its key with the options a
    real-time run has under that key (the outputs of ``hilcontact_rt::output::OUTPUTS``), e.g.
    ``{"mcap": {"path": "run.mcap", "chunk_interval": 1.0}}``; ``mcap`` above is the same as
    ``outputs={"mcap": {"path": mcap, "overwrite": overwrite}}``.

    ``compensator``: a compensator written in Python (``"path/file.py:Class"``,
    ``"module:Class"`` or a :class:`hilcontact.Compensator` subclass, see
    :mod:`hilcontact.plugin`) in place of the scenario's ``[compensator]`` (a scenario with
    ``compensator.kind = "python"`` names one itself); ``step_limit``: the longest one of its
    steps may take, s (default :data:`hilcontact.plugin.STEP_LIMIT`). It cannot be recorded to
    ``mcap`` or ``outputs``. A plug-in that fails raises :class:`~hilcontact.plugin.PluginError`.

    Raises ScenarioError for an invalid scenario. A diverging loop is not an error: the run's
    ``status`` is ``"diverged"`` and ``metrics["reason"]`` says why. A Ctrl-C stops the loop
    at its next tick and raises :class:`RunInterrupted` (a ``KeyboardInterrupt``) with the run
    so far (status ``"interrupted"``; recorded to ``mcap`` and ``outputs`` up to there); a
    second Ctrl-C meanwhile is a plain ``KeyboardInterrupt``.
    """
    if outputs is not None and not isinstance(outputs, Mapping):
        raise ArgumentError(f"outputs: expected a mapping output -> options, e.g. {{'mcap': {{'path': 'run.mcap'}}}}, got {describe(outputs)}")
    if mcap is not None and not isinstance(mcap, (str, os.PathLike)):
        raise ArgumentError(f"mcap: expected a file path or None, got {describe(mcap)}")
    if not isinstance(overwrite, bool):
        raise ArgumentError(f"overwrite: expected True or False, got {describe(overwrite)}")
    if not isinstance(scenario, Scenario):
        scenario = load_scenario(scenario)
    if compensator is None:
        compensator = scenario.python_entry
    if scenario.facility.kind == "mujoco":
        if compensator is not None or mcap is not None or outputs:
            raise ScenarioError("facility.kind: a run on the mujoco facility cannot be recorded or use a Python compensator yet")
        return _simulate_mujoco(scenario)
    if compensator is not None:
        if mcap is not None or outputs:
            raise ScenarioError("mcap, outputs: a run with a Python compensator cannot be recorded yet")
        return _simulate_python(scenario, compensator, step_limit)
    wanted = dict(outputs or {})
    if mcap is not None:
        wanted["mcap"] = {"path": os.fspath(mcap), "overwrite": bool(overwrite)}
    core = _core()
    result = core.simulate(scenario.to_json(), json.dumps(wanted)) if wanted else core.simulate(scenario.to_json())
    metrics = json.loads(result["metrics"])
    recorded = result.get("mcap")
    tables = result["tables"]
    run = Run(
        scenario=scenario,
        metrics=metrics,
        timeseries=_LazyFrame(tables.timeseries, TIMESERIES_COLUMNS + OPTIONAL_TIMESERIES_COLUMNS),  # type: ignore[arg-type]
        reference=_LazyFrame(tables.reference, REFERENCE_COLUMNS),  # type: ignore[arg-type]
        mcap=json.loads(recorded) if recorded else None,
    )
    if result.get("interrupted"):
        raise RunInterrupted(run)
    return run


def _simulate_mujoco(scenario: Scenario) -> Run:
    """A run on the MuJoCo facility (``facility.kind = "mujoco"``, :mod:`hilcontact.mujoco`)."""
    from .mujoco import require

    require()
    from .mujoco.facility import simulate_facility

    result = simulate_facility(scenario)
    return Run(
        scenario=scenario,
        metrics=json.loads(result["metrics"]),
        timeseries=_frame(result["timeseries"], TIMESERIES_COLUMNS + OPTIONAL_TIMESERIES_COLUMNS),
        reference=_frame(result["reference"], REFERENCE_COLUMNS),
    )


def _simulate_python(scenario: Scenario, compensator: Any, step_limit: float | None) -> Run:
    """A run with a compensator written in Python (``_core.simulate_python``)."""
    from .plugin import STEP_LIMIT, compensator_name, make_adapter, stop_on_interrupt

    adapter = make_adapter(compensator, scenario, STEP_LIMIT if step_limit is None else step_limit)
    if isinstance(compensator, str) and scenario.python_entry != compensator:
        scenario = scenario.model_copy()  # scenario.toml names the compensator that ran
        scenario._python_entry = compensator
    with stop_on_interrupt(adapter):  # Ctrl-C: the run so far, as a native run's
        result = _core().simulate_python(scenario.to_json(), adapter, compensator_name(compensator))
    run = Run(
        scenario=scenario,
        metrics=json.loads(result["metrics"]),
        timeseries=_frame(result["timeseries"], TIMESERIES_COLUMNS + OPTIONAL_TIMESERIES_COLUMNS),
        reference=_frame(result["reference"], REFERENCE_COLUMNS),
    )
    if result.get("interrupted") or adapter.interrupted:  # (after the last tick: the whole run)
        raise RunInterrupted(run)
    return run
