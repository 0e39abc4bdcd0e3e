"""Real-time HIL: the loop against a facility over its devices' protocols, and an emulated
facility that speaks them.

- :func:`run_hil` runs the HIL loop of a scenario in real time against an ATI Net F/T sensor
  (RDT over UDP, counts per unit from ``/netftapi2.xml``) and an ABB robot controller (EGM
  over UDP): compensator and virtual dynamics in a Rust real-time thread, the same step code
  as :func:`hilcontact.simulate`. It returns a :class:`~hilcontact.Run` whose ``metrics`` has a
  ``realtime`` section (timing statistics, packet counters, the stop and its exit code).
- :func:`check` is a dry run: it connects to the sensor and the robot as :func:`run_hil` would,
  listens for a while commanding nothing to the robot, and reports both links and whether a
  run would start (and if not, why).
- :func:`start_facility` starts the emulated facility of a scenario (robot with the scenario's
  response lag, contact, sensor with its delay and noise) behind those protocols.

Options are plain dicts with the keys of the Rust ``RuntimeOptions`` / ``EmulatorOptions``
(see :func:`realtime_defaults`, the one place the defaults live); keys left out take their
defaults. In both, the devices are grouped per link, each with its protocol: ``{"sensor":
{"kind": "rdt", "port": 49152, ...}, "robot": {"kind": "egm", "port": 6510, ...}, "limits":
{...}}``; a ``kind`` must be one of ``realtime_defaults()["protocols"]``. The flat keys of
earlier versions (``sensor_port``, ``egm_port``, ...) still work and are moved into their link
by :data:`LEGACY_KEYS`. Units: SI, except where the key says otherwise
(``watchdog_ms``, ``offset_mm``).

Ctrl-C: :func:`run_hil` polls the loop with the GIL released and, on ``KeyboardInterrupt``,
asks it to stop; the loop then commands the robot to hold, stops the sensor's streaming and
flushes its log, and the run is returned with status ``interrupted`` (exit code 130).
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Mapping
from typing import Any

from .errors import RealtimeOptionError
from .native import core as _core
from .run import OPTIONAL_TIMESERIES_COLUMNS, REFERENCE_COLUMNS, TIMESERIES_COLUMNS, Run, _frame
from .scenario import Scenario, load_scenario

__all__ = [
    "EXIT_INTERRUPTED",
    "EXIT_OK",
    "EXIT_SAFETY_STOP",
    "LEGACY_KEYS",
    "REALTIME_COLUMNS",
    "Facility",
    "check",
    "exit_code",
    "realtime_defaults",
    "run_hil",
    "start_facility",
]

#: Exit code of a run that ran its whole duration.
EXIT_OK = 0
#: Exit code of a run stopped by a safety function (force/moment limit, watchdog, workspace,
#: non-finite command, divergence).
EXIT_SAFETY_STOP = 3
#: Exit code of a run stopped by the user (Ctrl-C).
EXIT_INTERRUPTED = 130

#: Extra time-series columns of a real-time run (s): the tick's wake-up latency, the age of the
#: sensor record used and of the newest robot feedback.
REALTIME_COLUMNS: list[str] = [name for name, _, _ in _core().table_columns()["realtime"]]


def realtime_defaults() -> dict[str, Any]:
    """The default options: ``{"runtime": {...}, "facility": {...}, "protocols": {...},
    "kinds": {...}}`` (``protocols``: the sensor and robot kinds, each implemented by the runtime
    and the emulator; ``kinds``: each protocol's default options for the runtime and the
    facility, ``robot_paced`` (the robots that pace the loop) and ``transport`` (``udp``,
    ``tcp-client`` or ``tcp-server`` per protocol))."""
    return json.loads(_core().realtime_defaults())


#: The kind of a flat key every protocol of its link has (host, port): it implies no kind.
ANY_KIND = "*"

#: Flat option keys of earlier versions, per section: ``key -> (link, kind, key in the link)``.
#: ``{"sensor_port": 49152}`` is ``{"sensor": {"kind": "rdt", "port": 49152}}`` (the default
#: kind; with ``"sensor": {"kind": "sri"}`` the SRI box's port). The one mapping table between
#: the flat keys (and the CLI flags built on them) and the grouped form.
LEGACY_KEYS: dict[str, dict[str, tuple[str, str, str]]] = {
    "runtime": {
        "sensor_host": ("sensor", ANY_KIND, "host"),
        "rdt_local_port": ("sensor", "rdt", "local_port"),
        "bias": ("sensor", "rdt", "bias"),
        "egm_bind_host": ("robot", "egm", "bind_host"),
        "robot_host": ("robot", ANY_KIND, "robot_host"),
    },
    "facility": {
        "bind_host": ("sensor", ANY_KIND, "bind_host"),
        "egm_host": ("robot", "egm", "host"),
        "egm_local_port": ("robot", "egm", "local_port"),
        "egm_period": ("robot", "egm", "period"),
    },
}
#: The flat keys both sections have.
_SHARED_LEGACY_KEYS = {
    "sensor_port": ("sensor", ANY_KIND, "port"),
    "http_port": ("sensor", "rdt", "http_port"),
    "counts_per_force": ("sensor", "rdt", "counts_per_force"),
    "counts_per_torque": ("sensor", "rdt", "counts_per_torque"),
    "egm_port": ("robot", "egm", "port"),
    "egm_offset_mm": ("robot", "egm", "offset_mm"),
    "egm_rotation": ("robot", "egm", "rotation"),
}
LEGACY_KEYS["runtime"].update(_SHARED_LEGACY_KEYS)
LEGACY_KEYS["facility"].update(_SHARED_LEGACY_KEYS)

#: The link groups of the options (each a dict with a ``kind``).
LINKS = ("sensor", "robot")


def _options(options: Mapping[str, Any] | None, section: str) -> str:
    """Options as the Rust side takes them: grouped links (``sensor``/``robot`` with a
    ``kind``), flat legacy keys moved into their link (see :data:`LEGACY_KEYS`), ``None`` values
    left out (defaults)."""
    defaults = realtime_defaults()
    known, protocols = defaults[section], defaults.get("protocols", {})
    legacy = LEGACY_KEYS.get(section, {})
    clean: dict[str, Any] = {}
    links: dict[str, dict[str, Any]] = {}
    implied: dict[str, tuple[str, str]] = {}  # link -> (kind, the legacy key that implies it)
    for key, value in (options or {}).items():
        if value is None:
            continue
        if key == "mcap" and isinstance(value, (str, os.PathLike)):
            clean[key] = {"path": os.fspath(value)}  # a file name alone: the defaults otherwise
        elif key in legacy:
            link, kind, inner = legacy[key]
            links.setdefault(link, {})[inner] = value
            if kind != ANY_KIND:
                implied.setdefault(link, (kind, key))
        elif key in LINKS and key in known:
            if not isinstance(value, Mapping):
                raise RealtimeOptionError(f"{section} option {key!r} must be a table with a 'kind', got {value!r}")
            links.setdefault(key, {}).update({k: v for k, v in value.items() if v is not None})
        elif key in known:
            clean[key] = value
        else:
            allowed = ", ".join(sorted(set(known) | set(legacy)))
            raise RealtimeOptionError(f"unknown {section} option {key!r}; allowed: {allowed}")
    for link, group in links.items():
        default_kind = known[link]["kind"] if isinstance(known.get(link), dict) else None
        kind = group.setdefault("kind", implied[link][0] if link in implied else default_kind)
        if link in implied and implied[link][0] != kind:
            raise RealtimeOptionError(
                f"{section} option {implied[link][1]!r} belongs to {link} kind {implied[link][0]!r}, not {kind!r}"
            )
        allowed_kinds = protocols.get(link)
        if allowed_kinds and kind not in allowed_kinds:
            raise RealtimeOptionError(
                f"{section} option {link}.kind: unknown {link} protocol {kind!r}; allowed: {', '.join(allowed_kinds)}"
            )
        clean[link] = group
    return json.dumps(clean)


def _scenario(scenario: Scenario | str) -> Scenario:
    return scenario if isinstance(scenario, Scenario) else load_scenario(scenario)


def exit_code(run: Run) -> int:
    """The exit code of a real-time run: 0 completed, 3 safety stop, 130 interrupted."""
    return int(run.metrics.get("realtime", {}).get("stop", {}).get("exit_code", EXIT_OK))


def run_hil(
    scenario: Scenario | str,
    options: Mapping[str, Any] | None = None,
    *,
    on_status: Callable[[dict[str, Any]], None] | None = None,
    poll_interval: float = 0.1,
) -> Run:
    """Run the HIL loop of ``scenario`` in real time against the facility in ``options``.

    Returns when the run ends (its duration, a safety stop, or Ctrl-C); ``on_status`` gets the
    loop's status dict (phase, time, force, energy, timing and packet counters) every
    ``poll_interval`` seconds. Raises :class:`~hilcontact.errors.RealtimeError` if the sensor or
    the robot cannot be reached, ScenarioError/RealtimeOptionError for invalid input.

    ``options["mcap"]`` (a file name, or ``{"path", "overwrite", "chunk_interval"}``) records
    the run as MCAP from the writer thread (docs/realtime.md, "MCAP recordings"); an existing
    file is refused unless ``overwrite``; ``Run.mcap`` (and ``metrics["realtime"]["mcap"]``)
    says what was written.
    """
    scenario = _scenario(scenario)
    core = _core()
    handle = core.start_hil(scenario.to_json(), _options(options, "runtime"))
    try:
        while not handle.wait(poll_interval):
            if on_status is not None:
                on_status(handle.status())
    except KeyboardInterrupt:
        handle.stop()
        while not handle.wait(poll_interval):
            pass
    result = handle.finish()
    metrics = json.loads(result["metrics"])
    return Run(
        scenario=scenario,
        metrics=metrics,
        mcap=metrics.get("realtime", {}).get("mcap"),
        timeseries=_frame(result["timeseries"], TIMESERIES_COLUMNS + OPTIONAL_TIMESERIES_COLUMNS + REALTIME_COLUMNS),
        reference=_frame(result["reference"], REFERENCE_COLUMNS),
    )


def check(scenario: Scenario | str, options: Mapping[str, Any] | None = None, duration: float = 1.0) -> dict[str, Any]:
    """A dry run of :func:`run_hil`: open the sensor and robot links of ``options`` exactly as
    a run would, listen for ``duration`` seconds, and apply the run's start checks, commanding
    nothing to the robot (not even a hold; the sensor is asked to stream and to stop).

    Returns the report as a dict: ``sensor`` (protocol, address, rate in Hz, stats, the link's
    ``report`` such as counts per unit, ``offset`` and ``noise`` as ``[Fx, Fy, Fz, Mx, My, Mz]``
    in N and N m, the offset bounds), ``robot`` (protocol, address, ``peer`` locked onto, rate
    in Hz, stats, ``rod_tip`` and ``start_rod_tip`` in m, ``start_distance`` and
    ``start_tolerance`` in m), ``would_start`` and ``reasons`` (the run's own refusal messages).
    Raises ScenarioError/RealtimeOptionError for invalid input and
    :class:`~hilcontact.errors.RealtimeError` when a link cannot be opened (a port in use, the
    sensor's ``/netftapi2.xml`` unreachable).
    """
    scenario = _scenario(scenario)
    return json.loads(_core().check(scenario.to_json(), _options(options, "runtime"), float(duration)))


class Facility:
    """A running emulated facility (see :func:`start_facility`); a context manager that stops
    it on exit."""

    def __init__(self, handle: Any) -> None:
        self._handle = handle
        self.addresses: dict[str, str | None] = dict(handle.addresses())
        self.final_status: dict[str, Any] | None = None

    def status(self) -> dict[str, Any]:
        """Counters: time (s), contact_force (N), ``sensor`` and ``robot`` (each: received,
        accepted, malformed, invalid, foreign, stale, lost, sent, send_errors, io_errors),
        io_errors (both), overruns, and the names of earlier versions (rdt_requests,
        corrections, corrections_dropped, ...)."""
        if self.final_status is not None:
            return self.final_status
        return dict(self._handle.status())

    def stop(self) -> dict[str, Any]:
        """Stop the emulator and return its final counters (idempotent)."""
        if self.final_status is None:
            self.final_status = dict(self._handle.join())
        return self.final_status

    def __enter__(self) -> Facility:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def start_facility(scenario: Scenario | str, options: Mapping[str, Any] | None = None) -> Facility:
    """Start the emulated facility of ``scenario`` (its robot delay, servo lag, contact, sensor
    delay and noise) with ``options``, grouped per device like :func:`run_hil`'s: ``{"sensor":
    {"kind": "rdt", "bind_host", "port", "http_port", "counts_per_force", ...}, "robot":
    {"kind": "egm", "host", "port", "local_port", "period", "offset_mm", "rotation",
    "robotware"}, "silence_sensor_after", "silence_robot_after"}`` (the flat keys
    ``sensor_port``, ``egm_port``, ... still work, see :data:`LEGACY_KEYS`).

    RDT: the sensor answers requests on ``bind_host:port`` and serves ``/netftapi2.xml`` on
    ``http_port`` (0 = no HTTP). EGM: the robot sends feedback to ``host:port`` every 4 ms and
    follows the corrections it gets back; ``robotware = 6`` (default 7) sends RobotWare 6's
    ``measuredForce`` layout. Raises :class:`~hilcontact.errors.RealtimeError` (with
    ``errno``, e.g. ``EADDRINUSE``) if a port cannot be bound.
    """
    scenario = _scenario(scenario)
    return Facility(_core().start_facility(scenario.to_json(), _options(options, "facility")))
