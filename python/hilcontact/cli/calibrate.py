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

from ..errors import ScenarioError
from ..native import VERSION, core
from ..scenario import load_scenario
from .options import POSITIVE, _errors, _fail, cli, parse_set_options

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


def read_calibration(path: str | os.PathLike[str]) -> dict[str, Any]:
    """A calibration file's tables (``[measured]``, ``[[walls]]``, ``[law]``, ``[robot]``), for
    ``compensator.calibration``; raises ScenarioError naming the file."""
    import tomllib

    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise ScenarioError(f"--calibration {path}: {exc.strerror or exc}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"--calibration {path}: not a TOML file: {exc}") from None
    if not data.get("walls"):
        raise ScenarioError(f"--calibration {path}: no [[walls]]: not a calibration file")
    return data


def with_calibration(overrides: dict[str, Any], path: str | None) -> dict[str, Any]:
    """``overrides`` plus ``compensator.calibration`` from the calibration file at ``path``
    (for ``model-mediated``; none without a path)."""
    if path is None:
        return overrides
    return {**overrides, "compensator.calibration": read_calibration(path)}


#: ``--calibration FILE`` of run, compare, sweep and hil.
CALIBRATION_OPTION = click.option(
    "--calibration", "calibration", metavar="FILE", default=None,
    help="A calibration file (`hilcontact calibrate`): model-mediated renders its walls and law from the first contact "
         "(sets compensator.calibration).",
)


def _write_atomically(path: Path, text: str) -> None:
    fd, staging = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.replace(staging, path)
    except BaseException:
        Path(staging).unlink(missing_ok=True)
        raise


@cli.command(name="calibrate", short_help="Measure the facility's walls, contact law and robot delay with its own robot.")
@click.argument("scenario")
@click.option("--out", "out", required=True, metavar="FILE", help="The calibration file to write (TOML).")
@click.option("--simulate", is_flag=True, help="Against the scenario's simulated facility (the facility model of the true hardware).")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP)
@click.option("--option", "options", multiple=True, metavar="KEY=VALUE",
              help="A procedure option, e.g. --option points_per_side=3 (docs/calibration.md lists them). Repeatable.")
@click.option("--force-limit", type=POSITIVE, default=500.0, show_default=True, metavar="N",
              help="The run's force limit: the probes press to a fifth of it, a force past two fifths stops.")
@click.option("--force", is_flag=True, help="Replace FILE if it exists.")
def calibrate_command(scenario: str, out: str, simulate: bool, sets: tuple[str, ...], options: tuple[str, ...],
                      force_limit: float, force: bool) -> None:
    """Probe each wall of SCENARIO with the robot (approach along the nominal normal, press to a
    force well below the force limit, dwell, retreat; a grid of probes per wall), fit each
    wall's plane, the contact law and the robot's delay with their uncertainties, and write
    them to FILE for `--calibration FILE` (model-mediated).

    \b
    Example:
      hilcontact calibrate paper-table1 --simulate --out cal.toml \\
          --set facility.mount_offset=[0.0005,0,0] --set facility.robot_repeatability=3e-5
      hilcontact run paper-table1 --set compensator.kind=model-mediated --calibration cal.toml
    """
    with _errors():
        target = Path(out)
        if target.is_dir():
            raise ScenarioError(f"--out {out}: is a directory")
        if not target.parent.is_dir():
            raise ScenarioError(f"--out {out}: no such folder {str(target.parent)!r}")
        if target.exists() and not force:
            raise ScenarioError(f"--out {out}: exists; --force replaces it")
        if not simulate:
            raise ScenarioError(
                "calibrate: the real-time procedure over the device links is not built yet; use --simulate"
            )
        resolved = load_scenario(scenario, parse_set_options(sets))
        procedure = _procedure_options(options)
        click.echo(f"calibrating {resolved.name} (simulated facility): {len(resolved.walls)} wall(s)")
        now = datetime.datetime.now(datetime.timezone.utc).replace(microsecond=0).isoformat()
        result = core().calibrate_simulated(
            resolved.to_json(), json.dumps(procedure), float(force_limit), now,
            on_progress=lambda line: click.echo("  " + line),
        )
    if result["error"]:
        _fail(f"calibration stopped: {result['error']} (the contact is released, the robot holds; nothing written)", 1)
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
