"""Type stubs of the native extension ``hilcontact._core`` (built from crates/py by maturin).

Conventions: SI units (m, s, N, N m, kg, J); the rod-tip motion is the virtual relative
motion in the target mockup frame ``t``; measured/applied wrenches are the wrench on the
frame, in the sensor frame ``s``, about the sensor origin.
"""

from typing import Any

def simulate(scenario_json: str, outputs: str | None = None) -> dict[str, Any]:
    """Run one HIL simulation and its ideal reference.

    ``scenario_json`` is the fully resolved scenario as JSON (``Scenario.to_json()``).
    Returns ``{"tables": Tables, "metrics": str}``: ``tables.timeseries()`` and
    ``tables.reference()`` make the HIL loop's and the reference's ``{column: float64 array}``
    when called (the run's records are kept until then); ``metrics`` is JSON text (the core's ``Metrics``; every field is
    described in docs/model.md, "Metrics"). The columns and their units: :func:`table_columns`.
    Each of ``metrics["collisions"]`` (and ``"reference_collisions"``) is a contact episode:
    ``normal_impulse``, ``tangential_impulse`` (N s), ``peak_moment`` (N m, about the sensor
    origin), ``rebound_velocity`` and ``rebound_angular_velocity`` (``[x, y, z]``, m/s, rad/s,
    ``t``), and for a compared HIL collision ``direction_error`` (degrees),
    ``normal_impulse_error``, ``tangential_impulse_error`` (fractions) and
    ``peak_moment_ratio``, and against the collision's local (restarted) reference
    ``local_start`` (s), ``local_velocity_error``, ``local_cof``,
    ``local_tangential_impulse_error``, ``local_normal_impulse_error`` (``None`` without one;
    docs/model.md "Metrics") (``hilcontact.Run.collision_table`` puts them in a DataFrame).

    ``outputs``: JSON of the outputs to also write the run to, each under its key with a
    real-time run's options for it (``{"mcap": {"path": ..., "overwrite": false}}``); the
    result then has, under each output's key (``"mcap"``), what it wrote as JSON text (else
    None). An unknown key or an existing file raises RealtimeOptionError.

    ``"interrupted"``: whether a Ctrl-C came while it ran; the first one stops the loop at its
    next tick and the run so far is returned (status ``interrupted``, the reference over the
    same span); a second one raises KeyboardInterrupt.

    Raises ``hilcontact.errors.ScenarioError`` for an invalid scenario.
    """

def simulate_batch(scenarios: list[str], threads: int | None = None) -> dict[str, Any]:
    """Run many scenarios (resolved JSON each) in parallel on Rust threads, the GIL released,
    keeping only each run's summary. ``threads``: pool size (default: one per core).

    Returns columns, one value per scenario in order: ``status`` (list of "ok"/"unfaithful"/
    "diverged") and one float64 array per column of :func:`summary_columns` (NaN where a run
    has no such value). Raises ScenarioError for an invalid scenario.
    """

def simulate_facility(scenario_json: str, engine: Any) -> dict[str, Any]:
    """Run one HIL simulation whose facility's contact is computed by ``engine`` (a Python
    object with ``contact_flat(motion)``: 13 numbers in (the robot's actual relative motion:
    position m, quaternion [w, x, y, z], velocity m/s, angular velocity rad/s, all in ``t``), 12
    out (force on the rod, force on the frame, its moment about the sensor origin, the friction
    part of the force on the rod, ``t``); e.g.
    ``hilcontact.mujoco.facility.MujocoContact``), the robot and the sensor as the facility
    model's. Returns ``{"timeseries": {column: float64 array}, "reference": {column: float64
    array}, "metrics": str}`` (the tables of :func:`simulate`, made at once); an error raised
    by the engine stops the run and is raised again."""

def contact_frequency(scenario_json: str) -> float:
    """Undamped contact frequency of a linear contact, Hz (``sqrt(k/μ)/2π``, μ the reduced
    mass); NaN for Hunt-Crossley. Raises ScenarioError for an invalid scenario."""

def summary_columns() -> list[tuple[str, str, str]]:
    """The numeric columns of a run's summary row (after ``status``), in order, as
    ``(name, unit, meaning)``."""

def table_columns() -> dict[str, list[tuple[str, str, str]]]:
    """The tables' columns with their units: ``{"timeseries", "reference", "realtime"}``, each
    a list of ``(name, unit, only)`` in order; ``only`` is "always", "estimates" or
    "observed_energy" (the columns only some compensators produce)."""

def version() -> str:
    """Version of the native core."""


def compensator_registry() -> str:
    """The compensator registry (the one list of compensators), as JSON text: a list, in the
    registry's order, of ``{"kind", "summary", "colour", "defaults": {"kind": kind,
    parameter: default, ...}}``."""


def scenario_schema() -> str:
    """The JSON Schema of a scenario file (draft 2020-12), as JSON text: every key with its
    description (units), default, allowed values and range (``minimum``,
    ``exclusiveMinimum``, ``maximum``, ``exclusiveMaximum``); ``[compensator]`` is a
    ``oneOf`` tagged by ``kind``; vectors, quaternions and inertias carry ``x-value``
    (``"vec3"``, ``"quaternion"``, ``"inertia"``). ``hilcontact.scenario`` builds its models
    from it."""


def resolve_scenario(scenario_json: str) -> str:
    """Check and resolve a scenario (JSON) as a run does; return the resolved scenario as JSON
    (defaults filled in, quaternions and wall normals normalised, inertia as a symmetric 3x3
    tensor, wall names set, delays rounded with ``facility.round_delays``).

    Raises ``hilcontact.errors.ScenarioError`` whose ``issues`` lists every problem as
    ``(key, message)``.
    """


class HilContactError(Exception):
    """Base class of every error raised on purpose by hilcontact."""


class ScenarioError(HilContactError, ValueError):
    """An invalid scenario; ``issues`` lists every problem as ``(key, message)``."""

    issues: list[tuple[str, str]]


class RealtimeError(HilContactError, OSError):
    """The real-time runtime or the emulated facility could not start or finish."""


class RealtimeOptionError(RealtimeError, ValueError):
    """An invalid real-time option; the message names it."""


class Tables:
    """The tables of a :func:`simulate` run, made when asked (each call makes new arrays)."""

    def timeseries(self) -> dict[str, Any]:
        """The HIL loop's ``{column: float64 array}``."""

    def reference(self) -> dict[str, Any]:
        """The ideal reference's ``{column: float64 array}``."""

class HilHandle:
    """A running real-time HIL loop (from :func:`start_hil`). The loop runs in Rust threads."""

    def status(self) -> dict[str, Any]:
        """Live status: ``phase`` (connecting/running/holding/finished), ``tick``, ``time`` (s),
        ``force`` (measured, N), ``energy`` (J), ``max_latency_us``, ``overruns``,
        ``sensor_lost``, ``sensor_late``, ``robot_lost``, ``robot_late``, ``dropped``,
        ``stop`` (None or the stop kind, e.g. ``"force-limit"``)."""

    def stop(self) -> None:
        """Ask the loop to stop: it commands the robot to hold, stops the sensor's streaming
        and flushes its log. Returns at once."""

    def is_finished(self) -> bool:
        """Whether the loop has ended."""

    def wait(self, timeout: float) -> bool:
        """Wait up to ``timeout`` s with the GIL released; return whether the loop has ended."""

    def finish(self) -> dict[str, Any]:
        """Wait for the loop and its writer; return ``{"timeseries": {column: ndarray},
        "reference": {column: ndarray}, "metrics": str (JSON, with a "realtime" section),
        "exit_code": int}``. Call once."""


class FacilityHandle:
    """A running emulated facility (from :func:`start_facility`)."""

    def status(self) -> dict[str, Any]:
        """``finished``, ``tick``, ``time`` (s), ``contact_force`` (N), ``sensor_protocol``,
        ``robot_protocol``, ``sensor`` and ``robot`` (each a dict of packet counters, e.g.
        ``sent``), ``io_errors``, ``rdt_requests``, ``rdt_bad_requests``, ``corrections``,
        ``corrections_dropped``, ``overruns``, ``max_latency_us``."""

    def addresses(self) -> dict[str, str | None]:
        """``{"sensor", "http", "robot", "egm_peer"}`` as ``host:port`` (http None if off)."""

    def stop(self) -> None:
        """Ask the emulator to stop; returns at once."""

    def is_finished(self) -> bool:
        """Whether the emulator has ended."""

    def join(self) -> dict[str, Any]:
        """Stop, wait (GIL released), return the final status. Call once."""


def start_hil(scenario_json: str, options_json: str) -> HilHandle:
    """Start the real-time HIL loop of a scenario (JSON) with runtime options (JSON object,
    keys of ``realtime_defaults()["runtime"]``; missing keys take the defaults). Binds the
    sockets and reads the sensor's counts per unit before returning.

    Raises ``ScenarioError``, ``RealtimeOptionError`` (bad option) or ``RealtimeError``
    (port in use, sensor HTTP unreachable)."""


def start_facility(scenario_json: str, options_json: str) -> FacilityHandle:
    """Start the emulated facility of a scenario (JSON) with options (JSON object, keys of
    ``realtime_defaults()["facility"]``). Raises like :func:`start_hil`."""


def check(scenario_json: str, options_json: str, duration: float) -> str:
    """A dry run (``hilcontact check``): open the sensor and robot links of the runtime options
    (as :func:`start_hil`) as a run would, listen for ``duration`` s (GIL released) commanding
    nothing to the robot, and return the report as JSON (``sensor``, ``robot``,
    ``would_start``, ``reasons``). Raises like :func:`start_hil`."""


def realtime_defaults() -> str:
    """The default runtime and facility options as JSON: ``{"runtime": {...}, "facility": {...}}``."""


def realtime_schema() -> str:
    """The JSON Schema of the real-time options (draft 2020-12), as JSON text:
    ``{"runtime": <schema of the runtime's options>, "facility": <schema of the emulator's>}``,
    every key with its description (units), default, allowed values and range (``minimum``,
    ``exclusiveMinimum``, ``maximum``, ``exclusiveMaximum``); ``sensor`` and ``robot`` are a
    ``oneOf`` tagged by ``kind``, one variant per protocol."""


def replay(scenario_json: str, columns: dict[str, Any]) -> dict[str, Any]:
    """Replay a recording (``{column: 1-D float array}``: time, measured_force_*,
    measured_moment_* in the sensor frame, actual_tip_position_*, actual_tip_velocity_*,
    tip_position_*, tip_velocity_* in ``t``) through the scenario's compensator, built as the
    live loop builds it. Returns ``{column: ndarray}``: time, applied_force_*, applied_moment_*
    (sensor frame), velocity_correction_*, stiffness_estimate, damping_estimate,
    observed_energy. Raises ``ScenarioError`` (a bad recording's message starts with
    ``recording: ``)."""


def identify(scenario_json: str, columns: dict[str, Any]) -> dict[str, Any]:
    """Identify a recording's contacts (columns as :func:`replay`'s, without the desired tip)
    with the scenario compensator's identification front end. Returns ``{"timeseries":
    {column: ndarray}, "collisions": [dict]}`` (index, start, end, samples, updates,
    stiffness, stiffness_std, damping, damping_std, normal, normal_std (rad), point,
    offset_std (m), peak_force). Raises like :func:`replay`."""


def online_identification(scenario_json: str, columns: dict[str, Any]) -> dict[str, Any] | None:
    """The live loop's own identification at the end of a run, replayed over its recording
    (columns as :func:`identify`'s) as the loop runs its front end (one filter, never
    restarted): ``{stiffness, stiffness_std (N/m), damping, damping_std (N s/m), updates,
    contacts}``, None before any update. Raises like :func:`replay`."""


def calibrate_simulated(
    scenario_json: str,
    options_json: str,
    force_limit: float,
    measured_at: str,
    on_progress: Any | None = None,
) -> dict[str, Any]:
    """``hilcontact calibrate --simulate``: the calibration procedure against the scenario's
    simulated facility (its true hardware). ``on_progress(line)`` gets each progress line.
    Returns ``{"calibration": dict | None, "error": str | None, "progress": [str], "duration":
    s, "peak_force": N, "final_force": N}``. Raises ``RealtimeOptionError`` for bad options or a
    refused procedure (nothing moved), ``ScenarioError`` for a bad scenario."""

def calibration_schema() -> str:
    """The JSON Schema of the calibration file and of the procedure's options:
    ``{"file": ..., "options": ...}``."""

def frames(scenario_json: str, sensor_vectors: Any | None = None, points: list[Any] = ...) -> dict[str, Any]:
    """The frame maths of a run's figures, from the core's resolved scenario:
    ``{"in_t": ndarray | None, "normals": ndarray, "distances": [ndarray]}``: ``sensor_vectors``
    (rows of x, y, z, sensor frame) turned into ``t``; the walls' unit normals (one row per
    wall, ``t``); per array of ``points`` (rows of x, y, z in ``t``, m) the signed distance of
    each point to each wall's plane (m, < 0 inside), shaped (walls, rows). Raises
    ``ScenarioError`` for a bad scenario, ``ValueError`` for an array that is not (rows, 3)."""

def read_mesh(path: str) -> tuple[list[list[float]], list[list[int]]]:
    """A mesh file's vertices (its units) and triangles (vertex indices), STL (binary or ASCII)
    or OBJ by its extension. Raises ValueError with the reason."""
    ...
