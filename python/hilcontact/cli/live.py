"""The live view on the command line: ``--live [HOST:]PORT`` and its companions
(``--live-control``, ``--live-remote``, ``--live-wait``, and ``--speed`` on ``run``), turned into
the options of the Rust ``live`` output (``hilcontact_rt::output::live::LiveOptions``, which
checks them: loopback unless ``--live-remote``, and prints where it listens once bound), the
summary after the run, and ``hilcontact layout`` (the Foxglove layout shipped with the
package)."""

from __future__ import annotations

import json
from importlib import resources
from typing import Any

import click

from ..errors import RealtimeOptionError
from .options import cli

__all__ = ["live_flags", "live_settings", "live_report_line", "layout_text"]

_LIVE_HELP = (
    "Serve a Foxglove live view of the run on [HOST:]PORT (WebSocket, foxglove.sdk.v1 = "
    "foxglove.websocket.v1; HOST defaults to 127.0.0.1, another address needs --live-remote): "
    "the channels of the MCAP recording, the facility in 3-D, the server's clock as run time. "
    "Open it in Foxglove or Lichtblick (ws://HOST:PORT) with the layout of `hilcontact layout`."
)


def live_flags(replay: bool = False) -> list[Any]:
    """The live view's click options; ``replay``: a simulation's (``--speed``, and a wait for a
    viewer by default)."""
    flags = [
        click.option("--live", "live", metavar="[HOST:]PORT", default=None, help=_LIVE_HELP),
        click.option("--live-control", is_flag=True,
                     help="Accept the operator's actions from the live view: /hilcontact/stop "
                          "(the run stops as after a force limit: retreat, hold, exit 3, stop "
                          "'operator') and /hilcontact/mark (an event). Refused (and logged) "
                          "without it."),
        click.option("--live-remote", is_flag=True,
                     help="Allow --live on an address other than loopback: anyone who reaches "
                          "the port sees the run (and with --live-control can stop it)."),
        click.option("--live-wait", type=click.FloatRange(0.0, 3600.0), default=30.0 if replay else 0.0,
                     show_default=True, metavar="S",
                     help="Wait up to S seconds for a viewer to subscribe before the run starts."),
    ]
    if replay:
        flags.append(click.option("--speed", type=click.FloatRange(0.0, 1000.0, min_open=True), default=1.0,
                                  show_default=True, metavar="X",
                                  help="With --live: replay the finished simulation at X times real time."))
    return flags


def _address(text: str) -> tuple[str, int]:
    """``PORT``, ``HOST:PORT`` or ``[IPV6]:PORT`` -> (host, port)."""
    host, sep, port = text.rpartition(":")
    if not sep:
        host, port = "127.0.0.1", text
    host = host.strip("[]") or "127.0.0.1"
    try:
        number = int(port)
    except ValueError:
        number = -1
    if not 0 <= number <= 65535:
        raise RealtimeOptionError(f"--live {text}: expected [HOST:]PORT with PORT from 0 to 65535")
    return host, number


def live_settings(live: str | None, live_control: bool, live_remote: bool, live_wait: float,
                  speed: float | None = None) -> dict[str, Any] | None:
    """The ``live`` output's options from the flags (None without ``--live``); the companions
    without ``--live`` are refused."""
    if live is None:
        for given, flag in ((live_control, "--live-control"), (live_remote, "--live-remote")):
            if given:
                raise RealtimeOptionError(f"{flag}: needs --live [HOST:]PORT")
        return None
    host, port = _address(live)
    settings: dict[str, Any] = {"host": host, "port": port, "remote": live_remote, "control": live_control,
                                "wait": live_wait}
    if speed is not None:
        settings["speed"] = speed
    return settings


def live_report_line(report: dict[str, Any] | None) -> str | None:
    """The live view's summary after the run (``metrics.json`` ``realtime.live``)."""
    if not report:
        return None
    line = (f"live view {report.get('address')}: {report.get('messages')} messages, "
            f"{report.get('connections')} connections (at most {report.get('peak_clients')} at once), "
            f"stop calls {report.get('stop_calls')}, marks {report.get('mark_calls')}, "
            f"refused calls {report.get('refused_calls')}")
    if report.get("outbox_full_reports"):
        line += (f"; clients fell behind and lost their oldest messages: "
                 f"{', '.join(report.get('lossy_clients') or []) or 'unknown'}")
    if report.get("events_dropped"):
        line += f"; {report['events_dropped']} operator events dropped (more than 64 waiting)"
    if report.get("scene_points_dropped"):
        line += f"; {report['scene_points_dropped']} contact points not drawn (more than 16 at once)"
    if report.get("scene_meshes_boxed"):
        line += f"; {report['scene_meshes_boxed']} meshes drawn as their bounding box (over 1024 triangles)"
    return line


def layout_text() -> str:
    """The Foxglove layout shipped with the package (``hilcontact/layouts/hil.json``)."""
    return resources.files("hilcontact").joinpath("layouts/hil.json").read_text()


@cli.command(name="layout", short_help="Print the Foxglove layout of a run (3-D view, force, velocity, energy, loop).")
def layout() -> None:
    """Print the Foxglove (or Lichtblick) layout shipped with hilcontact: the facility in 3-D,
    plots of the contact force, the rod tip's velocity, the energy and the loop's timing, the
    run's events and the stop and mark buttons. Save it and import it in Foxglove (Layouts,
    Import from file):

    \b
      hilcontact layout > hil.json
    """
    click.echo(json.dumps(json.loads(layout_text()), indent=2))
