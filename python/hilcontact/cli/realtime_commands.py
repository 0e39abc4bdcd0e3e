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
from .calibration_file import CALIBRATION_OPTION, with_calibration
from .options import (
    _SET_HELP,
    NON_NEGATIVE,
    POSITIVE,
    _errors,
    _mcap_file,
    _Number,
    _out_folder,
    _raise_keyboard_interrupt,
    _run_output_options,
    _with,
    cli,
    parse_set_options,
)
from .live import live_flags, live_report_line, live_settings
from .realtime_flags import RealtimeFlag, flags_from_schema, options_from_flags
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


def _protocols(link: str) -> list[str]:
    """The protocols of a link (``sensor``/``robot``), from the Rust registry (the one list)."""
    return list(_RT_DEFAULTS.get("protocols", {}).get(link, []))


def _default_kind(section: str, link: str) -> str:
    """`` [default: KIND]``: a link's default protocol (from the Rust defaults)."""
    kind = (_RT_DEFAULTS.get(section, {}).get(link) or {}).get("kind")
    return f" [default: {kind}]" if kind else ""


def _protocol_option(link: str, section: str) -> Any:
    choices = _protocols(link)
    return click.option(
        f"--{link}-protocol", f"{link}_protocol", default=None,
        type=click.Choice(choices) if choices else str,
        help=f"Protocol of the {link}." + _default_kind(section, link),
    )


def _stop_on_signals() -> None:
    """Ctrl-C (SIGINT) and SIGTERM stop a real-time command cleanly (hold, stop streaming, save),
    even when the process was started with SIGINT ignored (a background job of a
    non-interactive shell inherits SIG_IGN, and Python then keeps it)."""
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, _raise_keyboard_interrupt)


def _scheme(link: str, kind: str) -> str:
    """``tcp`` or ``udp``: how a protocol of ``link`` (``sensor``/``robot``) is reached, from the
    Rust registry (``udp``, ``tcp-client``, ``tcp-server``), for addresses shown to the user."""
    transports = _RT_DEFAULTS.get("kinds", {}).get("transport", {}).get(link, {})
    return str(transports.get(kind.lower(), "udp")).split("-")[0]


def _link_option_flags(section: str) -> list[Any]:
    """``--sensor-option``/``--robot-option KEY=VALUE``: any key of the protocol's options, those
    without a flag of their own too (docs/realtime.md, "Options of each protocol")."""
    return [
        click.option("--sensor-option", "sensor_options", multiple=True, metavar="KEY=VALUE",
                     help=f"An option of the {section}'s sensor protocol (repeatable), e.g. sample_rate=1000 for SRI; keys per protocol in docs/realtime.md."),
        click.option("--robot-option", "robot_options", multiple=True, metavar="KEY=VALUE",
                     help=f"An option of the {section}'s robot protocol (repeatable), e.g. correction=relative or state_element=RIst for RSI; keys per protocol in docs/realtime.md."),
    ]


def _link_groups(sensor_protocol: str | None, robot_protocol: str | None,
                 sensor_options: Sequence[str], robot_options: Sequence[str]) -> dict[str, Any]:
    """The ``sensor``/``robot`` option groups from the protocol and KEY=VALUE flags (None where
    nothing was given: the defaults)."""
    sensor = parse_set_options(sensor_options, "--sensor-option", "sample_rate=1000")
    robot = parse_set_options(robot_options, "--robot-option", "correction=relative")
    if sensor_protocol:
        sensor["kind"] = sensor_protocol
    if robot_protocol:
        robot["kind"] = robot_protocol
    return {"sensor": sensor or None, "robot": robot or None}


#: The flags of the options of the emulated facility, of the loop, of the loop's scheduling
#: (from the options' schema: hilcontact.cli.realtime_flags).
_FACILITY_FLAGS = flags_from_schema("facility")
_RUNTIME_FLAGS = flags_from_schema("runtime")
_SCHEDULING_FLAGS = flags_from_schema("runtime", only=("scheduling",))


def _link_flags(section: str, flags: list[RealtimeFlag]) -> list[Any]:
    """A section's flags: the protocols, each option's, ``--sensor-option``/``--robot-option``."""
    return ([_protocol_option("sensor", section), _protocol_option("robot", section)]
            + [flag.option for flag in flags] + _link_option_flags(section))


def _realtime_options(section: str, flags: list[RealtimeFlag], kw: dict[str, Any]) -> dict[str, Any]:
    """The options of a section from its flags' values (taken out of ``kw``)."""
    groups = _link_groups(kw.pop("sensor_protocol"), kw.pop("robot_protocol"), kw.pop("sensor_options"),
                          kw.pop("robot_options"))
    return options_from_flags(section, flags, kw, groups)


@cli.command(name="facility", short_help="Run the emulated facility (Net F/T sensor + ABB EGM robot) in real time.")
@click.argument("scenario")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP)
@_with(_link_flags("facility", _FACILITY_FLAGS))
@click.option("--duration", type=POSITIVE, default=None, metavar="S", help="Stop after S seconds [default: run until Ctrl-C].")
@_with(live_flags())
def facility_command(scenario: str, sets: tuple[str, ...], duration: float | None, live: str | None,
                     live_control: bool, live_remote: bool, live_wait: float, **kw: Any) -> None:
    """Emulate the facility of SCENARIO in real time: an F/T sensor speaking ATI's Net F/T RDT
    protocol (UDP, 1 record per control period, /netftapi2.xml over HTTP) and a robot speaking
    ABB's EGM (UDP + protobuf, feedback every 4 ms to --egm-host:--egm-port, corrections back),
    with the scenario's robot delay, sensor delay and noise, and the contact between them.

    With --live, a Foxglove live view of the facility's physical truth (the commanded pose it
    received, the actual pose, the contact force and moment, the sensor's wrench, its own loop
    timing) and the scene; with --live-control its /hilcontact/stop ends the facility (it stops
    serving; exit 3, reason operator).

    Exit code: 0 stopped by --duration or Ctrl-C, 3 stopped by the live view's operator, 1 a
    port cannot be bound, 2 bad input.

    \b
    Example (then run `hilcontact hil` against it, see there):
      hilcontact facility paper-table1 --set facility.robot_delay=0.02 --http-port 8080
    """
    from ..realtime import start_facility

    with _errors():
        resolved = load_scenario(scenario, parse_set_options(sets))
        options = _realtime_options("facility", _FACILITY_FLAGS, kw)
        settings = live_settings(live, live_control, live_remote, live_wait)
        if settings is not None:
            options["live"] = settings
        facility = start_facility(resolved, options)
    _stop_on_signals()
    a = facility.addresses
    f = resolved.facility
    sensor, robot = facility.status()["sensor_protocol"], facility.status()["robot_protocol"]
    robot_scheme = _scheme("robot", robot)
    click.echo(
        f"ready: facility {resolved.name}: sensor {sensor} {_scheme('sensor', sensor)}://{a['sensor']}, "
        f"netftapi2.xml {'http://' + str(a['http']) + '/netftapi2.xml' if a['http'] else 'off'}, "
        f"robot {robot} {robot_scheme}://{a['robot']} -> {robot_scheme}://{a['robot_peer']}; robot delay {f.robot_delay * 1e3:g} ms, "
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
                now = facility.status()
                if now.get("operator_stop") or now.get("finished"):
                    break
                status.update(_facility_line(now))
    except KeyboardInterrupt:
        pass
    final = facility.stop()
    click.echo("stopped: " + _facility_line(final))
    click.echo("endpoints: " + _facility_errors(final))
    live_summary = live_report_line(final.get("live"))
    if live_summary:
        click.echo(live_summary)
    if final.get("live_samples_dropped"):
        click.echo(f"live view: {final['live_samples_dropped']} periods not shown (its thread fell behind)")
    for refused in (final.get("scheduling") or {}).get("refused", []):
        click.echo(f"facility thread scheduling: {refused}")
    if final.get("operator_stop"):
        click.echo("stop: operator (live view): the facility stopped serving")
        raise click.exceptions.Exit(3)


def _scheduling_options(rt_priority: int | None, no_lock_memory: bool | None, cpu: int | None) -> dict[str, Any] | None:
    """``{"scheduling": ...}``'s value from the values of --rt-priority, --no-lock-memory and
    --cpu (None: the Rust defaults)."""
    given = {"opt_rt_priority": rt_priority, "opt_no_lock_memory": no_lock_memory, "opt_cpu": cpu}
    return options_from_flags("runtime", _SCHEDULING_FLAGS, given).get("scheduling")


def _run_realtime(resolved: Any, options: dict[str, Any], folder: Path, no_plots: bool, force: bool,
                  mcap: Path | None = None, live: dict[str, Any] | None = None) -> None:
    from ..realtime import exit_code, run_hil

    if mcap is not None:
        options = {**options, "mcap": {"path": str(mcap), "overwrite": force}}
    _stop_on_signals()
    stderr = Console(stderr=True)
    if live is not None:
        options = {**options, "live": live}  # the server prints where it listens once bound
    with stderr.status(f"{escape(resolved.name)}: connecting to the sensor and the robot ...") as status:
        result = run_hil(resolved, options, on_status=lambda s: status.update(escape(_hil_line(s))))
    result.save(folder, plots=not no_plots, overwrite=force)
    console = Console()
    _report(console, result, folder)
    _report_realtime(console, result)
    _report_mcap(console, result.mcap)
    live_summary = live_report_line(result.metrics.get("realtime", {}).get("live"))
    if live_summary:
        console.print(escape(live_summary), soft_wrap=True)
    code = exit_code(result)
    if code:
        raise click.exceptions.Exit(code)


@cli.command(name="hil", short_help="Run the HIL loop in real time against a facility (real or emulated).")
@click.argument("scenario")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP)
@_with(_link_flags("runtime", _RUNTIME_FLAGS))
@_with(_run_output_options("runs/<scenario name>-rt"))
@_with(live_flags())
@CALIBRATION_OPTION
def hil_command(scenario: str, sets: tuple[str, ...], out: str | None, no_plots: bool, mcap: str | None, force: bool,
                max_memory: float, max_time: float, live: str | None, live_control: bool, live_remote: bool,
                live_wait: float, **kw: Any) -> None:
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
        calibration = kw.pop("calibration", None)
        resolved = load_scenario(scenario, with_calibration(parse_set_options(sets), calibration))
        check_run(resolved, Limits(max_memory, max_time))
        folder = _out_folder(out, Path("runs") / f"{resolved.name}-rt", force)
        mcap_path = _mcap_file(mcap, folder, force)
        settings = live_settings(live, live_control, live_remote, live_wait)
        _run_realtime(resolved, _realtime_options("runtime", _RUNTIME_FLAGS, kw), folder, no_plots, force, mcap_path,
                      settings)


@cli.command(name="check", short_help="Dry run: connect to the sensor and the robot as `hil` would, command nothing, report.")
@click.argument("scenario")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP)
@_with(_link_flags("runtime", _RUNTIME_FLAGS))
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
            report = check(resolved, _realtime_options("runtime", _RUNTIME_FLAGS, kw), duration)
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
    (every protocol's options have a ``port``; a sensor protocol with an ``http_port`` in the
    options' schema, RDT's /netftapi2.xml, gets a free one too)."""
    defaults = _RT_DEFAULTS.get("facility", {})
    sensor_kind = sensor_protocol or defaults.get("sensor", {}).get("kind", "rdt")
    robot_kind = robot_protocol or defaults.get("robot", {}).get("kind", "egm")
    sensor_socket = socket.SOCK_STREAM if _scheme("sensor", sensor_kind) == "tcp" else socket.SOCK_DGRAM
    sensor = {"kind": sensor_kind, "port": _free_port(sensor_socket)}
    robot_socket = socket.SOCK_STREAM if _scheme("robot", robot_kind) == "tcp" else socket.SOCK_DGRAM
    robot = {"kind": robot_kind, "port": _free_port(robot_socket)}
    if any(flag.path[:2] == ("sensor", sensor_kind) and flag.path[-1] == "http_port" for flag in _FACILITY_FLAGS):
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
@_with([flag.option for flag in _SCHEDULING_FLAGS])
@_with(_run_output_options("runs/<scenario name>-demo-rt"))
@_with(live_flags())
def demo_rt(scenario: str, sets: tuple[str, ...], compensator: str, robot_delay: float, sensor_protocol: str | None,
            robot_protocol: str | None, opt_rt_priority: int | None, opt_no_lock_memory: bool | None, opt_cpu: int | None,
            out: str | None, no_plots: bool, mcap: str | None, force: bool, max_memory: float, max_time: float,
            live: str | None, live_control: bool, live_remote: bool, live_wait: float) -> None:
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
        settings = live_settings(live, live_control, live_remote, live_wait)
        scheduling = _scheduling_options(opt_rt_priority, opt_no_lock_memory, opt_cpu)
        if scheduling:
            runtime_options["scheduling"] = scheduling
        with start_facility(resolved, facility_options) as facility:
            a = facility.addresses
            robot_scheme = _scheme("robot", robot_kind)
            Console(stderr=True).print(
                f"facility: sensor {_scheme('sensor', facility_options['sensor']['kind'])}://{a['sensor']}{', http://' + str(a['http']) + '/netftapi2.xml' if a['http'] else ''}, "
                f"robot {robot_scheme}://{a['robot']} -> {robot_scheme}://{a['robot_peer']}",
                soft_wrap=True,
            )
            try:
                _run_realtime(resolved, runtime_options, folder, no_plots, force, mcap_path, settings)
            finally:
                final = facility.stop()
                if final.get("io_errors"):
                    Console(stderr=True).print("facility " + escape(_facility_errors(final)), soft_wrap=True)
