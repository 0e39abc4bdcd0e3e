"""``hilcontact calibrate SCENARIO --out cal.toml``: the facility's hardware measured with its
own robot before a run (docs/calibration.md): each wall's plane, the contact law and the
robot's delay, written as a calibration file that ``model-mediated`` takes with
``--calibration FILE`` (or ``compensator.calibration``).

``--simulate`` runs the procedure against the scenario's simulated facility (the facility model
of the true hardware: ``facility.mount_offset``, ``mount_rotation``, ``robot_repeatability``,
``stiffness_error``, ``damping_error``), as fast as it computes.
"""

from __future__ import annotations

import datetime
import json
import os
import tempfile
from pathlib import Path
from typing import Any

import click
import tomli_w

from rich.console import Console
from rich.markup import escape

from ..errors import ScenarioError
from ..native import VERSION, core
from ..scenario import load_scenario
from .calibration_file import CALIBRATION_OPTION, read_calibration, with_calibration
from .live import live_flags, live_settings
from .options import EXIT_INTERRUPTED, _errors, _fail, _with, cli, parse_set_options
from .realtime_commands import _RT_DEFAULTS, _RUNTIME_FLAGS, _link_flags, _realtime_options, _stop_on_signals
from .reports import _hil_line

__all__ = ["CALIBRATION_OPTION", "calibrate_command", "read_calibration", "with_calibration"]

_SET_HELP = "Override a scenario key (dotted), e.g. --set facility.mount_offset=[0.0005,0,0]. Repeatable."


def _procedure_options(items: tuple[str, ...]) -> dict[str, Any]:
    """``--option KEY=VALUE`` pairs as the procedure's options (values parsed as TOML values)."""
    options: dict[str, Any] = {}
    schema = json.loads(core().calibration_schema())["options"]["properties"]
    for item in items:
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ScenarioError(f"--option: expected KEY=VALUE, got {item!r}")
        if key not in schema:
            raise ScenarioError(f"--option: unknown key {key!r}; known: {', '.join(schema)}")
        try:
            options[key] = tomllib_value(value)
        except ValueError as exc:
            raise ScenarioError(f"--option {key}: {exc}") from None
    return options


def tomllib_value(text: str) -> Any:
    """One TOML value (``3``, ``0.015``, ``true``)."""
    import tomllib

    try:
        return tomllib.loads(f"v = {text.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        raise ValueError(f"not a number or boolean: {text!r}") from None


def _write_atomically(path: Path, text: str) -> None:
    fd, staging = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.replace(staging, path)
    except BaseException:
        Path(staging).unlink(missing_ok=True)
        raise


def _force_limit(runtime: dict[str, Any]) -> float:
    """The run's force limit, N: ``--force-limit`` (the runtime option ``limits.force_limit``),
    else its default."""
    given = (runtime.get("limits") or {}).get("force_limit")
    if given is None:
        given = _RT_DEFAULTS.get("runtime", {}).get("limits", {}).get("force_limit", 500.0)
    return float(given)


def _calibrate_realtime(resolved: Any, runtime: dict[str, Any], procedure: dict[str, Any], now: str) -> dict[str, Any]:
    """The procedure over the device links of ``runtime`` (as ``hil``'s): progress lines as
    they come, the live line on stderr; Ctrl-C (or SIGTERM) stops it (the robot backs out of
    contact and holds)."""
    from ..realtime import _options

    handle = core().start_calibration(resolved.to_json(), _options(runtime, "runtime"), json.dumps(procedure), now)
    _stop_on_signals()
    stderr = Console(stderr=True)
    interrupted = False
    with stderr.status(f"{escape(resolved.name)}: connecting to the sensor and the robot ...") as status:
        try:
            while not handle.wait(0.1):
                for line in handle.progress():
                    click.echo("  " + line)
                status.update(escape(_hil_line(handle.status())))
        except KeyboardInterrupt:
            interrupted = True
            handle.stop()
            while not handle.wait(0.1):
                pass
    for line in handle.progress():
        click.echo("  " + line)
    result = dict(handle.finish())
    if interrupted and result["exit_code"] == 0:
        result["exit_code"] = EXIT_INTERRUPTED
    return result


@cli.command(name="calibrate", short_help="Measure the facility's walls, contact law and robot delay with its own robot.")
@click.argument("scenario")
@click.option("--out", "out", required=True, metavar="FILE", help="The calibration file to write (TOML).")
@click.option("--simulate", is_flag=True,
              help="Against the scenario's simulated facility (the facility model of the true hardware), as fast as it "
                   "computes; of the device options only --force-limit applies then.")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP)
@click.option("--option", "options", multiple=True, metavar="KEY=VALUE",
              help="A procedure option, e.g. --option points_per_side=3 (docs/calibration.md lists them). Repeatable.")
@click.option("--force", is_flag=True, help="Replace FILE if it exists.")
@_with(_link_flags("runtime", _RUNTIME_FLAGS))
@_with(live_flags())
def calibrate_command(scenario: str, out: str, simulate: bool, sets: tuple[str, ...], options: tuple[str, ...],
                      force: bool, live: str | None, live_control: bool, live_remote: bool, live_wait: float,
                      **kw: Any) -> None:
    """Probe each wall of SCENARIO with the robot (approach along the nominal normal, press to a
    force well below the force limit, dwell, retreat; a grid of probes per wall), fit each
    wall's plane, the contact law and the robot's delay with their uncertainties, and write
    them to FILE for `--calibration FILE` (model-mediated).

    Without --simulate the procedure runs in real time over the device links, with the
    options and the safety functions of `hil` (--sensor, --robot, the protocols,
    --connect-timeout, the limits, --rt-priority, ...): the probes press to a fifth of
    --force-limit, a measured force past two fifths stops the procedure.

    Exit code: 0 calibrated (FILE written), 1 the procedure stopped itself (a wall not where
    the scenario says, its force bound, a failed fit: the tip backed out of contact, the robot
    holds) or the facility is unreachable, 3 a safety stop of the loop (as `hil`: the robot
    backs out of contact and holds), 130 Ctrl-C, 2 bad input; nothing is written unless 0.

    \b
    Examples:
      hilcontact calibrate paper-table1 --simulate --out cal.toml \\
          --set facility.mount_offset=[0.0005,0,0] --set facility.robot_repeatability=3e-5
      hilcontact run paper-table1 --set compensator.kind=model-mediated --calibration cal.toml
    \b
    Against `hilcontact facility paper-table1 --http-port 8080` (another process, or the cell):
      hilcontact calibrate paper-table1 --out cal.toml --sensor 127.0.0.1 --http-port 8080 --egm-port 6510
    """
    with _errors():
        target = Path(out)
        if target.is_dir():
            raise ScenarioError(f"--out {out}: is a directory")
        if not target.parent.is_dir():
            raise ScenarioError(f"--out {out}: no such folder {str(target.parent)!r}")
        if target.exists() and not force:
            raise ScenarioError(f"--out {out}: exists; --force replaces it")
        resolved = load_scenario(scenario, parse_set_options(sets))
        procedure = _procedure_options(options)
        runtime = _realtime_options("runtime", _RUNTIME_FLAGS, kw)
        settings = live_settings(live, live_control, live_remote, live_wait)
        if settings is not None:
            if simulate:
                raise ScenarioError("--live: only without --simulate (the real-time procedure)")
            runtime = {**runtime, "live": settings}
        force_limit = _force_limit(runtime)
        now = datetime.datetime.now(datetime.timezone.utc).replace(microsecond=0).isoformat()
        if simulate:
            click.echo(f"calibrating {resolved.name} (simulated facility): {len(resolved.walls)} wall(s)")
            result = core().calibrate_simulated(
                resolved.to_json(), json.dumps(procedure), force_limit, now,
                on_progress=lambda line: click.echo("  " + line),
            )
            code = 1
        else:
            click.echo(f"calibrating {resolved.name} in real time over the device links: {len(resolved.walls)} wall(s)")
            result = _calibrate_realtime(resolved, runtime, procedure, now)
            code = int(result["exit_code"]) or 1
    if result["error"] or code == EXIT_INTERRUPTED:
        reason = result["error"] or "stopped by the user"
        _fail(f"calibration stopped: {reason} (the contact is released, the robot holds; nothing written)", code)
    calibration = result["calibration"]
    calibration["measured"]["version"] = VERSION
    header = (
        f"# Calibration of {resolved.name!r}, written by hilcontact {VERSION} (hilcontact calibrate).\n"
        "# SI units, target frame t; sigma: one standard deviation (angle_sigma in degrees).\n"
    )
    with _errors():
        _write_atomically(target, header + tomli_w.dumps(calibration))
    click.echo(
        f"calibrated in {result['duration']:.1f} s: {len(calibration['walls'])} wall(s), "
        f"k {calibration['law']['stiffness']:.6g} ± {calibration['law']['stiffness_sigma']:.2g}, "
        f"c {calibration['law']['damping']:.4g} ± {calibration['law']['damping_sigma']:.2g}, "
        f"robot delay {calibration['robot']['delay'] * 1e3:.1f} ms; wrote {target}"
    )
