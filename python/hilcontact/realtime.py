"""Real-time HIL: the loop against a facility over its devices' protocols, and an emulated
facility that speaks them.

- :func:`run_hil` runs the HIL loop of a scenario in real time against an ATI Net F/T sensor
  (RDT over UDP, counts per unit from ``/netftapi2.xml``) and an ABB robot controller (EGM
  over UDP): compensator and virtual dynamics in a Rust real-time thread, the same step code
  as :func:`hilcontact.simulate`. It returns a :class:`~hilcontact.Run` whose ``metrics`` has a
  ``realtime`` section (timing statistics, packet counters, the stop and its exit code).
- :func:`start_facility` starts the emulated facility of a scenario (robot with the scenario's
  response lag, contact, sensor with its delay and noise) behind those protocols.

Options are plain dicts with the keys of the Rust ``RuntimeOptions`` / ``EmulatorOptions``
(see :func:`realtime_defaults`, the one place the defaults live); keys left out take their
defaults. Units: SI, except where the key says otherwise (``watchdog_ms``, ``egm_offset_mm``).

Ctrl-C: :func:`run_hil` polls the loop with the GIL released and, on ``KeyboardInterrupt``,
asks it to stop; the loop then commands the robot to hold, stops the sensor's streaming and
flushes its log, and the run is returned with status ``interrupted`` (exit code 130).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from typing import Any

from .errors import RealtimeOptionError
from .run import OPTIONAL_TIMESERIES_COLUMNS, REFERENCE_COLUMNS, TIMESERIES_COLUMNS, Run, _core, _frame
from .scenario import Scenario, load_scenario

__all__ = [
    "EXIT_INTERRUPTED",
    "EXIT_OK",
    "EXIT_SAFETY_STOP",
    "REALTIME_COLUMNS",
    "Facility",
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
REALTIME_COLUMNS: list[str] = ["wake_latency", "sensor_age", "robot_age"]


def realtime_defaults() -> dict[str, dict[str, Any]]:
    """The default options: ``{"runtime": {...}, "facility": {...}}``."""
    return json.loads(_core().realtime_defaults())


def _options(options: Mapping[str, Any] | None, section: str) -> str:
    known = realtime_defaults()[section]
    clean: dict[str, Any] = {}
    for key, value in (options or {}).items():
        if value is None:
            continue
        if key not in known:
            allowed = ", ".join(sorted(known))
            raise RealtimeOptionError(f"unknown {section} option {key!r}; allowed: {allowed}")
        clean[key] = value
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
    return Run(
        scenario=scenario,
        metrics=json.loads(result["metrics"]),
        timeseries=_frame(result["timeseries"], TIMESERIES_COLUMNS + OPTIONAL_TIMESERIES_COLUMNS + REALTIME_COLUMNS),
        reference=_frame(result["reference"], REFERENCE_COLUMNS),
    )


class Facility:
    """A running emulated facility (see :func:`start_facility`); a context manager that stops
    it on exit."""

    def __init__(self, handle: Any) -> None:
        self._handle = handle
        self.addresses: dict[str, str | None] = dict(handle.addresses())
        self.final_status: dict[str, Any] | None = None

    def status(self) -> dict[str, Any]:
        """Counters: time (s), contact_force (N), rdt_sent, egm_sent, corrections, ..."""
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
    delay and noise) with ``options`` (ports, hosts, counts per unit, EGM mapping).

    The sensor answers RDT requests on ``bind_host:sensor_port`` and serves
    ``/netftapi2.xml`` on ``http_port`` (0 = no HTTP); the robot sends EGM feedback to
    ``egm_host:egm_port`` every 4 ms and follows the corrections it gets back.
    """
    scenario = _scenario(scenario)
    return Facility(_core().start_facility(scenario.to_json(), _options(options, "facility")))
