"""The real-time commands: ``facility`` (the emulated facility), ``hil`` (the loop against a
facility), ``check`` (a dry run) and ``demo-rt`` (both together on loopback)."""

from __future__ import annotations

import json
import signal
import socket
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import click
from rich.console import Console
from rich.markup import escape

from ..errors import HilContactError, ScenarioError
from ..limits import Limits, check_run
from ..scenario import load_scenario
from .options import (
    _FORCE_HELP,
    _LIMIT_OPTIONS,
    _MCAP_HELP,
    _SET_HELP,
    NON_NEGATIVE,
    NUMBER,
    PORT,
    POSITIVE,
    _errors,
    _mcap_file,
    _Number,
    _numbers,
    _out_folder,
    _raise_keyboard_interrupt,
    _with,
    cli,
    parse_set_options,
)
from .reports import (
    _facility_errors,
    _facility_line,
    _hil_line,
    _report,
    _report_check,
    _report_mcap,
    _report_realtime,
)


def _rt_defaults() -> dict[str, dict[str, Any]]:
    from ..realtime import realtime_defaults

    try:
        return realtime_defaults()
    except HilContactError:  # native core not built: help without defaults
        return {"runtime": {}, "facility": {}, "protocols": {}}


_RT_DEFAULTS = _rt_defaults()


def _dflt(section: str, key: str, unit: str = "") -> str:
    """``[default: VALUE UNIT]`` from the Rust defaults (the one place they live)."""
    value: Any = _RT_DEFAULTS.get(section, {})
    for part in key.split("."):
        value = value.get(part) if isinstance(value, dict) else None
    if value is None:
        return ""
    if isinstance(value, list):
        value = ",".join(f"{v:g}" for v in value)
    return f" [default: {value}{' ' + unit if unit else ''}]"


def _protocols(link: str) -> list[str]:
    """The protocols of a link (``sensor``/``robot``), from the Rust registry (the one list)."""
    return list(_RT_DEFAULTS.get("protocols", {}).get(link, []))


def _protocol_option(link: str, section: str) -> Any:
    choices = _protocols(link)
    return click.option(
        f"--{link}-protocol", f"{link}_protocol", default=None,
        type=click.Choice(choices) if choices else str,
        help=f"Protocol of the {link}." + _dflt(section, f"{link}.kind"),
    )



def _stop_on_signals() -> None:
    """Ctrl-C (SIGINT) and SIGTERM stop a real-time command cleanly (hold, stop streaming, save),
    even when the process was started with SIGINT ignored (a background job of a
    non-interactive shell inherits SIG_IGN, and Python then keeps it)."""
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, _raise_keyboard_interrupt)



#: Sensor protocols that stream over TCP (the others over UDP): SRI M812x boxes.
_TCP_SENSORS = ("sri",)


def _sensor_scheme(kind: str) -> str:
    """``tcp`` or ``udp``: the transport of a sensor protocol, for addresses shown to the user."""
    return "tcp" if kind.lower() in _TCP_SENSORS else "udp"


def _link_option_flags(section: str) -> list[Any]:
    """``--robot-port`` (any robot protocol) and ``--sensor-option``/``--robot-option
    KEY=VALUE`` (any key of the protocol's options, e.g. the RSI element names: docs/realtime.md,
    "Options of each protocol")."""
    return [
        click.option("--robot-port", type=click.IntRange(0, 65535), default=None, metavar="PORT",
                     help="UDP port the robot sends its feedback to (the PC's port), any robot protocol [default: the protocol's: EGM 6510, RSI 59152]."),
        click.option("--sensor-option", "sensor_options", multiple=True, metavar="KEY=VALUE",
                     help=f"An option of the {section}'s sensor protocol (repeatable), e.g. sample_rate=1000 for SRI; keys per protocol in docs/realtime.md."),
        click.option("--robot-option", "robot_options", multiple=True, metavar="KEY=VALUE",
                     help=f"An option of the {section}'s robot protocol (repeatable), e.g. correction=relative or state_element=RIst for RSI; keys per protocol in docs/realtime.md."),
    ]


def _link_groups(sensor_protocol: str | None, robot_protocol: str | None, robot_port: int | None,
                 sensor_options: Sequence[str], robot_options: Sequence[str]) -> dict[str, Any]:
    """The ``sensor``/``robot`` option groups from the protocol, port and KEY=VALUE flags (None
    where nothing was given: the defaults)."""
    sensor = parse_set_options(sensor_options, "--sensor-option", "sample_rate=1000")
    robot = parse_set_options(robot_options, "--robot-option", "correction=relative")
    if sensor_protocol:
        sensor["kind"] = sensor_protocol
    if robot_protocol:
        robot["kind"] = robot_protocol
    if robot_port is not None:
        robot["port"] = robot_port
    return {"sensor": sensor or None, "robot": robot or None}


_FACILITY_OPTIONS = [
    click.option("--bind-host", default=None, help="Address the sensor's RDT and HTTP servers bind to." + _dflt("facility", "bind_host")),
    click.option("--sensor-port", type=PORT, default=None, help="RDT (UDP) port of the sensor." + _dflt("facility", "sensor_port")),
    click.option("--http-port", type=PORT, default=None, help="HTTP port of /netftapi2.xml (0 = none)." + _dflt("facility", "http_port")),
    click.option("--egm-host", default=None, help="Host the robot sends EGM feedback to (the PC)." + _dflt("facility", "egm_host")),
    click.option("--egm-port", type=PORT, default=None, help="UDP port the robot sends EGM feedback to." + _dflt("facility", "egm_port")),
    click.option("--egm-local-port", type=PORT, default=None, help="The robot's own UDP port (0 = any)." + _dflt("facility", "egm_local_port")),
    click.option("--counts-per-force", type=NUMBER, default=None, help="RDT counts per N (cfgcpf)." + _dflt("facility", "counts_per_force")),
    click.option("--counts-per-torque", type=NUMBER, default=None, help="RDT counts per N m (cfgcpt)." + _dflt("facility", "counts_per_torque")),
]


_MAPPING_OPTIONS = [
    click.option("--egm-offset", default=None, metavar="X,Y,Z", help="Origin of the target frame t in the EGM frame, mm." + _dflt("runtime", "robot.offset_mm")),
    click.option("--egm-rotation", default=None, metavar="W,X,Y,Z", help="Rotation from t to the EGM frame, quaternion." + _dflt("runtime", "robot.rotation")),
]


@cli.command(name="facility", short_help="Run the emulated facility (Net F/T sensor + ABB EGM robot) in real time.")
@click.argument("scenario")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP)
@_with([_protocol_option("sensor", "facility"), _protocol_option("robot", "facility")] + _FACILITY_OPTIONS + _MAPPING_OPTIONS
       + _link_option_flags("facility"))
@click.option("--silence-sensor-after", type=NON_NEGATIVE, default=None, metavar="S", help="Fault injection: the sensor stops sending S seconds after the robot's first command (the run's start).")
@click.option("--silence-robot-after", type=NON_NEGATIVE, default=None, metavar="S", help="Fault injection: the robot stops sending S seconds after its first command.")
@click.option("--duration", type=POSITIVE, default=None, metavar="S", help="Stop after S seconds [default: run until Ctrl-C].")
def facility_command(scenario: str, sets: tuple[str, ...], sensor_protocol: str | None, robot_protocol: str | None,
                     bind_host: str | None, sensor_port: int | None,
                     http_port: int | None, egm_host: str | None, egm_port: int | None, egm_local_port: int | None,
                     counts_per_force: float | None, counts_per_torque: float | None, egm_offset: str | None,
                     egm_rotation: str | None, robot_port: int | None, sensor_options: tuple[str, ...],
                     robot_options: tuple[str, ...], silence_sensor_after: float | None,
                     silence_robot_after: float | None, duration: float | None) -> None:
    """Emulate the facility of SCENARIO in real time: an F/T sensor speaking ATI's Net F/T RDT
    protocol (UDP, 1 record per control period, /netftapi2.xml over HTTP) and a robot speaking
    ABB's EGM (UDP + protobuf, feedback every 4 ms to --egm-host:--egm-port, corrections back),
    with the scenario's robot delay, sensor delay and noise, and the contact between them.

    \b
    Example (then run `hilcontact hil` against it, see there):
      hilcontact facility paper-table1 --set facility.robot_delay=0.02 --http-port 8080
    """
    from ..realtime import start_facility

    with _errors():
        resolved = load_scenario(scenario, parse_set_options(sets))
        # the flags keep their flat keys; hilcontact.realtime.LEGACY_KEYS moves them into the devices
        options = {
            **_link_groups(sensor_protocol, robot_protocol, robot_port, sensor_options, robot_options),
            "bind_host": bind_host, "sensor_port": sensor_port, "http_port": http_port, "egm_host": egm_host,
            "egm_port": egm_port, "egm_local_port": egm_local_port, "counts_per_force": counts_per_force,
            "counts_per_torque": counts_per_torque, "egm_offset_mm": _numbers(egm_offset, 3, "--egm-offset"),
            "egm_rotation": _numbers(egm_rotation, 4, "--egm-rotation"),
            "silence_sensor_after": silence_sensor_after, "silence_robot_after": silence_robot_after,
        }
        facility = start_facility(resolved, options)
    _stop_on_signals()
    a = facility.addresses
    f = resolved.facility
    sensor = facility.status()["sensor_protocol"]
    click.echo(
        f"ready: facility {resolved.name}: sensor {sensor} {_sensor_scheme(sensor)}://{a['sensor']}, "
        f"netftapi2.xml {'http://' + str(a['http']) + '/netftapi2.xml' if a['http'] else 'off'}, "
        f"robot {facility.status()['robot_protocol']} udp://{a['robot']} -> udp://{a['robot_peer']}; robot delay {f.robot_delay * 1e3:g} ms, "
        f"sensor delay {f.sensor_delay * 1e3:g} ms, noise {f.sensor_noise:g} N; Ctrl-C stops",
        nl=True,
    )
    import sys

    sys.stdout.flush()
    stderr = Console(stderr=True)
    try:
        with stderr.status("facility starting ...") as status:
            while duration is None or facility.status()["time"] < duration:
                time.sleep(0.1)
                status.update(_facility_line(facility.status()))
    except KeyboardInterrupt:
        pass
    final = facility.stop()
    click.echo("stopped: " + _facility_line(final))
    click.echo("endpoints: " + _facility_errors(final))


_SCHEDULING_OPTIONS = [
    click.option("--rt-priority", type=click.IntRange(0, 99), default=None, metavar="N",
                 help="SCHED_FIFO priority of the loop thread, 1-99 (0 = normal scheduling); a refusal by the OS is reported, not an error (docs/realtime.md)." + _dflt("runtime", "scheduling.priority")),
    click.option("--no-lock-memory", is_flag=True, default=False, help="Do not lock the process's memory (mlockall) [default: locked]."),
    click.option("--cpu", type=click.IntRange(min=0), default=None, metavar="N", help="Pin the loop thread to this CPU (0-based) [default: any CPU]."),
]


def _scheduling_options(rt_priority: int | None, no_lock_memory: bool, cpu: int | None) -> dict[str, Any] | None:
    """``{"scheduling": ...}``'s value from the CLI flags (None: the Rust defaults)."""
    scheduling = {k: v for k, v in (("priority", rt_priority), ("cpu", cpu)) if v is not None}
    if no_lock_memory:
        scheduling["lock_memory"] = False
    return scheduling or None


_HIL_OPTIONS = [
    _protocol_option("sensor", "runtime"),
    _protocol_option("robot", "runtime"),
    click.option("--sensor", "sensor_host", default=None, metavar="HOST", help="Host of the F/T sensor (Net F/T)." + _dflt("runtime", "sensor.host")),
    click.option("--sensor-port", type=PORT, default=None, help="RDT port of the sensor." + _dflt("runtime", "sensor.port")),
    click.option("--http-port", type=PORT, default=None, help="HTTP port of the sensor's /netftapi2.xml." + _dflt("runtime", "sensor.http_port")),
    click.option("--counts-per-force", type=NUMBER, default=None, help="Counts per N; with --counts-per-torque, /netftapi2.xml is not read."),
    click.option("--counts-per-torque", type=NUMBER, default=None, help="Counts per N m."),
    click.option("--rdt-local-port", type=PORT, default=None, help="Local UDP port of the RDT client (0 = any)." + _dflt("runtime", "sensor.local_port")),
    click.option("--bias", is_flag=True, default=None, help="Bias the sensor (RDT 0x0042) before streaming; the rod must be free."),
    click.option("--egm-port", type=PORT, default=None, help="UDP port the robot sends EGM feedback to." + _dflt("runtime", "robot.port")),
    click.option("--egm-bind", "egm_bind_host", default=None, metavar="HOST", help="Address the EGM endpoint binds to." + _dflt("runtime", "robot.bind_host")),
    click.option("--robot", "robot_host", default=None, metavar="HOST", help="Accept robot feedback (EGM, RSI) only from this host [default: the first sender whose feedback is at the scenario's start (within --start-tolerance)]."),
    click.option("--extrapolation", type=click.Choice(["quadratic", "linear", "hold"]), default=None, help="Actual motion between EGM feedback messages." + _dflt("runtime", "extrapolation")),
    click.option("--force-limit", type=NUMBER, default=None, help="Safety stop above this measured force." + _dflt("runtime", "limits.force_limit", "N")),
    click.option("--moment-limit", type=NUMBER, default=None, help="Safety stop above this measured moment." + _dflt("runtime", "limits.moment_limit", "N m")),
    click.option("--watchdog-ms", type=NUMBER, default=None, help="Safety stop after this long without sensor records or robot feedback." + _dflt("runtime", "limits.watchdog_ms", "ms")),
    click.option("--workspace", type=NUMBER, default=None, help="Safety stop when the commanded rod tip is this far from its start." + _dflt("runtime", "limits.workspace", "m")),
    click.option("--hold-deviation", type=NUMBER, default=None, help="A stop holds the robot at its fed-back pose only within this distance of the last command (else at the last command)." + _dflt("runtime", "limits.hold_deviation", "m")),
    click.option("--retreat-speed", type=NUMBER, default=None, help="After a force or moment stop, back away to the last contact-free pose at this speed." + _dflt("runtime", "limits.retreat_speed", "m/s")),
    click.option("--retreat-distance", type=NUMBER, default=None, help="Longest retreat after a force or moment stop." + _dflt("runtime", "limits.retreat_distance", "m")),
    click.option("--tracking-limit", type=NUMBER, default=None, help="Safety stop when the fed-back rod tip is this far from every command of the tracking window (frozen feedback, a robot that does not follow)." + _dflt("runtime", "limits.tracking_limit", "m")),
    click.option("--tracking-window", type=NUMBER, default=None, help="How far back commands are compared with the feedback (longer than the robot's delay)." + _dflt("runtime", "limits.tracking_window", "s")),
    click.option("--offset", "offset_mode", type=click.Choice(["measure", "off"]), default=None, help="The sensor's offset at start: measured with the rod free (nothing commanded) and subtracted, or used as it comes." + _dflt("runtime", "offset.mode")),
    click.option("--offset-time", type=NUMBER, default=None, help="How long the offset is averaged at start." + _dflt("runtime", "offset.time", "s")),
    click.option("--max-offset-force", type=NUMBER, default=None, help="Refuse the start when the force offset is larger (the rod may touch something)." + _dflt("runtime", "offset.max_force", "N")),
    click.option("--max-offset-moment", type=NUMBER, default=None, help="Refuse the start when the moment offset is larger." + _dflt("runtime", "offset.max_moment", "N m")),
    click.option("--connect-timeout", type=_Number(min=0.0, max=3600.0, min_open=True), default=None, help="Longest wait for the sensor and the robot." + _dflt("runtime", "connect_timeout", "s")),
    click.option("--start-tolerance", type=NUMBER, default=None, help="Largest distance of the robot from the initial pose at start." + _dflt("runtime", "start_tolerance", "m")),
    *_SCHEDULING_OPTIONS,
    *_link_option_flags("runtime"),
]


def _runtime_options(sensor_protocol: str | None, robot_protocol: str | None, sensor_host: str | None, sensor_port: int | None, http_port: int | None,
                     counts_per_force: float | None, counts_per_torque: float | None, rdt_local_port: int | None,
                     bias: bool | None, egm_port: int | None, egm_bind_host: str | None, robot_host: str | None,
                     extrapolation: str | None, force_limit: float | None, moment_limit: float | None,
                     watchdog_ms: float | None, workspace: float | None, hold_deviation: float | None,
                     retreat_speed: float | None, retreat_distance: float | None, tracking_limit: float | None,
                     tracking_window: float | None, offset_mode: str | None, offset_time: float | None,
                     max_offset_force: float | None, max_offset_moment: float | None, connect_timeout: float | None, start_tolerance: float | None, egm_offset: str | None,
                     egm_rotation: str | None, rt_priority: int | None, no_lock_memory: bool, cpu: int | None,
                     robot_port: int | None, sensor_options: tuple[str, ...], robot_options: tuple[str, ...]) -> dict[str, Any]:
    limits = {k: v for k, v in (("force_limit", force_limit), ("moment_limit", moment_limit),
                                ("watchdog_ms", watchdog_ms), ("workspace", workspace),
                                ("hold_deviation", hold_deviation), ("retreat_speed", retreat_speed),
                                ("retreat_distance", retreat_distance), ("tracking_limit", tracking_limit),
                                ("tracking_window", tracking_window)) if v is not None}
    offset = {k: v for k, v in (("mode", offset_mode), ("time", offset_time), ("max_force", max_offset_force),
                                ("max_moment", max_offset_moment)) if v is not None}
    # the flags keep their flat keys; hilcontact.realtime.LEGACY_KEYS moves them into the links
    return {
        "offset": offset or None,
        "scheduling": _scheduling_options(rt_priority, no_lock_memory, cpu),
        **_link_groups(sensor_protocol, robot_protocol, robot_port, sensor_options, robot_options),
        "sensor_host": sensor_host, "sensor_port": sensor_port, "http_port": http_port,
        "counts_per_force": counts_per_force, "counts_per_torque": counts_per_torque,
        "rdt_local_port": rdt_local_port, "bias": bias, "egm_port": egm_port, "egm_bind_host": egm_bind_host,
        "robot_host": robot_host, "extrapolation": extrapolation, "limits": limits or None,
        "connect_timeout": connect_timeout, "start_tolerance": start_tolerance,
        "egm_offset_mm": _numbers(egm_offset, 3, "--egm-offset"), "egm_rotation": _numbers(egm_rotation, 4, "--egm-rotation"),
    }


def _run_realtime(resolved: Any, options: dict[str, Any], folder: Path, no_plots: bool, force: bool,
                  mcap: Path | None = None) -> None:
    from ..realtime import exit_code, run_hil

    if mcap is not None:
        options = {**options, "mcap": {"path": str(mcap), "overwrite": force}}
    _stop_on_signals()
    stderr = Console(stderr=True)
    with stderr.status(f"{escape(resolved.name)}: connecting to the sensor and the robot ...") as status:
        result = run_hil(resolved, options, on_status=lambda s: status.update(escape(_hil_line(s))))
    result.save(folder, plots=not no_plots, overwrite=force)
    console = Console()
    _report(console, result, folder)
    _report_realtime(console, result)
    _report_mcap(console, result.mcap)
    code = exit_code(result)
    if code:
        raise click.exceptions.Exit(code)


@cli.command(name="hil", short_help="Run the HIL loop in real time against a facility (real or emulated).")
@click.argument("scenario")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP)
@_with(_HIL_OPTIONS + _MAPPING_OPTIONS)
@click.option("--out", "out", metavar="DIR", default=None, help="Output folder [default: runs/<scenario name>-rt].")
@click.option("--no-plots", is_flag=True, help="Do not write the PNG figures.")
@click.option("--mcap", "mcap", metavar="FILE", default=None, help=_MCAP_HELP)
@click.option("--force", is_flag=True, help=_FORCE_HELP + " Replace --mcap FILE.")
@_with(_LIMIT_OPTIONS)
def hil_command(scenario: str, sets: tuple[str, ...], out: str | None, no_plots: bool, mcap: str | None, force: bool,
                max_memory: float, max_time: float, **kw: Any) -> None:
    """Run the HIL loop of SCENARIO in real time: RDT client of the F/T sensor at --sensor,
    EGM endpoint on UDP --egm-port for the robot controller, the scenario's compensator and
    virtual dynamics in a Rust real-time thread. Shows a live line; writes the same files as
    `run` (metrics.json with a "realtime" section: timing statistics, packet counters, stop,
    and the loop thread's scheduling: SCHED_FIFO --rt-priority, locked memory, --cpu, each
    granted or refused by the OS; a refusal is reported, the run goes on).

    Exit code: 0 completed, 3 safety stop (force/moment limit, watchdog, workspace, divergence;
    the robot is commanded to hold, streaming stops, the run is saved), 130 Ctrl-C (same),
    1 facility unreachable, 2 bad input.

    \b
    Example, against `hilcontact facility paper-table1 --set facility.robot_delay=0.02 --http-port 8080`:
      hilcontact hil paper-table1 --set compensator.kind=pida --sensor 127.0.0.1 --http-port 8080 --egm-port 6510 --out runs/rt1
    """
    with _errors():
        resolved = load_scenario(scenario, parse_set_options(sets))
        check_run(resolved, Limits(max_memory, max_time))
        folder = _out_folder(out, Path("runs") / f"{resolved.name}-rt", force)
        mcap_path = _mcap_file(mcap, folder, force)
        _run_realtime(resolved, _runtime_options(**kw), folder, no_plots, force, mcap_path)



@cli.command(name="check", short_help="Dry run: connect to the sensor and the robot as `hil` would, command nothing, report.")
@click.argument("scenario")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP)
@_with(_HIL_OPTIONS + _MAPPING_OPTIONS)
@click.option("--duration", type=_Number(min=0.0, max=3600.0, min_open=True), default=1.0, show_default=True, metavar="S", help="How long to listen to the sensor and the robot, s.")
@click.option("--out", "out", metavar="DIR", default=None, help="Write check.json (the report) to this folder.")
def check_command(scenario: str, sets: tuple[str, ...], duration: float, out: str | None, **kw: Any) -> None:
    """Check that `hilcontact hil SCENARIO` with the same options would start, commanding
    nothing: connect to the sensor and the robot exactly as `hil` would, listen for --duration
    seconds, and report the sensor (rate, counters, counts per unit and units, the offset and
    the noise with the rod free) and the robot (the address locked onto, feedback rate,
    counters, the rod tip's distance from the scenario's start), then the verdict with the run's
    own reasons. The robot is sent nothing at all, not even a hold.

    Exit code: 0 a run would start, 1 it would refuse (or a link cannot be opened), 2 bad input.

    \b
    Example, against `hilcontact facility paper-table1 --http-port 8080`:
      hilcontact check paper-table1 --sensor 127.0.0.1 --http-port 8080 --egm-port 6510
    """
    from ..realtime import check

    with _errors():
        resolved = load_scenario(scenario, parse_set_options(sets))
        folder = Path(out) if out is not None else None
        if folder is not None and folder.exists() and not folder.is_dir():
            raise ScenarioError(f"--out {folder}: exists and is not a directory")
        with Console(stderr=True).status(f"{escape(resolved.name)}: listening to the sensor and the robot for {duration:g} s ..."):
            report = check(resolved, _runtime_options(**kw), duration)
        if folder is not None:
            folder.mkdir(parents=True, exist_ok=True)
            (folder / "check.json").write_text(json.dumps(report, indent=2) + "\n")
    _report_check(Console(), report)
    if not report["would_start"]:
        raise click.exceptions.Exit(1)


def _free_port(kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _demo_options(sensor_protocol: str | None, robot_protocol: str | None) -> tuple[dict[str, Any], dict[str, Any]]:
    """Emulator and runtime options that meet on loopback on free ports, grouped per device
    (every protocol's options have a ``port``; RDT also an HTTP port for /netftapi2.xml)."""
    defaults = _RT_DEFAULTS.get("facility", {})
    sensor_kind = sensor_protocol or defaults.get("sensor", {}).get("kind", "rdt")
    robot_kind = robot_protocol or defaults.get("robot", {}).get("kind", "egm")
    sensor_socket = socket.SOCK_STREAM if _sensor_scheme(sensor_kind) == "tcp" else socket.SOCK_DGRAM
    sensor = {"kind": sensor_kind, "port": _free_port(sensor_socket)}
    robot = {"kind": robot_kind, "port": _free_port(socket.SOCK_DGRAM)}
    if sensor_kind == "rdt":
        sensor["http_port"] = _free_port(socket.SOCK_STREAM)
    facility = {"sensor": dict(sensor), "robot": dict(robot)}
    runtime = {"sensor": dict(sensor), "robot": {**robot, "bind_host": "127.0.0.1"}}
    return facility, runtime


@cli.command(name="demo-rt", short_help="Emulated facility and real-time HIL loop together, in one command.")
@click.argument("scenario", default="paper-table1")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP)
@click.option("--compensator", default="pida", show_default=True, help="Compensator kind of the loop (none shows the safety stop).")
@click.option("--robot-delay", type=NON_NEGATIVE, default=0.02, show_default=True, help="The emulated robot's response delay, s.")
@_protocol_option("sensor", "facility")
@_protocol_option("robot", "facility")
@_with(_SCHEDULING_OPTIONS)
@click.option("--out", "out", metavar="DIR", default=None, help="Output folder [default: runs/<scenario name>-demo-rt].")
@click.option("--no-plots", is_flag=True, help="Do not write the PNG figures.")
@click.option("--mcap", "mcap", metavar="FILE", default=None, help=_MCAP_HELP)
@click.option("--force", is_flag=True, help=_FORCE_HELP + " Replace --mcap FILE.")
@_with(_LIMIT_OPTIONS)
def demo_rt(scenario: str, sets: tuple[str, ...], compensator: str, robot_delay: float, sensor_protocol: str | None,
            robot_protocol: str | None, rt_priority: int | None, no_lock_memory: bool, cpu: int | None,
            out: str | None, no_plots: bool, mcap: str | None, force: bool, max_memory: float, max_time: float) -> None:
    """Run the emulated facility and the real-time HIL loop on loopback in one process (free
    ports, HTTP included): `hilcontact facility` and `hilcontact hil` together.

    \b
    Examples:
      hilcontact demo-rt                                  # paper-table1, 20 ms robot delay, pida
      hilcontact demo-rt --compensator none               # diverges; the force limit stops it
    """
    from ..realtime import start_facility

    with _errors():
        overrides = parse_set_options(sets)
        overrides.setdefault("facility.robot_delay", robot_delay)
        overrides["compensator.kind"] = compensator
        facility_options, runtime_options = _demo_options(sensor_protocol, robot_protocol)
        kinds = _RT_DEFAULTS.get("kinds", {})
        robot_kind = facility_options["robot"]["kind"]
        if robot_kind in kinds.get("robot_paced", []) and "simulation.period" not in overrides:
            # the robot's packets clock the loop (KUKA RSI): the scenario runs at its cycle
            overrides["simulation.period"] = kinds["facility"]["robot"][robot_kind]["period"]
        resolved = load_scenario(scenario, overrides)
        check_run(resolved, Limits(max_memory, max_time))
        folder = _out_folder(out, Path("runs") / f"{resolved.name}-demo-rt", force)
        mcap_path = _mcap_file(mcap, folder, force)
        scheduling = _scheduling_options(rt_priority, no_lock_memory, cpu)
        if scheduling:
            runtime_options["scheduling"] = scheduling
        with start_facility(resolved, facility_options) as facility:
            a = facility.addresses
            Console(stderr=True).print(
                f"facility: sensor {_sensor_scheme(facility_options['sensor']['kind'])}://{a['sensor']}{', http://' + str(a['http']) + '/netftapi2.xml' if a['http'] else ''}, "
                f"robot udp://{a['robot']} -> udp://{a['robot_peer']}",
                soft_wrap=True,
            )
            try:
                _run_realtime(resolved, runtime_options, folder, no_plots, force, mcap_path)
            finally:
                final = facility.stop()
                if final.get("io_errors"):
                    Console(stderr=True).print("facility " + escape(_facility_errors(final)), soft_wrap=True)
